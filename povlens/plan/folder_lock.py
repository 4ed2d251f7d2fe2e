"""One writer per render folder: ``fcntl.flock`` on the folder's lock file.

Two processes writing one render folder corrupt each other: one deletes the ray mesh
(``sample_KKKK.inc``) another's POV-Ray is reading, or re-plans under a running render.
So every command that writes a folder holds its lock
(:attr:`~povlens.plan.render_folder.RenderFolder.lock_file`) while it runs:

* exclusive: ``povlens render`` (conversion, samples, composite), ``povlens convert``,
  ``povlens render-view``;
* shared: ``povlens render-batch`` and ``povlens composite``, the recipes ``make -jN``
  runs side by side in one folder; each ``render-batch`` also holds its batch's own
  lock (:meth:`~povlens.plan.render_folder.RenderFolder.batch_lock`) exclusively, so
  two ``make`` in one folder never render one batch twice at once.

A command that finds the folder in use says which process holds it (PID and command
line, from ``/proc/locks``, else what the holder wrote into the lock file) and waits
for it to end; Ctrl-C stops the wait.  The kernel drops a lock when its process
ends, however it ends, so a crash never leaves a folder locked.  Locks are
re-entrant within a process (``povlens render`` composites under the lock it holds);
the POV-Ray processes povlens starts do not inherit them (Python's descriptors are
not inheritable).
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import fcntl
import os
import sys
import threading
from pathlib import Path
from typing import Iterator

from povlens.errors import PovlensError, UsageError
from povlens.plan.render_folder import RenderFolder

__all__ = ["folder_lock", "batch_lock", "lock_holders"]

#: Longest command line quoted in the waiting message.
_COMMAND_CHARS = 160


@dataclasses.dataclass
class _Held:
    fd: int
    shared: bool
    count: int = 1


_held: dict[str, _Held] = {}
_guard = threading.Lock()


def _command_of(pid: int) -> str:
    """The command line of process ``pid`` (empty if it cannot be read)."""
    try:
        raw = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return ""
    text = " ".join(" ".join(a.decode(errors="replace").split()) for a in raw.split(b"\0"))
    text = text.strip()
    return text if len(text) <= _COMMAND_CHARS else text[:_COMMAND_CHARS - 3] + "..."


def lock_holders(path: str | os.PathLike) -> list[str]:
    """Who holds a lock on the file ``path``: ``PID N (command line)`` for each holder
    ``/proc/locks`` lists (Linux), else what an exclusive holder wrote into the file."""
    path = Path(path)
    try:
        st = os.stat(path)
        lines = Path("/proc/locks").read_text().splitlines()
    except OSError:
        lines, st = [], None
    pids = []
    if st is not None:
        dev = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
        for line in lines:
            fields = line.split()
            if "FLOCK" in fields and dev in fields and "->" not in fields:
                pid = int(fields[fields.index(dev) - 1])
                if pid != os.getpid() and pid not in pids:
                    pids.append(pid)
    if pids:
        return [f"PID {pid} ({_command_of(pid) or 'command unknown'})" for pid in pids]
    try:
        written = path.read_text().strip()
    except OSError:
        written = ""
    return [written] if written else []


def _open_locked(path: Path, shared: bool, name: str) -> int:
    """Open ``path`` (created if need be) and lock it; a descriptor of the file now at
    ``path`` (a holder that removed it meanwhile: open the new one)."""
    op = fcntl.LOCK_SH if shared else fcntl.LOCK_EX
    said = False
    while True:
        path.parent.mkdir(parents=True, exist_ok=True)     # removed by a failed holder
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        try:
            try:
                fcntl.flock(fd, op | fcntl.LOCK_NB)
            except BlockingIOError:
                if not said:
                    holders = "; ".join(lock_holders(path)) or "another process"
                    print(f"povlens: {name} is in use by {holders}; waiting until it is "
                          f"free (Ctrl-C stops waiting)", file=sys.stderr, flush=True)
                    said = True
                fcntl.flock(fd, op)
            if os.path.exists(path) and os.path.samestat(os.fstat(fd), os.stat(path)):
                return fd
        except BaseException:
            os.close(fd)
            raise
        os.close(fd)


def _write_holder(fd: int) -> None:
    """An exclusive holder writes ``PID N (command)`` into the lock file: what a
    waiter shows where ``/proc/locks`` is not there."""
    text = f"PID {os.getpid()} ({' '.join(sys.argv)[:_COMMAND_CHARS]})\n".encode()
    os.ftruncate(fd, 0)
    os.pwrite(fd, text, 0)


@contextlib.contextmanager
def _locked(path: Path, shared: bool, name: str) -> Iterator[None]:
    """Hold the lock of file ``path`` (re-entrant in this process: a nested request
    of a lock held exclusively, or shared within shared, just goes on)."""
    key = os.path.realpath(path)
    with _guard:
        held = _held.get(key)
        if held is not None:
            if held.shared and not shared:
                raise PovlensError(f"{name}: an exclusive lock asked for under a shared one",
                                   "this is a bug in povlens; please report it")
            held.count += 1
    if held is None:
        try:
            fd = _open_locked(path, shared, name)
        except OSError as e:
            if e.errno not in (errno.EACCES, errno.EPERM, errno.EROFS):
                raise
            if not shared:
                raise UsageError(f"{name}: cannot lock the folder ({e.strerror})",
                                 "check that you may write in it") from None
            yield                           # a read-only folder: nobody writes it
            return
        if not shared:
            _write_holder(fd)
        with _guard:
            held = _held[key] = _Held(fd, shared)
    try:
        yield
    finally:
        with _guard:
            held.count -= 1
            if held.count == 0:
                del _held[key]
                os.close(held.fd)          # releases the lock


@contextlib.contextmanager
def folder_lock(outdir: str | os.PathLike, shared: bool = False) -> Iterator[None]:
    """Hold the render folder ``outdir``'s lock during the block: exclusive (a writer
    that changes the plan or renders everything) or ``shared`` (make's recipes).

    The folder is created if it does not exist; if the block fails and leaves the new
    folder holding only the lock file, both are removed (a refused conversion writes
    nothing)."""
    folder = RenderFolder(outdir)
    created = not folder.path.is_dir()
    folder.path.mkdir(parents=True, exist_ok=True)
    try:
        with _locked(folder.lock_file, shared, os.path.abspath(folder.path)):
            yield
    except BaseException:
        if created and [p.name for p in folder.path.iterdir()] == [folder.lock_file.name]:
            with contextlib.suppress(OSError):
                folder.lock_file.unlink()
                folder.path.rmdir()
        raise


@contextlib.contextmanager
def batch_lock(outdir: str | os.PathLike, batch: int) -> Iterator[None]:
    """Hold batch ``batch``'s own lock (exclusive) and the folder's shared lock: what
    ``povlens render-batch`` holds."""
    folder = RenderFolder(outdir)
    with folder_lock(outdir, shared=True):
        with _locked(folder.batch_lock(batch), False,
                     f"{os.path.abspath(folder.path)} (batch {batch})"):
            yield
