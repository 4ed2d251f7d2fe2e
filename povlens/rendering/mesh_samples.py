"""The mesh method's lens samples: each traced, its ray mesh written and rendered by its
own POV-Ray process, several in flight.

Batch b of a mesh plan (``povlens render-batch``, make's target) and every sample of
``povlens render`` (:mod:`povlens.rendering.driver`) go through :func:`render_samples`.
Sample k's outputs (names: :class:`~povlens.plan.render_folder.RenderFolder`), each
written under a temporary name and then renamed, so an interrupted run never leaves a
half-written file at a final name:

* its image (POV-Ray, linear EXR) and its per-pixel radiometric weights (float32; field
  meshes: its pass mask instead, :mod:`povlens.rendering.field_samples`), or, when
  every ray of its rows is blocked, the marker that it has no image (black, weight 0);
* its ray mesh, written just before its POV-Ray process starts and deleted when the
  render ends; samples are traced one at a time while earlier ones render (several
  in flight, :data:`POVRAY_IN_FLIGHT`);
* a batch's marker once all its samples are done (:func:`mark_batches_done`).

Every POV-Ray run gets the user's POV-Ray options the plan records (library paths,
clock, passthrough options: :func:`povlens.plan.options.povray_options_of`), so
``make`` and ``povlens render-batch`` render as ``povlens render`` does; lens samples
run without anti-aliasing whatever the options say (:data:`MESH_SWITCHES`).
Re-running skips every sample that is done: that is how an interrupted render resumes.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from povlens.errors import PovlensError
from povlens.plan.folder_lock import batch_lock, folder_lock
from povlens.plan.options import povray_options_of
from povlens.plan.plan_finish import no_pretrace
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Plan, PovraySettings, read_plan
from povlens.pov.executable import find_povray
from povlens.pov.mesh import RADIOSITY_READ_FLAG, eye_text, write_ray_mesh
from povlens.pov.povray_output import povray_failure
from povlens.pov.render_statistics import (STATISTICS_SWITCHES, render_statistics,
                                           statistics_complete)
from povlens.pov.process import (FIRST_OUTPUT_S, output_written, pixel_range_args,
                                 poll_interval_s, povray_command, povray_finished,
                                 render_switches, start_povray)
from povlens.pupil.rays import sample_points, sample_rays
from povlens.rendering.field_samples import (placement_of, render_rows, sample_lens,
                                             write_field_stack)
from povlens.rendering.folder_inputs import exposure_for, lens_for, pupil_table_for
from povlens.rendering.pixel_sampler import pixel_sampler
from povlens.util.files import write_text
from povlens.util.images import write_exr
from povlens.rendering.photon_map import photon_load_args, photon_map_for, photon_map_ready
from povlens.rendering.sample_stacks import (StackPlan, recorded_bands, split_stack, stack_bands,
                                             stack_plan,
                                             stack_row_args, stack_runs)
from povlens.rendering.radiosity_cache import (choice_from, probe_measurement,
                                               probes_missing, radiosity_cache_for,
                                               radiosity_cache_ready, radiosity_read_args,
                                               record_probes, sharing_chosen)
from povlens.util.signals import interrupts_deferred

__all__ = ["render_samples", "render_batch", "sample_rows", "film_row_args",
           "mark_batches_done", "POVRAY_IN_FLIGHT", "MESH_SWITCHES"]


def sample_rows(plan: Plan, k: int) -> tuple[int, int]:
    """Film rows [start, end) sample k renders (all rows unless the plan is adaptive)."""
    return plan.rows_of_sample(k)


def _write_mesh(plan: Plan, lens, table, outdir: Path, k: int,
                points: np.ndarray | None = None) -> bool:
    """Write sample k's ray mesh and weights.

    ``table`` is the lens sampler (the plan's exit-pupil table; any object with
    the ``sample(film_xy, u)`` protocol of :func:`povlens.pupil.rays.sample_rays`
    works).  ``points`` overrides the plan's (H, W, 4) sample points of sample k
    (default: :func:`povlens.pupil.rays.sample_points`); :mod:`povlens.bench`
    uses both to render with the baseline samplers and random points.  A plan
    with field meshes writes its sample with
    :func:`_write_stack` (no ``points``).
    """
    folder = RenderFolder(outdir)
    inc = folder.sample_mesh(k)
    folder.sample_blocked(k).unlink(missing_ok=True)    # one of an earlier render: stale
    if plan.field_mesh is not None:
        if points is not None:
            raise PovlensError("field-mesh samples share one pupil point per sample: "
                               "they take no per-pixel sample points",
                               "convert with --ray-mesh pixel")
        return _write_stack(plan, lens, table, outdir, [k], stack_bands(plan, outdir))[0]
    film = plan.film
    placement = placement_of(plan)
    inp = plan.inputs
    if points is None:
        points = sample_points(inp.samples, film.height_px, film.width_px, inp.seed)(k)
    else:
        points = np.array(points, dtype=np.float64)
    if not inp.jitter:
        points[..., :2] = 0.5  # pixel centres, as POV-Ray's perspective camera
    table = pixel_sampler(plan, lens, table)    # the band with --dispersion; an iris's domain
    if inp.dispersion:                           # sample k's wavelength
        lens = sample_lens(plan, lens, k)
    r0, r1 = sample_rows(plan, k)
    rays = sample_rays(lens, plan.focus.film_distance_mm, film, table, placement, points,
                       rows=(r0, r1))  # rows this sample does not render: no rays, weight 0
    valid, weight = rays.valid, rays.weight
    if not np.any(weight[r0:r1] > 0):
        # every ray of its rows blocked: black, weight 0, nothing to render
        write_exr(folder.sample_weight(k), np.zeros(weight.shape + (1,), dtype=np.float32))
        write_text(folder.sample_blocked(k), f"{r0} {r1}\n")
        return False
    part = folder.partial(inc)
    t = write_ray_mesh(part, "PovlensRays", rays.origin, rays.direction, valid,
                       sink_centre=plan.sink_centre)
    with open(part, "a") as f:
        f.write(f"#declare PovlensTranslate = <{t[0]:.17g}, {t[1]:.17g}, {t[2]:.17g}>;\n")
        f.write(eye_text(pixel_mesh_eye(plan)))
    os.replace(part, inc)
    write_exr(folder.sample_weight(k), weight[..., None].astype(np.float32))
    return True


def pixel_mesh_eye(plan: Plan) -> tuple[float, float, float]:
    """The ``location`` of a per-pixel (distribution 0) mesh camera: the scene camera's,
    from which POV-Ray measures radiosity's reuse distances.  POV-Ray 3.7.0.10 moves no
    distribution-0 ray by it (measured: the same bits as at the origin; the room of
    ``tests/rendering/test_mesh_camera_eye.py`` with radiosity 0.2-0.3 % off
    focal_blur's mean at the eye, 1.4-3.4 % at the origin); other versions keep the
    origin."""
    if not str(plan.povray.version).startswith("3.7.0"):
        return (0.0, 0.0, 0.0)
    x, y, z = (float(v) for v in plan.povray_camera.location)
    return (x, y, z)


def _write_stack(plan: Plan, lens, table, outdir: Path, ks: list[int],
                 bands: int) -> list[bool]:
    """Write the one ray mesh of field passes ``ks``, each in its band of a stack of
    ``bands`` (:mod:`povlens.rendering.sample_stacks`), as the first one's, and their
    pass masks; a blocked pass gets its marker.  Returns which passes have a band to
    render."""
    folder = RenderFolder(outdir)
    for k in ks:
        folder.sample_blocked(k).unlink(missing_ok=True)    # one of an earlier render: stale
    drawn = write_field_stack(plan, lens, table, outdir, ks, folder.sample_mesh(ks[0]), bands)
    for k, ok in zip(ks, drawn):
        if not ok:
            write_text(folder.sample_blocked(k), "%d %d\n" % plan.rows_of_sample(k))
    return drawn


def film_row_args(povray: PovraySettings, rows: tuple[int, int]) -> list[str]:
    """POV-Ray's +SR/+ER switches rendering only the film rows ``rows``.

    Parameters
    ----------
    povray : the plan's POV-Ray settings (``drop_top_rows``, ``render_height``).
    rows : film rows [r0, r1), 0 = top.

    Returns
    -------
    list of str
        Output row = film row + drop_top_rows (:func:`povlens.pov.process.pixel_range_args`);
        the columns before ``drop_right_columns`` when there are such.
    """
    r0, r1 = rows
    drop = povray.drop_top_rows
    cols = []
    if povray.drop_right_columns:       # field meshes: the last column is not traced
        cols = pixel_range_args(0, povray.render_width - povray.drop_right_columns,
                                povray.render_width, "col")
    return cols + pixel_range_args(r0 + drop, r1 + drop, povray.render_height, "row")


#: POV-Ray switches of a lens sample's render after the user's options: no
#: anti-aliasing, which would take rays between pixels from the neighbouring pixels'
#: mesh faces (the plan's notes say so when the user's options turn it on).
MESH_SWITCHES = ("-A",)

#: POV-Ray processes in flight per core (``render_outdir``) or per batch (``povlens
#: render-batch``): each run idles ~0.6 s in start-up, so several overlap on a core
#: (measurements: docs/decisions/planning.md, "POV-Ray processes in flight").
POVRAY_IN_FLIGHT = 4

#: POV-Ray's fatal-error log of a sample's run, in its temporary folder (``+GF``).
FATAL_LOG = "fatal.log"


class _SampleRenders:
    """POV-Ray processes rendering single lens samples of a batch, at most
    ``limit`` at once.  :meth:`start` returns once a slot is free; :meth:`finish`
    waits for all.  Each sample renders into its own temporary folder (stderr to a
    file there, so a chatty scene cannot fill a pipe) and is renamed to
    ``sample_KKKK.exr`` when POV-Ray succeeds; its mesh is deleted then."""

    def __init__(self, plan: Plan, outdir: Path, batch: int, limit: int = POVRAY_IN_FLIGHT,
                 on_done=None, threads: int = 1, one_run: bool = False,
                 chained: bool = False, statistics: bool = False,
                 read_shared: bool = False, keep_chain: bool = False,
                 exiting: list | None = None, wait_first=(), idle: bool = False):
        self.plan, self.folder, self.batch = plan, RenderFolder(outdir), batch
        self.on_done = on_done
        self.samples = self.folder.samples
        self.limit = 1 if chained else max(1, int(limit))
        self.threads = max(1, int(threads))
        self.chained = chained          # runs in turn, handing on their radiosity samples
        # POV-Ray's statistics of each run, waited for as it exits: first sample -> (its
        # run's wall time, RenderStatistics)
        self.statistics = statistics
        self.run_statistics: dict[int, tuple[float, object]] = {}
        # runs whose image and statistics are in while POV-Ray still idles before it
        # exits: killed, or, chained, handed to ``exiting`` (it saves its radiosity
        # samples as it exits; the caller waits for it or kills it, or passes it in
        # ``wait_first`` to a later render, whose first run starts once it has exited)
        self.exiting = exiting
        self.early: set[int] = set()
        self.wait_first: list[subprocess.Popen] = list(wait_first)
        self.idle = idle                # POV-Ray on CPU time nothing else wants
        self.running: dict[int, tuple[subprocess.Popen, Path, float]] = {}
        # first sample of a run -> (its samples, which are drawn, the stack's bands)
        self.stacks: dict[int, tuple[list[int], list[bool], int]] = {}
        self.povray_s = 0.0
        self.povray_options = povray_options_of(plan.inputs)   # the user's, checked once
        # the radiosity samples of one pretrace, made before the first sample that reads
        # them; until the folder chose whether they pay, two samples measure that
        self.photons: list[str] | None = None   # shot once, found when the first run starts
        self.radiosity: list[str] = []
        self.probes: dict[int, str] = {}            # sample -> "own" / "shared", running
        self.measured: dict[str, dict] = {}         # kind -> its finished measurement
        chosen = sharing_chosen(outdir)
        # a folder whose layout a lead recorded read the shared samples (lead_render): so
        # do its samples rendered again (a resume, make, a cluster worker), the same bits
        read_shared = read_shared or (plan.povray.radiosity_cache
                                      and recorded_bands(outdir) is not None)
        # nothing to choose for one run of every sample left or a chain (one pretrace
        # serves them all), nor where the caller has chosen to read the shared samples
        self.choosing = (plan.povray.radiosity_cache and chosen is None and not one_run
                         and not chained and not read_shared
                         and not no_pretrace(plan.povray.radiosity_pretrace))
        self.read_shared = read_shared
        if chained and not keep_chain:
            self.folder.radiosity_chain.unlink(missing_ok=True)     # an earlier render's
        # the shared samples' switches, found when the first run starts: a pinhole render
        # making them (start_radiosity_cache) runs while the first meshes are written
        self.read_pending = not self.choosing and not chained and (
            chosen is not None or not one_run or read_shared)
        # runs whose meshes are written, started once that render is done: (k, stack)
        self.pending: list[tuple[int, tuple | None]] = []
        self.shared_made = False

    def _radiosity_args(self, k: int) -> list[str]:
        """Sample k's radiosity switches; while choosing, a probe's (module doc of
        :mod:`povlens.rendering.radiosity_cache`), after waiting for the choice when
        both measurements are running; chained runs read the samples of the runs
        before them and save them with their own."""
        if self.chained:
            chain = self.folder.radiosity_chain
            if self.read_shared and not chain.is_file():    # the chain starts from them
                shared = radiosity_cache_for(self.plan, self.folder.path)
                if shared is not None:
                    shutil.copyfile(shared, chain)
            return [f"Radiosity_File_Name={os.path.relpath(chain, self.samples)}", "+RFO",
                    *(["+RFI"] if chain.is_file() else [])]
        while self.choosing:
            kinds = [p for p in probes_missing(self.folder.path)
                     if p not in self.probes.values() and p not in self.measured]
            if kinds:
                # the file first, on every core: then the two probes start together, and
                # the first to finish has won (the other has taken as long already)
                cache = radiosity_cache_for(self.plan, self.folder.path) \
                    if "shared" in kinds else None
                self.probes[k] = kinds[0]
                args = radiosity_read_args(cache if kinds[0] == "shared" else None,
                                           self.samples)
                return [*args, *STATISTICS_SWITCHES]
            self._reap(block=False)
            if self.choosing and not self._settle(final=False):
                time.sleep(0.01)
        if self.read_pending:
            self.radiosity = radiosity_read_args(
                radiosity_cache_for(self.plan, self.folder.path), self.samples)
            self.read_pending = False
        return self.radiosity

    def _settle(self, final: bool) -> bool:
        """Choose if the probes' measurements decide (the running ones' elapsed times as
        lower bounds); record them when deciding or ``final`` (a probe just finished).
        Returns whether the choice is made."""
        now = time.perf_counter()
        m = dict(self.measured)
        for k, kind in self.probes.items():
            if k in self.running:
                m[kind] = probe_measurement(k, now - self.running[k][2])
        if choice_from(m) is None and not final:
            return False
        share = record_probes(self.folder.path, m)
        if share is None:
            return False
        self.choosing = False
        cache = radiosity_cache_for(self.plan, self.folder.path) if share else None
        self.radiosity = radiosity_read_args(cache, self.samples)
        return True

    def _rows_args(self, k: int) -> tuple[int, list[str]]:
        """The render's height and POV-Ray's column and row switches for the run whose
        first sample is k: one pass's film rows, or every band of a stack."""
        pv = self.plan.povray
        ks, _, bands = self.stacks[k]
        if bands == 1:
            return pv.render_height, film_row_args(pv, render_rows(self.plan, k))
        return stack_row_args(self.plan, ks, bands)

    def start(self, k: int, stack: tuple[list[int], list[bool], int] | None = None) -> None:
        """Start the run of sample k, or of the passes ``(ks, drawn, bands)`` of one
        stack whose first is k (:mod:`povlens.rendering.sample_stacks`); while the
        shared files it reads are still being made, it waits in
        ``pending`` and this returns at once (the next sample's mesh is written
        meanwhile)."""
        while len(self.running) + len(self.pending) >= self.limit:
            self._reap(block=True)
        if self.pending or not self._shared_ready():
            self.pending.append((k, stack))
            return
        self._launch(k, stack)

    def _shared_ready(self) -> bool:
        """Whether the files every run reads that this process is making in the
        background (the photon map, the shared radiosity samples) are made; once they
        are, it is not asked again (each asking reads the folder's radiosity choice)."""
        self.shared_made = self.shared_made or (
            (self.photons is not None or photon_map_ready(self.plan, self.folder.path))
            and (not self.read_pending or radiosity_cache_ready(self.plan, self.folder.path)))
        return self.shared_made

    def _launch_pending(self, block: bool) -> None:
        """Start the runs waiting for the shared files once they are made (``block``:
        wait for them)."""
        if self.pending and (block or self._shared_ready()):
            while self.pending:
                self._launch(*self.pending.pop(0))

    def _launch(self, k: int, stack: tuple[list[int], list[bool], int] | None) -> None:
        """Start POV-Ray on the run of :meth:`start`."""
        while self.wait_first:      # an earlier run still saving the radiosity this one reads
            self._saved(self.wait_first.pop())
        self.stacks[k] = stack or ([k], [True], 1)
        if self.photons is None:
            self.photons = photon_load_args(photon_map_for(self.plan, self.folder.path))
        radiosity = self._radiosity_args(k)
        pv = self.plan.povray
        if pv.radiosity_pretrace is not None and "+RFI" in radiosity:
            radiosity = [*radiosity, f"Declare={RADIOSITY_READ_FLAG}=1"]   # pretrace_block
        height, rows = self._rows_args(k)
        pov = self.folder.batch_wrapper(self.batch)
        tmp = None
        try:        # until the process is tracked, the folder is this call's to remove
            with interrupts_deferred():     # made and named at once: never left unnamed
                tmp = Path(tempfile.mkdtemp(prefix=self.folder.sample_temp_prefix(k),
                                            dir=self.samples))
            rel = os.path.relpath(tmp, self.samples)
            switches = render_switches(
                "f.exr", pv.render_width, height, threads=self.threads,
                library_paths=[Path(self.plan.inputs.scene).parent],
                povray_options=self.povray_options,
                extra_args=[*MESH_SWITCHES, *radiosity, *self.photons,
                            *(STATISTICS_SWITCHES if self.statistics else ()),
                            f"Declare=PovlensFrame={k}", *rows])
            # the fatal-error log too: POV-Ray's stderr sometimes lacks the parse error's
            # own line (which include file is missing), the log has it
            cmd = povray_command(find_povray(), pov.name, f"{rel}/f.exr", switches,
                                 error_log=FATAL_LOG)
            with interrupts_deferred(), open(tmp / "stderr.txt", "w") as err:
                proc = start_povray(cmd, self.samples, err, idle=self.idle)
                self.running[k] = (proc, tmp, time.perf_counter())   # abort() sees it
        except BaseException:
            if k in self.running:
                raise           # tracked: abort() stops it and removes the folder
            if "proc" in locals():
                proc.kill()
                proc.wait()
            if tmp is not None:
                shutil.rmtree(tmp, ignore_errors=True)
            raise

    def _finished(self, k: int, proc: subprocess.Popen, tmp: Path) -> bool:
        """POV-Ray exited, or wrote and closed its image (it then idles ~0.3 s
        before exiting: :func:`povlens.pov.process.povray_finished`)."""
        if self.statistics:
            return self._statistics_in(k, proc, tmp)
        # a chained run saves the radiosity samples it hands on after its image: it has
        # finished once it has closed both (it is then killed, its exit idle skipped)
        products = [self.folder.radiosity_chain] if self.chained else []
        return povray_finished(proc, tmp / "f.exr", time.perf_counter() - self.running[k][2],
                               products)

    def _saved(self, proc: subprocess.Popen) -> None:
        """Wait until an earlier run whose image is in (``wait_first``) has saved the
        radiosity samples it hands on, then stop it: POV-Ray closes the file about
        0.1 s after its image and exits about 0.2 s later, after an idle shutdown
        (docs/decisions/planning.md, "The chain's hand-over").  The file is the last it
        writes, so :func:`~povlens.pov.process.povray_finished` judges by it."""
        while not povray_finished(proc, self.folder.radiosity_chain, FIRST_OUTPUT_S):
            time.sleep(0.005)

    def _statistics_in(self, k: int, proc: subprocess.Popen, tmp: Path) -> bool:
        """POV-Ray exited, or printed its statistics and closed its image (it then idles
        ~0.35 s before it exits, saving the radiosity samples it hands on)."""
        if proc.poll() is not None:
            return True
        if time.perf_counter() - self.running[k][2] < FIRST_OUTPUT_S:
            return False
        try:
            text = (tmp / "stderr.txt").read_text(errors="replace")
        except OSError:
            return False
        if not (statistics_complete(text) and output_written(proc.pid, tmp / "f.exr")):
            return False
        if self.chained and self.exiting is not None:
            self.exiting.append(proc)
        else:
            proc.kill()
            proc.wait()
        self.early.add(k)
        return True

    def _reap(self, block: bool) -> None:
        self._launch_pending(block=block and not self.running)
        while True:
            done = [k for k, (p, tmp, _) in self.running.items() if self._finished(k, p, tmp)]
            if done or not block:
                break
            time.sleep(self._poll_s())
        for k in done:
            proc, tmp, t0 = self.running[k]     # tracked until its folder is gone
            try:
                self.povray_s += time.perf_counter() - t0
                self._collect(k, proc, tmp)
            finally:
                shutil.rmtree(tmp, ignore_errors=True)
                self.folder.sample_mesh(k).unlink(missing_ok=True)
                self.running.pop(k, None)
            ks, drawn, _ = self.stacks.pop(k, ([k], [True], 1))
            if self.on_done is not None:
                for _ in range(sum(drawn)):
                    self.on_done()

    def _collect(self, k: int, proc: subprocess.Popen, tmp: Path) -> None:
        pov = self.folder.batch_wrapper(self.batch)
        out = tmp / "f.exr"
        if (proc.returncode != 0 and k not in self.early) or not out.exists():
            # its real cause: a full disk, a parse error in the wrapper, or the scene
            stderr = (tmp / "stderr.txt").read_text(errors="replace")
            log = tmp / FATAL_LOG
            log_text = log.read_text(errors="replace") if log.is_file() else ""
            raise povray_failure(pov, self.samples, proc.returncode, stderr, log_text,
                                 self.folder.sample_image(k), what=self._what(k, pov),
                                 hint="fix the scene, or run 'make' in the folder to see "
                                      "the command")
        ks, drawn, bands = self.stacks[k]
        if bands == 1:
            os.replace(out, self.folder.sample_image(k))
        else:
            split_stack(self.plan, out, self.folder.path, ks, drawn, bands)
        if self.statistics:
            self.run_statistics[k] = (time.perf_counter() - self.running[k][2], render_statistics(
                (tmp / "stderr.txt").read_text(errors="replace")))
        kind = self.probes.pop(k, None)
        if kind is not None and self.choosing:
            self.measured[kind] = probe_measurement(
                k, time.perf_counter() - self.running[k][2],
                (tmp / "stderr.txt").read_text(errors="replace"))
            self._settle(final=True)

    def _poll_s(self) -> float:
        """How long to sleep before looking at the runs again (the oldest's age:
        :func:`~povlens.pov.process.poll_interval_s`)."""
        now = time.perf_counter()
        return poll_interval_s(now - min((t0 for _, _, t0 in self.running.values()), default=now))

    def _what(self, k: int, pov: Path) -> str:
        ks = self.stacks.get(k, ([k],))[0]
        return (f"lens sample {k} of {pov}" if len(ks) == 1 else
                f"lens samples {', '.join(map(str, ks))} (one run) of {pov}")

    def finish(self, stop=None) -> None:
        """Wait for every run; once ``stop`` (a :class:`threading.Event`) is set, stop
        those left instead."""
        while self.running or self.pending:
            if stop is not None and stop.is_set():
                self.abort()
                return
            self._launch_pending(block=not self.running)
            self._reap(block=False)
            if self.running:
                time.sleep(self._poll_s())

    def abort(self) -> None:
        """Stop every running process (an error, an interrupt, a cancelled guess).
        SIGKILL: what a sample's POV-Ray holds is its temporary folder, deleted here,
        and SIGTERM would run POV-Ray's slow shutdown (docs/decisions/planning.md)."""
        for p, _, _ in self.running.values():
            p.kill()
        for k, (p, tmp, _) in list(self.running.items()):
            p.wait()
            shutil.rmtree(tmp, ignore_errors=True)
            self.folder.sample_mesh(k).unlink(missing_ok=True)
        for k, _ in self.pending:
            self.folder.sample_mesh(k).unlink(missing_ok=True)
        self.pending.clear()
        self.running.clear()
        self.stacks.clear()


