"""Running POV-Ray: finding the executable, its version, and one render.

Everything here follows the measured behaviour of POV-Ray 3.7.0.10 described
in ``/work/shared/reference/povray-mesh-camera.md`` (§10):

* ``-D`` is required (Debian's ``povray.ini`` sets ``Display=On``);
  ``-V -GR -GS`` leave only warnings and errors on stderr (plus a banner);
* exit code 0 on success (also with warnings), 1 on a parse error or a
  missing input file;
* a failed render deletes or truncates the output file, so :func:`render`
  always writes to a temporary name next to the final file and renames it
  only on success;
* the fatal-error log (``+GF``) must be given as a bare file name; POV-Ray
  writes it into the image's folder and refuses any name with a folder part
  ("Stream output files must reside in same directory as image output file");
* ``+SR``/``+ER``/``+SC``/``+EC`` values in (0, 1] are fractions of the image,
  so "+ER1" means the whole height; :func:`render` takes 0-based pixel
  ranges and writes them unambiguously;
* POV-Ray resolves ``#include`` and image-map file names relative to its
  working directory and its library paths (``+L``), *not* relative to the
  file that contains the ``#include``.  :func:`render` runs in the folder of
  the ``.pov`` file; pass the folders of included scenes as
  ``library_paths``.

The executable is ``$POVLENS_POVRAY`` if that is set, else ``povray`` on
``PATH``.
"""

from __future__ import annotations

import contextlib
import functools
import io
import json
import os
import re
import shlex
import shutil
import subprocess
import tempfile
import time
import uuid
from pathlib import Path
from typing import Iterable, Sequence

from povlens.errors import PovrayError, UsageError
from povlens.util.files import atomic_output

__all__ = [
    "ENV_VAR",
    "find_povray",
    "povray_version",
    "needs_row_workaround",
    "render",
    "start_render",
    "RenderJob",
    "output_written",
]

#: Environment variable that overrides which POV-Ray executable is used.
ENV_VAR = "POVLENS_POVRAY"

#: Output file suffix -> POV-Ray output-format switch.
_FORMATS = {".exr": "+FE", ".png": "+FN", ".hdr": "+FH", ".tga": "+FT", ".ppm": "+FP"}

#: Lines of POV-Ray's start-up banner and progress output that carry no
#: information about a failure.
_NOISE = re.compile(
    r"^(povray: cannot open the user configuration file|==== \[|POV-Ray finished)"
)


# ---------------------------------------------------------------------------


# ---------------------------------------------------------------------------
# the executable and its version


def find_povray() -> str:
    """Absolute path of the POV-Ray executable, or :class:`PovrayError`.

    ``$POVLENS_POVRAY`` (a path or a command name) overrides ``povray`` on PATH.
    """
    override = os.environ.get(ENV_VAR)
    if override:
        found = shutil.which(override)
        if found is None:
            raise PovrayError(
                f"{ENV_VAR}={override!r} is not an executable POV-Ray program",
                f"point {ENV_VAR} to the povray executable, or unset it to use "
                "'povray' from PATH",
            )
        return os.path.abspath(found)
    found = shutil.which("povray")
    if found is None:
        raise PovrayError(
            "POV-Ray (the 'povray' program) was not found on PATH",
            "install it (Debian/Ubuntu: apt-get install povray) or set "
            f"{ENV_VAR} to the povray executable",
        )
    return os.path.abspath(found)


def _version_cache_path() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "povlens" / "povray-version.json"


def _binary_key(executable: str) -> str | None:
    """Identity of an executable file for the version cache: its real path, inode,
    size and modification time.  None for scripts (a wrapper's POV-Ray may change
    while the wrapper does not) and for what cannot be read."""
    try:
        real = os.path.realpath(executable)
        with open(real, "rb") as f:
            if f.read(4) != b"\x7fELF":
                return None
        st = os.stat(real)
    except OSError:
        return None
    return f"{real}:{st.st_ino}:{st.st_size}:{st.st_mtime_ns}"


@functools.lru_cache(maxsize=None)
def _version_of(executable: str) -> str:
    """POV-Ray's version, remembered across runs in the user's cache folder
    (``$XDG_CACHE_HOME/povlens/povray-version.json``): ``povray --version`` takes
    ~0.2 s, mostly idle start-up, on every conversion otherwise.  The entry is
    keyed by the binary's path, inode, size and mtime, so an upgrade asks again."""
    key = _binary_key(executable)
    cache = _version_cache_path()
    known: dict = {}
    if key is not None:
        try:
            known = json.loads(cache.read_text())
            if isinstance(known.get(key), str):
                return known[key]
        except (OSError, ValueError, AttributeError):
            known = {}
    version = _ask_version(executable)
    if key is not None:
        try:
            cache.parent.mkdir(parents=True, exist_ok=True)
            tmp = cache.with_name(f".{cache.name}.{os.getpid()}")
            tmp.write_text(json.dumps({**(known if isinstance(known, dict) else {}),
                                       key: version}) + "\n")
            os.replace(tmp, cache)
        except OSError:
            pass                     # no cache folder: ask again next time
    return version


