"""The client of a distributed render: lens samples on a Dask cluster, composited here.

``povlens render --scheduler ADDRESS`` converts as usual, then
:func:`render_outdir_on_cluster` sends every lens sample not yet rendered to the
scheduler as one task (:func:`povlens.cluster.worker.render_sample`), the render
folder's bundle (:mod:`povlens.cluster.bundle`) scattered to every worker once.  Each
sample's files are written into ``OUTDIR/samples/`` (atomically) as it comes back
and added to the composite's sums, in sample order (:func:`povlens.rendering.samples.sample_sums`,
then :func:`~povlens.rendering.samples.composite_outdir`), so the image is bit for bit
the one a local render makes.  A worker that dies
loses its samples in flight; the scheduler runs them again on another worker.  An
interrupted render resumes from the samples on disk, locally or on a cluster.
"""

from __future__ import annotations

import json
import os
import sys
import time
import uuid
from pathlib import Path

from povlens.cluster.bundle import make_bundle
from povlens.cluster.worker import render_sample
from povlens.errors import ParameterError, PovlensError, PovrayError
from povlens.plan.convert import ConvertOptions, convert
from povlens.plan.schema import read_plan
from povlens.rendering.samples import (composite_outdir, exposure_for, lens_for,
                                       mark_batches_done, pupil_table_for, render_outdir,
                                       sample_done, sample_sums)
from povlens.util.files import write_bytes, write_text

__all__ = ["ENV_VAR", "CONNECT_TIMEOUT_S", "WORKER_WAIT_S", "scheduler_address", "connect",
           "render_outdir_on_cluster", "convert_and_render_on_cluster"]

#: Environment variable naming the scheduler when ``--scheduler`` is not given.
ENV_VAR = "POVLENS_SCHEDULER"
#: Seconds to wait for the scheduler to answer.
CONNECT_TIMEOUT_S = 10.0
#: Seconds to wait for a first worker to join (a batch queue may take a while).
WORKER_WAIT_S = 600.0
#: Times a task is run again after an exception other than a PovlensError (a worker's
#: full disk, say).  A worker that dies does not count: the scheduler reschedules its
#: tasks by itself (up to Dask's ``distributed.scheduler.allowed-failures``).
RETRIES = 3


def scheduler_address(scheduler: str | None) -> str | None:
    """``scheduler``, else the environment's :data:`ENV_VAR`, else None (local)."""
    return scheduler or os.environ.get(ENV_VAR) or None


def connect(address: str, timeout_s: float = CONNECT_TIMEOUT_S):
    """A ``distributed.Client`` of the scheduler at ``address``.

    Raises
    ------
    PovlensError
        Dask distributed is not installed.
    ParameterError
        ``scheduler``: nothing answers at ``address`` within ``timeout_s`` seconds,
        or the address is not one.
    """
    try:
        from distributed import Client
    except ImportError:
        raise PovlensError("scheduler=... needs Dask distributed, which is not installed",
                           "pip install 'povlens[distributed]' (also on the workers)") from None
    from distributed.comm.addressing import parse_address, parse_host_port
    try:
        scheme, location = parse_address(address)
        if scheme in ("tcp", "tls"):
            parse_host_port(location)
    except ValueError as e:                 # checked here: Client would hang, then warn
        raise ParameterError("scheduler", address,
                             f"scheduler={address}: not a scheduler address ({e})",
                             "write it as tcp://HOST:PORT (Dask's default port is 8786)"
                             ) from None
    try:
        return Client(address, timeout=f"{float(timeout_s)}s", set_as_default=False)
    except (OSError, TimeoutError, ValueError) as e:
        reason = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ParameterError(
            "scheduler", address,
            f"scheduler={address}: no Dask scheduler answered within {timeout_s:g} s "
            f"({reason})",
            "start one ('dask scheduler') and give its address (tcp://HOST:8786), or "
            "leave out 'scheduler' to render on this machine") from None


def _raise_task_error(err: dict, k: int, host: str) -> None:
    cls = PovrayError if err["type"] == "PovrayError" else PovlensError
    raise cls(f"lens sample {k} on worker {host}: {err['message']}", err["hint"])


