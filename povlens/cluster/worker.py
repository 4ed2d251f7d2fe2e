"""The tasks a Dask worker runs: lens samples, rendered by the local code.

:func:`render_group` renders a group of consecutive samples with several POV-Ray
processes in flight and returns their partial sums (:mod:`povlens.rendering.groups`);
:func:`render_sample` (group size 1) traces sample k and runs POV-Ray for it with
:func:`povlens.rendering.mesh_samples.render_samples`, exactly as ``povlens render`` does on
one machine, in the worker's replica of the render folder
(:func:`povlens.cluster.bundle.replica_root`), then returns the sample's files (image,
pass mask or weights, blocked marker) as bytes.  A sample is fixed by the plan (seed,
sample number), so where and in which order samples render does not change them.

Each task is recorded while it runs (:func:`povlens.cluster.running.task_running`), so
:func:`forget_render` (the client's render ended) first stops its POV-Ray processes and
waits for it, a bounded time, and only then deletes the replica they work in.

Dask is imported only to ask the worker its thread count: the worker imports this module
by name when it unpickles the task.
"""

from __future__ import annotations

import asyncio
import os
import socket
import threading
import time
from pathlib import Path

from povlens.cluster.bundle import in_replica, is_bundle_key, remove_replica, replica_root
from povlens.cluster.running import stop_tasks, task_running
from povlens.errors import PovlensError
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import read_plan
from povlens.rendering.folder_composite import sample_sums
from povlens.rendering.folder_inputs import lens_for, pupil_table_for
from povlens.rendering.groups import GroupSums, pack_group
from povlens.rendering.mesh_samples import POVRAY_IN_FLIGHT, render_samples
from povlens.rendering.sample_stacks import stack_plan
from povlens.util.blas import single_threaded_blas

__all__ = ["render_sample", "render_group", "forget_render", "forget_render_async"]

#: Render folder key -> (plan, lens, pupil table): read once per worker process.
_loaded: dict[str, tuple] = {}
_loaded_lock = threading.Lock()


def _load(key: str, outdir: Path):
    with _loaded_lock:
        if key not in _loaded:
            plan = read_plan(outdir)
            lens = lens_for(plan)
            _loaded[key] = (plan, lens, pupil_table_for(outdir, plan, lens))
        return _loaded[key]