def _ask_version(executable: str) -> str:
    try:
        proc = subprocess.run(
            [executable, "--version"],
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            errors="replace",
            timeout=60,
        )
    except OSError as exc:
        raise PovrayError(
            f"cannot run POV-Ray at {executable}: {exc.strerror or exc}",
            f"check the installation or set {ENV_VAR} to a working povray",
        ) from None
    except subprocess.TimeoutExpired:
        raise PovrayError(
            f"'{executable} --version' did not finish within 60 s",
            f"check the installation or set {ENV_VAR} to a working povray",
        ) from None
    text = proc.stdout + "\n" + proc.stderr
    m = re.search(r"POV-Ray\s+(?:v(?:ersion)?\s*)?(\d+(?:\.\d+)+)", text)
    if m is None:
        raise PovrayError(
            f"'{executable} --version' did not report a POV-Ray version; it printed:\n"
            + _tail(text),
            f"set {ENV_VAR} to the povray executable",
        )
    return m.group(1)


def povray_version(executable: str | None = None) -> str:
    """POV-Ray's version number, e.g. ``"3.7.0.10"`` (cached per executable)."""
    return _version_of(executable or find_povray())


def needs_row_workaround(version: str) -> bool:
    """True for POV-Ray 3.7.0.x, whose mesh_camera repeats the first face row.

    (FS#254, fixed in 3.7.1/3.8.)  Such versions need a ``W x (H+1)`` render
    whose top output row is dropped; see :func:`povlens.mesh_camera.render_size`.
    """
    parts = version.split(".")
    return parts[:3] == ["3", "7", "0"]


# ---------------------------------------------------------------------------
# rendering


def _tail(text: str, lines: int = 25) -> str:
    kept = [ln for ln in text.splitlines() if ln.strip()]
    return "\n".join(kept[-lines:])


def _strip_banner(lines: list[str]) -> list[str]:
    """Drop POV-Ray's start-up banner (everything up to the library list)."""
    start = next((i for i, ln in enumerate(lines) if ln.startswith("==== [")), None)
    if start is not None:
        return lines[start:]
    hdr = next((i for i, ln in enumerate(lines) if ln.startswith("Support libraries used by")), None)
    if hdr is None:
        return lines
    i = hdr + 1
    while i < len(lines) and (lines[i].startswith(" ") or not lines[i].strip()):
        i += 1
    return lines[i:]


def _error_text(stderr: str, log_text: str) -> str:
    """POV-Ray's own description of a failure, without the start-up banner."""
    body = _strip_banner(stderr.splitlines())
    body = [ln for ln in body if ln.strip() and not _NOISE.match(ln)]
    parts = []
    if log_text.strip():
        parts.append(log_text.strip())
    if body:
        stderr_text = "\n".join(dict.fromkeys(body[-25:]))  # drop repeated lines
        if stderr_text not in log_text:
            parts.append(stderr_text)
    if not parts:
        parts.append(_tail(stderr) or "(POV-Ray printed nothing)")
    return "\n".join(parts)


def _span_args(
    start: int | None, end: int | None, size: int, start_flag: str, end_flag: str, what: str
) -> list[str]:
    """POV-Ray +S?/+E? switches for the 0-based half-open span [start, end).

    POV-Ray counts from 1 and reads values in (0, 1] as fractions of the
    image, so "+ER1" would mean the whole image; an end of 1 is therefore
    written as the fraction 1.5/size, which POV-Ray truncates to row 1.
    """
    s = 0 if start is None else int(start)
    e = size if end is None else int(end)
    if not (0 <= s < e <= size):
        raise UsageError(
            f"bad {what} range [{start}, {end}) for an image {size} pixels wide/high",
            f"use 0 <= start_{what} < end_{what} <= {size}",
        )
    args = []
    if s > 0:
        args.append(f"{start_flag}{s + 1}")  # >= 2: always read as a pixel number
    if e < size:
        args.append(f"{end_flag}{e}" if e >= 2 else f"{end_flag}{1.5 / size:.9f}")
    return args


