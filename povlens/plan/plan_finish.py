"""The plan of a conversion with a given method (pinhole, focal-blur or mesh).

A plan is derived in two steps.  :func:`start_plan` validates the options and
derives what does not depend on the method or the sample count: the focused
lens, the film, the thin-lens model and POV-Ray's camera (cheap: no pupil
table).  :func:`finish_plan` adds the exit-pupil table (kept in
OUTDIR/pupil.npz), the model's measured error, POV-Ray's image size and the
lens-sample batches (a pinhole plan needs neither the table nor the error, and
skips them).  ``--method auto`` (:mod:`povlens.plan.convert`) runs its depth probe
between the two steps and finishes the plan of the method it chooses.

Scene units: ``units`` says what one scene unit is (the lens is in mm).  The
focus distance is measured from the camera ``location``, where the lens's
entrance pupil is placed.  Without ``focus``, :func:`start_plan` takes it from the
camera (:func:`camera_focus`); :mod:`povlens.plan.autofocus` measures it otherwise.

The scene's camera gives the position and orientation; the lens replaces its
projection, whatever its type.  Its proportions follow POV-Ray's rule
(:func:`film_of`): when |right|/|up| differs from the image's width/height, the film
takes the camera's proportions and the image keeps its pixels, which are then not
square, so the picture is stretched as POV-Ray stretches it.  What of the camera
povlens replaces or ignores becomes the plan's ``notes``.
"""

from __future__ import annotations

import dataclasses
import math
import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Callable

import numpy as np

from povlens.errors import ParameterError, UsageError
from povlens.lens.film import Film, parse_shift
from povlens.lens.focus import UNITS_MM, exact_film_distance_mm, thick_lens_film_distance_mm
from povlens.lens.aperture_shape import shaped_lens
from povlens.lens.paraxial import paraxial_data, stopped_down
from povlens.lens.prescription import LensPrescription, read_lens
from povlens.plan.aperture import apply_aperture_shape, inputs_of_shape, shape_of_options
from povlens.plan.dispersion_plan import apply_dispersion
from povlens.plan.options import ConvertOptions, povray_options_of, stored_values
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import (CameraPlacement, FocusSolution, Inputs, LensSummary, Plan,
                                 PovrayCamera, PovraySettings)
from povlens.pov.mesh import default_sink_centre, render_size
from povlens.pov.executable import povray_version
from povlens.pov.povray_options import PovrayOptions
from povlens.pov.sdl import ASPECT_TOLERANCE, parse_scene_camera
from povlens.pupil.storage import cached_pupil_table
from povlens.thinlens.model import EquivalentThinLens, fit_thin_lens
from povlens.thinlens.model_error import ModelError, measure_model_error

__all__ = ["PlanStart", "start_plan", "PlanReuse", "finish_plan", "make_plan",
           "make_plan_with_lens", "camera_focus", "film_of", "camera_notes", "round_robin_batches",
           "run_in_background", "MESH_ANTIALIAS_NOTE", "PINHOLE_NOTE"]

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


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v)
    if not (n > 0 and math.isfinite(n)):
        raise UsageError(f"degenerate camera vector {v.tolist()}")
    return v / n


def _scene_camera(opts: ConvertOptions):
    """The scene's camera, or None when the options give location and look_at."""
    if opts.pose.location is not None or opts.pose.look_at is not None:
        return None
    # the user's library paths and clock: the camera POV-Ray renders with them
    return parse_scene_camera(opts.scene, opts.film.width, opts.film.height,
                              library_paths=opts.povray.library_paths, clock=opts.povray.clock)


def _camera_focus(opts: ConvertOptions, cam) -> tuple[float, str] | None:
    """:func:`camera_focus` of an already read scene camera ``cam`` (None: the options')."""
    if cam is None:
        if opts.pose.location is None or opts.pose.look_at is None:
            return None                   # _camera_basis says what is missing
        d = float(np.linalg.norm(np.asarray(opts.pose.look_at, float) - np.asarray(opts.pose.location,
                                                                                  float)))
        return (d, "look_at") if d > 0 and math.isfinite(d) else None
    fd = cam.focal_distance
    if cam.aperture is not None and cam.aperture > 0 and fd is not None and 0 < fd < math.inf:
        return float(fd), "focal_point"
    if cam.look_at is not None:
        d = float(np.linalg.norm(np.asarray(cam.look_at, float) - np.asarray(cam.location,
                                                                               float)))
        if d > 0 and math.isfinite(d):
            return d, "look_at"
    return None


