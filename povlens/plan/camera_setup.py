"""The camera and film of a conversion, read from the options and the scene's camera.

Scene units: ``units`` says what one scene unit is (the lens is in mm).  The
focus distance is measured from the camera ``location``, where the lens's
entrance pupil is placed.  Without ``focus``,
:func:`~povlens.plan.plan_start.start_plan` takes it from the camera
(:func:`camera_focus`); :mod:`povlens.plan.autofocus` measures it otherwise.

The scene's camera gives the position and orientation; the lens replaces its
projection, whatever its type.  Its proportions follow POV-Ray's rule
(:func:`film_of`): when |right|/|up| differs from the image's width/height, the film
takes the camera's proportions and the image keeps its pixels, which are then not
square, so the picture is stretched as POV-Ray stretches it.  What of the camera
povlens replaces or ignores becomes the plan's ``notes``.
"""

from __future__ import annotations

import math

import numpy as np

from povlens.errors import ParameterError, UsageError
from povlens.lens.film import Film
from povlens.plan.options import ConvertOptions
from povlens.pov.sdl import ASPECT_TOLERANCE, parse_scene_camera

__all__ = ["scene_camera_of", "camera_focus", "camera_basis", "focus_of", "film_of",
           "camera_notes", "framing_note", "FRAMING_NOTE_START", "off_axis_direction", "vector_tuple"]

#: The lens's field of view may differ from the scene camera's by this fraction (of
#: tan(hfov/2)) without a note: a film-diagonal rounding, not another framing.
FRAMING_TOLERANCE = 0.02
#: How :func:`framing_note` begins.
FRAMING_NOTE_START = "the scene's camera ("


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v)
    if not (n > 0 and math.isfinite(n)):
        raise UsageError(f"degenerate camera vector {v.tolist()}")
    return v / n


def scene_camera_of(opts: ConvertOptions):
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
            return None                   # camera_basis says what is missing
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
    return _camera_focus(opts, scene_camera_of(opts))


def camera_basis(opts: ConvertOptions, cam):
    """(location, right, up, forward, source) from options or the scene's camera
    ``cam`` (:func:`scene_camera_of`)."""
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


def vector_tuple(a) -> tuple[float, float, float]:
    """The (3,) vector ``a`` as a tuple of floats (as the plan's records hold it)."""
    return tuple(float(x) for x in np.asarray(a, dtype=np.float64).tolist())


def off_axis_direction(forward, right, up, film: Film, image_distance_mm) -> np.ndarray:
    """POV-Ray's perspective ``direction`` for a shifted film (:mod:`povlens.lens.film`).

    Parameters
    ----------
    forward, right, up : (3,) unit vectors of the camera (world frame).
    film : the film; its shift (mm, image plane) tilts the direction.
    image_distance_mm : the thin lens's image distance (mm), which scales right/up; or
        (v_x, v_y), one per meridian (an anamorphic lens).

    Returns
    -------
    ndarray
        (3,) ``forward + (shift_x / v) right + (shift_y / v) up``: POV-Ray traces
        ``direction + x right + y up`` for x, y in [-1/2, 1/2], so the frame's centre
        looks where the thin lens images film point -shift; ``forward`` itself
        (unit) without a shift.
    """
    sx, sy = film.shift_mm
    vx, vy = (float(v) for v in np.broadcast_to(np.asarray(image_distance_mm, float), (2,)))
    return (np.asarray(forward, np.float64) + (sx / vx) * np.asarray(right, np.float64)
            + (sy / vy) * np.asarray(up, np.float64))


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


def framing_note(cam, film: Film, image_distance_mm: float, lens_name: str) -> str | None:
    """A note when the lens frames the scene otherwise than its own camera did.

    Parameters
    ----------
    cam : the scene camera (:class:`~povlens.pov.sdl.SceneCamera`), or None.
    film : the film of the conversion.
    image_distance_mm : float
        The thin-lens model's image distance: the film's width over it is the
        lens's horizontal field, as the pinhole and focal_blur cameras use it.
    lens_name : str
        How the note names the lens.

    Returns
    -------
    str or None
        None when the scene's camera is not a perspective one, or when the fields
        agree within :data:`FRAMING_TOLERANCE`.  Otherwise the two fields of view and
        the film diagonal that frames the scene about as its author did (about: the
        thin-lens model is fitted over the film, so its image distance changes a
        little with the film's size, more for a lens used beyond its image circle).
        A picture with another field of view has other content, so its mean, its
        highlights and its look are not the scene camera's, whatever the gamma.
    """
    hfov = None if cam is None else getattr(cam, "hfov_deg", None)
    if hfov is None or not 0.0 < hfov < 180.0:
        return None
    scene_half = math.tan(math.radians(hfov) / 2.0)
    lens_half = 0.5 * film.width_mm / image_distance_mm
    if abs(lens_half / scene_half - 1.0) <= FRAMING_TOLERANCE:
        return None
    diagonal_mm = 2.0 * film.half_diagonal_mm
    matching = diagonal_mm * scene_half / lens_half
    lens_hfov = math.degrees(2.0 * math.atan(lens_half))
    tighter = lens_half < scene_half
    focal = "shorter" if tighter else "longer"
    return (f"{FRAMING_NOTE_START}{cam.source}) sees {hfov:.1f} deg across, {lens_name} on "
            f"this {diagonal_mm:.4g} mm film {lens_hfov:.1f} deg: the picture is framed "
            f"{'tighter' if tighter else 'wider'} than the author's; a film diagonal of about "
            f"{matching:.3g} mm (--film-diagonal), or a lens of {focal} focal length, frames "
            f"it as the scene's camera does")


def focus_of(opts: ConvertOptions, cam) -> tuple[float, str]:
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