def render(
    pov_path: str | os.PathLike,
    out_path: str | os.PathLike,
    width: int,
    height: int,
    *,
    extra_args: Sequence[str] = (),
    threads: int = 1,
    cwd: str | os.PathLike | None = None,
    start_row: int | None = None,
    end_row: int | None = None,
    start_col: int | None = None,
    end_col: int | None = None,
    library_paths: Iterable[str | os.PathLike] = (),
    timeout: float | None = None,
) -> Path:
    """Render ``pov_path`` to ``out_path`` (``width`` x ``height`` pixels).

    Runs ``povray -D -V -GR -GS +I<pov> +O<tmp> +F? +W +H -A +WT<threads>
    [+SR +ER +SC +EC] [+L...] [extra_args]`` with the working directory set to
    the folder of ``pov_path`` (or ``cwd``).  The output format follows the
    suffix of ``out_path`` (``.exr`` -> OpenEXR, linear half float; also
    ``.png``, ``.hdr``, ``.tga``, ``.ppm``).  Anti-aliasing is off (``-A``);
    ``extra_args`` come last and may override it.

    ``start_row``/``end_row`` and ``start_col``/``end_col`` select a
    sub-rectangle as 0-based half-open pixel ranges (row 0 = top); the output
    file still has the full ``width`` x ``height`` size and untraced pixels
    are black.

    The image is written to a temporary name in the folder of ``out_path`` and
    renamed on success; on failure ``out_path`` is not touched.  Returns
    ``out_path`` as a :class:`Path`.

    Raises :class:`PovrayError` (carrying POV-Ray's own error text) if POV-Ray
    is missing or exits with a non-zero status, :class:`UsageError` for bad
    arguments.  :func:`start_render` is the same without waiting.
    """
    return start_render(
        pov_path, out_path, width, height, extra_args=extra_args, threads=threads, cwd=cwd,
        start_row=start_row, end_row=end_row, start_col=start_col, end_col=end_col,
        library_paths=library_paths, timeout=timeout,
    ).wait()  # fmt: skip


@functools.lru_cache(maxsize=None)
def _priority_tools() -> tuple[str | None, str | None]:
    """Paths of util-linux ``chrt`` and coreutils ``nice``, or None.  ``chrt`` only
    where Python knows ``SCHED_IDLE`` and a first ``chrt --idle 0 true`` works (a
    sandbox may forbid the policy: chrt would then fail instead of running POV-Ray;
    the ``preexec_fn`` falls back to nice 19)."""
    chrt = shutil.which("chrt") if hasattr(os, "SCHED_IDLE") else None
    true = shutil.which("true")
    if chrt is not None:
        try:
            ok = true is not None and subprocess.run(
                [chrt, "--idle", "0", true], stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=10).returncode == 0
        except (OSError, subprocess.SubprocessError):
            ok = False
        chrt = chrt if ok else None
    return chrt, shutil.which("nice")


def _lower_priority(nice: int, idle: bool) -> tuple[list[str], object]:
    """How :func:`start_render` lowers POV-Ray's priority: (command prefix,
    ``preexec_fn``).

    A prefix program where there is one: ``chrt --idle 0`` (``SCHED_IDLE``) or
    ``nice -n N``, which sets the policy and execs POV-Ray in the same process.
    Popen then starts the child with ``vfork``; a ``preexec_fn`` forces a full
    ``fork`` of this (large, threaded) process: 6.3-6.6 ms of the caller's time
    per start instead of 0.8-1.1 ms (measured, 160 MB process), with the
    interpreter lock held, which the thread writing lens samples waits for.  The
    ``preexec_fn`` (the same settings, made in the child) is the fallback."""
    chrt, nice_cmd = _priority_tools()
    if idle:
        if chrt is not None:
            return [chrt, "--idle", "0"], None

        def lower():
            try:
                os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
            except (AttributeError, OSError):
                os.nice(19)
        return [], lower
    if nice > 0:
        if nice_cmd is not None:
            return [nice_cmd, "-n", str(int(nice))], None
        return [], lambda: os.nice(nice)
    return [], None


