"""Finding the POV-Ray executable and asking its version.

The executable is ``$POVLENS_POVRAY`` if that is set, else ``povray`` on ``PATH``.
Its version decides the mesh_camera row workaround (:func:`needs_row_workaround`);
asking costs ~0.2 s of POV-Ray start-up, so the answer is remembered across runs
(:func:`cached_povray_version`; docs/decisions/pov.md).
"""

from __future__ import annotations

import functools
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

from povlens.errors import PovrayError
from povlens.pov.povray_output import last_lines
from povlens.util.user_cache import cache_folder
from povlens.util.files import write_text

__all__ = [
    "ENV_VAR",
    "find_povray",
    "povray_version",
    "cached_povray_version",
    "ask_povray_version",
    "needs_row_workaround",
]

#: Environment variable that overrides which POV-Ray executable is used.
ENV_VAR = "POVLENS_POVRAY"


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
    return cache_folder() / "povray-version.json"


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
def cached_povray_version(executable: str) -> str:
    """POV-Ray's version, remembered across runs in the user's cache folder
    (``$XDG_CACHE_HOME/povlens/povray-version.json``): ``povray --version`` costs
    ~0.2 s of idle start-up on every conversion otherwise.  The entry is keyed by
    the binary's path, inode, size and mtime, so an upgrade asks again."""
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
    version = ask_povray_version(executable)
    if key is not None:
        try:
            cache.parent.mkdir(parents=True, exist_ok=True)
            write_text(cache, json.dumps({**(known if isinstance(known, dict) else {}),
                                          key: version}) + "\n")
        except OSError:
            pass                     # no cache folder: ask again next time
    return version


def ask_povray_version(executable: str) -> str:
    """Run ``executable --version`` and return the version number it reports
    (:class:`PovrayError` if it cannot run or reports none)."""
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
            + last_lines(text),
            f"set {ENV_VAR} to the povray executable",
        )
    return m.group(1)


def povray_version(executable: str | None = None) -> str:
    """POV-Ray's version number, e.g. ``"3.7.0.10"`` (cached per executable)."""
    return cached_povray_version(executable or find_povray())


def needs_row_workaround(version: str) -> bool:
    """True for POV-Ray 3.7.0.x, whose mesh_camera repeats the first face row.

    (FS#254, fixed in 3.7.1/3.8.)  Such versions need a ``W x (H+1)`` render
    whose top output row is dropped; see :func:`povlens.pov.mesh.render_size`.
    """
    parts = version.split(".")
    return parts[:3] == ["3", "7", "0"]
