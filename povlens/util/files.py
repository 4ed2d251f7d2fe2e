"""Atomic file output: a file appears at its final name complete or not at all.

Every writer in povlens goes through :func:`atomic_output` (a temporary name in the
same folder, renamed on success, removed on failure).  A write the system refuses (a
full device, a quota, a read-only file system, no permission) raises
:class:`~povlens.errors.WriteError` naming the final path and the cause
(:func:`write_error`), not a bare ``[Errno 28]``.  Text read from users' files is
decoded by :func:`decode_text` (UTF-16 as Windows editors and Zemax write it, UTF-8,
Latin-1).
"""
from __future__ import annotations

import contextlib
import errno
import os
import uuid
from pathlib import Path
from typing import Iterator

from povlens.errors import PovrayError, UsageError, WriteError

__all__ = ["temporary_path", "atomic_output", "write_text", "write_bytes", "decode_text",
           "WRITE_ERRNOS", "free_bytes", "write_error", "write_error_reason", "write_error_hint"]

#: errno values of a write the system refused, and the cause in words.
WRITE_ERRNOS = {
    errno.ENOSPC: "no space left on device",
    errno.EDQUOT: "disk quota exceeded",
    errno.EROFS: "read-only file system",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
    errno.EFBIG: "file too large (the file size limit, ulimit -f, or the file system's)",
}

#: A folder with less free space than this (bytes) counts as full when a write into it
#: failed without saying why (a library's error, POV-Ray's "Cannot access data in file").
FULL_BELOW_BYTES = 64 * 1024

#: What libraries say when a write failed for want of space.
_NO_SPACE_WORDS = ("no space left", "disk quota")


def free_bytes(folder: str | os.PathLike) -> int | None:
    """Bytes this process may still write on the file system of ``folder``
    (``os.statvfs``: f_bavail x f_frsize; f_bfree for root, who may use the blocks
    reserved for it), or None where it cannot be asked or the file system tells no
    size (f_blocks 0: an unlimited tmpfs, some FUSE file systems)."""
    try:
        st = os.statvfs(folder)
    except (OSError, AttributeError):
        return None
    if st.f_blocks == 0:
        return None
    blocks = st.f_bfree if hasattr(os, "geteuid") and os.geteuid() == 0 else st.f_bavail
    return blocks * st.f_frsize


def write_error_reason(folder: str | os.PathLike, code: int | None) -> str:
    """The cause of a refused write into ``folder`` in words, for errno ``code``
    (:data:`WRITE_ERRNOS`); a full device's message gives the free space left."""
    reason = WRITE_ERRNOS.get(code, os.strerror(code) if code else "the write failed")
    if code in (errno.ENOSPC, errno.EDQUOT):
        free = free_bytes(folder)
        if free is not None:
            reason += f" ({free} bytes free on the file system of {folder})"
    return reason


def write_error_hint(code: int | None) -> str:
    """What to do about a write refused with errno ``code``."""
    if code in (errno.EROFS, errno.EACCES, errno.EPERM):
        return "write to another folder, or make this one writable"
    if code == errno.EFBIG:
        return "raise the file size limit (ulimit -f), or render a smaller image"
    return ("free some space there (or raise the quota), or write to another folder; "
            "a rerun resumes where this one stopped")


