"""Work ``povlens render --method auto`` starts before its depth probe is in.

The decision (:func:`povlens.plan.decision.decide`) waits for the depth probe,
but a guess from the lens alone (:func:`early_guess`) is often right, and what
the guess needs can render meanwhile:

* the first lens samples of a mesh render: sample k does not depend on the
  sample count, so a provisional plan of :data:`~povlens.plan.decision.MIN_SAMPLES`
  samples is written and rendered (:func:`start_early_samples`); the final plan
  adds the samples the decision wants;
* the adaptive focal_blur view (:func:`start_speculative_focal_blur`), whose
  settings (:data:`~povlens.plan.decision.FOCAL_BLUR_ADAPTIVE`) do not depend on
  the probe either; it runs at idle priority (:data:`SPECULATIVE_IDLE`).

:func:`povlens.plan.convert.convert` keeps what the decision confirms and stops
the rest.  Measurements behind the guesses: docs/decisions/planning.md.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Callable

import numpy as np

from povlens.plan.decision import (FOCAL_BLUR_ADAPTIVE, MIN_SAMPLES, STRONG_VIGNETTING,
                                   shape_error_px)
from povlens.plan.plan_finish import PlanReuse, finish_plan
from povlens.plan.plan_start import PlanStart
from povlens.plan.options import ConvertOptions, povray_options_of
from povlens.plan.folder_writer import focal_blur_text, write_folder
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Decision, Plan
from povlens.pov.process import RenderJob, start_render
from povlens.util.files import write_text

__all__ = ["SPECULATIVE_IDLE", "early_guess", "lens_rules_out_views",
           "vignetting_may_choose_mesh", "start_speculative_focal_blur", "SpeculativeView",
           "start_early_samples", "EarlySamples"]

#: The focal_blur render started on a guess runs at idle priority (Linux
#: ``SCHED_IDLE``): it gets only the CPU time the probe, the model error and the
#: early lens samples leave, and all of it once the guess is confirmed.
SPECULATIVE_IDLE = True


def lens_rules_out_views(opts: ConvertOptions, plan0: Plan) -> bool:
    """Whether the lens alone makes ``--method auto`` choose mesh (a guess).

    True when, at the plan's standard depths (half, once, twice and ten times the
    focus distance), the distortion, half the blur-size error or half the shape
    error (the measures of :func:`povlens.plan.decision.decide`) is over the
    budget ``opts.auto.tolerance_px``.  The vignetting does not count: the views get it
    as a map (:mod:`povlens.rendering.vignetting`), and what the map cannot carry
    depends on the scene's defocus (:func:`vignetting_may_choose_mesh`).
    """
    e = plan0.model_error
    tol = opts.auto.tolerance_px
    shape = shape_error_px(np.asarray(e.blur_real_px), np.asarray(e.elongation))
    return bool(e.max_distortion_px >= tol or e.max_blur_size_error_px / 2 >= tol
                or float(np.max(shape)) / 2 >= tol)


def vignetting_may_choose_mesh(opts: ConvertOptions, plan0: Plan) -> bool:
    """Whether the cat's eye may make ``--method auto`` prefer mesh to the views.

    True when the vignetting is wanted and strong (relative illumination below
    :data:`~povlens.plan.decision.STRONG_VIGNETTING` somewhere in the frame: the
    rims cut much of the pupil) and half the largest thin-lens blur at the plan's
    standard depths reaches the budget: whether the cat's eye of out-of-focus light
    is beyond it then depends on where the scene is out of focus, which the depth
    probe tells (:func:`povlens.plan.image_error.catseye_rmse`).
    """
    e = plan0.model_error
    illum = e.min_relative_illumination
    blur = float(np.max(e.blur_model_px)) if np.size(e.blur_model_px) else 0.0
    return bool(opts.sampling.vignetting and illum < STRONG_VIGNETTING
                and 0.5 * blur >= opts.auto.tolerance_px)


def early_guess(opts: ConvertOptions, plan0: Plan) -> str:
    """What ``povlens render --method auto`` starts before the depth probe is in.

    Returns
    -------
    str
        * ``"mesh"``: the lens alone rules out the views (:func:`lens_rules_out_views`;
          a shaped stop or an anamorphic lens, which focal_blur cannot draw, with a
          visible blur): the first lens samples of the mesh render;
        * ``"either"``: the thin lens may do, but the lens vignettes strongly and
          blurs enough for its cat's eye to matter (:func:`vignetting_may_choose_mesh`):
          whether the decision takes mesh depends on the scene's depths, so both
          start: the first lens samples, and the adaptive focal_blur view at low
          priority, which takes the CPU the samples leave;
        * ``"views"``: otherwise, the adaptive focal_blur view (low priority).
    """
    if lens_rules_out_views(opts, plan0):
        return "mesh"
    e = plan0.model_error
    if plan0.anamorphic is not None and np.size(e.blur_model_px) and (
            np.max(e.blur_model_px) >= opts.auto.tolerance_px):
        return "mesh"          # an anamorphic lens: no focal_blur (povlens.plan.anamorphic)
    # a shaped stop: focal_blur is out wherever blur shows
    if ((opts.aperture.aperture_blades or opts.aperture.aperture_image)
            and np.size(e.blur_model_px) and np.max(e.blur_model_px) >= opts.auto.tolerance_px):
        return "mesh"
    if vignetting_may_choose_mesh(opts, plan0):
        return "either"
    return "views"


class SpeculativeView:
    """A running speculative focal_blur render (:func:`start_speculative_focal_blur`);
    its wrapper is deleted once it is waited for or cancelled."""

    def __init__(self, job: RenderJob, pov: Path):
        self._job, self._pov = job, pov
        self.out_path = job.out_path

    def wait(self) -> Path:
        """Wait for the render; the image's path (raises POV-Ray's error)."""
        try:
            return self._job.wait()
        finally:
            self._pov.unlink(missing_ok=True)

    def cancel(self) -> None:
        """Stop the render (if still running) and remove its files; idempotent."""
        try:
            self._job.cancel()
        finally:
            self._pov.unlink(missing_ok=True)


def start_speculative_focal_blur(opts: ConvertOptions, plan0: Plan) -> SpeculativeView:
    """Start the focal_blur render ``--method auto`` may choose (:func:`early_guess`).

    Its wrapper is its own file (``.speculative-focal-blur.pov``, the text the
    final ``focal_blur.pov`` gets): the provisional mesh plan an "either" guess
    writes at the same time rewrites ``focal_blur.pov`` with its own sample
    count, possibly before POV-Ray has read it.  The image goes to
    ``.speculative-focal-blur.exr`` in OUTDIR; POV-Ray gets the user's options, as the
    final view would (:func:`povlens.rendering.views.render_view`).
    """
    out = Path(opts.outdir)
    pov = RenderFolder(out).speculative_wrapper
    write_text(pov, focal_blur_text(plan0, out, FOCAL_BLUR_ADAPTIVE))
    film = plan0.film
    try:
        job = start_render(pov, RenderFolder(out).speculative_view,
                           film.width_px, film.height_px, threads=os.cpu_count() or 1,
                           library_paths=[Path(plan0.inputs.scene).parent],
                           povray_options=povray_options_of(plan0.inputs),
                           idle=SPECULATIVE_IDLE)
    except BaseException:
        pov.unlink(missing_ok=True)
        raise
    return SpeculativeView(job, pov)


@dataclasses.dataclass
class EarlySamples:
    """Lens samples rendering before the decision: the provisional plan they belong
    to and the handle ``render_early`` returned (``extend(plan)``, ``wait()``,
    ``cancel()``; :class:`povlens.rendering.driver.EarlyRender`)."""

    plan: Plan
    render: object


def start_early_samples(opts: ConvertOptions, start: PlanStart, reuse: PlanReuse, table,
                        render_early: Callable) -> EarlySamples:
    """Write the provisional mesh plan of an auto conversion whose lens rules out the
    views (or may), and start rendering it with ``render_early(plan, lens, table)``.

    Parameters
    ----------
    opts : the auto conversion's options.
    start : its :class:`~povlens.plan.plan_start.PlanStart`.
    reuse : the pupil table, model error and POV-Ray version already known
        (:class:`~povlens.plan.plan_finish.PlanReuse`).
    table : the exit-pupil table, for the render.
    render_early : starts the render of a plan (see :func:`povlens.plan.convert.convert`).
    """
    n = MIN_SAMPLES if opts.sampling.auto_samples else opts.sampling.sample_count
    eopts = opts.replace(method="mesh", samples=n)
    plan = finish_plan(eopts, start, reuse)[0]
    plan.record_auto_choice(Decision(
        "mesh", n, ["provisional: the lens alone rules out the pinhole and focal_blur views "
                    "(distortion, blur size or shape), or its cat's eye may; the depth "
                    "probe decides"],
        provisional=True), opts.auto.tolerance_px, opts.sampling.auto_samples)
    write_folder(Path(opts.outdir), plan)
    return EarlySamples(plan, render_early(plan, start.lens, table))
