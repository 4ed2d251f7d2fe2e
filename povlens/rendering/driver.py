"""Rendering a converted folder from start to image: the driver of ``povlens render``.

:func:`render_outdir` renders what a folder lacks and composites: a pinhole or
focal-blur plan's view (:mod:`povlens.rendering.views`), or a mesh plan's lens samples
in this process (:mod:`povlens.rendering.mesh_samples`) and then their composite
(:mod:`povlens.rendering.folder_composite`).  :func:`convert_and_render` converts first,
and while ``--method auto`` probes the scene its likely choice starts: the first lens
samples render in a thread (:class:`EarlyRender`) or the adaptive focal_blur view
(:mod:`povlens.plan.speculative`).  Re-running skips what is done: an interrupted
render resumes.
"""

from __future__ import annotations

import json
import os
import sys
import threading
from pathlib import Path

from tqdm import tqdm

from povlens.plan.convert import ConvertOptions, convert
from povlens.plan.folder_lock import folder_lock
from povlens.plan.plan_finish import shared_photon_settings, shares_radiosity
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Plan, read_plan
from povlens.rendering.folder_composite import composite_outdir
from povlens.rendering.field_samples import illumination_map
from povlens.rendering.folder_inputs import exposure_for, lens_for, pupil_table_for
from povlens.rendering.mesh_samples import POVRAY_IN_FLIGHT, mark_batches_done, render_samples
from povlens.rendering.photon_map import cancel_photon_map, start_photon_map
from povlens.rendering.radiosity_cache import cancel_radiosity_cache, start_radiosity_cache_early
from povlens.rendering.lead_render import render_led
from povlens.rendering.running_sums import RunningSums
from povlens.rendering.sample_stacks import recorded_bands, stack_plan
from povlens.rendering.views import render_view
from povlens.util.files import write_text

__all__ = ["render_outdir", "convert_and_render", "EarlyRender"]


def _progress(total: int, desc: str, quiet: bool):
    return tqdm(total=total, desc=desc, unit="sample", disable=quiet or not sys.stderr.isatty(),
                file=sys.stderr)


def render_outdir(outdir: str | os.PathLike, jobs: int | None = None, quiet: bool = False,
                  in_flight: int | None = None) -> Path:
    """Render everything a converted folder needs and composite.

    Mesh plans: every lens sample not yet rendered, in this process
    (:func:`~povlens.rendering.mesh_samples.render_samples`: trace, write the mesh,
    start its POV-Ray process, go on), with up to ``in_flight`` POV-Ray processes at
    once (default :data:`~povlens.rendering.mesh_samples.POVRAY_IN_FLIGHT` per core,
    ``jobs`` cores, default all).  One process
    with the lens and pupil table in memory is faster than a worker process per
    batch: a worker's Python start-up costs more than the tracing it would share
    (docs/decisions/planning.md).  ``make -jN`` in the folder renders its batches
    in parallel processes (``povlens render-batch``).  It holds the folder's lock
    (:func:`povlens.plan.folder_lock.folder_lock`): another render of the folder, or
    make's recipes, wait for it."""
    with folder_lock(outdir):       # one writer: waits for another render of the folder
        return _render_locked(Path(outdir), jobs, quiet, in_flight)


def _render_locked(outdir: Path, jobs: int | None, quiet: bool,
                   in_flight: int | None) -> Path:
    """:func:`render_outdir` with the folder's lock held."""
    folder = RenderFolder(outdir)
    plan = read_plan(outdir)
    method = plan.inputs.method
    if method != "mesh":
        render_view(outdir, method)
        return folder.image_exr
    jobs = jobs or os.cpu_count() or 1
    in_flight = in_flight or POVRAY_IN_FLIGHT * jobs
    todo = [k for k in range(plan.inputs.samples) if not folder.sample_done(k)]
    if todo:
        lens = lens_for(plan)
        table = pupil_table_for(outdir, plan, lens)

        def samples(ks):
            yield from ks
            # every sample is written and its POV-Ray started: the composite's
            # exposure and the lens's relative illumination (its profile, kept in
            # illumination.json) are computed while they run (not after)
            exposure_for(outdir, plan, lens, table)
            if plan.inputs.vignetting:
                illumination_map(outdir, plan, table)

        running = None if folder.group_files() else RunningSums(outdir, plan, table)
        try:
            with _progress(len(todo), "lens samples", quiet) as bar:
                timing = _render_mesh_samples(plan, lens, table, outdir, todo, samples, jobs,
                                              in_flight, lambda: bar.update(1))
        except BaseException:
            if running is not None:
                running.stop()
            raise
        write_text(folder.timing("render"), json.dumps(timing) + "\n")
        sums = None if running is None else running.result()
    else:
        sums = None
    mark_batches_done(outdir, plan)
    composite_outdir(outdir, sums=sums)
    return folder.image_exr