def start_render(
    pov_path: str | os.PathLike,
    out_path: str | os.PathLike,
    width: int,
    height: int,
    *,
    extra_args: Sequence[str] = (),
    threads: int = 1,
    cwd: str | os.PathLike | None = None,
    start_row: int | None = None,
    end_row: int | None = None,
    start_col: int | None = None,
    end_col: int | None = None,
    library_paths: Iterable[str | os.PathLike] = (),
    timeout: float | None = None,
    nice: int = 0,
    idle: bool = False,
) -> "RenderJob":
    """Start the render :func:`render` describes and return at once.

    ``nice`` > 0 lowers the process's scheduling priority (``os.nice``).  ``idle``
    runs it only on CPU time nothing else wants (Linux ``SCHED_IDLE``; ``nice 19``
    where the OS has no such policy): a render started on a guess yields the cores
    to the work that decides whether it is needed, and gets them all once that
    work is done.

    POV-Ray 3.7 spends most of a small render's wall time idle (~0.6 s per
    process, a few ms of CPU), so independent renders are best started together
    and collected with :meth:`RenderJob.wait`, which renames the image into place
    or raises the error :func:`render` would.  ``timeout`` counts from the start.
    Bad arguments and a missing POV-Ray raise here, before any process starts.
    """
    pov_path = Path(pov_path).resolve()
    out_path = Path(out_path).absolute()
    if not pov_path.is_file():
        raise UsageError(f"scene file {pov_path} does not exist", "check the path")
    fmt = _FORMATS.get(out_path.suffix.lower())
    if fmt is None:
        raise UsageError(
            f"cannot render to {out_path}: unknown image suffix {out_path.suffix!r}",
            "use one of " + ", ".join(sorted(_FORMATS)),
        )
    width, height, threads = int(width), int(height), int(threads)
    if width < 1 or height < 1:
        raise UsageError(f"bad image size {width}x{height}", "width and height must be >= 1")
    if threads < 1:
        raise UsageError(f"bad thread count {threads}", "use threads >= 1")
    spans = _span_args(start_row, end_row, height, "+SR", "+ER", "row")
    spans += _span_args(start_col, end_col, width, "+SC", "+EC", "col")

    executable = find_povray()
    workdir = Path(cwd).absolute() if cwd is not None else pov_path.parent
    stack = contextlib.ExitStack()
    try:
        tmp = stack.enter_context(atomic_output(out_path))
        # POV-Ray 3.7 takes the fatal-error log ("stream") file as a bare name
        # and writes it into the image's folder ("Stream output files must
        # reside in same directory as image output file" otherwise).
        log = tmp.parent / f".povlens-{os.getpid()}-{uuid.uuid4().hex[:12]}.log"
        stack.callback(lambda: log.unlink(missing_ok=True))
        # Relative names where possible: POV-Ray's I/O restrictions permit the
        # working directory.
        inp = os.path.relpath(pov_path, workdir) if _inside(pov_path, workdir) else str(pov_path)
        outp = os.path.relpath(tmp, workdir) if _inside(tmp, workdir) else str(tmp)
        cmd = [
            executable, "-D", "-V", "-GR", "-GS", f"+GF{log.name}",
            f"+I{inp}", f"+O{outp}", fmt, f"+W{width}", f"+H{height}", "-A", f"+WT{threads}",
            *spans,
            *(f"+L{Path(p).absolute()}" for p in library_paths),
            *extra_args,
        ]  # fmt: skip
        # stderr goes to an unnamed file, not a pipe: nobody reads it while POV-Ray
        # runs, and a chatty scene must not block on a full pipe.
        err = stack.enter_context(tempfile.TemporaryFile())
        prefix, preexec = _lower_priority(nice, idle)
        try:
            proc = subprocess.Popen(
                prefix + cmd,
                cwd=workdir,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                stderr=err,
                preexec_fn=preexec,
            )
        except FileNotFoundError:
            raise PovrayError(
                f"POV-Ray at {executable} could not be started",
                f"check the installation or set {ENV_VAR} to a working povray",
            ) from None
        except OSError as exc:
            raise PovrayError(
                f"cannot run POV-Ray ({executable}) in {workdir}: {exc.strerror or exc}",
                "check that the folder exists and the program is executable",
            ) from None
    except BaseException as exc:
        stack.__exit__(type(exc), exc, exc.__traceback__)
        raise
    deadline = None if timeout is None else time.monotonic() + timeout
    return RenderJob(proc, stack, cmd, workdir, pov_path, out_path, tmp, log, err,
                     timeout, deadline)


#: No POV-Ray run has written its image this soon after its start (s): a 64x48
#: image appears 0.33 s after the start (:func:`output_written`), POV-Ray's start-up
#: alone sits idle ~0.2 s.  Waiting jobs are not examined before then, and are
#: polled less often, so they take less time from the Python threads that work.
FIRST_OUTPUT_S = 0.2