def camera_focus(opts: ConvertOptions) -> tuple[float, str] | None:
    """The focus distance the camera gives, and where from (no rendering).

    Parameters
    ----------
    opts : the options; their ``location`` / ``look_at`` if given, else the scene's
        camera.

    Returns
    -------
    (float, str) or None
        Distance from the camera location in scene units and ``"focal_point"`` (the
        scene camera's, when it has focal blur: ``aperture`` > 0; the distance
        |focal_point - location| is what POV-Ray focuses at) or ``"look_at"`` (the
        distance to it); None when the camera has neither.
    """
    return _camera_focus(opts, _scene_camera(opts))


def _camera_basis(opts: ConvertOptions, cam):
    """(location, right, up, forward, source) from options or the scene's camera
    ``cam`` (:func:`_scene_camera`)."""
    if cam is None:
        if opts.pose.location is None or opts.pose.look_at is None:
            missing = "location" if opts.pose.location is None else "look_at"
            raise ParameterError(missing, None, "'location' and 'look_at' go together",
                                 "give both 'location' and 'look_at' (points x, y, z in "
                                 "scene units)")
        loc = np.asarray(opts.pose.location, float)
        fwd = _unit(np.asarray(opts.pose.look_at, float) - loc)
        right = np.cross(np.asarray(opts.pose.sky, float), fwd)
        if np.linalg.norm(right) < 1e-12:
            raise ParameterError("sky", opts.pose.sky, "'sky' is parallel to the view direction",
                                 "choose another 'sky'")
        right = _unit(right)
        up = np.cross(fwd, right)
        return loc, right, up, fwd, "command line"
    # any camera type: the lens replaces its projection (a note says so)
    return (np.asarray(cam.location, float), _unit(cam.right), _unit(cam.up),
            _unit(cam.forward), cam.source)


def _focus(lens, p, focus_from_pupil_mm: float, real: bool):
    """Film distance f and object distance from the film D for a focus measured from
    the entrance pupil.  The pupil moves with the lens, so iterate (3 steps converge
    to 1e-12 relative: the dependence is through the small focus travel)."""
    if math.isinf(focus_from_pupil_mm):
        f = thick_lens_film_distance_mm(lens, math.inf, p)
        d = math.inf
    else:
        f = p.bfl
        for _ in range(6):
            d = focus_from_pupil_mm + f + p.total_track - p.entrance_pupil_position
            f = thick_lens_film_distance_mm(lens, d, p)
    thick = f
    spot = None
    if real:
        f, spot = exact_film_distance_mm(lens, d, p, thick)
    return f, d, thick, spot


@dataclasses.dataclass
class PlanStart:
    """The first part of a plan (:func:`start_plan`): validated inputs, the focused
    lens, its thin-lens model and POV-Ray's pinhole camera; no pupil table and no
    model error yet.  Nothing in it depends on the method or the sample count.

    Distances in mm unless named; ``location`` / ``right`` / ``up`` / ``forward``
    are the camera's world frame (shape (3,), scene units / unit vectors).
    """

    mm_per_unit: float
    lens: LensPrescription
    paraxial: object
    film: Film
    focus_mm: float
    film_distance_mm: float
    object_distance_mm: float
    thick_lens_film_distance_mm: float
    rms_spot_mm: float | None
    thin_lens: EquivalentThinLens
    location: np.ndarray
    right: np.ndarray
    up: np.ndarray
    forward: np.ndarray
    camera_from: str
    povray_camera: PovrayCamera
    focus: float = math.nan            # the focus distance, scene units
    focus_from: str = "option"         # where it came from (Inputs.focus_from)
    povray: PovrayOptions = PovrayOptions()  # the user's POV-Ray options, checked
    notes: list[str] = dataclasses.field(default_factory=list)  # Plan.notes of the camera


def _vector(a) -> tuple[float, float, float]:
    return tuple(float(x) for x in np.asarray(a, dtype=np.float64).tolist())