def _in_flight() -> int:
    """POV-Ray processes a task keeps in flight: the local pipeline's
    :data:`~povlens.rendering.mesh_samples.POVRAY_IN_FLIGHT` per core, shared among the
    worker's threads (each runs a task)."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:                      # not Linux
        cores = os.cpu_count() or 1
    try:
        from distributed import get_worker
        threads = get_worker().state.nthreads
    except Exception:                           # not in a worker (a test calls it)
        threads = 1
    return max(1, round(POVRAY_IN_FLIGHT * cores / max(1, threads)))


def _run(job: dict, ks: list[int], group: bool) -> dict:
    t0 = time.perf_counter()
    host = socket.gethostname()
    try:
        if job["shared"]:
            outdir = Path(job["outdir"])
        else:
            outdir = in_replica(replica_root(job["key"], job["bundle"], job["outdir"]),
                                job["outdir"])
        t_unpack = time.perf_counter() - t0
        with task_running(job["key"], outdir) as stop:
            files, timing, t_sums, in_flight = _render(job, outdir, ks, group, stop)
        if stop.is_set():           # the render ended meanwhile: nobody waits for this
            return {"k": ks[0], "ks": ks, "host": host,
                    "error": {"type": "PovlensError", "hint": None,
                              "message": "stopped: the client's render ended"}}
    except PovlensError as e:
        return {"k": ks[0], "ks": ks, "host": host,
                "error": {"type": type(e).__name__, "message": e.message, "hint": e.hint}}
    return {"k": ks[0], "ks": ks, "host": host, "pid": os.getpid(), "files": files,
            "timing": {"unpack_s": t_unpack, "rays_and_meshes_s": timing["rays_and_meshes_s"],
                       "povray_s": timing["povray_s"], "sums_s": t_sums,
                       "in_flight": in_flight if group else 1,
                       "task_s": time.perf_counter() - t0}}


def _render(job: dict, outdir: Path, ks: list[int], group: bool, stop: threading.Event):
    """Render samples ``ks`` in ``outdir`` (the replica's render folder, or the
    client's when shared) until done or ``stop`` is set: (files, timing, seconds of
    partial sums, POV-Ray processes in flight)."""
    plan, lens, table = _load(job["key"] + ("-shared" if job["shared"] else ""), outdir)
    folder = RenderFolder(outdir)
    if not job["shared"]:
        for k in ks:         # an earlier attempt's, on this machine
            for p in folder.sample_outputs(k):
                p.unlink(missing_ok=True)
    in_flight = job.get("in_flight") or _in_flight()
    # the group's partial sums, each sample added here in sample order as soon as
    # it is rendered, while the group's other POV-Ray processes run
    sums = GroupSums(ks, lambda k: sample_sums(outdir, k, plan, table))
    t_sums = 0.0

    def add_ready():
        nonlocal t_sums
        t = time.perf_counter()
        sums.ready(folder.sample_done)
        t_sums += time.perf_counter() - t

    cores = max(1, in_flight // POVRAY_IN_FLIGHT)
    timing = render_samples(plan, lens, table, outdir, 0, ks,
                            in_flight=in_flight if group else 1,
                            on_done=add_ready if group else None, stop=stop,
                            stacking=stack_plan(plan, ks, cores, outdir=outdir) if group else None)
    files = {}
    if stop.is_set():
        return files, timing, t_sums, in_flight
    if group:
        add_ready()
        files["group"] = pack_group(ks, *sums.result())
    if not job["shared"]:
        for k in ks:
            for p in folder.sample_outputs(k):
                if not group:
                    files[p.name] = p.read_bytes()
                p.unlink(missing_ok=True)
    return files, timing, t_sums, in_flight


@single_threaded_blas
def render_sample(job: dict, k: int) -> dict:
    """Render lens sample ``k`` of the render folder ``job`` describes (group size 1).

    Parameters
    ----------
    job : dict
        ``outdir`` (the client's render folder, absolute), ``key`` and ``bundle``
        (:func:`povlens.cluster.bundle.make_bundle`; ``bundle`` None with
        ``shared``: the worker sees ``outdir`` itself and writes the sample there);
        optional ``in_flight`` (POV-Ray processes of a group task).
    k : int
        The sample number.

    Returns
    -------
    dict
        ``k``, ``ks`` = [k]; ``files``: {file name: bytes} of the sample's outputs
        (empty when shared); ``timing``: seconds of unpacking (``unpack_s``), tracing
        (``rays_and_meshes_s``), POV-Ray (``povray_s``, summed over processes),
        partial sums (``sums_s``) and the whole task (``task_s``); ``host``, ``pid``.
        A :class:`~povlens.errors.PovlensError` (the scene fails in POV-Ray, say) is
        returned as ``error`` = {type, message, hint}, not raised, so Dask does not
        retry what would fail again.
    """
    return _run(job, [int(k)], group=False)


@single_threaded_blas
def render_group(job: dict, ks: list[int]) -> dict:
    """Render the lens samples ``ks`` (consecutive, ascending) with several POV-Ray
    processes in flight (:func:`_in_flight`) and return their partial sums.

    Returns
    -------
    dict
        As :func:`render_sample`, but ``files`` = {"group": bytes of the group file}
        (:func:`povlens.rendering.groups.pack_group`: float32 ``sum w I`` (H, W, 3) and
        ``sum w``, added in sample order); the samples' own files are deleted (kept
        in place when shared).
    """
    return _run(job, [int(k) for k in ks], group=True)


def forget_render(key: str) -> dict:
    """Stop this process's tasks of the render ``key`` (their POV-Ray processes
    killed: :func:`povlens.cluster.running.stop_tasks`, every wait bounded), then
    delete this machine's replica of bundle ``key`` and this process's loaded plan
    (run on every worker when the client's render ends).

    Returns
    -------
    dict
        ``tasks`` stopped, ``killed`` POV-Ray processes, ``left`` tasks still running
        after the wait (the last of them deletes the replica when it ends).
    """
    def cleanup():
        with _loaded_lock:
            _loaded.pop(key, None)
            _loaded.pop(key + "-shared", None)
        if is_bundle_key(key):          # "shared-...": no replica
            remove_replica(key)

    return stop_tasks(key, cleanup)


async def forget_render_async(key: str) -> dict:
    """:func:`forget_render` in a thread of its own, so the worker's event loop (which
    runs what ``Client.run`` sends) keeps answering the scheduler meanwhile."""
    return await asyncio.get_running_loop().run_in_executor(None, forget_render, key)