def render_samples(plan: Plan, lens, sampler, outdir: str | os.PathLike, batch: int,
                   samples, points=None, in_flight: int = POVRAY_IN_FLIGHT,
                   stop=None, on_done=None, plan_for=None, stacking=None,
                   statistics: bool = False, read_shared: bool = False,
                   keep_chain: bool = False, exiting: list | None = None,
                   wait_first=(), idle: bool = False) -> dict:
    """Trace, write and render lens samples ``samples`` of batch ``batch``, pipelined.

    For each sample in turn: trace its rays and write its mesh and weights
    (:func:`_write_mesh`), then start its POV-Ray process and go on to the next
    sample while it runs (at most ``in_flight`` at once).  A field plan draws each
    pass in its band of a stack (:mod:`povlens.rendering.sample_stacks`);
    ``stacking``, a :class:`~povlens.rendering.sample_stacks.StackPlan`
    (:func:`~povlens.rendering.sample_stacks.stack_plan`), renders the samples of one
    stack in one run on ``stacking.threads`` threads (default: each sample alone, one
    thread).  Samples whose rays are
    all blocked are not rendered.  ``sampler`` is the lens sampler (normally the
    plan's exit-pupil table); ``points(k)`` overrides the plan's sample points
    (:mod:`povlens.bench`).  ``stop``: a :class:`threading.Event`; once set, no
    further sample starts and the running ones are stopped.  ``on_done()`` is called
    as each sample is finished (progress).  ``samples`` may be any iterable of
    sample numbers (a generator that waits for more:
    :class:`povlens.rendering.driver.EarlyRender`), and
    ``plan_for(k)`` the plan to trace sample k with (default ``plan``; plans that
    differ only in the sample count give the same sample k).  ``statistics``: POV-Ray
    prints its statistics and each run is waited for to exit
    (:mod:`povlens.pov.render_statistics`); ``read_shared``: every run reads the folder's
    shared radiosity samples (:func:`~povlens.rendering.radiosity_cache.radiosity_cache_for`,
    made if missing; a chain starts from them), without measuring whether they pay;
    ``keep_chain``: a chained
    render's radiosity file is the caller's (kept from an earlier call, left for a
    later one); ``exiting`` and ``wait_first``: :class:`_SampleRenders`; ``idle``: the
    POV-Ray runs take only CPU time nothing else wants.  Returns timings: {samples, blocked, rays_and_meshes_s (Python),
    povray_s (summed over the overlapping processes), wall_s, bands, runs_together,
    threads, chained}, and with ``statistics`` {"statistics": {first sample of a run:
    (wall s, RenderStatistics)}}.
    """
    outdir = Path(outdir)
    t0 = time.perf_counter()
    t_mesh = 0.0
    blocked = 0
    bands = stack_bands(plan, outdir) if points is None else 1
    if stacking is None or stacking.bands != bands:
        stacking = StackPlan(bands, 0, 1, False)
    queue = _SampleRenders(plan, outdir, batch, in_flight, on_done, stacking.threads,
                           stacking.runs == 1, stacking.chained, statistics, read_shared,
                           keep_chain, exiting, wait_first, idle)
    seen: list[int] = []
    try:
        for ks in stack_runs(samples, bands, stacking.together):
            if stop is not None and stop.is_set():
                queue.abort()
                break
            seen += ks
            t = time.perf_counter()
            run_plan = plan if plan_for is None else plan_for(ks[0])
            if len(ks) == 1:
                drawn = [_write_mesh(run_plan, lens, sampler, outdir, ks[0],
                                     points=None if points is None else points(ks[0]))]
            else:
                drawn = _write_stack(run_plan, lens, sampler, outdir, ks, bands)
            t_mesh += time.perf_counter() - t
            if any(drawn):
                queue.start(ks[0], (ks, drawn, bands))
            blocked += len(ks) - sum(drawn)
            if on_done is not None:
                for _ in range(len(ks) - sum(drawn)):
                    on_done()
            queue._reap(block=False)
        queue.finish(stop)      # stopped (now or while waiting): the running ones stop
    except BaseException:
        queue.abort()
        raise
    finally:
        for k in seen:
            RenderFolder(outdir).sample_mesh(k).unlink(missing_ok=True)
        if stacking.chained and not keep_chain:
            RenderFolder(outdir).radiosity_chain.unlink(missing_ok=True)
    return _timing(queue, stacking, len(seen), blocked, t_mesh, time.perf_counter() - t0,
                   statistics)


