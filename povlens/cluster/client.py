"""The client of a distributed render: lens samples on a Dask cluster, composited here.

``povlens render --scheduler ADDRESS`` converts as usual, then
:func:`render_outdir_on_cluster` cuts the lens samples not yet rendered into groups of
consecutive samples, one task each (:func:`povlens.cluster.worker.render_group`: the
worker renders them with several POV-Ray processes in flight and adds them into a
partial sum), the render folder's bundle (:mod:`povlens.cluster.bundle`) scattered to
every worker once.  Each group's partial sums are written into
``OUTDIR/samples/group_K0_K1.npz`` (atomically) as they come back and added to the
composite's sums in group order (:mod:`povlens.rendering.groups`), so the image is
the local one within the float32 rounding of the partials, whatever the number of
workers or the order groups finish in.  With group size 1 a task is one sample
(:func:`~povlens.cluster.worker.render_sample`), its files come back, and the image is
the local one bit for bit.  A worker that dies loses its groups in flight; the
scheduler runs them again on another worker.  An interrupted render resumes from the
groups and samples on disk, locally or on a cluster.  When the render ends (done, failed
or interrupted), the workers stop its tasks still running, POV-Ray processes killed,
and delete their copies of the bundle (:func:`~povlens.cluster.worker.forget_render`;
at most :data:`FORGET_TIMEOUT_S`).

The scheduler's address may be ``tcp://`` or ``tls://``; a ``tls://`` scheduler is
reached with Dask's own TLS configuration (``distributed.comm.tls.*`` in the Dask
config files or ``DASK_DISTRIBUTED__COMM__TLS__...`` variables), or the ``security``
of the ``Client`` or cluster object given.
"""

from __future__ import annotations

import json
import os
import sys
import time
import uuid
from pathlib import Path

from povlens.cluster.bundle import bundle_files, make_bundle
from povlens.cluster.running import STOP_WAIT_S
from povlens.cluster.worker import forget_render_async, render_group, render_sample
from povlens.errors import ParameterError, PovlensError, PovrayError
from povlens.plan.convert import ConvertOptions, convert
from povlens.plan.options import SCHEDULER_ENV_VAR, DaskOptions
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import read_plan
from povlens.rendering.driver import render_outdir
from povlens.rendering.folder_composite import composite_outdir, sample_sums
from povlens.rendering.folder_inputs import exposure_for, lens_for, pupil_table_for
from povlens.rendering.groups import (UnitSums, choose_group_size, chunk_groups, render_units,
                                      unit_terms, write_group)
from povlens.rendering.mesh_samples import mark_batches_done
from povlens.rendering.photon_map import photon_map_for
from povlens.rendering.radiosity_cache import radiosity_cache_for
from povlens.util.files import write_bytes, write_text

__all__ = ["DaskRenderer", "ENV_VAR", "CONNECT_TIMEOUT_S", "WORKER_WAIT_S", "scheduler_address",
           "connect",
           "render_outdir_on_cluster", "convert_and_render_on_cluster",
           "render_frames_on_cluster", "task_samples"]

#: Environment variable naming the scheduler when ``--scheduler`` is not given.
ENV_VAR = SCHEDULER_ENV_VAR
#: Seconds to wait for the scheduler to answer.
CONNECT_TIMEOUT_S = DaskOptions.scheduler_timeout_s   # --scheduler-timeout's default
#: Seconds to wait for a first worker to join (a batch queue may take a while).
WORKER_WAIT_S = 600.0
#: Times a task is run again after an exception other than a PovlensError (a worker's
#: full disk, say).  A worker that dies does not count: the scheduler reschedules its
#: tasks by itself (up to Dask's ``distributed.scheduler.allowed-failures``).
RETRIES = 3
#: Seconds the client waits for the workers to stop a render's tasks and delete its
#: replica (:func:`~povlens.cluster.worker.forget_render`); a worker slower than
#: that cleans up by itself.
FORGET_TIMEOUT_S = STOP_WAIT_S + 10.0
#: How to start a scheduler, as the hints say it: listening on an address of the
#: user's choice (without ``--host``, ``dask scheduler`` listens on every interface and
#: anyone who reaches the port can run code on the workers).
START_SCHEDULER = ("'dask scheduler --host HOST' (HOST: 127.0.0.1 on one machine, else an "
                   "address of a network only your machines reach; elsewhere tls:// with "
                   "--tls-ca-file, --tls-cert and --tls-key)")


def scheduler_address(scheduler: str | None) -> str | None:
    """``scheduler``, else the environment's :data:`ENV_VAR`, else None (local)."""
    return scheduler or os.environ.get(ENV_VAR) or None


