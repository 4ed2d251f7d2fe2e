"""Atomic file output: a file appears at its final name complete or not at all.

Every writer in povlens goes through :func:`atomic_output` (a temporary name in the
same folder, renamed on success, removed on failure).  Text read from users' files is
decoded by :func:`decode_text` (UTF-16 as Windows editors and Zemax write it, UTF-8,
Latin-1).
"""
from __future__ import annotations

import contextlib
import os
import uuid
from pathlib import Path
from typing import Iterator

from povlens.errors import UsageError


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
    was, so a half-written file never appears under the final name.
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
        os.replace(tmp, final)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
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
