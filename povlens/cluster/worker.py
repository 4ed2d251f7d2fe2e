"""The task a Dask worker runs: one lens sample, rendered by the local code.

:func:`render_sample` traces sample k and runs POV-Ray for it with
:func:`povlens.rendering.samples.render_samples`, exactly as ``povlens render`` does on
one machine, in the worker's replica of the render folder
(:func:`povlens.cluster.bundle.replica_root`), then returns the sample's files (image,
pass mask or weights, blocked marker) as bytes.  A sample is fixed by the plan (seed,
sample number), so where and in which order samples render does not change them.

No Dask import here: the worker imports this module by name when it unpickles the task.
"""

from __future__ import annotations

import os
import socket
import threading
import time
from pathlib import Path

from povlens.cluster.bundle import in_replica, replica_root
from povlens.errors import PovlensError
from povlens.plan.schema import read_plan
from povlens.rendering.samples import lens_for, pupil_table_for, render_samples

__all__ = ["render_sample", "sample_files"]

#: Render folder key -> (plan, lens, pupil table): read once per worker process.
_loaded: dict[str, tuple] = {}
_loaded_lock = threading.Lock()


def sample_files(samples_dir: Path, k: int) -> list[Path]:
    """The outputs of sample k in a ``samples`` folder: ``sample_KKKK.*`` but the
    ray mesh and files being written."""
    prefix = f"sample_{k:04d}."
    return sorted(p for p in Path(samples_dir).glob(prefix + "*")
                  if p.is_file() and not p.name.endswith((".inc", ".part")))


def _load(key: str, outdir: Path):
    with _loaded_lock:
        if key not in _loaded:
            plan = read_plan(outdir)
            lens = lens_for(plan)
            _loaded[key] = (plan, lens, pupil_table_for(outdir, plan, lens))
        return _loaded[key]


def render_sample(job: dict, k: int) -> dict:
    """Render lens sample ``k`` of the render folder ``job`` describes.

    Parameters
    ----------
    job : dict
        ``outdir`` (the client's render folder, absolute), ``key`` and ``bundle``
        (:func:`povlens.cluster.bundle.make_bundle`; ``bundle`` None with
        ``shared``: the worker sees ``outdir`` itself and writes the sample there).
    k : int
        The sample number.

    Returns
    -------
    dict
        ``k``; ``files``: {file name: bytes} of the sample's outputs (empty when
        shared); ``timing``: seconds of unpacking (``unpack_s``), tracing
        (``rays_and_meshes_s``), POV-Ray (``povray_s``) and the whole task
        (``task_s``); ``host``.  A :class:`~povlens.errors.PovlensError` (the scene
        fails in POV-Ray, say) is returned as ``error`` = {type, message, hint}, not
        raised, so Dask does not retry what would fail again.
    """
    t0 = time.perf_counter()
    host = socket.gethostname()
    try:
        if job["shared"]:
            outdir = Path(job["outdir"])
        else:
            outdir = in_replica(replica_root(job["key"], job["bundle"], job["outdir"]),
                                job["outdir"])
        t_unpack = time.perf_counter() - t0
        plan, lens, table = _load(job["key"] + ("-shared" if job["shared"] else ""), outdir)
        samples = outdir / "samples"
        if not job["shared"]:
            for p in sample_files(samples, k):  # an earlier attempt's, on this machine
                p.unlink(missing_ok=True)
        timing = render_samples(plan, lens, table, outdir, 0, [k], in_flight=1)
        files = {}
        if not job["shared"]:
            for p in sample_files(samples, k):
                files[p.name] = p.read_bytes()
                p.unlink(missing_ok=True)
    except PovlensError as e:
        return {"k": k, "host": host, "error": {"type": type(e).__name__,
                                                "message": e.message, "hint": e.hint}}
    return {"k": k, "host": host, "pid": os.getpid(), "files": files,
            "timing": {"unpack_s": t_unpack, "rays_and_meshes_s": timing["rays_and_meshes_s"],
                       "povray_s": timing["povray_s"], "task_s": time.perf_counter() - t0}}