def connect(address: str, timeout_s: float = CONNECT_TIMEOUT_S, security=None):
    """A ``distributed.Client`` of the scheduler at ``address``; ``security`` (a
    ``distributed.Security``) as the Client takes it, None: Dask's configuration
    (``distributed.comm.tls.*``).

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
                             "write it as tcp://HOST:PORT or tls://HOST:PORT (Dask's "
                             "default port is 8786)") from None
    if scheme == "tls":
        _check_tls(address, security)
    try:
        return Client(address, timeout=f"{float(timeout_s)}s", set_as_default=False,
                      security=security)
    except (OSError, TimeoutError, ValueError, TypeError) as e:
        reason = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ParameterError(
            "scheduler", address,
            f"scheduler={address}: no Dask scheduler answered within {timeout_s:g} s "
            f"({reason})",
            f"start one with {START_SCHEDULER} and give its address (tcp://HOST:8786), or "
            "leave out 'scheduler' to render on this machine") from None


#: The Dask configuration a tls:// scheduler needs on the client, as variables.
TLS_VARIABLES = ("DASK_DISTRIBUTED__COMM__TLS__CA_FILE",
                 "DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT",
                 "DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY")


def _check_tls(address: str, security) -> None:
    """A ``tls://`` scheduler needs the client's TLS settings: ``security``, else
    Dask's configuration (``distributed.comm.tls.ca-file``, ``client.cert``,
    ``client.key``).  Without them ``distributed.Client`` fails with a TypeError
    about an SSL context; say what is missing instead."""
    from distributed.security import Security
    try:
        sec = security if security is not None else Security()
        context = sec.get_connection_args("client").get("ssl_context")
    except (OSError, ValueError) as e:      # a certificate file missing or unreadable
        raise ParameterError("scheduler", address,
                             f"scheduler={address}: the TLS configuration cannot be used "
                             f"({e})",
                             "check the files Dask's distributed.comm.tls settings name"
                             ) from None
    if context is None:
        raise ParameterError(
            "scheduler", address,
            f"scheduler={address}: a tls:// scheduler, but Dask has no TLS configuration "
            f"for this client (distributed.comm.tls.ca-file, client.cert, client.key)",
            f"set {', '.join(TLS_VARIABLES)} (or distributed.comm.tls in "
            f"~/.config/dask/distributed.yaml) to the CA file, certificate and key the "
            f"scheduler was started with")


def _raise_task_error(err: dict, k: int, host: str) -> None:
    cls = PovrayError if err["type"] == "PovrayError" else PovlensError
    raise cls(f"lens sample {k} on worker {host}: {err['message']}", err["hint"])


def _wait_for_workers(client, worker_wait_s: float) -> None:
    try:
        client.wait_for_workers(1, timeout=worker_wait_s)
    except TimeoutError:
        raise PovlensError(f"no Dask worker joined the scheduler {client.scheduler.address} "
                           f"within {worker_wait_s:g} s",
                           "start workers ('dask worker ADDRESS --host HOST') with POV-Ray "
                           "and povlens installed") from None


def _submit(client, job: dict, groups: list[list[int]], group_size: int) -> list:
    """One task per group (:func:`~povlens.cluster.worker.render_group`; with group
    size 1, one per sample: :func:`~povlens.cluster.worker.render_sample`)."""
    # every worker gets the bundle once (not with each task); a worker that joins
    # later fetches it from another
    [job_future] = client.scatter([job], broadcast=True, hash=False)
    token = uuid.uuid4().hex[:8]
    if group_size == 1:
        return [client.submit(render_sample, job_future, ks[0],
                              key=f"povlens-sample-{ks[0]:04d}-{token}", retries=RETRIES,
                              pure=False) for ks in groups]
    return [client.submit(render_group, job_future, ks,
                          key=f"povlens-group-{ks[0]:04d}-{ks[-1] + 1:04d}-{token}",
                          retries=RETRIES, pure=False) for ks in groups]


def task_samples(key: str) -> list[int]:
    """The lens samples of a task of :func:`_submit`, from its key."""
    parts = key.split("-")
    k0 = int(parts[2])
    return list(range(k0, int(parts[3]))) if parts[1] == "group" else [k0]


def _write_result(outdir: Path, res: dict, shared: bool) -> None:
    """Write a task's files into ``OUTDIR/samples`` (atomically; a sample's image last:
    then it is done) and check they are there."""
    folder = RenderFolder(outdir)
    samples = folder.samples
    ks = res["ks"]
    if "group" in res["files"]:
        write_group(outdir, ks, res["files"]["group"])
        return
    for name, data in sorted(res["files"].items(), key=lambda f: f[0].endswith(".exr")):
        write_bytes(samples / name, data)
    if not all(folder.sample_done(k) for k in ks):
        raise PovlensError(f"lens sample {ks[0]}: worker {res['host']} rendered it, but "
                           f"{samples} has no result" + (
                               ": do the workers see this folder at the same path?"
                               if shared else ""),
                           "leave out 'shared_dir'" if shared else None)


def _collect(client, futures, outdir: Path, shared: bool, on_sample, bar,
             sums: UnitSums) -> list[dict]:
    """Write each task's files as it comes back and add them to ``sums``; returns the
    results' timings (one record per task)."""
    from distributed import as_completed
    tasks = []
    t0 = time.perf_counter()
    for fut in as_completed(futures, loop=client.loop):
        ks = task_samples(fut.key)
        try:
            res = fut.result()
        except Exception as e:     # retries exhausted, or a sample that killed its workers
            raise PovlensError(f"lens samples {ks[0]}..{ks[-1]} failed on the cluster: "
                               f"{type(e).__name__}: {e}",
                               "see the workers' logs; the samples already rendered are "
                               "kept, so running again resumes") from None
        if "error" in res:
            _raise_task_error(res["error"], ks[0], res["host"])
        t1 = time.perf_counter()
        _write_result(outdir, res, shared)
        sums.add(ks[0], ks[-1] + 1)
        tasks.append({"k": ks[0], "ks": ks, "host": res["host"], "pid": res["pid"],
                      "arrived_s": t1 - t0, "client_s": time.perf_counter() - t1,
                      "result_bytes": sum(len(d) for d in res["files"].values()),
                      **res["timing"]})
        bar.update(len(ks))
        if on_sample is not None:
            on_sample(tasks[-1])
    return tasks