def start_plan(opts: ConvertOptions) -> PlanStart:
    """Validate ``opts`` and derive the focused lens, film, thin lens and camera.

    Parameters
    ----------
    opts : the conversion's options (any method; ``auto``'s decision is not made
        here).  Without ``focus`` (and ``focus_at``), the
        camera's (:func:`camera_focus`); what needs the depth probe is
        :func:`povlens.plan.autofocus.resolve_focus`'s.

    Returns
    -------
    PlanStart
        Cheap to compute: no pupil table, no rendering.
    """
    # the options' own values were checked when they were made (plan.options)
    if not Path(opts.scene).is_file():
        raise UsageError(f"scene file {opts.scene} does not exist", "check the path")
    mm_per_unit = UNITS_MM[opts.pose.units]
    povray = povray_options_of(opts.povray)      # checked before any POV-Ray run or scene read
    opts = opts.replace(library_paths=povray.library_paths, clock=povray.clock,
                        povray_options=povray.extra_options)
    lens = stopped_down(read_lens(opts.lens), stop_diameter_mm=opts.aperture.stop_diameter_mm,
                        f_number=opts.aperture.f_number)
    lens = shaped_lens(lens, shape_of_options(opts.aperture))    # iris / mask (plan.aperture)
    p = paraxial_data(lens)
    cam = _scene_camera(opts)
    film, proportions = film_of(opts, cam)
    if opts.film.shift_mm is not None:        # lens shift: the frame off the axis (lens.film)
        sx, sy = parse_shift(opts.film.shift_mm)
        film = dataclasses.replace(film, shift_x_mm=sx, shift_y_mm=sy)
    focus, focus_from = _focus_of(opts, cam)
    focus_mm = focus * mm_per_unit
    film_d, object_d, thick_d, spot = _focus(lens, p, focus_mm, opts.film.real_focus)
    model = fit_thin_lens(lens, film_d, object_d, film)
    loc, right, up, fwd, cam_source = _camera_basis(opts, cam)
    # lens shift: an off-axis frustum, POV-Ray's direction tilted by the shift while
    # right/up (the image plane) stay; focal_blur's focal plane then lies at
    # focal_distance / |direction| along the axis, so the distance is scaled by it
    direction = off_axis_direction(fwd, right, up, film, model.image_distance_mm)
    stretch = float(np.linalg.norm(direction))
    camera = PovrayCamera(
        location=_vector(loc), direction=_vector(direction),
        right=_vector(right * film.width_mm / model.image_distance_mm),
        up=_vector(up * film.height_mm / model.image_distance_mm),
        aperture=2.0 * model.pupil_diameter_mm / mm_per_unit,
        focal_distance=(model.focus_distance_mm / mm_per_unit * stretch
                        if math.isfinite(model.focus_distance_mm) else 1e9),
        hfov_deg=math.degrees(2 * math.atan(0.5 * film.width_mm / model.image_distance_mm)))
    return PlanStart(mm_per_unit, lens, p, film, focus_mm, film_d, object_d, thick_d, spot,
                     model, loc, right, up, fwd, cam_source, camera, focus, focus_from,
                     povray, camera_notes(cam, proportions))


def off_axis_direction(forward, right, up, film: Film, image_distance_mm: float) -> np.ndarray:
    """POV-Ray's perspective ``direction`` for a shifted film (:mod:`povlens.lens.film`).

    Parameters
    ----------
    forward, right, up : (3,) unit vectors of the camera (world frame).
    film : the film; its shift (mm, image plane) tilts the direction.
    image_distance_mm : the thin lens's image distance (mm), which scales right/up.

    Returns
    -------
    ndarray
        (3,) ``forward + (shift_x / v) right + (shift_y / v) up``: POV-Ray traces
        ``direction + x right + y up`` for x, y in [-1/2, 1/2], so the frame's centre
        looks where the thin lens images film point -shift; ``forward`` itself
        (unit) without a shift.
    """
    sx, sy = film.shift_mm
    v = float(image_distance_mm)
    return (np.asarray(forward, np.float64) + (sx / v) * np.asarray(right, np.float64)
            + (sy / v) * np.asarray(up, np.float64))


#: How the scene-camera reader's note on the camera's proportions begins
#: (:func:`camera_notes` replaces it with :func:`film_of`'s, which says what povlens does).
_READER_PROPORTIONS_NOTE = "the camera's proportions"


