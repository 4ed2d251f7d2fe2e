"""Atomic file output: a file appears at its final name complete or not at all.

Every writer in povlens goes through :func:`atomic_output` (a temporary name in the
same folder, renamed on success, removed on failure).
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
