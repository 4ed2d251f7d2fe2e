"""First-order (paraxial) optics by ray-transfer matrices.

Rays are meridional pairs (y, n u): height y in mm and reduced angle n u
(refractive index times the slope dy/ds), travelling from the scene (front
vertex) to the film.  Each surface of curvature c between indices n and n'
refracts with ``R = [[1, 0], [-(n' - n) c, 1]]`` (an even asphere: its base
curvature plus twice its r^2 coefficient, :mod:`povlens.lens.asphere`); a gap of thickness t in index
n' transfers with ``T = [[1, t / n'], [0, 1]]`` (Hecht, *Optics*, §6.2; the
y-nu method of Smith, *Modern Optical Engineering*, ch. 3).  The system matrix
from the front vertex to the rear vertex, ``[[A, B], [C, D]]``, gives

    EFL = -1/C,   BFL = -A/C (rear vertex to rear focal point),
    FFL = -D/C (front focal point in front of the front vertex).

Positions below are signed along the axis in mm, positive toward the film,
measured from the vertex named in each field.

Anamorphic lenses (toric rows, :mod:`povlens.lens.toric`) have two sets of first-order
data: ``meridian="y"`` (the default, and the only one of a rotationally symmetric lens)
traces the y-z meridian with each row's y-z curvature, ``meridian="x"`` the x-z meridian
with its x-z curvature (the two decouple paraxially: toric rows have no twist).
:func:`anamorphic_data` gives both focal lengths, their ratio (the squeeze), the two
f-numbers and the two paraxial foci (astigmatic); a meridian without power has an
infinite focal length there.
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np

from povlens.errors import NominalFNumberWarning, OpticsError, ParameterError, UsageError
from povlens.lens.asphere import paraxial_curvature_per_mm
from povlens.lens.prescription import LensPrescription
from povlens.lens.toric import paraxial_curvatures_per_mm

__all__ = ["ParaxialData", "paraxial_data", "system_matrix", "axial_ray_heights",
           "stop_index", "stopped_down", "lensmaker_focal_length_mm", "image_of_object",
           "NOMINAL_F_NUMBER_TOLERANCE", "MERIDIANS", "primary_meridian", "entrance_pupil",
           "AnamorphicData", "anamorphic_data", "anamorphic_squeeze"]

#: The meridians of first-order data: the y-z plane (default) and the x-z plane.
MERIDIANS = ("y", "x")


def _curvatures(lens: LensPrescription, meridian: str) -> np.ndarray:
    """(n_surfaces,) paraxial curvatures (1/mm) in ``meridian``."""
    if meridian == "y":
        return paraxial_curvature_per_mm(lens)   # base curvature (+ 2 a2 on aspheres)
    if meridian not in MERIDIANS:
        raise ParameterError("meridian", meridian,
                             f"meridian={meridian!r}: give 'y' (the y-z plane) or 'x'")
    return paraxial_curvatures_per_mm(lens, meridian)

#: An f-number this much (relative) faster than the lens's widest is taken as the lens
#: wide open: makers round the engraved f-number (a 50 mm "f/2" that opens to F/2.03).
NOMINAL_F_NUMBER_TOLERANCE = 0.05


def _refraction(c: float, n: float, n_after: float) -> np.ndarray:
    return np.array([[1.0, 0.0], [-(n_after - n) * c, 1.0]])


def _transfer(t: float, n: float) -> np.ndarray:
    return np.array([[1.0, t / n], [0.0, 1.0]])


def system_matrix(lens: LensPrescription, first: int = 0, last: int | None = None,
                  include_last_refraction: bool = True, meridian: str = "y") -> np.ndarray:
    """2x2 matrix from just before surface ``first`` to just after surface ``last``.

    With ``include_last_refraction=False`` the matrix ends on the plane of
    surface ``last`` before it refracts (used to reach the stop plane).
    ``meridian``: "y" (the y-z plane) or "x" (differs on anamorphic lenses only).
    """
    last = lens.n_surfaces - 1 if last is None else last
    c = _curvatures(lens, meridian)
    nb, na = lens.index_before, lens.index_after
    m = np.eye(2)
    for i in range(first, last + 1):
        if i > first:
            m = _transfer(lens.thickness_mm[i - 1], nb[i]) @ m
        if i < last or include_last_refraction:
            m = _refraction(c[i], nb[i], na[i]) @ m
    return m


def axial_ray_heights(lens: LensPrescription, meridian: str = "y") -> np.ndarray:
    """Heights (mm) at every surface of the paraxial ray entering parallel at height 1
    (in ``meridian``, "y" or "x")."""
    c = _curvatures(lens, meridian)
    nb, na = lens.index_before, lens.index_after
    y, nu = 1.0, 0.0
    out = np.empty(lens.n_surfaces)
    for i in range(lens.n_surfaces):
        if i > 0:
            y += lens.thickness_mm[i - 1] * nu / nb[i]
        out[i] = y
        nu -= y * (na[i] - nb[i]) * c[i]
    return out


def _limiting_surface(lens: LensPrescription, candidates: np.ndarray,
                      meridian: str = "y") -> int:
    h = np.abs(axial_ray_heights(lens, meridian))
    ratio = np.where(candidates & (h > 0), lens.aperture_radius_mm / np.where(h > 0, h, 1.0),
                     np.inf)
    return int(np.argmin(ratio))


def stop_index(lens: LensPrescription, meridian: str = "y") -> int:
    """Row of the aperture stop (0-based).

    Among aperture rows (planes in air), the one that limits the axial beam of
    an object at infinity; with no aperture row, the surface that limits it (in
    ``meridian``, "y" or "x").
    """
    ap = lens.is_aperture
    return _limiting_surface(lens, ap if ap.any() else np.ones(lens.n_surfaces, bool),
                             meridian)


def entrance_pupil(lens: LensPrescription, meridian: str = "y") -> tuple[float, float, int]:
    """The entrance pupil in ``meridian``: (position from the front vertex, + toward the
    film (mm), diameter (mm), stop row); defined without power too (an afocal meridian).
    """
    s = stop_index(lens, meridian)
    (sa, sb), _ = system_matrix(lens, 0, s, include_last_refraction=False, meridian=meridian)
    pos = sb / sa if sa != 0 else math.inf
    diameter = float(lens.aperture_diameter_mm[s]) / abs(sa) if sa != 0 else math.inf
    return float(pos), float(diameter), s


@dataclasses.dataclass(frozen=True)
class ParaxialData:
    """First-order data of a lens, object at infinity unless stated (mm)."""

    efl: float
    bfl: float                      # rear vertex -> rear focal point
    ffl: float                      # front focal point in front of the front vertex
    front_focal_point: float        # from the front vertex, + toward the film (= -ffl)
    rear_focal_point: float         # from the rear vertex, + toward the film (= bfl)
    principal_front: float          # H, from the front vertex, + toward the film
    principal_rear: float           # H', from the front vertex, + toward the film
    principal_rear_from_rear_vertex: float
    entrance_pupil_position: float  # from the front vertex, + toward the film
    entrance_pupil_diameter: float
    exit_pupil_position: float      # from the rear vertex, + toward the film
    exit_pupil_diameter: float
    f_number: float                 # EFL / entrance-pupil diameter
    stop_index: int
    stop_is_aperture: bool          # False: a lens rim is the stop
    limiting_index: int             # surface that limits the axial beam
    stop_diameter: float
    total_track: float

    def to_dict(self) -> dict:
        return {
            "efl": self.efl, "bfl": self.bfl, "ffl": self.ffl, "f_number": self.f_number,
            "focal_points": {"front": self.front_focal_point, "rear": self.rear_focal_point},
            "principal_planes": {"front": self.principal_front, "rear": self.principal_rear},
            "entrance_pupil": {"position": self.entrance_pupil_position,
                               "diameter": self.entrance_pupil_diameter},
            "exit_pupil": {"position": self.exit_pupil_position,
                           "diameter": self.exit_pupil_diameter},
            "stop_index": self.stop_index, "stop_is_aperture": self.stop_is_aperture,
            "limiting_index": self.limiting_index, "stop_diameter": self.stop_diameter,
            "total_track": self.total_track,
        }


def paraxial_data(lens: LensPrescription, meridian: str = "y") -> ParaxialData:
    """Cardinal points, pupils and f-number of ``lens`` (its current stop) in
    ``meridian``: "y" (the y-z plane, the default) or "x" (the x-z plane; the same on a
    rotationally symmetric lens).  Raises :class:`OpticsError` when the lens has no power
    (in that meridian)."""
    (a, b), (c, d) = system_matrix(lens, meridian=meridian)
    if c == 0.0:
        if lens.is_anamorphic:
            raise OpticsError(f"{lens.source}: the lens has no power in {meridian} (afocal "
                              f"in {meridian}); it forms no image in the {meridian}-z plane",
                              "see the other meridian with meridian='x' or 'y'")
        raise OpticsError(f"{lens.source}: the lens is afocal (zero power); it cannot form an "
                          f"image on film")
    efl, bfl, ffl = -1.0 / c, -a / c, -d / c
    track = lens.total_track_mm
    s = stop_index(lens, meridian)
    limiting = _limiting_surface(lens, np.ones(lens.n_surfaces, bool), meridian)

    # Entrance pupil: the stop imaged backwards through the surfaces before it.
    (sa, sb), _ = system_matrix(lens, 0, s, include_last_refraction=False, meridian=meridian)
    ep_pos = sb / sa if sa != 0 else math.inf
    # Exit pupil: the stop imaged through the surfaces after it; the chief ray
    # leaves the stop centre
    # (including the rim's own refraction when a lens rim is the stop).
    m_after = system_matrix(lens, s, None, meridian=meridian)
    (xa, xb), (xc, xd) = m_after
    xp_pos = -xb / xd if xd != 0 else math.inf
    stop_d = float(lens.aperture_diameter_mm[s])
    # Pupils are the paraxial images of the stop (the optical-design convention,
    # and pbrt's); a rim that clips the axial beam first is reported separately
    # as ``limiting_index``.
    epd = stop_d / abs(sa) if sa != 0 else math.inf
    xp_d = stop_d / abs(xd) if xd != 0 else math.inf
    h_rear = track + bfl - efl  # H' from the front vertex
    efl, bfl, ffl, ep_pos, xp_pos, epd, xp_d = map(
        float, (efl, bfl, ffl, ep_pos, xp_pos, epd, xp_d))
    return ParaxialData(
        efl=efl, bfl=bfl, ffl=ffl, front_focal_point=-ffl, rear_focal_point=bfl,
        principal_front=efl - ffl, principal_rear=h_rear,
        principal_rear_from_rear_vertex=bfl - efl,
        entrance_pupil_position=ep_pos, entrance_pupil_diameter=epd,
        exit_pupil_position=xp_pos, exit_pupil_diameter=xp_d,
        f_number=efl / epd, stop_index=s, stop_is_aperture=bool(lens.is_aperture[s]),
        limiting_index=limiting, stop_diameter=stop_d, total_track=track)


def primary_meridian(lens: LensPrescription) -> str:
    """The meridian whose first-order data stand for the lens: "y", unless the lens has
    no power in y but has in x (a cylinder curving in x only)."""
    if lens.is_anamorphic and system_matrix(lens)[1, 0] == 0.0:
        if system_matrix(lens, meridian="x")[1, 0] != 0.0:
            return "x"
    return "y"


@dataclasses.dataclass(frozen=True)
class AnamorphicData:
    """First-order data of the two meridians of a lens (object at infinity; mm).

    efl_x_mm, efl_y_mm : focal lengths in the x-z and y-z planes; +inf in a meridian
        without power (afocal there).
    squeeze : efl_y / efl_x, the anamorphic squeeze (1 for a rotationally symmetric
        lens; +inf when afocal in y, 0 when afocal in x).
    f_number_x, f_number_y : EFL / entrance-pupil diameter per meridian (+inf afocal).
    focus_x_mm, focus_y_mm : the paraxial foci (astigmatic when they differ), from the
        rear vertex, + toward the film (the BFL per meridian; +inf afocal).
    entrance_pupil_x_mm, entrance_pupil_y_mm : entrance-pupil positions from the front
        vertex, + toward the film.
    afocal : "" or the meridian ("x" or "y") without power.
    """

    efl_x_mm: float
    efl_y_mm: float
    squeeze: float
    f_number_x: float
    f_number_y: float
    focus_x_mm: float
    focus_y_mm: float
    entrance_pupil_x_mm: float
    entrance_pupil_y_mm: float
    afocal: str = ""

    def to_dict(self) -> dict:
        """The fields as JSON-ready values (None for an infinite one)."""
        return {k: (v if not isinstance(v, float) or math.isfinite(v) else None)
                for k, v in dataclasses.asdict(self).items()}


def _meridian_data(lens: LensPrescription, meridian: str) -> tuple[float, float, float, float]:
    """(EFL, f-number, paraxial focus from the rear vertex, entrance pupil position) in
    ``meridian``; the first three +inf when it has no power."""
    ep_pos, epd, _ = entrance_pupil(lens, meridian)
    (a, _), (c, _) = system_matrix(lens, meridian=meridian)
    if c == 0.0:
        return math.inf, math.inf, math.inf, ep_pos
    efl = -1.0 / c
    return float(efl), float(efl / epd), float(-a / c), ep_pos


def anamorphic_data(lens: LensPrescription) -> AnamorphicData:
    """EFL, f-number and paraxial focus of both meridians, and the squeeze EFL_y / EFL_x.

    Parameters
    ----------
    lens : LensPrescription
        Any lens (a rotationally symmetric one has equal meridians, squeeze 1).

    Returns
    -------
    AnamorphicData
        A meridian without power has infinite EFL, f-number and focus there (no NaN).

    Raises
    ------
    OpticsError
        When the lens has power in neither meridian.
    """
    ex, fx, bx, px = _meridian_data(lens, "x")
    ey, fy, by, py = _meridian_data(lens, "y")
    if math.isinf(ex) and math.isinf(ey):
        raise OpticsError(f"{lens.source}: the lens is afocal in both meridians (zero power); "
                          f"it cannot form an image on film")
    squeeze = math.inf if math.isinf(ey) else 0.0 if math.isinf(ex) else ey / ex
    afocal = "x" if math.isinf(ex) else "y" if math.isinf(ey) else ""
    return AnamorphicData(ex, ey, squeeze, fx, fy, bx, by, px, py, afocal)


def anamorphic_squeeze(lens: LensPrescription) -> float:
    """EFL_y / EFL_x of ``lens`` (:func:`anamorphic_data`); 1 for a rotationally
    symmetric lens, +inf when afocal in y, 0 when afocal in x."""
    return anamorphic_data(lens).squeeze


def stopped_down(lens: LensPrescription, *, stop_diameter_mm: float | None = None,
                 f_number: float | None = None) -> LensPrescription:
    """A copy of ``lens`` with its aperture stop set by diameter or f-number.

    The stop cannot open beyond the diameter in the file.  An f-number up to
    ``NOMINAL_F_NUMBER_TOLERANCE`` (5 %) faster than the widest is a nominal one:
    the lens is used wide open, with a :class:`~povlens.errors.NominalFNumberWarning`.

    Parameters
    ----------
    lens : LensPrescription
        The lens, its stop at the diameter in the file.
    stop_diameter_mm : float, optional
        The stop diameter, mm.
    f_number : float, optional
        The f-number (EFL / entrance-pupil diameter); not with ``stop_diameter_mm``.

    Returns
    -------
    LensPrescription
        ``lens`` itself when neither is given, else a copy with the stop set.

    Raises
    ------
    ParameterError
        Naming ``f_number`` or ``stop_diameter_mm``, with the allowed range, for a
        value beyond what the lens opens to (or not positive).
    UsageError
        When the lens has no aperture row to stop down.
    """
    if stop_diameter_mm is None and f_number is None:
        return lens
    if stop_diameter_mm is not None and f_number is not None:
        raise ParameterError("f_number", f_number,
                             "give either 'f_number' or 'stop_diameter_mm', not both")
    meridian = primary_meridian(lens)          # "y" unless a lens has power in x only
    s = stop_index(lens, meridian)
    if not lens.is_aperture[s]:
        raise UsageError(f"{lens.source}: the lens has no aperture row to stop down (its beam is "
                         f"limited by {lens.row_label(s)})",
                         "add an aperture row 'radius 0, thickness, index 0, diameter' to the file")
    max_d = lens.max_stop_diameter_mm or float(lens.aperture_diameter_mm[s])
    if f_number is not None:
        if not (f_number > 0 and math.isfinite(f_number)):
            raise ParameterError("f_number", f_number,
                                 f"f_number={f_number}: must be a positive number")
        full = paraxial_data(lens.with_aperture_diameter(s, max_d), meridian)
        (sa, _), _ = system_matrix(lens, 0, s, include_last_refraction=False,
                                   meridian=meridian)
        stop_diameter_mm = full.efl / f_number * abs(sa)
        if stop_diameter_mm > max_d * (1 + 1e-12):
            if f_number < full.f_number * (1 - NOMINAL_F_NUMBER_TOLERANCE):
                raise ParameterError("f_number", f_number,
                                     f"f_number={f_number:g}: {lens.source} opens only to "
                                     f"F/{full.f_number:.3g}",
                                     f"use f_number={math.ceil(full.f_number * 100) / 100:g} "
                                     f"or more")
            warnings.warn(NominalFNumberWarning(
                f"f_number={f_number:g}: {lens.source} opens only to F/{full.f_number:.3g}; "
                f"taken as a nominal f-number (within {NOMINAL_F_NUMBER_TOLERANCE:.0%}), the "
                f"lens is used wide open"), stacklevel=2)
        stop_diameter_mm = min(stop_diameter_mm, max_d)
    if not (stop_diameter_mm > 0 and math.isfinite(stop_diameter_mm)):
        raise ParameterError("stop_diameter_mm", stop_diameter_mm,
                             f"stop_diameter_mm={stop_diameter_mm}: must be a positive number "
                             f"of mm")
    if stop_diameter_mm > max_d * (1 + 1e-12):
        raise ParameterError("stop_diameter_mm", stop_diameter_mm,
                             f"stop_diameter_mm={stop_diameter_mm:g}: the stop of {lens.source} "
                             f"opens only to {max_d:g} mm")
    return lens.with_aperture_diameter(s, stop_diameter_mm)


def image_of_object(lens: LensPrescription, object_distance_from_front_vertex_mm: float
                    ) -> tuple[float, float]:
    """Paraxial image of an axial object ``d`` mm in front of the front vertex.

    Returns (image distance from the rear vertex, + toward the film; lateral
    magnification).  d = inf gives (BFL, 0).
    """
    (a, b), (c, d) = system_matrix(lens)
    dist = object_distance_from_front_vertex_mm
    if math.isinf(dist):
        return -a / c, 0.0
    denom = c * dist + d
    if denom == 0:
        return math.inf, math.inf
    z = -(a * dist + b) / denom
    return z, a + c * z


def lensmaker_focal_length_mm(r1_mm: float, r2_mm: float, thickness_mm: float, n: float) -> float:
    """Lensmaker's equation for a thick singlet in air (R = 0 or inf: flat face).

    1/f = (n - 1) [1/R1 - 1/R2 + (n - 1) t / (n R1 R2)]
    """
    c1 = 0.0 if r1_mm in (0, math.inf) else 1.0 / r1_mm
    c2 = 0.0 if r2_mm in (0, math.inf) else 1.0 / r2_mm
    power = (n - 1.0) * (c1 - c2 + (n - 1.0) * thickness_mm * c1 * c2 / n)
    return 1.0 / power
