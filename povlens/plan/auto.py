"""``--method auto``: measure the scene and the lens, then decide.

The choice is made from measurements, not guesses:

1. **Depth range** -- :func:`start_depth_probe` renders a small pinhole depth
   probe (:mod:`povlens.plan.depth_probe`: three POV-Ray renders with and without a
   fading light at the eye, run at the same time) of the plan's own camera (the same
   film in mm, so the same view) at most :data:`PROBE_WIDTH` pixels wide, in a
   temporary folder in OUTDIR.  :func:`povlens.plan.convert.convert` starts it before
   it builds the pupil table and measures the plan's model error, and collects it
   after.  Near and far are robust percentiles of the axial distances of the pixels
   that hit something with a depth (:func:`povlens.plan.depth_probe.depth_limits`:
   background is infinitely far, pixels without a depth of their own -- black,
   emissive, clear surfaces -- are left out and counted); depths are converted to
   camera-frame z in mm (the thin-lens model's frame: ``centre_z_mm + axial
   distance``).
2. **Model error over that range** -- :func:`povlens.thinlens.model_error.measure_model_error`
   with the exact tracer through the pupil at depths spanning [near, far], with
   the plan's exit-pupil table (built once, kept in OUTDIR/pupil.npz).
3. **Decision** -- :func:`povlens.plan.decision.decide` (pure).
4. **Adaptive mesh sampling** (``--adaptive``, off by default) --
   :func:`povlens.plan.adaptive.adaptive_rows` from the same probe.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from povlens.lens.film import Film
from povlens.plan.adaptive import adaptive_rows
from povlens.plan.anamorphic import anamorphic_text
from povlens.plan.aperture import AUTO_NOTE, PINHOLE_NOTE, describe
from povlens.plan.decision import decide, model_depths, pupil_cut, shift_tilt_cos
from povlens.plan.depth_probe import DepthProbe, ProbeView, axial_depth, depth_limits, start_probe
from povlens.plan.image_error import probe_image_error
from povlens.plan.options import povray_options_of
from povlens.plan.plan_start import start_plan
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import AdaptiveSampling, Decision, Plan
from povlens.pupil.illumination import illumination_profile, profile_record
from povlens.pupil.grid_table import frame_extent_mm
from povlens.pupil.storage import cached_pupil_table
from povlens.thinlens.model_error import measure_model_error
from povlens.util.threads import run_in_background

__all__ = ["PROBE_WIDTH", "probe_size", "start_depth_probe", "probe_axial_mm",
           "measure_depth_map", "measure_depth_range", "choose_method"]

#: Largest width (pixels) of the depth probe.
PROBE_WIDTH = 64


def probe_size(film: Film) -> tuple[int, int]:
    """(width, height) in pixels of the depth probe of ``film``: at most
    :data:`PROBE_WIDTH` wide, the film's aspect, at least 2 rows."""
    pw = min(PROBE_WIDTH, film.width_px)
    ph = max(2, round(pw * film.height_px / film.width_px))
    return pw, ph


def start_depth_probe(opts, film: Film, plan, threads: int = 1) -> DepthProbe:
    """Start the small pinhole depth probe of ``opts`` (:func:`probe_size` pixels).

    ``plan`` is a :class:`~povlens.plan.schema.Plan` of ``opts`` (any method) or
    the :class:`~povlens.plan.plan_start.PlanStart` of one: its ``povray_camera`` is
    the probe's, since the probe's film is the same in mm; only the pixels
    differ.  Every render gets the user's POV-Ray options (``opts.povray.library_paths``,
    ``clock``, ``povray_options``).  Besides the three depth renders, the view as it
    is is rendered (``image`` of the probe: the vignetting's effect on the image) when the lens's
    vignetting is wanted (``opts.sampling.vignetting``); with ``--no-vignetting`` nothing
    reads it, and the probe is one POV-Ray process fewer.  The renders run in a
    temporary folder ``.probe.*`` in OUTDIR (``threads`` POV-Ray threads each).

    Returns
    -------
    DepthProbe
        Running; collect it with :func:`probe_axial_mm`.
    """
    pw, ph = probe_size(film)
    out = Path(opts.outdir)
    out.mkdir(parents=True, exist_ok=True)
    view = ProbeView(plan.povray_camera, film.resized(film.width_mm, film.height_mm, pw, ph),
                     plan.mm_per_unit, str(Path(opts.scene).resolve()), float(opts.pose.focus),
                     povray_options_of(opts.povray))
    return start_probe(view, out, threads=threads, keep_wrappers=False, prefix=".probe.",
                       label=str(opts.scene), with_image=opts.sampling.vignetting)


def probe_axial_mm(probe: DepthProbe) -> np.ndarray:
    """Wait for a :func:`start_depth_probe` probe: per-pixel axial distances (H, W)
    in mm from the camera location (= entrance pupil); inf for background, nan where
    the probe measured no depth (black, emissive or clear surfaces)."""
    d = probe.result()
    return axial_depth(probe.view, d) * probe.view.mm_per_unit


