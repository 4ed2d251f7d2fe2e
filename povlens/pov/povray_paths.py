"""Paths as POV-Ray 3.7 can read them.

Measured on Debian's POV-Ray 3.7.0.10:

* its command line is split again at spaces, so ``+L/a dir`` fails ("Problem with
  option setting"); a quoted value, ``+L"/a dir"`` or ``Name="/a dir"``, works;
* a path with a character outside ASCII never opens, quoted or not, on the command
  line or in ``#include`` ("Non-ASCII character has been replaced"); an ASCII name
  that is a symbolic link to it does.

So a path POV-Ray is given is written as it is when it is plain ASCII without spaces
or quotes, quoted when it only has spaces, and otherwise replaced by an ASCII
symbolic link (:func:`ascii_alias`): a per-user folder of links named by a hash of the
real path, made atomically, so any number of processes share them.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

from povlens.errors import PovlensError

__all__ = ["readable_by_povray", "command_line_path", "quoted_value", "ascii_alias",
           "alias_folder", "include_text"]


def readable_by_povray(text: str) -> bool:
    """True when POV-Ray reads ``text`` as written: printable ASCII, no space, no quote."""
    return text.isascii() and text.isprintable() and not any(c in text for c in ' "\t')


def quoted_value(text: str) -> str:
    """``text`` as one value on POV-Ray's command line: quoted when it has whitespace
    (and is not quoted already)."""
    if any(c.isspace() for c in text) and not (text.startswith('"') and text.endswith('"')):
        return f'"{text}"'
    return text


def alias_folder() -> Path:
    """The folder of this user's ASCII links (made, mode 0700, owned by this user)."""
    for base in (tempfile.gettempdir(), "/tmp"):
        folder = Path(base) / f"povlens-{os.getuid()}" / "paths"
        if readable_by_povray(str(folder)):
            break
    folder.mkdir(parents=True, exist_ok=True)
    os.chmod(folder.parent, 0o700)
    if folder.parent.stat().st_uid != os.getuid():
        raise PovlensError(f"{folder.parent} belongs to another user: povlens cannot keep "
                           f"its links for POV-Ray there", "set TMPDIR to a folder of yours")
    return folder


def ascii_alias(path: str | os.PathLike) -> Path:
    """An ASCII path that is a symbolic link to ``path`` (absolute; the same link for
    the same path, made once, atomically)."""
    real = Path(path).absolute()
    digest = hashlib.sha256(os.fsencode(real)).hexdigest()[:20]
    suffix = real.suffix if readable_by_povray(real.suffix) else ""
    return _linked(alias_folder() / f"{digest}{suffix}", real)


def _linked(link: Path, target: Path) -> Path:
    """``link``, a symbolic link to ``target`` (absolute): left as it is when it already
    points there, else made under a temporary name and renamed (atomic: concurrent
    processes never see a half-made or missing link)."""
    if not (link.is_symlink() and os.readlink(link) == str(target)):
        tmp = link.with_name(f".{link.name}.{os.getpid()}.tmp")
        tmp.unlink(missing_ok=True)
        os.symlink(target, tmp)
        os.replace(tmp, link)
    return link


def command_line_path(path: str | os.PathLike) -> str:
    """``path`` as a value of POV-Ray's command line (``+L``, ``Library_Path=``)."""
    text = str(path)
    if readable_by_povray(text):
        return text
    if text.isascii() and text.isprintable() and '"' not in text:
        return quoted_value(text)
    return str(ascii_alias(text))


def include_text(target: str | os.PathLike, wrapper_dir: str | os.PathLike,
                 link: str | os.PathLike) -> str:
    """The ``#include`` text of ``target`` in a wrapper in ``wrapper_dir``: the relative
    path when POV-Ray reads it as written, else the relative path of ``link`` (an ASCII
    name in the wrapper's folder tree), made a symbolic link to ``target``."""
    rel = os.path.relpath(target, wrapper_dir)
    if readable_by_povray(rel):
        return rel
    return os.path.relpath(_linked(Path(link), Path(target).absolute()), wrapper_dir)