def _camera_proportions(cam, width: int, height: int) -> float | None:
    """|right|/|up| of scene camera ``cam`` when POV-Ray would stretch the image to it
    (a perspective or orthographic camera whose proportions differ from the image's
    by more than :data:`~povlens.pov.sdl.ASPECT_TOLERANCE`), else None."""
    if cam is None or cam.projection not in ("perspective", "orthographic"):
        return None
    r = float(np.linalg.norm(cam.right_vector))
    u = float(np.linalg.norm(cam.up_vector))
    if not (r > 0 and u > 0 and math.isfinite(r / u)):
        return None
    ratio = r / u
    return None if abs(ratio / (width / height) - 1.0) <= ASPECT_TOLERANCE else ratio


def film_of(opts: ConvertOptions, cam) -> tuple[Film, str | None]:
    """The film of a conversion, and a note when the camera's proportions set it.

    Parameters
    ----------
    opts : the options: ``film_size_mm``, else ``film_diagonal_mm``; ``width`` x
        ``height`` pixels.
    cam : the scene camera (:class:`~povlens.pov.sdl.SceneCamera`), or None.

    Returns
    -------
    (Film, str or None)
        POV-Ray's rule: the image spans the camera's ``right`` x ``up`` whatever its
        pixels, so when |right|/|up| differs from width/height (beyond
        :data:`~povlens.pov.sdl.ASPECT_TOLERANCE`) the film of the diagonal
        takes the camera's proportions and the pixels are not square: the picture is
        stretched as POV-Ray stretches it (the note says so).  ``film_size_mm`` is
        kept as given; the note then says the camera's proportions are not used.
        Otherwise the film takes the image's proportions (square pixels), no note.
    """
    w, h = int(opts.film.width), int(opts.film.height)
    if w < 1 or h < 1:
        return Film.from_diagonal(opts.film.film_diagonal_mm, w, h), None   # raises
    ratio = _camera_proportions(cam, w, h)
    differ = None if ratio is None else (
        f"the camera's proportions |right|/|up| = {ratio:.4g} ({cam.source}) differ from "
        f"the image's {w}x{h} ({w / h:.4g})")
    if opts.film.film_size_mm is not None:
        fw, fh = (float(v) for v in opts.film.film_size_mm)
        note = None if differ is None else (
            f"{differ}: film_size_mm={fw:g},{fh:g} sets the film instead (POV-Ray would "
            f"stretch the picture to the camera's proportions)")
        return Film(fw, fh, w, h), note
    square = Film.from_diagonal(opts.film.film_diagonal_mm, w, h)          # validates
    if ratio is None:
        return square, None
    fw = float(opts.film.film_diagonal_mm) / math.hypot(1.0, 1.0 / ratio)
    film = Film(fw, fw / ratio, w, h)
    tall = (film.height_mm / h) / (film.width_mm / w)
    return film, (f"{differ}: as POV-Ray does, the film takes the camera's proportions "
                  f"({film.width_mm:.4g} x {film.height_mm:.4g} mm) and the image's pixels "
                  f"are {tall:.4g} times as tall as wide, so the picture is stretched as "
                  f"POV-Ray stretches it; for square pixels give the image the camera's "
                  f"proportions, or write 'right x*image_width/image_height' in the scene")


def camera_notes(cam, proportions_note: str | None = None) -> list[str]:
    """What of scene camera ``cam`` povlens replaces or ignores: the reader's notes
    (``cam.replaced``), its note on the proportions replaced by ``proportions_note``
    (:func:`film_of`'s); empty without a scene camera."""
    notes = [] if cam is None else [n for n in getattr(cam, "replaced", ())
                                    if not n.startswith(_READER_PROPORTIONS_NOTE)]
    return notes + ([proportions_note] if proportions_note else [])


def _focus_of(opts: ConvertOptions, cam) -> tuple[float, str]:
    """The focus distance (scene units) and its source: the option, else the camera's
    (:func:`camera_focus`); :class:`ParameterError` when neither gives one."""
    if opts.pose.focus is None:
        got = None if opts.pose.focus_at is not None else _camera_focus(opts, cam)
        if got is None:
            why = ("focus_at needs the depth probe" if opts.pose.focus_at is not None else
                   "no focus given, and the camera has neither focal_point (with "
                   "focal_blur) nor look_at")
            raise ParameterError("focus", None, why,
                                 "give 'focus' (scene units), or convert with "
                                 "povlens.plan.convert.convert, which measures it")
        return got
    return float(opts.pose.focus), opts.pose.focus_from or "option"


