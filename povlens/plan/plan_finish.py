"""The plan of a conversion with a given method (pinhole, focal-blur or mesh).

A plan is derived in two steps.  :func:`~povlens.plan.plan_start.start_plan`
validates the options and derives what does not depend on the method or the sample
count: the focused lens, the film, the thin-lens model and POV-Ray's camera (cheap:
no pupil table).  :func:`finish_plan` adds the exit-pupil table (kept in
OUTDIR/pupil.npz), the model's measured error, POV-Ray's image size and the
lens-sample batches (a pinhole plan needs neither the table nor the error, and
skips them).  ``--method auto`` (:mod:`povlens.plan.convert`) runs its depth probe
between the two steps and finishes the plan of the method it chooses;
:func:`make_plan` takes both steps.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Callable

import numpy as np

from povlens.errors import ParameterError
from povlens.lens.film import Film
from povlens.lens.prescription import LensPrescription
from povlens.plan.anamorphic import apply_anamorphic
from povlens.plan.aperture import apply_aperture_shape, inputs_of_shape
from povlens.plan.batches import round_robin_batches
from povlens.plan.camera_setup import vector_tuple
from povlens.plan.dispersion_plan import apply_dispersion
from povlens.plan.options import ConvertOptions, stored_values
from povlens.plan.plan_start import PlanStart, start_plan
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import (CameraPlacement, FocusSolution, Inputs, LensSummary, Plan,
                                 PovraySettings)
from povlens.pov.mesh import default_sink_centre, render_size
from povlens.pov.executable import povray_version
from povlens.pov.povray_options import PovrayOptions
from povlens.pupil.grid_table import frame_extent_mm
from povlens.pupil.storage import cached_pupil_table
from povlens.thinlens.model import EquivalentThinLens
from povlens.thinlens.model_error import ModelError, measure_model_error
from povlens.util.threads import run_in_background

__all__ = ["PlanReuse", "finish_plan", "make_plan", "make_plan_with_lens",
           "check_shift_sees_light", "shift_focal_blur_note", "MESH_ANTIALIAS_NOTE",
           "PINHOLE_NOTE", "shares_radiosity", "shared_photon_settings", "no_pretrace"]

#: The note of a pinhole plan, which skips what only the lens's blur needs
#: (:func:`finish_plan`): ``model_error`` is empty, and the plan builds no exit-pupil
#: table (the render builds it if the vignetting map wants it).
PINHOLE_NOTE = ("method pinhole: the thin-lens model's error was not measured (a pinhole "
                "view needs none; plan.json's model_error is empty)")

#: The note of a mesh plan whose ``povray_options`` turn anti-aliasing on.
MESH_ANTIALIAS_NOTE = (
    "povray_options={option!r} turns anti-aliasing on, which the mesh render's lens "
    "samples do not use: POV-Ray's anti-aliasing shoots rays between pixels, which "
    "the mesh camera takes from the neighbouring pixels' faces; povlens renders them "
    "with -A, and its lens samples, jittered within each pixel, anti-alias the image "
    "(the views, the pinhole and focal-blur methods, use the option)")


def _standard_depths_mm(model: EquivalentThinLens, object_d: float, efl_mm: float) -> list[float]:
    """Camera-frame depths (mm) the model is checked at: half, once, twice and ten
    times the focus distance (focus at infinity: 1, 10, 100 x 1000 EFL)."""
    if math.isinf(object_d):
        return [model.centre_z_mm + k * 1000.0 * efl_mm for k in (1, 10, 100)]
    s = object_d - model.centre_z_mm
    return [model.centre_z_mm + k * s for k in (0.5, 1.0, 2.0, 10.0)]


def _inputs(opts: ConvertOptions, st: PlanStart) -> Inputs:
    """The plan's ``inputs``: the options kept as given (:func:`stored_values`) and the
    others as the conversion resolved them."""
    return Inputs(
        **stored_values(opts),
        scene=str(Path(opts.scene).resolve()), lens=st.lens.source,
        lens_sha256=st.lens.sha256(), focus=st.focus, samples=opts.sampling.sample_count,
        camera_from=st.camera_from, focus_from=st.focus_from,
        focus_at=None if opts.pose.focus_at is None else tuple(int(v) for v in opts.pose.focus_at),
        library_paths=st.povray.library_paths, clock=st.povray.clock,
        povray_options=st.povray.extra_options,
        ray_mesh=opts.sampling.ray_mesh if opts.sampling.method == "mesh" else None,
        shift_mm=st.film.shift_mm if st.film.shifted else None,
        desqueeze=None if st.anamorphic is None else bool(opts.film.desqueeze),
        **inputs_of_shape(st.lens.aperture_shape))


def _field_mesh_choice(st: PlanStart, plan: Plan, placement, table):
    """:func:`~povlens.plan.field_grid.choose_field_mesh` of ``st``'s lens, focus and
    film with ``table``, made once per start: the plans auto finishes from one start
    differ only in the method and the samples, on which the choice does not depend
    (``PlanStart.field_mesh_choices``; the table is kept with it, so its key stays its)."""
    key = (id(table), plan.povray.version)
    kept = st.field_mesh_choices.get(key)
    if kept is not None and kept[0] is table:
        return kept[1]
    from povlens.plan.field_grid import choose_field_mesh
    choice = choose_field_mesh(st.lens, st.film_distance_mm, plan.film, table, placement,
                               plan.lens.efl_mm, plan.povray.version)
    st.field_mesh_choices[key] = (table, choice)
    return choice


def _field_mesh(opts: ConvertOptions, plan: Plan, st: PlanStart, placement, table) -> None:
    """Give a mesh plan of ``--ray-mesh field`` its certified field meshes and the
    render size they need (:mod:`povlens.plan.field_grid`)."""
    if opts.sampling.method != "mesh" or opts.sampling.ray_mesh != "field":
        return
    film = plan.film
    plan.field_mesh, why_not = _field_mesh_choice(st, plan, placement, table)
    if plan.field_mesh is None:
        plan.inputs = dataclasses.replace(plan.inputs, ray_mesh="pixel")
        plan.add_note(why_not)
        return
    radiosity = "radiosity" in st.scene_settings
    at_film_size = (f"lens samples render one pass per run at {film.width_px + 1}x"
                    f"{film.height_px + 1} (POV-Ray 3.7's extra row and column), not "
                    f"interleaved or stacked")
    sized = bool(st.scene_size_uses) or (radiosity and st.scene_pretrace is None)
    if st.scene_size_uses:   # the passes render at the film's size (+ FS#261's row, column)
        plan.add_note(f"the scene reads image_width/image_height ({st.scene_size_uses[0]}) "
                      f"outside its camera, which POV-Ray sets to the size it renders: "
                      f"{at_film_size}")
    elif sized:
        plan.add_note(f"radiosity: povlens cannot tell the scene's pretrace_start and "
                      f"pretrace_end, which POV-Ray spaces by the size it renders: "
                      f"{at_film_size}")
    if sized:
        plan.field_mesh = dataclasses.replace(plan.field_mesh, interleave=1)
    from povlens.pov.field_mesh import pass_size
    wr, hr = pass_size(film.width_px, film.height_px, plan.field_mesh.interleave)
    pretrace = st.scene_pretrace if radiosity and not sized else None
    plan.povray = PovraySettings(plan.povray.version, wr, hr, 1, 1, image_size_read=sized,
                                 radiosity_pretrace=pretrace)
    if pretrace is not None:
        plan.add_note(PRETRACE_NOTE.format(start=pretrace[0], end=pretrace[1]))


#: What a field-mesh plan of a scene with radiosity says it adds.
PRETRACE_NOTE = (
    "radiosity: a lens sample's run renders the frame as interleaved tiles side by side "
    "(and stacks of them), larger than the frame, and POV-Ray spaces its radiosity pretrace "
    "by the size it renders; so each run repeats the scene's pretrace_start {start:g} and "
    "pretrace_end {end:g} scaled to its size (a global_settings radiosity block after the "
    "scene), spacing the pretrace on the scene as on the frame")


def _antialias_note(opts: ConvertOptions, st: PlanStart) -> str | None:
    """:data:`MESH_ANTIALIAS_NOTE` for a mesh plan whose options turn anti-aliasing on."""
    if opts.sampling.method != "mesh" or not st.povray.antialiasing():
        return None
    last = [o for o in st.povray.extra_options
            if PovrayOptions(extra_options=(o,)).antialiasing() is not None][-1]
    return MESH_ANTIALIAS_NOTE.format(option=last)


@dataclasses.dataclass(frozen=True)
class PlanReuse:
    """What :func:`finish_plan` takes instead of computing it: parts already known for
    the same lens, focus and film (they do not depend on the method or the samples).

    Attributes
    ----------
    pupil_table : the exit-pupil table (:class:`povlens.pupil.table.PupilTable`; None:
        OUTDIR/pupil.npz if current, else built and saved there).
    model_error : the thin-lens model's error
        (:class:`povlens.thinlens.model_error.ModelError`; None: measured).
    version : called for POV-Ray's version string (a background lookup may be passed).
    """

    pupil_table: object | None = None
    model_error: ModelError | None = None
    version: Callable[[], str] = povray_version


def finish_plan(opts: ConvertOptions, st: PlanStart, reuse: PlanReuse = PlanReuse()):
    """The plan of ``opts`` from :func:`~povlens.plan.plan_start.start_plan`'s part.

    Parameters
    ----------
    opts : the options ``st`` was started from, with a concrete method.
    st : :func:`~povlens.plan.plan_start.start_plan` of ``opts`` (or of options
        differing only in the method and sample count).
    reuse : the pupil table, model error and POV-Ray version lookup already known
        (default: none; see :class:`PlanReuse`).  A pinhole plan given neither table
        nor model error computes neither: its table is None, its ``model_error`` None
        (``{}`` in plan.json), and :data:`PINHOLE_NOTE` says so.

    Returns
    -------
    (Plan, PupilTable or None)
        The plan and the exit-pupil table it used (None: a pinhole plan's).
    """
    lens, p, film, model = st.lens, st.paraxial, st.film, st.thin_lens
    # imported here, once the inputs are validated (its scipy.stats loads only with points)
    from povlens.pupil.rays import ScenePlacement
    placement = ScenePlacement.at_entrance_pupil(st.location, st.right, st.up, st.forward,
                                                 model.centre_z_mm, st.mm_per_unit)
    table, model_error = reuse.pupil_table, reuse.model_error
    # a pinhole render needs neither the exit-pupil table nor the thin-lens model's
    # error (issue 14: ~1 s of a 96x72 render); auto's pinhole keeps what it measured
    skip = opts.sampling.method == "pinhole" and table is None and model_error is None
    if table is None and not skip:  # exact vignetting; saved in OUTDIR for the render
        table, _ = cached_pupil_table(RenderFolder(opts.outdir).pupil_npz, lens,
                                      st.film_distance_mm, film.max_field_radius_mm,
                                      save=Path(opts.outdir).is_dir(),
                                      film_extent_mm=frame_extent_mm(film))
    check_shift_sees_light(film, table, lens.source)
    if model_error is None and not skip:
        depths = _standard_depths_mm(model, st.object_distance_mm, p.efl)
        model_error = measure_model_error(lens, st.film_distance_mm, model, film, depths,
                                          pupil_table=table)
    version = reuse.version()
    rw, rh, drop = render_size(film.width_px, film.height_px, version)
    plan = Plan(
        inputs=_inputs(opts, st),
        lens=LensSummary(surfaces=int(lens.n_surfaces), stop_index=int(p.stop_index),
                         stop_diameter_mm=float(lens.aperture_diameter_mm[p.stop_index]),
                         efl_mm=p.efl, f_number=p.f_number,
                         entrance_pupil_diameter_mm=p.entrance_pupil_diameter),
        focus=FocusSolution(st.focus_mm, st.object_distance_mm, st.film_distance_mm,
                            st.thick_lens_film_distance_mm, st.rms_spot_mm),
        film=film, mm_per_unit=st.mm_per_unit,
        placement=CameraPlacement(vector_tuple(placement.film_centre), vector_tuple(placement.right),
                                  vector_tuple(placement.up), vector_tuple(placement.forward),
                                  placement.mm_per_unit),
        thin_lens=model, povray_camera=st.povray_camera, model_error=model_error,
        povray=PovraySettings(version, rw, rh, drop),
        sink_centre=vector_tuple(default_sink_centre(st.location, st.forward)),
        batches=round_robin_batches(opts.sampling.sample_count, opts.sampling.batch_size),
        notes=list(st.notes))
    plan.add_note(_antialias_note(opts, st))
    plan.add_note(PINHOLE_NOTE if skip else None)
    plan.add_note(shift_focal_blur_note(plan) if opts.sampling.method == "focal-blur" else None)
    apply_anamorphic(opts, plan, st)             # two focal lengths: the record, focal_blur
    _field_mesh(opts, plan, st, placement, table)
    apply_dispersion(opts, plan, lens, table)    # --dispersion: colour numbers, wider disc
    apply_aperture_shape(opts, plan, lens, table)  # iris/mask: notes, the iris's pupil domain
    _radiosity_cache(opts, plan, st)
    _photon_map(opts, plan, st)
    return plan, table


#: What a mesh plan of a scene with radiosity says it adds.
RADIOSITY_CACHE_NOTE = (
    "radiosity: its samples are computed once, by a pinhole render of the frame that saves "
    "them (POV-Ray's Radiosity_File_Name with +RFO), and every lens sample reads them (+RFI) "
    "instead of redoing the pretrace; make's batches and cluster groups of a folder "
    "'povlens render' has not started first measure whether it pays on their first two lens "
    "samples (one computing its own radiosity, one reading the file; radiosity.json in the "
    "folder records their times and the choice); the scene's radiosity settings are kept")


def _radiosity_cache(opts: ConvertOptions, plan: Plan, st: PlanStart) -> None:
    """Mark a mesh plan of a scene with radiosity for the shared radiosity samples
    (:mod:`povlens.rendering.radiosity_cache`), unless the user's own POV-Ray options
    name a radiosity file."""
    if opts.sampling.method != "mesh" or "radiosity" not in st.scene_settings:
        return
    if st.scene_writes:
        plan.add_note(f"radiosity: {_WRITES_NOTE.format(where=st.scene_writes[0])} its own "
                      f"radiosity samples")
        return
    if _names_radiosity_file(st):
        plan.add_note("radiosity: the POV-Ray options name a radiosity file, so each lens "
                      "sample computes its own radiosity samples")
        return
    plan.povray = dataclasses.replace(plan.povray, radiosity_cache=True)
    plan.add_note(NO_PRETRACE_NOTE if no_pretrace(st.scene_pretrace) else RADIOSITY_CACHE_NOTE)


#: What a mesh plan of a scene whose radiosity has no pretrace says instead.
NO_PRETRACE_NOTE = (
    "radiosity: the scene has no pretrace (pretrace_end 1), so a pinhole render of the frame "
    "would save only the samples its final trace computes, where the lens samples' rays, "
    "elsewhere, mostly compute their own (stackernight.pov: its first lens sample shot as "
    "many radiosity rays reading them as without); the first lens sample computes its own "
    "and the runs after it read and extend them in turn; the scene's radiosity settings are "
    "kept")


def no_pretrace(pretrace: tuple[float, float] | None) -> bool:
    """Whether a scene's radiosity pretrace ``(pretrace_start, pretrace_end)`` (None:
    unknown) does nothing: its finest pass spans the whole image (``pretrace_end 1``).
    Then one pinhole render's radiosity samples are those its final trace computed, at
    the frame's pixels, and serve lens samples little (module
    :mod:`povlens.rendering.radiosity_cache`)."""
    return pretrace is not None and float(pretrace[1]) >= 1.0


def _names_radiosity_file(st: PlanStart) -> bool:
    """Whether the user's POV-Ray options name a radiosity file (or its switches)."""
    return any("radiosity_file" in o.lower() or o.lower().lstrip("+-").startswith("rf")
               for o in st.povray.extra_options)


