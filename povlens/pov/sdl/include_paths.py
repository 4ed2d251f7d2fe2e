"""Where POV-Ray finds an ``#include`` file: the working directory (a user renders a
scene from its folder), then the library paths in order -- those of POV-Ray's ``povray.ini``
(``Library_Path=`` / ``+L`` lines) and the standard include folder, then the caller's.

Measured with POV-Ray 3.7.0.10 (docs/decisions/pov.md): a name is not looked up next to
the file that includes it, and the ``povray.ini`` paths come before a command line's
``+L``.
"""

from __future__ import annotations

import functools
import os
import re
from pathlib import Path
from typing import Iterable, Sequence

__all__ = ["povray_ini_files", "default_library_paths", "find_include"]

#: The system configuration of POV-Ray on Unix (Debian: povray 3.7).
SYSTEM_INI_DIRS = ("/etc/povray/3.7", "/usr/local/etc/povray/3.7", "/etc/povray/3.8",
                   "/usr/local/etc/povray/3.8")
#: POV-Ray's standard include folders (also searched if no ini names them).
STANDARD_INCLUDE_DIRS = ("/usr/share/povray-3.7/include", "/usr/local/share/povray-3.7/include",
                         "/usr/share/povray-3.8/include", "/usr/local/share/povray-3.8/include")

_LIBRARY_RE = re.compile(r"^\s*(?:Library_Path\s*=\s*|[+-]L)(.+?)\s*$", re.IGNORECASE)


def povray_ini_files() -> list[Path]:
    """The ``povray.ini`` POV-Ray reads on Unix: ``$POVINI``, else the user's
    ``~/.povray/3.7/povray.ini``, else the system one."""
    env = os.environ.get("POVINI")
    if env:
        return [Path(env)] if Path(env).is_file() else []
    for cand in [Path.home() / ".povray" / "3.7" / "povray.ini",
                 *(Path(d) / "povray.ini" for d in SYSTEM_INI_DIRS)]:
        if cand.is_file():
            return [cand]
    return []


def _ini_library_paths(ini: Path) -> list[Path]:
    """The ``Library_Path=`` and ``+L`` entries of one ini file, in order."""
    try:
        lines = ini.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return []
    out = []
    for line in lines:
        line = line.split(";", 1)[0]  # ini comments
        m = _LIBRARY_RE.match(line)
        if m:
            value = m.group(1).strip().strip('"').strip("'")
            if value:
                out.append(Path(os.path.expanduser(value)))
    return out


@functools.lru_cache(maxsize=4)
def _defaults(ini_key: tuple[str, ...]) -> tuple[Path, ...]:
    paths: list[Path] = []
    for ini in ini_key:
        paths.extend(_ini_library_paths(Path(ini)))
    paths.extend(Path(d) for d in STANDARD_INCLUDE_DIRS if Path(d).is_dir())
    seen, out = set(), []
    for p in paths:
        if p not in seen:
            seen.add(p)
            out.append(p)
    return tuple(out)


def default_library_paths() -> list[Path]:
    """POV-Ray's own library paths on this machine, in search order.

    Returns
    -------
    list of Path
        The ini file's ``Library_Path`` entries, then the standard include folders that
        exist (each once).
    """
    return list(_defaults(tuple(str(p) for p in povray_ini_files())))


def find_include(name: str, scene_dir: Path, library_paths: Sequence[Path]) -> Path | None:
    """The file ``#include name`` opens, or None.

    Parameters
    ----------
    name : the name as written (relative or absolute).
    scene_dir : POV-Ray's working directory: the scene's folder.
    library_paths : searched in order after ``scene_dir``.

    Returns
    -------
    Path or None
        The resolved path of the first existing candidate; without a suffix, ``name.inc``
        is tried too (POV-Ray appends the include file type's extension).
    """
    names = [name] if Path(name).suffix else [name, name + ".inc"]
    dirs: Iterable[Path] = [Path("/")] if os.path.isabs(name) else [scene_dir, *library_paths]
    for d in dirs:
        for n in names:
            cand = d / n
            if cand.is_file():
                return cand.resolve()
    return None