def _forget(client, key: str) -> None:
    """Stop the workers' tasks of render ``key`` still running (cancelling does not
    stop a running task; their POV-Ray processes are killed) and delete their
    replicas, waiting at most :data:`FORGET_TIMEOUT_S`.  A worker that does not answer
    keeps its copy (in its $TMPDIR) until it is stale."""
    try:
        client.sync(client._run, forget_render_async, key, on_error="ignore",
                    callback_timeout=FORGET_TIMEOUT_S)
    except Exception:           # a worker gone, a client closing, the wait over
        pass


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
    if hasattr(scheduler, "scheduler_address"):     # a cluster: its TLS settings too
        return connect(scheduler.scheduler_address, timeout_s,
                       security=getattr(scheduler, "security", None)), True
    raise ParameterError("scheduler", scheduler,
                         f"scheduler={scheduler!r}: not an address, a Dask client or a cluster",
                         "give the scheduler's address, tcp://HOST:8786")


def _group_size(group_size: int | None, client, samples: int) -> int:
    if group_size is None:
        return choose_group_size(samples, len(client.nthreads()))
    if isinstance(group_size, bool) or not isinstance(group_size, int) or group_size < 1:
        raise ParameterError("group_size", group_size,
                             f"group_size={group_size!r}: not a whole number >= 1",
                             "give the lens samples per task (1: one task per sample, the "
                             "image bit for bit the local one), or leave it out")
    return group_size