def _timing(queue: _SampleRenders, stacking: StackPlan, samples: int, blocked: int,
            mesh_s: float, wall_s: float, statistics: bool) -> dict:
    """:func:`render_samples`'s timing record."""
    timing = {"samples": samples, "blocked": blocked, "rays_and_meshes_s": mesh_s,
              "povray_s": queue.povray_s, "wall_s": wall_s, "bands": stacking.bands,
              "runs_together": stacking.together, "threads": stacking.threads,
              "chained": stacking.chained}
    if statistics:
        timing["statistics"] = dict(queue.run_statistics)
    return timing


def render_batch(outdir: str | os.PathLike, batch: int,
                 in_flight: int = POVRAY_IN_FLIGHT) -> list[int]:
    """Render batch ``batch`` of a mesh plan; returns the samples it rendered (resumes).

    It holds the folder's lock shared and the batch's own lock
    (:func:`povlens.plan.folder_lock.batch_lock`): ``make -jN`` runs batches side by
    side, and waits while ``povlens render`` or ``convert`` writes the folder."""
    outdir = Path(outdir)
    with folder_lock(outdir, shared=True):      # the plan as no other writer changes it
        plan = read_plan(outdir)
        if plan.inputs.method != "mesh":
            raise PovlensError(f"{outdir} was converted with the {plan.inputs.method} "
                               f"method; it has no sample batches", "use 'povlens render-view'")
        batches = plan.batches
        if not 0 <= batch < len(batches):
            raise PovlensError(f"batch {batch}: {outdir} has batches 0..{len(batches) - 1}")
        folder = RenderFolder(outdir)
        with batch_lock(outdir, batch):     # make's recipes share the folder, one per batch
            todo = [k for k in batches[batch] if not folder.sample_done(k)]
            if todo:
                lens = lens_for(plan)
                table = pupil_table_for(outdir, plan, lens)
                exposure_for(outdir, plan, lens, table)
                timing = render_samples(plan, lens, table, outdir, batch, todo,
                                        in_flight=in_flight,
                                        stacking=stack_plan(plan, todo, 1, outdir=outdir))
                write_text(folder.batch_timing(batch), json.dumps(timing) + "\n")
            folder.mark_batch_done(batch, batches[batch])
    return todo


def mark_batches_done(outdir: str | os.PathLike, plan: Plan) -> None:
    """Write the marker (make's target) of each batch whose samples are done."""
    folder = RenderFolder(outdir)
    for b, ks in enumerate(plan.batches):
        if all(folder.sample_done(k) for k in ks):
            folder.mark_batch_done(b, ks)
