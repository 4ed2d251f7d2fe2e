"""Which files of the scene's and library folders travel to the workers, and from where.

The bundle (:mod:`povlens.cluster.bundle`) stores each file under its path on the
client (the *name* POV-Ray opens: the scene's folder as ``+L``, the relative
``#include`` and image-map names below it) with the *content* of the file that
name leads to.  Walking a folder:

* hidden entries (a name starting with ``.``: ``.ssh/``, ``.git/``, ``.env``) never
  travel, at any depth, nor render folders (a folder holding a ``plan.json``) and
  caches (``__pycache__``);
* a symbolic link travels as the file it leads to (a link to a folder: that folder's
  files, under the link's name, walked by the same rules; a link back into a folder
  being walked is not walked again).  No link is stored, so a link inside the folder,
  an absolute one or a relative one leaving it arrives as the content the local render
  reads.  A dangling link is left out (the local render cannot read it either);
* a link whose target is hidden (or inside a hidden folder: ``key.inc ->
  ~/.ssh/id_rsa``) is refused with an error naming the link: hidden files never
  travel, even through a link;
* devices, pipes and sockets are left out.

The walk stops with an error as soon as the files hold more than the bundle's limit,
so a link to a large tree costs no more than the limit's worth of reading.
"""

from __future__ import annotations

import os
from pathlib import Path

from povlens.errors import ParameterError
from povlens.plan.render_folder import RenderFolder

__all__ = ["SceneFiles", "hidden_part"]

#: Folder names never walked besides hidden ones.
_SKIP_DIRS = {"__pycache__"}


def hidden_part(path: Path, below: Path) -> str | None:
    """The first component of ``path`` below its common folder with ``below`` (both
    absolute and resolved) whose name starts with ``.``, or None.  A scene folder that
    is itself inside a hidden one (``~/.cache/scene``) can still link to its own files."""
    common = Path(os.path.commonpath([path, below]))
    for part in Path(path).relative_to(common).parts:
        if part.startswith("."):
            return part
    return None


class SceneFiles:
    """The files a bundle holds: (name on the client, file to read), walked folder
    by folder with :meth:`add_tree`, single files with :meth:`add_file`.

    Parameters
    ----------
    outdir : the render folder (absolute), never walked as part of a scene folder.
    limit_bytes : the most the files may hold; past it :meth:`add_tree` raises.
    too_big : called with the total size in bytes when the limit is passed; returns
        the exception to raise (the bundle's "give shared_dir" error).
    """

    def __init__(self, outdir: Path, limit_bytes: int, too_big):
        self.outdir_real = Path(outdir).resolve()
        self.limit_bytes, self.too_big = int(limit_bytes), too_big
        self.files: dict[Path, Path] = {}      # name on the client -> file to read
        self.size_bytes = 0

    def add_file(self, name: Path, source: Path | None = None) -> None:
        """Add the file ``source`` (default ``name``, links followed) as ``name``."""
        name = Path(name)
        if name in self.files:
            return
        source = Path(source if source is not None else name).resolve()
        self.files[name] = source
        self.size_bytes += source.stat().st_size
        if self.size_bytes > self.limit_bytes:
            raise self.too_big(self.size_bytes)

    def add_tree(self, folder: Path) -> None:
        """Add the files of ``folder`` (absolute, as the plan names it) by the rules of
        this module."""
        real = Path(folder).resolve()
        self._root_real = real
        self._walk(Path(folder), real, frozenset([real]))

    def _walk(self, folder: Path, real: Path, chain: frozenset) -> None:
        """Add the files of ``folder``, whose real path is ``real``; ``chain`` holds the
        real paths of the folders being walked (a link back to one is not walked)."""
        try:
            entries = sorted(os.scandir(folder), key=lambda e: e.name)
        except OSError:                 # unreadable: the local render cannot read it either
            return
        for entry in entries:
            if entry.name.startswith(".") or entry.name in _SKIP_DIRS:
                continue                # hidden: never sent
            path = folder / entry.name
            if entry.is_symlink():
                self._linked(path, chain)
            elif entry.is_dir(follow_symlinks=False):
                if not self._render_folder(path, path.resolve()):
                    self._walk(path, path.resolve(), chain | {path.resolve()})
            elif entry.is_file(follow_symlinks=False):
                self.add_file(path, path)

    def _render_folder(self, path: Path, real: Path) -> bool:
        return real == self.outdir_real or RenderFolder(path).plan_json.exists()

    def _linked(self, link: Path, chain: frozenset) -> None:
        """Add what the link ``link`` leads to under its own name."""
        target = link.resolve()
        if not target.exists():
            return                      # dangling: the local render cannot read it either
        hidden = hidden_part(target, self._root_real)
        if hidden is not None:
            raise ParameterError(
                "shared_dir", False,
                f"{link} is a link to {target}, inside the hidden {hidden!r}: povlens "
                f"sends no hidden file or folder to the workers, not even through a link",
                f"copy what the scene reads from it into {link.parent} under a name not "
                f"starting with '.' (and remove the link), or give 'shared_dir' when the "
                f"workers see these files at the same paths")
        if target.is_dir():
            if target not in chain and not self._render_folder(target, target):
                self._walk(link, target, chain | {target})
        elif target.is_file():
            self.add_file(link, target)