def render_outdir_on_cluster(outdir: str | os.PathLike, scheduler,
                             shared_dir: bool = False, quiet: bool = False,
                             connect_timeout_s: float = CONNECT_TIMEOUT_S,
                             worker_wait_s: float = WORKER_WAIT_S,
                             on_sample=None, group_size: int | None = None) -> tuple[Path, dict]:
    """Render a converted folder's lens samples on a Dask cluster and composite.

    Parameters
    ----------
    outdir : a folder written by ``povlens convert``.  Other methods than mesh have
        a single POV-Ray run, rendered here (:func:`povlens.rendering.driver.render_outdir`).
    scheduler : the scheduler's address (``tcp://host:8786``), a ``distributed.Client``
        (left open) or a cluster object (``LocalCluster``, ``SLURMCluster``).
    shared_dir : the workers see the scene, lens and ``outdir`` at the same paths (a
        shared filesystem): nothing is sent, they write the samples in place.
    quiet : no progress bar.
    connect_timeout_s, worker_wait_s : how long to wait for the scheduler to answer
        and for a first worker.
    on_sample : called as each task's result is written, with its record (``k``,
        ``ks``, ``host``, ``pid`` of the worker, timings: as in ``stats["tasks"]``).
    group_size : lens samples per task (consecutive), summed on the worker with
        several POV-Ray processes in flight (:mod:`povlens.rendering.groups`); 1: one
        task per sample, whose files come back, and the image is the local one bit for
        bit.  Default :func:`~povlens.rendering.groups.choose_group_size`.

    Returns
    -------
    image : Path of ``image.exr``.
    stats : dict
        ``samples``, ``group_size``, ``wall_s``, ``connect_s``, ``scatter_s`` (bundle
        to the workers), ``bundle_bytes`` (compressed), ``bundle_files``,
        ``bundle_input_bytes`` (their size), ``bundle_trees_because`` (None: the files
        the scene names were sent; else why the folders' trees), ``workers``,
        ``threads``, and per task (``tasks``): samples, host, arrival time, the
        client's time on it (write and add), result bytes and the worker's timing
        (:func:`povlens.cluster.worker.render_sample`).  Also written to
        ``samples/cluster.timing.json``.
    """
    t0 = time.perf_counter()
    outdir = Path(os.path.abspath(outdir))
    folder = RenderFolder(outdir)
    plan = read_plan(outdir)
    if plan.inputs.method != "mesh":
        return render_outdir(outdir, quiet=quiet), {"samples": 0}
    done, todo = render_units(outdir, plan)   # groups and samples on disk
    stats = {"samples": len(todo), "tasks": []}
    sums = None
    if todo:
        lens = lens_for(plan)
        table = pupil_table_for(outdir, plan, lens)       # built here once, sent with the job
        client, owned = _client_of(scheduler, connect_timeout_s)
        stats["connect_s"] = time.perf_counter() - t0
        try:
            sums = _render_on(client, outdir, plan, lens, table, done, todo, stats, t0,
                              shared_dir=shared_dir, quiet=quiet, worker_wait_s=worker_wait_s,
                              on_sample=on_sample, group_size=group_size)
        finally:
            if owned:
                client.close()
    mark_batches_done(outdir, plan)
    t1 = time.perf_counter()
    composite_outdir(outdir, sums=sums.result(str(outdir)) if sums is not None else None)
    stats["composite_after_s"] = time.perf_counter() - t1
    stats["wall_s"] = time.perf_counter() - t0
    if todo:
        write_text(folder.timing("cluster"), json.dumps(stats) + "\n")
    return folder.image_exr, stats


def _job(outdir: Path, plan, shared_dir: bool) -> dict:
    """What every task gets: the render folder, the bundle's key and bytes (None when
    the workers see the folder: ``shared_dir``)."""
    radiosity_cache_for(plan, outdir)   # made here once, it travels with the bundle
    photon_map_for(plan, outdir)        # so does the photon map
    if shared_dir:
        return {"outdir": str(outdir), "key": f"shared-{uuid.uuid4().hex}",
                "bundle": None, "shared": True}
    files = bundle_files(outdir, plan)
    key, data = make_bundle(outdir, plan, files)
    return {"outdir": str(outdir), "key": key, "bundle": data, "shared": False,
            "files": len(files.files), "input_bytes": files.size_bytes,
            "trees_because": files.trees_because}


#: A bundle this large (bytes, before compression) is reported on stderr.
NOTE_BUNDLE_BYTES = 16 * 1024 * 1024


def _note_bundle(job: dict, plan, quiet: bool) -> None:
    """Say how much is sent to the workers when it is large (not when ``quiet``)."""
    size = job.get("input_bytes", 0)
    if not quiet and size >= NOTE_BUNDLE_BYTES:
        why = job.get("trees_because")
        what = ("the files the scene names" if why is None else
                f"the folder {Path(plan.inputs.scene).parent} and the library folders, "
                f"hidden files left out ({why})")
        print(f"povlens: sending {job['files']} files ({size / 1e6:.0f} MB) to the "
              f"workers: the render folder, the lens and {what}", file=sys.stderr)