def _submit(client, job: dict, todo: list[int], worker_wait_s: float) -> list:
    try:
        client.wait_for_workers(1, timeout=worker_wait_s)
    except TimeoutError:
        raise PovlensError(f"no Dask worker joined the scheduler {client.scheduler.address} "
                           f"within {worker_wait_s:g} s",
                           "start workers ('dask worker ADDRESS') with POV-Ray and povlens "
                           "installed") from None
    # every worker gets the bundle once (not with each task); a worker that joins
    # later fetches it from another
    [job_future] = client.scatter([job], broadcast=True, hash=False)
    token = uuid.uuid4().hex[:8]
    return [client.submit(render_sample, job_future, k, key=f"povlens-sample-{k:04d}-{token}",
                          retries=RETRIES, pure=False) for k in todo]


class _Sums:
    """The composite's sums, added in sample order as the samples arrive (one that
    comes early waits on disk for those before it), so the composite is the one of a
    local render bit for bit and its cost overlaps the cluster's rendering."""

    def __init__(self, outdir: Path, plan, table):
        self.outdir, self.plan, self.table = outdir, plan, table
        self.next_k, self.ready = 0, set()
        self.total = self.wsum = None
        self.seconds = 0.0

    def add(self, k: int) -> None:
        t0 = time.perf_counter()
        self.ready.add(k)
        while self.next_k in self.ready:
            terms = sample_sums(self.outdir, self.next_k, self.plan, self.table)
            if terms is not None and self.total is None:
                self.total, self.wsum = terms
            elif terms is not None:
                self.total += terms[0]
                self.wsum += terms[1]
            self.ready.discard(self.next_k)
            self.next_k += 1
        self.seconds += time.perf_counter() - t0

    def result(self):
        if self.next_k != self.plan.inputs.samples:
            raise PovlensError(f"{self.outdir}: sample {self.next_k} never came back")
        return None if self.total is None else (self.total, self.wsum)


def _collect(client, futures, outdir: Path, shared: bool, on_sample, bar,
             sums: _Sums) -> list[dict]:
    """Write each sample's files as it comes back and add it to ``sums``; returns the
    results' timings."""
    from distributed import as_completed
    samples = outdir / "samples"
    tasks = []
    t0 = time.perf_counter()
    for fut in as_completed(futures, loop=client.loop):
        k = int(fut.key.split("-")[2])
        try:
            res = fut.result()
        except Exception as e:     # retries exhausted, or a sample that killed its workers
            raise PovlensError(f"lens sample {k} failed on the cluster: "
                               f"{type(e).__name__}: {e}",
                               "see the workers' logs; the samples already rendered are "
                               "kept, so running again resumes") from None
        if "error" in res:
            _raise_task_error(res["error"], k, res["host"])
        for name, data in sorted(res["files"].items(), key=lambda f: f[0].endswith(".exr")):
            write_bytes(samples / name, data)     # the image last: then the sample is done
        if not sample_done(outdir, k):
            raise PovlensError(f"lens sample {k}: worker {res['host']} rendered it, but "
                               f"{samples} has no result" + (
                                   ": do the workers see this folder at the same path?"
                                   if shared else ""),
                               "leave out 'shared_dir'" if shared else None)
        sums.add(k)
        tasks.append({"k": k, "host": res["host"], "pid": res["pid"],
                      "arrived_s": time.perf_counter() - t0,
                      "result_bytes": sum(len(d) for d in res["files"].values()),
                      **res["timing"]})
        bar.update(1)
        if on_sample is not None:
            on_sample(tasks[-1])
    return tasks


def _client_of(scheduler, timeout_s: float):
    """(client, whether this call made it) of an address, a ``distributed.Client`` or a
    cluster object (``LocalCluster``, dask-jobqueue's ``SLURMCluster``)."""
    if isinstance(scheduler, str):
        if not scheduler.strip():
            raise ParameterError("scheduler", scheduler, "scheduler='': not an address",
                                 "give the scheduler's address, tcp://HOST:8786")
        return connect(scheduler.strip(), timeout_s), True
    if hasattr(scheduler, "submit"):
        return scheduler, False
    if hasattr(scheduler, "scheduler_address"):
        return connect(scheduler.scheduler_address, timeout_s), True
    raise ParameterError("scheduler", scheduler,
                         f"scheduler={scheduler!r}: not an address, a Dask client or a cluster",
                         "give the scheduler's address, tcp://HOST:8786")


