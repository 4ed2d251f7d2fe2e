"""What travels to a worker with the work, and its copy on the worker.

A bundle is a tar (gzip level 1) of every file a lens sample's POV-Ray run reads,
stored under its absolute path on the client (without the leading ``/``):

* the render folder's ``plan.json``, ``pupil.npz`` and wrappers (``*.pov``,
  ``samples/*.pov``);
* the scene file and the lens file;
* the files the scene reads: those its text and its include files' name by literals
  (``#include`` files, image maps, fonts, data files, found as POV-Ray finds them
  through the scene folder's ``+L`` and the ``library_paths``:
  :func:`povlens.cluster.scene_files.scene_reads`); when a file name is built by an
  expression, the scene's folder tree and each ``library_paths`` folder's instead,
  leaving out hidden entries (names starting with ``.``), render folders (a folder
  with a ``plan.json``) and caches.  Links travel as the content they lead to
  (:mod:`povlens.cluster.scene_files`), so the bundle holds only files and folders.

On the worker it is unpacked once per machine into ``<tmp>/povlens-cluster/<key>/``
(the *replica*; every member checked first: :mod:`povlens.cluster.safe_tar`), so
every relative path (the wrappers' ``#include`` of the scene is relative to the render
folder) is as on the client; the replica's ``plan.json`` is rewritten to name the
replica's scene, lens and library folders.  The client's end deletes the replicas
(:func:`remove_replica`, which deletes only a folder named by a bundle key); one whose
end never came (a killed worker) is deleted once stale (:func:`prune_stale_replicas`).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
import shutil
import tarfile
import tempfile
import threading
import time
from pathlib import Path

from povlens.cluster.safe_tar import extract_checked
from povlens.cluster.scene_files import SceneFiles, scene_reads
from povlens.errors import ParameterError, PovlensError
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Plan

__all__ = ["BUNDLE_LIMIT_BYTES", "make_bundle", "bundle_files", "replica_root", "in_replica",
           "remove_replica", "is_bundle_key", "replica_base", "prune_stale_replicas",
           "STALE_REPLICA_S"]

#: Largest bundle sent (bytes, before compression); past it the render asks for
#: ``shared_dir`` or a scene folder of its own.
BUNDLE_LIMIT_BYTES = 512 * 1024 * 1024

#: The bundle's member naming the client's absolute scene, lens and library paths.
_PATHS = "povlens-paths.json"

_lock = threading.Lock()


def _render_folder_files(outdir: Path) -> list[Path]:
    files = RenderFolder(outdir).worker_inputs()
    missing = [p for p in files if not p.is_file()]
    if missing:
        raise PovlensError(f"{missing[0]} is missing: the render folder is incomplete",
                           "run 'povlens convert' again")
    return files


def bundle_files(outdir: str | os.PathLike, plan: Plan) -> SceneFiles:
    """The files :func:`make_bundle` packs: ``.files`` {name on the client: file read},
    ``.size_bytes`` (before compression), ``.trees_because`` (None: the files the
    scene names; else why the folders' trees were taken).

    Raises
    ------
    ParameterError
        ``shared_dir``: the files are larger than :data:`BUNDLE_LIMIT_BYTES`, the
        scene names a hidden file, or a link it reads through leads to one
        (:mod:`povlens.cluster.scene_files`).
    """
    # absolute, not resolved: the wrappers' relative #include of the scene was
    # computed lexically from these paths (os.path.relpath)
    outdir = Path(os.path.abspath(outdir))
    inp = plan.inputs
    scene_dir = Path(os.path.abspath(inp.scene)).parent

    def too_big(size: int) -> ParameterError:
        return ParameterError(
            "shared_dir", False,
            f"the scene folder {scene_dir} (and the render folder, lens and library "
            f"folders) hold {size / 1e6:.0f} MB or more: more than the "
            f"{BUNDLE_LIMIT_BYTES / 1e6:.0f} MB povlens sends to the workers",
            "put the scene and what it reads in a folder of its own, or give "
            "'shared_dir' when the workers see these files at the same paths")

    files = SceneFiles(outdir, BUNDLE_LIMIT_BYTES, too_big)
    for p in _render_folder_files(outdir) + [Path(os.path.abspath(inp.scene)),
                                             Path(os.path.abspath(inp.lens))]:
        files.add_file(p)
    reads = scene_reads(inp.scene, inp.library_paths)
    if reads.files is not None:         # only the files the scene's text names
        for name in reads.files:
            files.add_read(name, next((f for f in reads.folders if _inside(name, f)),
                                      reads.folders[0]))
        return files
    files.trees_because = reads.reason  # names built by expressions: the folders' trees
    for folder in reads.folders:
        files.add_tree(folder)
    return files


def _inside(path: Path, folder: Path) -> bool:
    return os.path.commonpath([path, folder]) == str(folder)


def make_bundle(outdir: str | os.PathLike, plan: Plan,
                files: SceneFiles | None = None) -> tuple[str, bytes]:
    """Pack the files a worker needs to render lens samples of ``outdir``.

    Parameters
    ----------
    outdir : the render folder (converted; its pupil table built).
    plan : its plan.
    files : :func:`bundle_files` of them (default: found here).

    Returns
    -------
    key : str
        SHA-256 of the bundle (hex): the name of the replica on the workers.
    data : bytes
        The gzip-compressed tar: regular files and folders only.

    Raises
    ------
    ParameterError
        As :func:`bundle_files`.
    """
    if files is None:
        files = bundle_files(outdir, plan)
    inp = plan.inputs
    # the client's absolute paths, for the replica's plan (_rewrite_plan)
    paths = json.dumps({"scene": os.path.abspath(inp.scene), "lens": os.path.abspath(inp.lens),
                        "library_paths": [os.path.abspath(p) for p in inp.library_paths]})
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz", compresslevel=1) as tar:
        for name, source in files.files.items():
            # the content of the file the name leads to, stored as a regular file
            info = tar.gettarinfo(source, arcname=str(name).lstrip("/"))
            with open(source, "rb") as f:
                tar.addfile(info, f)
        info = tarfile.TarInfo(_PATHS)
        info.size = len(paths.encode())
        tar.addfile(info, io.BytesIO(paths.encode()))
    data = buf.getvalue()
    return hashlib.sha256(data).hexdigest(), data


def in_replica(root: Path, path: str | os.PathLike) -> Path:
    """Where the client's absolute ``path`` is in the replica at ``root``."""
    return Path(root) / os.path.normpath(str(path)).lstrip("/")


def _rewrite_plan(unpacked: Path, root: Path, outdir: str) -> None:
    """Make the replica's plan (unpacked at ``unpacked``, to be renamed ``root``) name
    the replica's scene, lens and library folders."""
    path = RenderFolder(in_replica(unpacked, outdir)).plan_json
    d = json.loads(path.read_text())
    client = json.loads((unpacked / _PATHS).read_text())
    inp = d["inputs"]
    inp["scene"] = str(in_replica(root, client["scene"]))
    inp["lens"] = str(in_replica(root, client["lens"]))
    if inp.get("library_paths"):
        inp["library_paths"] = [str(in_replica(root, p)) for p in client["library_paths"]]
    path.write_text(json.dumps(d, indent=1) + "\n")


def replica_root(key: str, data: bytes, outdir: str) -> Path:
    """The replica of bundle ``key`` on this machine, unpacked on first use.

    Parameters
    ----------
    key, data : :func:`make_bundle`'s result.
    outdir : the client's render folder (absolute, as :func:`make_bundle` packed it).

    Returns
    -------
    Path
        ``<tmp>/povlens-cluster/<key>``: unpacked into a temporary folder and renamed,
        so worker processes sharing the machine never see half a replica.
    """
    root = _replica_dir(key)
    base = root.parent
    with _lock:
        if root.is_dir():
            _touch(root)                 # in use: not stale (prune_stale_replicas)
            return root
        base.mkdir(parents=True, exist_ok=True)
        prune_stale_replicas(base)
        tmp = Path(tempfile.mkdtemp(prefix=f".{key[:12]}.", dir=base))
        try:
            try:
                tar = tarfile.open(fileobj=io.BytesIO(data), mode="r:gz")
            except (tarfile.TarError, EOFError, OSError) as e:
                raise PovlensError(f"the bundle {key[:12]} cannot be read ({e})",
                                   "render again") from None
            with tar:
                extract_checked(tar, tmp, f"the bundle {key[:12]}")
            _rewrite_plan(tmp, root, outdir)
            try:
                os.rename(tmp, root)
            except OSError:
                if not root.is_dir():        # not another process's replica: a real error
                    raise
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    return root


#: A replica no task has used for this long (s) belongs to a render whose end this
#: machine never heard of (its worker was killed, its client died): the next replica
#: unpacked here deletes it.  Half-unpacked folders (``.KEY.*``) go after an hour.
STALE_REPLICA_S = 24 * 3600.0
STALE_UNPACK_S = 3600.0


def _touch(path: Path) -> None:
    try:
        os.utime(path)
    except OSError:
        pass


def prune_stale_replicas(base: Path, now: float | None = None) -> list[Path]:
    """Delete the replicas in ``base`` untouched for :data:`STALE_REPLICA_S` and the
    unpacking folders left for :data:`STALE_UNPACK_S`; returns what was deleted."""
    now = time.time() if now is None else float(now)
    gone = []
    try:
        entries = list(Path(base).iterdir())
    except OSError:
        return gone
    for entry in entries:
        limit = STALE_UNPACK_S if entry.name.startswith(".") else STALE_REPLICA_S
        try:
            stale = entry.is_dir() and now - entry.stat().st_mtime > limit
        except OSError:
            continue
        if stale:
            shutil.rmtree(entry, ignore_errors=True)
            gone.append(entry)
    return gone


def is_bundle_key(key: str) -> bool:
    """Whether ``key`` names a replica: a SHA-256 in hex (:func:`make_bundle`)."""
    return isinstance(key, str) and re.fullmatch(r"[0-9a-f]{64}", key) is not None


def replica_base() -> Path:
    """The folder of this machine's replicas: ``<tmp>/povlens-cluster``."""
    return Path(tempfile.gettempdir()) / "povlens-cluster"


def _replica_dir(key: str) -> Path:
    """The replica folder of bundle ``key``; anything but a bundle key (``../x``, a
    path) is refused, so no folder outside :func:`replica_base` is ever named."""
    if not is_bundle_key(key):
        raise PovlensError(f"{key!r} is not a bundle key (64 hex digits): no replica has "
                           f"that name, and nothing outside {replica_base()} is touched",
                           "pass the key make_bundle returned")
    return replica_base() / key


def remove_replica(key: str) -> bool:
    """Delete this machine's replica of bundle ``key`` (the client's render ended);
    returns whether there was one.  A later task of the same bundle unpacks it again.

    Raises
    ------
    PovlensError
        ``key`` is not a bundle key (nothing deleted)."""
    root = _replica_dir(key)
    with _lock:
        if not root.is_dir():
            return False
        shutil.rmtree(root, ignore_errors=True)
    return True