def write_error(final: str | os.PathLike, exc: BaseException) -> WriteError | None:
    """The :class:`~povlens.errors.WriteError` that ``exc``, raised while writing
    ``final``, stands for; None if it is no refused write.

    An ``OSError`` with an errno of :data:`WRITE_ERRNOS`; an error of a library (or a
    povlens error) that says "No space left on device"; or any other error but
    POV-Ray's (classified by :func:`povlens.pov.povray_output.povray_failure`) while
    the folder has (almost) no free space left (OpenImageIO: "Failed to write pixel
    data").
    """
    final = Path(final)
    folder = final.parent
    if isinstance(exc, WriteError) or not isinstance(exc, Exception):
        return None
    if isinstance(exc, OSError) and exc.errno in WRITE_ERRNOS:
        named = Path(os.fsdecode(exc.filename)) if exc.filename else None
        if named is None or named.parent == folder:       # final, or its temporary name
            return WriteError(final, write_error_reason(folder, exc.errno),
                              hint=write_error_hint(exc.errno), code=exc.errno)
        if exc.errno in (errno.EACCES, errno.EPERM):      # another file: perhaps a read
            return None
        return WriteError(named, write_error_reason(named.parent, exc.errno),
                          hint=write_error_hint(exc.errno), code=exc.errno)
    text = getattr(exc, "message", None) or str(exc)      # a povlens error: without hint
    if any(w in text.lower() for w in _NO_SPACE_WORDS):
        return WriteError(final, write_error_reason(folder, errno.ENOSPC),
                          f"cannot write {final}: {write_error_reason(folder, errno.ENOSPC)}"
                          f" ({text.strip()})", code=errno.ENOSPC)
    free = free_bytes(folder)
    if not isinstance(exc, (OSError, PovrayError)) and free is not None \
            and free < FULL_BELOW_BYTES:
        return WriteError(final, write_error_reason(folder, errno.ENOSPC),
                          f"cannot write {final}: {write_error_reason(folder, errno.ENOSPC)}"
                          f" ({type(exc).__name__}: {text.strip()})", code=errno.ENOSPC)
    return None


def temporary_path(final: str | os.PathLike) -> Path:
    """A fresh temporary file name in the folder of ``final``, same suffix.

    The suffix is kept so that tools that pick a format from the file name
    (POV-Ray, OpenImageIO) write the right format.  The file is not created
    (so it gets ordinary permissions when it is written).
    """
    final = Path(final)
    return final.parent / f".{final.stem}.{os.getpid()}-{uuid.uuid4().hex[:12]}.tmp{final.suffix}"


@contextlib.contextmanager
def atomic_output(final: str | os.PathLike) -> Iterator[Path]:
    """Context manager: yields a temporary path; renames it to ``final`` on success.

    On an exception the temporary file is removed and ``final`` is left as it
    was, so a half-written file never appears under the final name.  A write the
    system refused (:func:`write_error`: a full device, a quota, a read-only file
    system, no permission) is raised as :class:`~povlens.errors.WriteError` naming
    ``final`` (the free space is measured before the temporary file is removed).
    """
    final = Path(final)
    if not final.parent.is_dir():
        raise UsageError(
            f"cannot write {final}: folder {final.parent} does not exist",
            "create the folder or choose another output path",
        )
    tmp = temporary_path(final)
    try:
        yield tmp
        if free_bytes(final.parent) == 0 and tmp.exists():
            # Some writers (OpenImageIO's PNG) report no error when the device fills:
            # a file written up to the last free byte is taken as cut short.
            raise WriteError(final, "no space left on device (the file system is full "
                                    "after the write: the file may be cut short)",
                             hint=write_error_hint(errno.ENOSPC), code=errno.ENOSPC)
        os.replace(tmp, final)
    except BaseException as exc:
        refused = write_error(final, exc)
        with contextlib.suppress(OSError):
            tmp.unlink()
        if refused is not None:
            raise refused from exc
        raise


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (temporary name + rename)."""
    path = Path(path)
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary name + rename)."""
    path = Path(path)
    with atomic_output(path) as tmp:
        tmp.write_bytes(data)
    return path


def decode_text(raw: bytes) -> str:
    """Text of a file in UTF-16 (with or without byte-order mark), UTF-8 or Latin-1.

    Optical-design programs write UTF-16 LE with a BOM (Zemax OpticStudio), older
    ones ASCII; a file without BOM whose every other byte is NUL is UTF-16 too.
    """
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        return raw.decode("utf-16")
    if raw.startswith(b"\xef\xbb\xbf"):
        return raw[3:].decode("utf-8", errors="replace")
    head = raw[:400]
    if len(head) >= 2 and head.count(b"\x00") * 3 > len(head):
        odd_nuls = head[1::2].count(b"\x00")
        return raw.decode("utf-16-le" if odd_nuls >= head[0::2].count(b"\x00") else "utf-16-be",
                          errors="replace")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("latin-1")