def shares_radiosity(opts: ConvertOptions, st: PlanStart) -> bool:
    """Whether the plan :func:`finish_plan` makes of ``opts`` and ``st`` shares the
    radiosity samples (its ``povray.radiosity_cache``), known before the plan is."""
    return (opts.sampling.method == "mesh" and "radiosity" in st.scene_settings
            and not st.scene_writes and not _names_radiosity_file(st))


def shared_photon_settings(opts: ConvertOptions, st: PlanStart) -> str:
    """The photons items the plan of ``opts`` and ``st`` shares a map of (its
    ``povray.photon_settings``; "" when none), known before the plan is."""
    if (opts.sampling.method != "mesh" or "photons" not in st.scene_settings
            or st.scene_writes or not st.scene_photons):
        return ""
    return st.scene_photons


#: Why a scene that writes files while it is parsed shares nothing between lens samples.
_WRITES_NOTE = ("the scene writes a file while it is parsed (#fopen at {where}), so a run "
                "may not see the scene another saw; each lens sample computes")

#: What a mesh plan of a scene with photons says it adds.
PHOTON_MAP_NOTE = (
    "photons: they are shot once, by a small pinhole render that saves the photon map "
    "(a global_settings photons block repeating the scene's own items with save_file), and "
    "every lens sample loads it (the same items with load_file) instead of shooting again")