def _render_mesh_samples(plan: Plan, lens, table, outdir: Path, todo: list[int], samples,
                         jobs: int, in_flight: int, on_done) -> dict:
    """Render the lens samples ``todo`` of ``povlens render`` (``samples(ks)`` yields
    them); returns the timing record.  A plan whose samples stack and share radiosity
    or a photon map, in a folder that holds none of them yet (a folder with some,
    rendered early by ``--method auto``, by ``make`` or before the layout was recorded,
    keeps the layout they have), lets its first sample choose between stacks and one
    run each (:func:`povlens.rendering.lead_render.render_led`).  Other plans stack:
    a scene with neither has only its parse and start-up to share.  Scenes with photons
    only stacked too until the 640x480 sweep: ``lights/phot_met_glass.pov`` at 640x480,
    8 samples, took 24.8 s stacked and 14.7 s one run each (focal_blur 10.3 s), its
    parse too small to pay for a stack's face lookup, where at 320x240 the two ways were
    within 10 % (``benchmarks/results/stock_heavy_*_early.txt``)."""
    stacking = stack_plan(plan, todo, jobs, chain=True, outdir=outdir)
    if (stacking.bands == 1 or len(todo) < plan.inputs.samples or len(todo) < 2
            or not (plan.povray.radiosity_cache or plan.povray.photon_settings)
            or os.environ.get("POVLENS_STACK")
            or recorded_bands(outdir) is not None):
        return render_samples(plan, lens, table, outdir, 0, samples(todo), in_flight=in_flight,
                              on_done=on_done, stacking=stacking,
                              read_shared=stacking.chained or stacking.runs == 1)
    return render_led(plan, lens, table, outdir, todo, samples, stacking.bands, jobs,
                      in_flight, on_done)


class EarlyRender:
    """Lens samples rendered in a thread of this process while
    :func:`povlens.plan.convert.convert` goes on (its ``render_early``): those of a
    provisional plan at first, then, after :meth:`extend`, those the final plan
    adds, without draining the POV-Ray pipeline in between.  The lens and pupil
    table are already in memory.  :meth:`wait` waits for the samples given so far
    and raises what the render raised; :meth:`cancel` stops it (what it finished
    stays)."""

    def __init__(self, outdir: Path, plan: Plan, lens, table, in_flight: int, quiet: bool):
        self._outdir = Path(outdir)
        self._folder = RenderFolder(outdir)
        self._stop = threading.Event()
        self._more = threading.Condition()
        self._closed = False
        self._error: BaseException | None = None
        self._plans = {k: plan for k in range(plan.inputs.samples)}
        self._todo = [k for k in range(plan.inputs.samples) if not self._folder.sample_done(k)]
        self._final = plan
        self._lens, self._table = lens, table
        self._bar = _progress(len(self._todo), "lens samples", quiet)
        self._thread = threading.Thread(target=self._run, args=(lens, table, in_flight),
                                        daemon=True)
        self._thread.start()

    def _samples(self):
        i = 0
        exposure_known = False
        while True:
            if i >= len(self._todo) and not exposure_known and not self._stop.is_set():
                # nothing to write until the decision adds samples: the composite's
                # exposure is computed now, while POV-Ray runs, instead of after
                exposure_for(self._outdir, self._final, self._lens, self._table)
                exposure_known = True
            with self._more:
                while i >= len(self._todo) and not self._closed and not self._stop.is_set():
                    self._more.wait(0.05)
                if i >= len(self._todo) or self._stop.is_set():
                    return
                k = self._todo[i]
            i += 1
            yield k

    def _run(self, lens, table, in_flight):
        try:
            timing = render_samples(self._final, lens, table, self._outdir, 0, self._samples(),
                                    in_flight=in_flight, stop=self._stop,
                                    on_done=lambda: self._bar.update(1),
                                    plan_for=lambda k: self._plans[k])
            if timing["samples"]:
                write_text(self._folder.timing("early"), json.dumps(timing) + "\n")
            if not self._stop.is_set():
                mark_batches_done(self._outdir, self._final)
        except BaseException as e:      # handed to wait()
            self._error = e
        finally:
            self._bar.close()

    def extend(self, plan: Plan) -> None:
        """Render also the samples ``plan`` (the final plan, more samples than the
        provisional one) adds."""
        with self._more:
            new = [k for k in range(plan.inputs.samples) if k not in self._plans]
            self._plans.update({k: plan for k in new})
            self._todo += [k for k in new if not self._folder.sample_done(k)]
            self._final = plan
            self._bar.total = len(self._todo)
            self._bar.refresh()
            self._more.notify_all()

    def wait(self) -> None:
        with self._more:
            self._closed = True
            self._more.notify_all()
        self._thread.join()
        if self._error is not None:
            raise self._error

    def cancel(self) -> None:
        self._stop.set()
        with self._more:
            self._more.notify_all()
        self._thread.join()


