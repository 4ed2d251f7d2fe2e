"""Unpacking a bundle on a worker: only files and folders, only inside the replica.

A bundle (:mod:`povlens.cluster.bundle`) holds regular files and folders, every name
relative.  :func:`extract_checked` checks every member before anything is written,
on every Python: an absolute name, a ``..`` component, a link (symbolic or hard), a
device or a pipe is refused with an error naming the member, and nothing is
unpacked.  Where Python has ``tarfile.data_filter`` (3.11.4, 3.12) the extraction
also goes through it; elsewhere the check above is the filter.
"""

from __future__ import annotations

import os
import tarfile
from pathlib import Path, PurePosixPath

from povlens.errors import PovlensError

__all__ = ["check_member", "extract_checked"]


def check_member(member: tarfile.TarInfo) -> str | None:
    """Why ``member`` may not be unpacked, or None when it may (a regular file or a
    folder with a relative name free of ``..``)."""
    name = member.name
    parts = PurePosixPath(name).parts
    if name.startswith(("/", "\\")) or os.path.isabs(name) or (parts and ":" in parts[0]):
        return "an absolute name"
    if ".." in parts or ".." in Path(name).parts:
        return "a '..' in its name"
    if member.issym() or member.islnk():
        return f"a link (to {member.linkname})"
    if not (member.isfile() or member.isdir()):
        return "a device, pipe or other special file"
    return None


def extract_checked(tar: tarfile.TarFile, dest: Path, origin: str) -> None:
    """Unpack ``tar`` into ``dest`` once every member passed :func:`check_member`.

    Parameters
    ----------
    tar : the open bundle.
    dest : the folder to unpack into (exists, empty).
    origin : what the bundle is, for messages (``the bundle KEY``).

    Raises
    ------
    PovlensError
        A member is refused (nothing written), or the archive is damaged.
    """
    try:
        members = tar.getmembers()
    except (tarfile.TarError, EOFError, OSError) as e:
        raise PovlensError(f"{origin} cannot be read ({type(e).__name__}: {e})",
                           "render again; if it persists, check the client's and workers' "
                           "povlens versions match") from None
    for member in members:
        why = check_member(member)
        if why is not None:
            raise PovlensError(f"{origin}: member {member.name!r} is {why}; povlens bundles "
                               f"hold only files and folders inside the replica, so nothing "
                               f"was unpacked",
                               "render from a povlens client of the same version as the "
                               "workers; do not feed bundles from elsewhere to the workers")
    try:
        if getattr(tarfile, "data_filter", None) is not None:
            tar.extractall(dest, members=members, filter="data")
        else:                   # Python < 3.11.4: the check above is the filter
            tar.extractall(dest, members=members)
    except tarfile.TarError as e:
        raise PovlensError(f"{origin} cannot be unpacked into {dest} "
                           f"({type(e).__name__}: {e})",
                           "check the worker's free space in its temporary folder") from None