def _photon_map(opts: ConvertOptions, plan: Plan, st: PlanStart) -> None:
    """Mark a mesh plan of a scene with photons for the shared photon map
    (:mod:`povlens.rendering.photon_map`) when its photons block can be repeated."""
    if opts.sampling.method != "mesh" or "photons" not in st.scene_settings:
        return
    if st.scene_writes:
        plan.add_note(f"photons: {_WRITES_NOTE.format(where=st.scene_writes[0])} its own "
                      f"photons")
        return
    if not st.scene_photons:
        plan.add_note("photons: povlens cannot repeat the scene's photons block whole (a "
                      "macro, a name it cannot evaluate, or the scene's own save_file or "
                      "load_file), so each lens sample shoots its own photons")
        return
    plan.povray = dataclasses.replace(plan.povray,
                                      photon_settings=shared_photon_settings(opts, st))
    plan.add_note(PHOTON_MAP_NOTE)


def check_shift_sees_light(film: Film, table, lens_name: str) -> None:
    """A :class:`ParameterError` (``shift_mm``) when a lens shift takes the whole frame
    beyond the lens's image circle (``table.vignetted_beyond_mm``: no pixel would see
    light); a partly dark frame is the effect, and passes.  No table: no check."""
    cut = None if table is None else table.vignetted_beyond_mm
    if not film.shifted or cut is None or film.min_field_radius_mm < cut:
        return
    sx, sy = film.shift_mm
    raise ParameterError("shift_mm", (sx, sy),
                         f"shift_mm={sx:g},{sy:g}: the frame's nearest point is "
                         f"{film.min_field_radius_mm:.3g} mm off the axis, beyond {lens_name}'s "
                         f"image circle (radius {cut:.3g} mm): no pixel would see light",
                         f"shift less: the frame's nearest edge must stay within "
                         f"{cut:.3g} mm of the axis")