def output_written(pid: int, path: Path) -> bool:
    """True once process ``pid`` has written ``path`` and closed it (Linux: no
    descriptor in /proc/PID/fd points to it).

    POV-Ray 3.7 writes its image in one go at the end of the render and then
    spends ~0.3 s idle before it exits (measured: a 64x48 image appears 0.33 s
    after the start, the process exits at 0.64-0.68 s).  The image is final once
    closed, so the caller need not wait for the exit.  Only a process running a
    POV-Ray executable is judged early: a wrapper script in POVLENS_POVRAY (its
    executable is the shell) may still have work to do after its POV-Ray child
    exits, so it gives False until it exits.  A process with children is never
    judged early either.
    """
    try:
        if "povray" not in os.path.basename(os.readlink(f"/proc/{pid}/exe")):
            return False
        if Path(path).stat().st_size == 0:
            return False
        for task in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{task}/children") as f:
                if f.read().strip():
                    return False
        target = str(Path(path).resolve())
        fd_dir = f"/proc/{pid}/fd"
        for fd in os.listdir(fd_dir):
            try:
                if os.readlink(f"{fd_dir}/{fd}") == target:
                    return False
            except OSError:
                continue
        return True
    except OSError:
        return False


class RenderJob:
    """A POV-Ray render started by :func:`start_render`."""

    def __init__(self, proc, stack, cmd, workdir, pov_path, out_path, tmp, log, err,
                 timeout, deadline):
        self.proc, self.cmd, self.pov_path, self.out_path = proc, cmd, pov_path, out_path
        self._stack, self._workdir, self._tmp, self._log, self._err = stack, workdir, tmp, log, err
        self._timeout, self._deadline = timeout, deadline
        self._started = time.monotonic()
        self._done = False

    def wait(self) -> Path:
        """Wait for POV-Ray; rename the image into place and return its path.

        Raises :class:`PovrayError` with POV-Ray's own message if it failed (or ran
        past the timeout: it is killed); the temporary image is removed then."""
        if self._done:
            raise RuntimeError("RenderJob.wait called twice")
        self._done = True
        try:
            self._collect()
        except BaseException as exc:
            self._kill()
            self._stack.__exit__(type(exc), exc, exc.__traceback__)  # drops the temporary image
            raise
        self._stack.close()  # renames the image to out_path, removes the log
        return self.out_path

    def cancel(self) -> None:
        """Stop POV-Ray (if still running) and remove its temporary files."""
        if self._done:
            return
        self._done = True
        self._kill()
        try:
            raise PovrayError(f"render of {self.pov_path} cancelled")
        except PovrayError as exc:
            self._stack.__exit__(type(exc), exc, exc.__traceback__)

    def _kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()

    def _collect(self) -> None:
        # Poll rather than wait: the image is final when POV-Ray has closed it,
        # ~0.3 s before the process exits (output_written); it is stopped then.
        while True:
            returncode = self.proc.poll()
            if returncode is not None:
                break
            if time.monotonic() - self._started < FIRST_OUTPUT_S:
                time.sleep(0.02)    # too young to have written its image: fewer wake-ups
                continue
            if output_written(self.proc.pid, self._tmp):
                self.proc.kill()  # SIGTERM would run POV-Ray's slow shutdown
                self.proc.wait()
                returncode = 0
                break
            if self._deadline is not None and time.monotonic() > self._deadline:
                raise PovrayError(
                    f"POV-Ray did not finish rendering {self.pov_path} within {self._timeout} s",
                    "render a smaller image, or raise the time limit",
                )
            time.sleep(0.005)
        self._err.seek(0)
        stderr = io.TextIOWrapper(io.BytesIO(self._err.read()), errors="replace").read()
        log_text = self._log.read_text(errors="replace") if self._log.exists() else ""
        if returncode != 0:
            raise PovrayError(
                f"POV-Ray failed on {self.pov_path} (exit status {returncode}):\n"
                + _error_text(stderr, log_text)
                + f"\n(command, run in {self._workdir}: {shlex.join(self.cmd)})",
                "fix the scene file named above, or run the command by hand "
                "to see POV-Ray's whole output",
            )
        if not self._tmp.exists() or self._tmp.stat().st_size == 0:
            raise PovrayError(
                f"POV-Ray reported success on {self.pov_path} but wrote no image:\n"
                + _error_text(stderr, log_text),
                "check that the output folder is writable by POV-Ray "
                "(see /etc/povray/3.7/povray.conf, [Permitted Paths])",
            )


def _inside(path: Path, folder: Path) -> bool:
    try:
        Path(path).resolve().relative_to(Path(folder).resolve())
        return True
    except ValueError:
        return False