def round_robin_batches(n_samples: int, batch_size: int | None = None) -> list[list[int]]:
    """Lens samples 0..n-1 dealt round-robin to batches of at most ``batch_size``.

    A batch is the work of one ``povlens render-batch`` (make runs them in
    parallel); the default is one batch per core.  Round-robin spreads the
    samples a smaller count renders first (0..n-1, the same for any count), and
    adaptive plans' later samples, which render fewer rows, evenly over the
    batches.

    Returns
    -------
    list of list of int
        Batch b holds samples b, b + nb, b + 2 nb, ... (nb batches).
    """
    bs = batch_size or math.ceil(n_samples / (os.cpu_count() or 1))
    nb = math.ceil(n_samples / bs)
    return [list(range(b, n_samples, nb)) for b in range(nb)]


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
        **inputs_of_shape(st.lens.aperture_shape))


def _field_mesh(opts: ConvertOptions, plan: Plan, st: PlanStart, placement, table) -> None:
    """Give a mesh plan of ``--ray-mesh field`` its certified field meshes and the
    render size they need (:mod:`povlens.plan.field_grid`)."""
    if opts.sampling.method != "mesh" or opts.sampling.ray_mesh != "field":
        return
    from povlens.plan.field_grid import choose_field_mesh
    film = plan.film
    plan.field_mesh, why_not = choose_field_mesh(st.lens, st.film_distance_mm, film, table,
                                                 placement, plan.lens.efl_mm, plan.povray.version)
    if plan.field_mesh is None:
        plan.inputs = dataclasses.replace(plan.inputs, ray_mesh="pixel")
        plan.add_note(why_not)
        return
    from povlens.pov.field_mesh import pass_size
    wr, hr = pass_size(film.width_px, film.height_px, plan.field_mesh.interleave)
    plan.povray = PovraySettings(plan.povray.version, wr, hr, 1, 1)


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
    """The plan of ``opts`` from :func:`start_plan`'s part.

    Parameters
    ----------
    opts : the options ``st`` was started from, with a concrete method.
    st : :func:`start_plan` of ``opts`` (or of options differing only in the method
        and sample count).
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
                                      save=Path(opts.outdir).is_dir())
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
        placement=CameraPlacement(_vector(placement.film_centre), _vector(placement.right),
                                  _vector(placement.up), _vector(placement.forward),
                                  placement.mm_per_unit),
        thin_lens=model, povray_camera=st.povray_camera, model_error=model_error,
        povray=PovraySettings(version, rw, rh, drop),
        sink_centre=_vector(default_sink_centre(st.location, st.forward)),
        batches=round_robin_batches(opts.sampling.sample_count, opts.sampling.batch_size), notes=list(st.notes))
    plan.add_note(_antialias_note(opts, st))
    plan.add_note(PINHOLE_NOTE if skip else None)
    plan.add_note(shift_focal_blur_note(plan) if opts.sampling.method == "focal-blur" else None)
    _field_mesh(opts, plan, st, placement, table)
    apply_dispersion(opts, plan, lens, table)    # --dispersion: colour numbers, wider disc
    apply_aperture_shape(opts, plan, lens, table)  # iris/mask: notes, the iris's pupil domain
    return plan, table


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
    perpendicular to the tilted ``direction`` (:func:`off_axis_direction`), so seen
    along the axis it is cos(theta) narrower along the shift (the focal plane stays
    perpendicular to the axis).  None without a shift."""
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


def run_in_background(fn: Callable):
    """Run ``fn()`` in a thread; returns a function that waits for its result (or
    raises its exception)."""
    pool = ThreadPoolExecutor(max_workers=1)
    future = pool.submit(fn)
    pool.shutdown(wait=False)
    return future.result


def make_plan_with_lens(opts: ConvertOptions) -> tuple[Plan, LensPrescription]:
    """:func:`make_plan` and the stopped-down lens the plan was derived from."""
    start = start_plan(opts)
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
