"""Which files of the scene's and library folders travel to the workers, and from where.

**The files the scene reads** (:func:`scene_reads`).  POV-Ray opens a file by a name
written in the scene: ``#include "parts/look.inc"``, ``image_map { png "maps/wood.png"
}``, ``text { ttf "font.ttf" ... }``, ``#fopen F "data.txt" read``, ``density_file df3
"smoke.df3"``.  It looks the name up in its working folder and its library paths
(``+L``; povlens gives the scene's folder first).  :func:`scene_reads` reads the
scene's text and, recursively, that of the files it includes, and returns every file a
string literal names there, found as POV-Ray would find it (the scene's folder, then the
library folders; the name, then the name with a file type's suffix).  It is a reading of
the text, not an evaluation, so it says when it cannot tell: a file name that is not a
literal (``#include concat("parts/", Name)``, ``png MapFile``, a macro's parameter)
makes it return None with the reason, and the bundle then holds the folders' trees.  A
literal naming a hidden file (``".secret/key.inc"``) is an error: hidden files never
travel.

**The folders' trees** (:meth:`SceneFiles.add_tree`), when the scene's names cannot be
told.  The bundle (:mod:`povlens.cluster.bundle`) stores each file under its path on
the client (the *name* POV-Ray opens) with the *content* of the file that name leads
to.  Walking a folder:

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
import re
from pathlib import Path

from povlens.errors import ParameterError
from povlens.plan.render_folder import RenderFolder

__all__ = ["SceneFiles", "SceneReads", "scene_reads", "hidden_part"]

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


def _refuse_hidden_target(link: Path, target: Path, below: Path) -> None:
    """Refuse the link ``link`` (a name in the folder ``below``) if its ``target`` is
    hidden, or inside a hidden folder, past their common folder."""
    hidden = hidden_part(target, below)
    if hidden is not None:
        raise ParameterError(
            "shared_dir", False,
            f"{link} is a link to {target}, inside the hidden {hidden!r}: povlens sends no "
            f"hidden file or folder to the workers, not even through a link",
            f"copy what the scene reads from it into {link.parent} under a name not "
            f"starting with '.' (and remove the link), or give 'shared_dir' when the "
            f"workers see these files at the same paths")


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
        #: How the scene's files were chosen: None, the files its text names
        #: (:func:`scene_reads`); else why the trees were sent.
        self.trees_because: str | None = None

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

    def add_read(self, name: Path, folder: Path) -> None:
        """Add the file the scene reads as ``name`` (found in ``folder``: the scene's or
        a library folder); through a link, its target must not be hidden."""
        name = Path(name)
        target = name.resolve()
        if target != name:
            _refuse_hidden_target(name, target, Path(folder).resolve())
        self.add_file(name, target)

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
        _refuse_hidden_target(link, target, self._root_real)
        if target.is_dir():
            if target not in chain and not self._render_folder(target, target):
                self._walk(link, target, chain | {target})
        elif target.is_file():
            self.add_file(link, target)


# ---------------------------------------------------------------------------
# the files the scene's text names

#: A POV-Ray token, roughly: comments, string literals (group 1), directives,
#: identifiers and keywords, and any other character.
_TOKEN = re.compile(r'//[^\n]*|/\*.*?\*/|"((?:[^"\\\n]|\\.)*)"|#\s*[A-Za-z_]\w*|[A-Za-z_]\w*|\S',
                    re.S)

#: Keywords whose next token is a file name (file types of image maps, height
#: fields, fonts, densities; photon and radiosity files; the include directive).
_FILE_TYPES = {"png", "jpeg", "tga", "tiff", "gif", "iff", "ppm", "pgm", "sys", "hdr", "exr",
               "ttf", "df3", "load_file", "save_file"}
#: Blocks whose first token is a file name or a file type (or ``function``).
_FILE_BLOCKS = {"image_map", "bump_map", "height_field", "material_map", "image_pattern"}
#: Suffixes POV-Ray may add to a name it does not find as written.
_SUFFIXES = (".inc", ".pov", ".png", ".jpg", ".jpeg", ".tga", ".tif", ".tiff", ".gif",
             ".iff", ".ppm", ".pgm", ".sys", ".hdr", ".exr", ".ttf", ".df3", ".mcr")
#: Files whose text is read for more names (include files and scenes).
_TEXT_SUFFIXES = {".inc", ".pov", ".mcr", ".ini"}
#: The most files followed: past it the scan gives up (the trees are sent).
_MAX_FILES = 2000


class SceneReads:
    """What :func:`scene_reads` found: ``files`` {name POV-Ray opens (absolute, as
    looked up): file}, or ``files`` None and ``reason`` why it cannot tell."""

    def __init__(self, folders: list[Path]):
        self.folders = folders
        self.files: dict[Path, Path] | None = {}
        self.reason: str | None = None


def _tokens(text: str) -> list[tuple[str, str]]:
    """(kind, text) of the tokens of ``text``: ``str`` (its content), ``word``,
    ``directive`` (``#include``, no space) or ``other``; comments dropped."""
    out = []
    for m in _TOKEN.finditer(text):
        tok = m.group(0)
        if tok.startswith(("//", "/*")):
            continue
        if m.group(1) is not None:
            out.append(("str", m.group(1)))
        elif tok.startswith("#") and len(tok) > 1:
            out.append(("directive", "#" + tok[1:].strip()))
        elif tok[0].isalpha() or tok[0] == "_":
            out.append(("word", tok))
        else:
            out.append(("other", tok))
    return out


def _dynamic_name(tokens: list[tuple[str, str]]) -> str | None:
    """The first place a file name is not a literal, as text for a message, or None."""
    for i, (kind, tok) in enumerate(tokens):
        nxt = tokens[i + 1] if i + 1 < len(tokens) else ("other", "")
        if (kind == "directive" and tok == "#include") or (kind == "word" and tok in _FILE_TYPES):
            if nxt[0] != "str":
                return f"{tok} {nxt[1]}"
        elif kind == "directive" and tok == "#fopen":
            after = tokens[i + 2] if i + 2 < len(tokens) else ("other", "")
            if after[0] != "str":
                return f"#fopen {nxt[1]} {after[1]}"
        elif kind == "word" and tok in _FILE_BLOCKS and nxt[1] == "{":
            first = tokens[i + 2] if i + 2 < len(tokens) else ("other", "")
            if first[0] != "str" and first[1] not in _FILE_TYPES | {"function", "pigment"}:
                return f"{tok} {{ {first[1]}"
    return None


def _find(name: str, folders: list[Path]) -> Path | None:
    """Where POV-Ray finds ``name``: absolute as written, else in ``folders`` in turn,
    as written and then with a file type's suffix."""
    if not name or "\x00" in name:
        return None
    bases = [Path("/")] if os.path.isabs(name) else folders
    for base in bases:
        for candidate in [name, *(name + s for s in _SUFFIXES if not name.endswith(s))]:
            path = base / candidate
            try:
                if path.is_file():
                    return Path(os.path.normpath(path))
            except OSError:
                continue
    return None


def _hidden_name(name: str, path: Path) -> None:
    """Refuse a literal that names a hidden file or a file in a hidden folder."""
    hidden = next((p for p in Path(name).parts if p.startswith(".") and p not in (".", "..")),
                  None)
    if hidden is not None:
        raise ParameterError(
            "shared_dir", False,
            f"the scene reads {path} (written \"{name}\"), which is hidden ({hidden!r}): "
            f"povlens sends no hidden file or folder to the workers",
            "rename it (and its mention in the scene) to a name not starting with '.', or "
            "give 'shared_dir' when the workers see these files at the same paths")


def _scan(path: Path, found: SceneReads, seen: set) -> None:
    """Add the files ``path``'s text names to ``found`` (recursively)."""
    if found.files is None or path in seen:
        return
    seen.add(path)
    if len(seen) > _MAX_FILES:
        found.files, found.reason = None, f"more than {_MAX_FILES} files named"
        return
    try:
        text = path.read_text(errors="replace")
    except OSError:
        return
    tokens = _tokens(text)
    dynamic = _dynamic_name(tokens)
    if dynamic is not None:
        found.files = None
        found.reason = f"{path} names a file by an expression ('{dynamic} ...')"
        return
    for kind, name in tokens:
        if kind != "str":
            continue
        if found.files is None:
            return                  # an include file named a file by an expression
        file = _find(name, found.folders)
        if file is None:
            continue                 # a message, or POV-Ray's own include: not sent
        _hidden_name(name, file)
        found.files[file] = file
        if file.suffix.lower() in _TEXT_SUFFIXES:
            _scan(file, found, seen)


def scene_reads(scene: str | os.PathLike, library_paths=()) -> SceneReads:
    """The files the scene ``scene`` (absolute) reads, by its text and its include
    files' (see the module's text).

    Returns
    -------
    SceneReads
        ``files``: {name as POV-Ray looks it up: the same path}, the scene itself
        included; None when a file name is built by an expression (``reason`` says
        where), and the caller sends the folders' trees instead.

    Raises
    ------
    ParameterError
        ``shared_dir``: the scene names a hidden file.
    """
    scene = Path(os.path.abspath(scene))
    found = SceneReads([scene.parent, *(Path(os.path.abspath(p)) for p in library_paths)])
    found.files[scene] = scene
    _scan(scene, found, set())
    return found