def _render_on(client, outdir: Path, plan, lens, table, done: list, todo: list[int],
               stats: dict, t0: float, *, shared_dir: bool, quiet: bool,
               worker_wait_s: float, on_sample, group_size: int | None) -> UnitSums:
    """Render the samples ``todo`` on ``client``'s workers and return the composite's
    sums, the units ``done`` (rendered before: resumed) added too; ``stats`` gets the
    group size, bundle, workers and tasks (:func:`render_outdir_on_cluster`).  The
    tasks left when it ends (an error, an interrupt) are cancelled and the workers'
    replicas deleted."""
    from tqdm import tqdm
    futures, job = [], None
    try:
        _wait_for_workers(client, worker_wait_s)
        size = _group_size(group_size, client, len(todo))
        groups = chunk_groups(todo, size)
        job = _job(outdir, plan, shared_dir)
        stats.update(bundle_bytes=len(job["bundle"] or b""), group_size=size,
                     groups=len(groups), bundle_files=job.get("files", 0),
                     bundle_input_bytes=job.get("input_bytes", 0),
                     bundle_trees_because=job.get("trees_because"))
        _note_bundle(job, plan, quiet)
        futures = _submit(client, job, groups, size)
        stats["scatter_s"] = time.perf_counter() - t0 - stats["connect_s"]
        stats["workers"] = len(client.nthreads())
        stats["threads"] = sum(client.nthreads().values())
        exposure_for(outdir, plan, lens, table)      # while the workers render
        sums = UnitSums(plan.inputs.samples, unit_terms(outdir, plan, table, sample_sums))
        for k0, k1 in done:
            sums.add(k0, k1)                         # rendered before: resumed
        with tqdm(total=len(todo), desc="lens samples", unit="sample", file=sys.stderr,
                  disable=quiet or not sys.stderr.isatty()) as bar:
            stats["tasks"] = _collect(client, futures, outdir, shared_dir, on_sample,
                                      bar, sums)
        return sums
    finally:
        if futures:
            client.cancel(futures)
        if job is not None:         # the workers' replica and loaded plan
            _forget(client, job["key"])


def convert_and_render_on_cluster(opts: ConvertOptions, scheduler, shared_dir: bool = False,
                                  quiet: bool = False, on_plan=None,
                                  connect_timeout_s: float = CONNECT_TIMEOUT_S,
                                  group_size: int | None = None, depth_probe=None):
    """``povlens render --scheduler``: convert ``opts`` here (the depth probe of
    ``--method auto`` too; ``depth_probe`` as :func:`~povlens.plan.convert.convert`
    takes it), then :func:`render_outdir_on_cluster`.  Returns (plan, path of
    image.exr).  The scheduler is asked first, so one that does not answer fails
    before the conversion's work."""
    client, owned = _client_of(scheduler, connect_timeout_s)
    try:
        if group_size is not None:
            _group_size(group_size, client, 1)          # checked before converting
        plan = convert(opts, depth_probe=depth_probe)
        if on_plan is not None:
            on_plan(plan)
        exr, _ = render_outdir_on_cluster(opts.outdir, client, shared_dir=shared_dir,
                                          quiet=quiet, group_size=group_size)
    finally:
        if owned:
            client.close()
    return plan, exr


def render_frames_on_cluster(opts: ConvertOptions, focus_values: list[float], scheduler,
                             shared_dir: bool = False, quiet: bool = False, on_plan=None,
                             connect_timeout_s: float = CONNECT_TIMEOUT_S,
                             group_size: int | None = None):
    """A focus pull (``povlens render --frames N --scheduler``): every frame converted
    here and its lens samples rendered on the cluster, one client for all frames
    (:func:`povlens.rendering.focus_pull.render_frames` with this frame renderer).
    Returns the frames' records."""
    from povlens.rendering.focus_pull import render_frames
    client, owned = _client_of(scheduler, connect_timeout_s)
    try:
        def render_frame(frame_opts, on_plan=None, depth_probe=None, **_):
            return convert_and_render_on_cluster(frame_opts, client, shared_dir=shared_dir,
                                                 quiet=quiet, on_plan=on_plan,
                                                 group_size=group_size,
                                                 depth_probe=depth_probe)
        return render_frames(opts, focus_values, quiet=quiet, on_plan=on_plan,
                             render_frame=render_frame)
    finally:
        if owned:
            client.close()


class DaskRenderer:
    """Renders the lens samples on the Dask cluster of ``options.scheduler``; what
    :func:`povlens.api.renderer_for` gives when a scheduler is named (its counterpart
    is :class:`povlens.rendering.local_renderer.LocalRenderer`)."""

    def __init__(self, options: DaskOptions):
        self.options = options

    def _keywords(self) -> dict:
        o = self.options
        return {"shared_dir": o.shared_dir, "connect_timeout_s": o.scheduler_timeout_s,
                "group_size": o.group_size}

    def render(self, opts: ConvertOptions, quiet: bool = False, on_plan=None):
        """Convert ``opts`` here, render its samples on the cluster: (plan, image.exr)."""
        return convert_and_render_on_cluster(opts, self.options.scheduler, quiet=quiet,
                                             on_plan=on_plan, **self._keywords())

    def render_frames(self, opts: ConvertOptions, focus_values: list[float],
                      quiet: bool = False, on_plan=None) -> list:
        """Every frame of a focus pull, one client for all: the frames' records."""
        return render_frames_on_cluster(opts, focus_values, self.options.scheduler,
                                        quiet=quiet, on_plan=on_plan, **self._keywords())