def convert_and_render(opts: ConvertOptions, jobs: int | None = None, quiet: bool = False,
                       on_plan=None, depth_probe=None) -> tuple[Plan, Path]:
    """What ``povlens render`` does: convert ``opts`` and render the folder
    (:func:`render_outdir`).

    With --method auto, the render auto is likely to choose starts while its depth
    probe runs (``speculate`` of :func:`povlens.plan.convert.convert`): the adaptive
    focal_blur view, or, when the lens alone rules out the views, the first lens
    samples of the mesh render (``render_early``).  What a mesh render's samples share
    (radiosity samples, a photon map) starts as soon as the scene and camera are read
    (:func:`start_shared_early`), while the rest of the plan is derived.  ``on_plan(plan)`` is called
    between conversion and rendering; ``depth_probe`` goes to ``convert`` (a focus
    pull's frames share one probe).  Returns (plan, path of image.exr).  The folder's
    lock is held throughout (:func:`povlens.plan.folder_lock.folder_lock`)."""
    jobs = jobs or os.cpu_count() or 1

    def render_early(plan, lens, table):
        return EarlyRender(Path(opts.outdir), plan, lens, table, POVRAY_IN_FLIGHT * jobs,
                           quiet)

    with folder_lock(opts.outdir):  # one writer from the conversion to the image
        try:
            plan = convert(opts.replace(speculate=True), render_early=render_early,
                           depth_probe=depth_probe, start_shared=start_shared_early)
            if on_plan is not None:
                on_plan(plan)
            return plan, render_outdir(opts.outdir, jobs=jobs, quiet=quiet)
        finally:
            _cancel_shared(opts.outdir)     # started early, and never needed


def start_shared_early(opts: ConvertOptions, start, outdir):
    """What every lens sample of the plan of ``opts`` reads, started as soon as its
    :class:`~povlens.plan.plan_start.PlanStart` is known (``convert``'s
    ``start_shared``): the radiosity samples
    (:func:`~povlens.rendering.radiosity_cache.start_radiosity_cache_early`) and the
    photon map (:func:`~povlens.rendering.photon_map.start_photon_map`); returns what
    stops them."""
    if shares_radiosity(opts, start):
        start_radiosity_cache_early(opts, start, outdir)
    if shared_photon_settings(opts, start):
        start_photon_map(outdir, opts.scene, start.povray)
    return lambda: _cancel_shared(outdir)


def _cancel_shared(outdir) -> None:
    cancel_radiosity_cache(outdir)
    cancel_photon_map(outdir)
