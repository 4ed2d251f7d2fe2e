"""What travels to a worker with the work, and its copy on the worker.

A bundle is a tar (gzip level 1) of every file a lens sample's POV-Ray run reads,
stored under its absolute path on the client (without the leading ``/``):

* the render folder's ``plan.json``, ``pupil.npz`` and wrappers (``*.pov``,
  ``samples/*.pov``);
* the lens file;
* the scene's folder tree (its ``#include`` files and image maps, which POV-Ray finds
  through the scene folder's ``+L``) and the tree of each ``library_paths`` folder,
  leaving out render folders (a folder with a ``plan.json``), ``.git`` and caches.

On the worker it is unpacked once per machine into ``<tmp>/povlens-cluster/<key>/``
(the *replica*), so every relative path (the wrappers' ``#include`` of the scene is
relative to the render folder) is as on the client; the replica's ``plan.json`` is
rewritten to name the replica's scene, lens and library folders.  The client's end
deletes the replicas (:func:`remove_replica`); one whose end never came (a killed
worker) is deleted once stale (:func:`prune_stale_replicas`).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
import tarfile
import tempfile
import threading
import time
from pathlib import Path

from povlens.errors import ParameterError, PovlensError
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Plan

__all__ = ["BUNDLE_LIMIT_BYTES", "make_bundle", "replica_root", "in_replica", "remove_replica",
           "prune_stale_replicas", "STALE_REPLICA_S"]

#: Largest bundle sent (bytes, before compression); past it the render asks for
#: ``shared_dir`` or a scene folder of its own.
BUNDLE_LIMIT_BYTES = 512 * 1024 * 1024

#: Folder names never sent.
_SKIP_DIRS = {".git", "__pycache__", ".hg", ".svn", ".pytest_cache"}

#: The bundle's member naming the client's absolute scene, lens and library paths.
_PATHS = "povlens-paths.json"

_lock = threading.Lock()


def _tree_files(folder: Path, outdir: Path) -> list[Path]:
    """Files under ``folder``, leaving out render folders (``outdir`` and any folder
    holding a ``plan.json``) and version-control folders."""
    files = []
    for top, dirs, names in os.walk(folder):
        top_path = Path(top)
        dirs[:] = sorted(d for d in dirs if d not in _SKIP_DIRS
                         and (top_path / d).resolve() != outdir.resolve()
                         and not RenderFolder(top_path / d).plan_json.exists())
        files += [top_path / n for n in sorted(names) if (top_path / n).is_file()]
    return files


def _render_folder_files(outdir: Path) -> list[Path]:
    files = RenderFolder(outdir).worker_inputs()
    missing = [p for p in files if not p.is_file()]
    if missing:
        raise PovlensError(f"{missing[0]} is missing: the render folder is incomplete",
                           "run 'povlens convert' again")
    return files


def make_bundle(outdir: str | os.PathLike, plan: Plan) -> tuple[str, bytes]:
    """Pack the files a worker needs to render lens samples of ``outdir``.

    Parameters
    ----------
    outdir : the render folder (converted; its pupil table built).
    plan : its plan.

    Returns
    -------
    key : str
        SHA-256 of the bundle (hex): the name of the replica on the workers.
    data : bytes
        The gzip-compressed tar.

    Raises
    ------
    ParameterError
        ``shared_dir``: the files are larger than :data:`BUNDLE_LIMIT_BYTES`.
    """
    # absolute, not resolved: the wrappers' relative #include of the scene was
    # computed lexically from these paths (os.path.relpath)
    outdir = Path(os.path.abspath(outdir))
    inp = plan.inputs
    scene_dir = Path(os.path.abspath(inp.scene)).parent
    files = _render_folder_files(outdir) + [Path(os.path.abspath(inp.lens))]
    for folder in [scene_dir, *(Path(os.path.abspath(p)) for p in inp.library_paths)]:
        files += _tree_files(folder, outdir)
    files = list(dict.fromkeys(files))
    size = sum(p.stat().st_size for p in files)
    if size > BUNDLE_LIMIT_BYTES:
        raise ParameterError(
            "shared_dir", False,
            f"the scene folder {scene_dir} (and the render folder, lens and library "
            f"folders) hold {size / 1e6:.0f} MB: more than the "
            f"{BUNDLE_LIMIT_BYTES / 1e6:.0f} MB povlens sends to the workers",
            "put the scene and what it reads in a folder of its own, or give "
            "'shared_dir' when the workers see these files at the same paths")
    # the client's absolute paths, for the replica's plan (_rewrite_plan)
    paths = json.dumps({"scene": os.path.abspath(inp.scene), "lens": os.path.abspath(inp.lens),
                        "library_paths": [os.path.abspath(p) for p in inp.library_paths]})
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz", compresslevel=1) as tar:
        for p in files:
            tar.add(p, arcname=str(p).lstrip("/"), recursive=False)
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
    base = Path(tempfile.gettempdir()) / "povlens-cluster"
    root = base / key
    with _lock:
        if root.is_dir():
            _touch(root)                 # in use: not stale (prune_stale_replicas)
            return root
        base.mkdir(parents=True, exist_ok=True)
        prune_stale_replicas(base)
        tmp = Path(tempfile.mkdtemp(prefix=f".{key[:12]}.", dir=base))
        try:
            with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as tar:
                if hasattr(tarfile, "data_filter"):
                    tar.extractall(tmp, filter="data")
                else:                                   # Python < 3.11.4
                    tar.extractall(tmp)
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


def remove_replica(key: str) -> bool:
    """Delete this machine's replica of bundle ``key`` (the client's render ended);
    returns whether there was one.  A later task of the same bundle unpacks it again."""
    root = Path(tempfile.gettempdir()) / "povlens-cluster" / key
    with _lock:
        if not root.is_dir():
            return False
        shutil.rmtree(root, ignore_errors=True)
    return True