def render_outdir_on_cluster(outdir: str | os.PathLike, scheduler,
                             shared_dir: bool = False, quiet: bool = False,
                             connect_timeout_s: float = CONNECT_TIMEOUT_S,
                             worker_wait_s: float = WORKER_WAIT_S,
                             on_sample=None) -> tuple[Path, dict]:
    """Render a converted folder's lens samples on a Dask cluster and composite.

    Parameters
    ----------
    outdir : a folder written by ``povlens convert``.  Other methods than mesh have
        a single POV-Ray run, rendered here (:func:`povlens.rendering.samples.render_outdir`).
    scheduler : the scheduler's address (``tcp://host:8786``), a ``distributed.Client``
        (left open) or a cluster object (``LocalCluster``, ``SLURMCluster``).
    shared_dir : the workers see the scene, lens and ``outdir`` at the same paths (a
        shared filesystem): nothing is sent, they write the samples in place.
    quiet : no progress bar.
    connect_timeout_s, worker_wait_s : how long to wait for the scheduler to answer
        and for a first worker.
    on_sample : called as each sample is written, with its record (``k``, ``host``,
        ``pid`` of the worker, timings: as in ``stats["tasks"]``).

    Returns
    -------
    image : Path of ``image.exr``.
    stats : dict
        ``samples``, ``wall_s``, ``connect_s``, ``scatter_s`` (bundle to the workers),
        ``bundle_bytes``, ``workers``, and per sample (``tasks``): host, arrival time,
        result bytes and the worker's timing (:func:`povlens.cluster.worker.render_sample`).
        Also written to ``samples/cluster.timing.json``.
    """
    from tqdm import tqdm
    t0 = time.perf_counter()
    outdir = Path(os.path.abspath(outdir))
    plan = read_plan(outdir)
    if plan.inputs.method != "mesh":
        return render_outdir(outdir, quiet=quiet), {"samples": 0}
    todo = [k for k in range(plan.inputs.samples) if not sample_done(outdir, k)]
    stats = {"samples": len(todo), "tasks": []}
    if todo:
        lens = lens_for(plan)
        table = pupil_table_for(outdir, plan, lens)       # built here once, sent with the job
        client, owned = _client_of(scheduler, connect_timeout_s)
        stats["connect_s"] = time.perf_counter() - t0
        futures = []
        try:
            if shared_dir:
                job = {"outdir": str(outdir), "key": f"shared-{uuid.uuid4().hex}",
                       "bundle": None, "shared": True}
            else:
                key, data = make_bundle(outdir, plan)
                job = {"outdir": str(outdir), "key": key, "bundle": data, "shared": False}
            stats["bundle_bytes"] = len(job["bundle"] or b"")
            futures = _submit(client, job, todo, worker_wait_s)
            stats["scatter_s"] = time.perf_counter() - t0 - stats["connect_s"]
            stats["workers"] = len(client.nthreads())
            exposure_for(outdir, plan, lens, table)      # while the workers render
            sums = _Sums(outdir, plan, table)
            for k in sorted(set(range(plan.inputs.samples)) - set(todo)):
                sums.add(k)                              # rendered before: resumed
            with tqdm(total=len(todo), desc="lens samples", unit="sample", file=sys.stderr,
                      disable=quiet or not sys.stderr.isatty()) as bar:
                stats["tasks"] = _collect(client, futures, outdir, shared_dir, on_sample,
                                          bar, sums)
            stats["composite_during_s"] = sums.seconds
        finally:
            if futures:
                client.cancel(futures)
            if owned:
                client.close()
    mark_batches_done(outdir, plan)
    t1 = time.perf_counter()
    composite_outdir(outdir, sums=sums.result() if todo else None)
    stats["composite_after_s"] = time.perf_counter() - t1
    stats["wall_s"] = time.perf_counter() - t0
    if todo:
        write_text(outdir / "samples" / "cluster.timing.json", json.dumps(stats) + "\n")
    return outdir / "image.exr", stats


def convert_and_render_on_cluster(opts: ConvertOptions, scheduler: str, shared_dir: bool = False,
                                  quiet: bool = False, on_plan=None,
                                  connect_timeout_s: float = CONNECT_TIMEOUT_S):
    """``povlens render --scheduler``: convert ``opts`` here (the depth probe of
    ``--method auto`` too), then :func:`render_outdir_on_cluster`.  Returns (plan,
    path of image.exr).  The scheduler is asked first, so one that does not answer
    fails before the conversion's work."""
    client, owned = _client_of(scheduler, connect_timeout_s)
    try:
        plan = convert(opts)
        if on_plan is not None:
            on_plan(plan)
        exr, _ = render_outdir_on_cluster(opts.outdir, client, shared_dir=shared_dir,
                                          quiet=quiet)
    finally:
        if owned:
            client.close()
    return plan, exr