def measure_depth_map(opts, film: Film, threads: int | None = None,
                      plan: Plan | None = None) -> np.ndarray:
    """Per-pixel axial distances (H, W) in mm from the camera location (= entrance
    pupil; inf for background) of a small pinhole depth probe
    (:func:`start_depth_probe`, at most :data:`PROBE_WIDTH` pixels wide, same film
    in mm).  ``plan``: a plan of ``opts`` for its camera (default: derived, without
    a pupil table)."""
    view = plan if plan is not None else start_plan(opts)
    return probe_axial_mm(start_depth_probe(opts, film, view, threads=threads or 1))


def measure_depth_range(opts, film: Film, threads: int | None = None,
                        axial_mm: np.ndarray | None = None) -> tuple[float, float, dict]:
    """Near / far axial distances (mm, from the camera location = entrance pupil) of
    what the scene shows, from a small pinhole depth probe (:func:`measure_depth_map`,
    or ``axial_mm`` if given), and the probe's numbers."""
    axial = measure_depth_map(opts, film, threads) if axial_mm is None else axial_mm
    near, far, info = depth_limits(axial)
    info.update({"probe_width": int(axial.shape[1]), "probe_height": int(axial.shape[0])})
    return near, far, info


def choose_method(opts, plan: Plan, model, lens, film: Film, *, probe: DepthProbe | None = None,
                  pupil_table=None) -> tuple[Decision, AdaptiveSampling | None]:
    """Measure the scene's depth range and the model error over it, and decide.

    Parameters
    ----------
    opts : the options (``tolerance_px``, ``vignetting``, ``adaptive``, ``outdir``).
    plan, model, lens, film : a plan of ``opts`` (any method), its thin lens, its
        stopped-down lens and its film.
    probe : the depth probe, already started (:func:`start_depth_probe`; default:
        started here).
    pupil_table : the plan's exit-pupil table (default: OUTDIR/pupil.npz if
        current, else built).

    Returns
    -------
    (Decision, AdaptiveSampling or None)
        The decision, and with ``opts.sampling.adaptive`` the row bands from the same probe.
    """
    if probe is None:
        probe = start_depth_probe(opts, film, plan)
    fd = plan.focus.film_distance_mm
    table = pupil_table
    try:
        if table is None:  # exact vignetting; normally saved by the plan
            table, _ = cached_pupil_table(RenderFolder(opts.outdir).pupil_npz, lens, fd,
                                          film.max_field_radius_mm, save=False,
                                          film_extent_mm=frame_extent_mm(film))
    except BaseException:
        probe.cancel()
        raise
    # the vignetting map the views get, and the pupil's cut: traced in a thread while
    # the probe finishes and the model error is measured
    profile_of = run_in_background(lambda: illumination_profile(table,
                                                                film.max_field_radius_mm))
    axial = probe_axial_mm(probe)
    near_d, far_d, info = measure_depth_range(opts, film, axial_mm=axial)
    if math.isinf(near_d):  # nothing but background: everything at infinity
        near_d = 1e4 * max(model.focus_distance_mm if math.isfinite(model.focus_distance_mm)
                           else 1e3, 1e3)
    c = model.centre_z_mm
    near_z, far_z = c + near_d, c + far_d
    err = measure_model_error(lens, fd, model, film, model_depths(model, near_z, far_z),
                              pupil_table=table)
    profile = profile_of()
    # an anamorphic lens: its illumination is over x and y, and focal_blur is ruled out
    # whatever its cat's eye (povlens.plan.anamorphic)
    ana = None if plan.anamorphic is None else anamorphic_text(plan.anamorphic)
    image_error = None
    if probe.image is not None:
        image_error = probe_image_error(probe.image, film, err, opts.auto.tolerance_px,
                                        profile=profile, table=None if ana else table,
                                        model=model, axial_mm=axial)
    d = decide(near_z_mm=near_z, far_z_mm=far_z, model=model, model_error=err,
               pixel_pitch_mm=film.pixel_pitch_mm, tolerance_px=opts.auto.tolerance_px,
               vignetting=opts.sampling.vignetting, image_error=image_error,
               catseye=None if ana else pupil_cut(profile),
               aperture_shape=(describe(lens.aperture_shape) if lens.aperture_shape is not None
                               else None),
               shift_tilt_cos=shift_tilt_cos(film.shift_mm, model.image_distance_mm),
               anamorphic=ana)
    if lens.aperture_shape is not None:
        d.add_remark((AUTO_NOTE if d.method == "mesh" else PINHOLE_NOTE).format(
            what=describe(lens.aperture_shape)))
    d.numbers["depth_probe"] = info
    if opts.sampling.vignetting:     # a view's render applies this profile (rendering/vignetting)
        d.numbers["illumination_profile"] = profile_record(profile, table)
    if info["no_depth_pixels"]:
        d.add_remark(f"{info['no_depth_pixels']} of the probe's {info['probe_pixels']} pixels "
                     f"hit surfaces without a measurable response to light (black, emissive, "
                     f"clear): left out of the depth range")
    adaptive = None
    if opts.sampling.adaptive:
        adaptive = adaptive_rows(model, axial, film, d.samples, model_error=err)
    return d, adaptive