def shift_focal_blur_note(plan: Plan) -> str | None:
    """The note of a focal-blur plan with a lens shift: POV-Ray's lens disc is
    perpendicular to the tilted ``direction``
    (:func:`~povlens.plan.camera_setup.off_axis_direction`), so seen along the axis it
    is cos(theta) narrower along the shift (the focal plane stays perpendicular to the
    axis).  None without a shift."""
    if not plan.film.shifted:
        return None
    d = np.asarray(plan.povray_camera.direction, dtype=np.float64)
    r, u = (np.asarray(v, dtype=np.float64) for v in (plan.povray_camera.right,
                                                       plan.povray_camera.up))
    axis = np.cross(r, u)
    cos_t = abs(float(axis @ d)) / float(np.linalg.norm(axis) * np.linalg.norm(d))
    return (f"lens shift with focal_blur: POV-Ray's lens disc is perpendicular to the "
            f"shifted view direction, tilted {math.degrees(math.acos(min(1.0, cos_t))):.2g} "
            f"deg from the axis, so its blur is {100 * (1 - cos_t):.2g} % narrower along the "
            f"shift than the thin lens's (the focal plane is placed on the axis); "
            f"--method mesh renders the shifted lens exactly")


def make_plan_with_lens(opts: ConvertOptions, on_start=None) -> tuple[Plan, LensPrescription]:
    """:func:`make_plan` and the stopped-down lens the plan was derived from;
    ``on_start(start)`` is called with the :class:`PlanStart` before the rest of the plan
    is derived (work that needs only the scene and camera starts then)."""
    start = start_plan(opts)
    if on_start is not None:
        on_start(start)
    # 'povray --version' (~0.2 s, idle) runs while the pupil table is built
    plan, _ = finish_plan(opts, start, PlanReuse(version=run_in_background(povray_version)))
    return plan, start.lens


def make_plan(opts: ConvertOptions) -> Plan:
    """Derive every number of a conversion with a given method.

    Reads the inputs; its only output file is OUTDIR/pupil.npz (the exit-pupil
    table, which the render reuses while current).  ``method="auto"`` needs
    renders (a depth probe): use :func:`povlens.plan.convert.convert`.

    Parameters
    ----------
    opts : the options, ``method`` one of pinhole, focal-blur, mesh.

    Returns
    -------
    Plan
    """
    if opts.sampling.method == "auto":
        raise ParameterError("method", opts.sampling.method, "make_plan: method='auto' is decided by "
                             "convert() (it renders a depth probe)",
                             "call convert(), or give a concrete method")
    return make_plan_with_lens(opts)[0]
