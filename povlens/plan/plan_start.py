"""The plan's start: the options validated, and what does not depend on the method.

:func:`start_plan` derives the focused lens, the film, the thin-lens model and
POV-Ray's camera (cheap: no pupil table) from the options and the scene's camera
(:mod:`povlens.plan.camera_setup`); :func:`povlens.plan.plan_finish.finish_plan`
completes the plan of a method from it.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from povlens.errors import UsageError
from povlens.lens.film import Film, parse_shift
from povlens.lens.focus import UNITS_MM, exact_film_distance_mm, thick_lens_film_distance_mm
from povlens.lens.aperture_shape import shaped_lens
from povlens.lens.paraxial import paraxial_data, stopped_down
from povlens.lens.prescription import LensPrescription, read_lens
from povlens.plan.anamorphic import anamorphic_data_of, anamorphic_record, squeezed_film
from povlens.plan.aperture import shape_of_options
from povlens.plan.camera_setup import (camera_basis, camera_notes, film_of, focus_of,
                                       framing_note, off_axis_direction, scene_camera_of,
                                       vector_tuple)
from povlens.plan.options import ConvertOptions, povray_options_of
from povlens.plan.request_size import check_request_size
from povlens.plan.schema import PovrayCamera
from povlens.pov.povray_options import PovrayOptions
from povlens.thinlens.model import EquivalentThinLens, fit_thin_lens

__all__ = ["PlanStart", "start_plan"]


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
    scene_settings: tuple[str, ...] = ()   # the items of the scene's global_settings
    scene_photons: str | None = None       # its photons block's items (SceneCamera)
    scene_writes: tuple[str, ...] = ()     # where it opens files to write (SceneCamera)
    scene_size_uses: tuple[str, ...] = ()  # where it reads image_width/height (SceneCamera)
    scene_pretrace: tuple[float, float] | None = None  # its radiosity pretrace (SceneCamera)
    anamorphic: dict | None = None         # Plan.anamorphic (povlens.plan.anamorphic)
    # the certified field-mesh choices made for this start (plan_finish._field_mesh), by
    # pupil table and POV-Ray version: auto finishes it up to three times (the probe's
    # mesh plan, the early samples' plan, the chosen one), the same choice each time
    field_mesh_choices: dict = dataclasses.field(default_factory=dict, repr=False,
                                                 compare=False)


def start_plan(opts: ConvertOptions) -> PlanStart:
    """Validate ``opts`` and derive the focused lens, film, thin lens and camera.

    Parameters
    ----------
    opts : the conversion's options (any method; ``auto``'s decision is not made
        here).  Without ``focus`` (and ``focus_at``), the
        camera's (:func:`~povlens.plan.camera_setup.camera_focus`); what needs the depth probe is
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
    samples = 1 if opts.sampling.method == "pinhole" else opts.sampling.sample_count
    check_request_size(samples, opts.film.width, opts.film.height, lens, opts.sampling.yes)
    p = paraxial_data(lens)
    cam = scene_camera_of(opts)
    film, proportions = film_of(opts, cam)
    if opts.film.shift_mm is not None:        # lens shift: the frame off the axis (lens.film)
        sx, sy = parse_shift(opts.film.shift_mm)
        film = dataclasses.replace(film, shift_x_mm=sx, shift_y_mm=sy)
    ana = anamorphic_data_of(lens)            # two focal lengths: the film desqueezed
    ana_notes = []
    if ana is not None:
        film, note = squeezed_film(film, ana, opts.film.desqueeze,
                                   opts.film.film_size_mm is not None)
        ana_notes.append(note)
    focus, focus_from = focus_of(opts, cam)
    focus_mm = focus * mm_per_unit
    film_d, object_d, thick_d, spot = _focus(lens, p, focus_mm, opts.film.real_focus)
    model = fit_thin_lens(lens, film_d, object_d, film)
    loc, right, up, fwd, cam_source = camera_basis(opts, cam)
    camera = _povray_camera(loc, right, up, fwd, film, model, mm_per_unit)
    start = PlanStart(mm_per_unit, lens, p, film, focus_mm, film_d, object_d, thick_d, spot,
                     model, loc, right, up, fwd, cam_source, camera, focus, focus_from,
                     povray, camera_notes(cam, proportions) + _framing(cam, film, model, opts)
                     + ana_notes,
                     () if cam is None else tuple(cam.global_settings),
                     None if cam is None else cam.photon_settings,
                     () if cam is None else tuple(cam.written_files),
                     () if cam is None else tuple(cam.image_size_uses),
                     None if cam is None else cam.radiosity_pretrace)
    if ana is not None:
        start.anamorphic = anamorphic_record(ana, model, film, opts.film.desqueeze)
    return start


def _povray_camera(loc, right, up, fwd, film, model, mm_per_unit: float) -> PovrayCamera:
    """POV-Ray's camera of the views: the thin lens's projection (``right`` and ``up``
    scaled by the film over each meridian's image distance: an anamorphic lens frames
    its two meridians apart), aperture and plane in focus."""
    vx, vy = model.image_distances_mm
    # lens shift: an off-axis frustum, POV-Ray's direction tilted by the shift while
    # right/up (the image plane) stay; focal_blur's focal plane then lies at
    # focal_distance / |direction| along the axis, so the distance is scaled by it
    direction = off_axis_direction(fwd, right, up, film, (vx, vy))
    stretch = float(np.linalg.norm(direction))
    return PovrayCamera(
        location=vector_tuple(loc), direction=vector_tuple(direction),
        right=vector_tuple(right * film.width_mm / vx),
        up=vector_tuple(up * film.height_mm / vy),
        aperture=2.0 * model.pupil_diameter_mm / mm_per_unit,
        focal_distance=(model.focus_distance_mm / mm_per_unit * stretch
                        if math.isfinite(model.focus_distance_mm) else 1e9),
        hfov_deg=math.degrees(2 * math.atan(0.5 * film.width_mm / vx)))


def _framing(cam, film, model, opts) -> list[str]:
    """:func:`framing_note` as a list (empty when the fields agree or the film is given:
    a film size or lens shift the user chose frames as the user means)."""
    if opts.film.film_size_mm is not None or opts.film.shift_mm is not None:
        return []
    note = framing_note(cam, film, model.image_distances_mm[0], Path(str(opts.lens)).name)
    return [] if note is None else [note]
