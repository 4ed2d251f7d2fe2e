"""Focusing: the film distance (rear vertex to film) for an object distance.

Object distances are measured from the film plane, as on a lens barrel
(pbrt's ``focusdistance``).  Two answers:

* **thick lens** — the Gaussian equation about the principal planes,
  ``1/u + 1/v = 1/f`` with u from H and v from H' (pbrt's ``FocusThickLens``,
  pbrt-v4 ``cameras.cpp``).  With L = D - T + z_H - z_H' (object-to-film
  distance less the track and the hiatus), v is the smaller root of
  ``v^2 - L v + f L = 0``, which exists only for L >= 4 f.
* **exact** — the film distance that minimises the RMS spot radius on the film
  of a bundle of real rays from the on-axis object point, spread evenly over
  the entrance pupil and traced through the real, stopped lens (rays the lens
  blocks are left out).

An anamorphic lens (toric rows, :mod:`povlens.lens.toric`) has a paraxial focus per
meridian (astigmatic foci, :func:`astigmatic_foci_mm`); its thick-lens answer is their
mean (the medial focus; the one focus when a meridian has no power), and the exact one
minimises the RMS spot of a full 2-D axial bundle through the elliptical entrance pupil
(:func:`anamorphic_axial_bundle`: each axis filled to its meridian's pupil diameter and
aimed through its meridian's pupil position), so both meridians count.  A rotationally
symmetric lens is focused exactly as before.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from povlens.errors import OpticsError, ParameterError
from povlens.lens.paraxial import (MERIDIANS, ParaxialData, entrance_pupil, paraxial_data,
                                   primary_meridian, system_matrix)
from povlens.lens.prescription import LensPrescription
from povlens.lens.tracer import trace_from_scene
from povlens.util.minimize import bounded_minimum  # scipy's, without its 0.5 s import

__all__ = ["FocusResult", "thick_lens_film_distance_mm", "closest_focus_distance_mm",
           "exact_film_distance_mm", "focus", "UNITS_MM", "LENS_SIDE_UNITS", "to_mm",
           "axial_bundle", "BUNDLE_START_MM", "astigmatic_foci_mm", "anamorphic_axial_bundle"]

UNITS_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
#: The unit of an object distance on the lens side (``povlens focus``, ``pupil``,
#: ``check``, :func:`povlens.api.focus`) when none is named: a lens barrel's mm.
LENS_SIDE_UNITS = "mm"


def to_mm(value: float, units: str) -> float:
    """Convert ``value`` in ``units`` (mm, cm, m, in) to millimetres; inf stays inf."""
    try:
        return float(value) * UNITS_MM[units]
    except KeyError:
        raise ParameterError("units", units, f"units={units!r}: unknown unit",
                             "use one of mm, cm, m, in") from None


def _hiatus_terms(p: ParaxialData) -> float:
    # z_H (from front vertex) - z_H' (from rear vertex), both + toward the film.
    return p.principal_front - p.principal_rear_from_rear_vertex


def closest_focus_distance_mm(lens: LensPrescription, p: ParaxialData | None = None) -> float:
    """Closest object distance (from the film) the thick-lens model can focus: L = 4 f.
    (Without ``p``, an anamorphic lens's: the larger of its meridians' with power.)"""
    if p is None and lens.is_anamorphic:
        return max(closest_focus_distance_mm(lens, paraxial_data(lens, m))
                   for m in MERIDIANS if system_matrix(lens, meridian=m)[1, 0] != 0.0)
    p = p or paraxial_data(lens)
    return 4.0 * p.efl + p.total_track - _hiatus_terms(p)


def thick_lens_film_distance_mm(lens: LensPrescription, distance_mm: float,
                                p: ParaxialData | None = None) -> float:
    """Film distance (rear vertex to film, mm) focusing an object ``distance_mm``
    from the film, by the thick-lens equation.  inf focuses at infinity.  (Without ``p``,
    an anamorphic lens's medial focus: the mean of :func:`astigmatic_foci_mm`.)"""
    if p is None and lens.is_anamorphic:
        return _medial_mm(astigmatic_foci_mm(lens, distance_mm))
    p = p or paraxial_data(lens)
    if math.isinf(distance_mm):
        return p.bfl
    f = p.efl
    L = distance_mm - p.total_track + _hiatus_terms(p)
    # Smaller root of v^2 - L v + f L = 0 without cancellation or overflow at any L:
    # v = 2 f / (1 + sqrt(1 - 4 f / L)), which tends to f as L grows (no L^2 formed).
    ratio = 1.0 - 4.0 * f / L if L > 0 else -1.0
    if not ratio >= 0:
        raise OpticsError(
            f"cannot focus {lens.source} at {distance_mm:g} mm from the film: the object is "
            f"inside the closest focus distance",
            f"the closest distance that works is {closest_focus_distance_mm(lens, p):.6g} mm "
            f"(object to film)")
    v = 2.0 * f / (1.0 + math.sqrt(ratio))
    return v + p.principal_rear_from_rear_vertex


def pupil_disc_points(n_rings: int) -> np.ndarray:
    """Points (m, 2) spread evenly over the unit disc: ring k at radius (k - 1/2)/n
    with 6k points, so every point stands for about the same area."""
    pts = []
    for k in range(1, n_rings + 1):
        r = (k - 0.5) / n_rings
        m = 6 * k
        a = (np.arange(m) + 0.5 * (k % 2)) * 2 * math.pi / m
        pts.append(np.stack([r * np.cos(a), r * np.sin(a)], axis=1))
    return np.concatenate(pts)


#: Where an axial bundle starts: this far (mm) in front of the front vertex.
BUNDLE_START_MM = 1.0


def axial_bundle(p: ParaxialData, film_distance_mm: float, distance_mm: float,
                 pupil_points_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rays of the on-axis object point ``distance_mm`` from the film through the
    entrance-pupil points ``pupil_points_mm`` (m, 2), started just in front of the lens.

    Every quantity is a difference of nearby lengths or a ratio close to 1, so the rays
    are as exact for an object at 1e14 mm as at 1 m; ``inf`` is the collimated beam,
    the limit of the same formulas (an object at the origin of a huge number would lose
    the rays' directions to rounding: their slopes are pupil radius / distance).

    Returns
    -------
    origin, direction : (m, 3) arrays, mm and unit-free (camera frame, +z toward the
        scene); the origin at :data:`BUNDLE_START_MM` in front of the front vertex, or at
        the object when it is closer.
    """
    front_z = film_distance_mm + p.total_track
    ep_z = front_z - p.entrance_pupil_position
    start_z = min(front_z + BUNDLE_START_MM, distance_mm)
    m = len(pupil_points_mm)
    if math.isinf(distance_mm):
        along, slope = 1.0, np.zeros((m, 2))
    else:
        span = distance_mm - ep_z          # object to entrance pupil, > 0
        # the ray from (0, 0, D) through (x, y, z_ep) is at (x, y) (D - z) / (D - z_ep)
        along = (distance_mm - start_z) / span
        slope = pupil_points_mm / span
    origin = np.column_stack([pupil_points_mm * along, np.full(m, start_z)])
    direction = np.column_stack([slope, np.full(m, -1.0)])
    return origin, direction


def anamorphic_axial_bundle(lens: LensPrescription, film_distance_mm: float,
                            distance_mm: float, unit_points: np.ndarray
                            ) -> tuple[np.ndarray, np.ndarray]:
    """Rays of the on-axis object point ``distance_mm`` from the film through the
    elliptical entrance pupil of an anamorphic lens, as :func:`axial_bundle` per axis:
    ``unit_points`` (m, 2) on the unit disc, x scaled to half the x-meridian pupil
    diameter and aimed through the x-meridian pupil position, y likewise (the two
    pupils of an anamorphic lens differ in size and position).

    Returns
    -------
    origin, direction : (m, 3) arrays (camera frame, mm and unit-free).
    """
    front_z = film_distance_mm + lens.total_track_mm
    start_z = min(front_z + BUNDLE_START_MM, distance_mm)
    m = len(unit_points)
    origin, direction = np.empty((m, 3)), np.empty((m, 3))
    origin[:, 2], direction[:, 2] = start_z, -1.0
    for k, meridian in enumerate(("x", "y")):
        ep_pos, epd, _ = entrance_pupil(lens, meridian)
        pts = unit_points[:, k] * (0.5 * epd)
        if math.isinf(distance_mm):
            origin[:, k], direction[:, k] = pts, 0.0
        else:
            span = distance_mm - (front_z - ep_pos)   # object to this meridian's pupil
            origin[:, k] = pts * ((distance_mm - start_z) / span)
            direction[:, k] = pts / span
    return origin, direction


def astigmatic_foci_mm(lens: LensPrescription, distance_mm: float) -> dict[str, float]:
    """Thick-lens film distance (rear vertex to film, mm) focusing each meridian of an
    anamorphic lens on an object ``distance_mm`` from the film: {"x": .., "y": ..};
    +inf in a meridian without power."""
    out = {}
    for meridian in MERIDIANS[::-1]:
        try:
            p = paraxial_data(lens, meridian)
        except OpticsError:                # no power in this meridian (and only there)
            out[meridian] = math.inf
            continue
        out[meridian] = thick_lens_film_distance_mm(lens, distance_mm, p)
    return out


def _medial_mm(foci: dict[str, float]) -> float:
    """The mean of the finite per-meridian foci (the medial focus)."""
    v = [f for f in foci.values() if math.isfinite(f)]
    return sum(v) / len(v)


def rms_spot_mm(lens: LensPrescription, film_distance_mm: float, distance_mm: float,
                p: ParaxialData | None = None, n_rings: int = 16, pupil_fill: float = 1.0
                ) -> tuple[float, int]:
    """RMS radius (mm) on the film of an axial object's bundle; and how many rays passed.
    (An anamorphic lens's bundle fills its elliptical pupil, :func:`anamorphic_axial_bundle`;
    ``p`` is not used for it.)"""
    if lens.is_anamorphic:
        origin, direction = anamorphic_axial_bundle(
            lens, film_distance_mm, distance_mm, pupil_disc_points(n_rings) * pupil_fill)
    else:
        p = p or paraxial_data(lens)
        disc = pupil_disc_points(n_rings) * (0.5 * p.entrance_pupil_diameter * pupil_fill)
        origin, direction = axial_bundle(p, film_distance_mm, distance_mm, disc)
    r = trace_from_scene(lens, film_distance_mm, origin, direction)
    o, d = r.origin_mm[r.passed], r.direction[r.passed]
    if len(o) < 3:
        return math.inf, int(len(o))
    t = -o[:, 2] / d[:, 2]
    xy = o[:, :2] + t[:, None] * d[:, :2]
    return float(np.sqrt(np.mean(np.sum(xy * xy, axis=1)))), int(len(o))


def exact_film_distance_mm(lens: LensPrescription, distance_mm: float,
                           p: ParaxialData | None = None, start_mm: float | None = None
                           ) -> tuple[float, float]:
    """Film distance minimising the real-ray RMS spot of the axial object point.

    Returns (film distance in mm, RMS spot radius in mm there).  An anamorphic lens
    starts from its medial focus and minimises the spot of its 2-D bundle.
    """
    p = p or paraxial_data(lens, primary_meridian(lens))
    if start_mm is not None:
        start = start_mm
    elif lens.is_anamorphic:
        start = _medial_mm(astigmatic_foci_mm(lens, distance_mm))
    else:
        start = thick_lens_film_distance_mm(lens, distance_mm, p)
    if not (start > 0 and math.isfinite(start)):
        # A diverging lens (or an object too close): the image is virtual, in front of
        # the rear vertex, and no film position behind the lens can receive it.
        raise OpticsError(f"{lens.source}: the image of an object at {distance_mm:g} mm lies "
                          f"{start:.6g} mm from the rear vertex (not behind the lens); no film "
                          f"distance focuses it", "a lens with positive power is needed")
    half = max(0.02 * abs(start), 0.01 * p.efl, 0.1)
    limit = max(abs(start), p.efl)
    while True:
        lo, hi = max(start - half, 1e-6), start + half
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise OpticsError(f"{lens.source}: the focus for {distance_mm:g} mm lies too far "
                              f"from the lens ({start:.6g} mm) to search with real rays")
        res = bounded_minimum(lambda f: rms_spot_mm(lens, f, distance_mm, p)[0], lo, hi,
                              xatol=1e-9 * max(1.0, start), maxiter=300)
        best = float(res.x)
        at_edge = min(best - lo, hi - best) < 1e-3 * half
        if not at_edge or half >= limit:
            break
        half *= 4.0  # the minimum lies outside: widen the bracket around the thick-lens focus
    spot, n = rms_spot_mm(lens, best, distance_mm, p)
    if not math.isfinite(spot):
        raise OpticsError(f"{lens.source}: no real ray from the object at {distance_mm:g} mm "
                          f"reaches the film; cannot focus with real rays",
                          "check the stop diameter ('stop_diameter_mm' / 'f_number')")
    if at_edge:
        raise OpticsError(f"{lens.source}: the real-ray focus for {distance_mm:g} mm lies more "
                          f"than {half:.3g} mm from the thick-lens focus; the lens is too "
                          f"aberrated to focus by RMS spot",
                          "stop the lens down ('f_number') and try again")
    return best, spot


@dataclasses.dataclass(frozen=True)
class FocusResult:
    """Focus of a lens for an object distance (all mm)."""

    distance_mm: float
    thick_lens_film_distance_mm: float
    exact_film_distance_mm: float
    exact_rms_spot_mm: float
    thick_lens_rms_spot_mm: float
    closest_focus_mm: float
    #: An anamorphic lens's paraxial film distance per meridian ({"x": .., "y": ..}, mm;
    #: +inf without power there), its astigmatic foci; None for other lenses.
    astigmatic_foci_mm: dict | None = None

    def to_dict(self) -> dict:
        def num(v):
            return v if math.isfinite(v) else None
        out = {
            "distance_mm": num(self.distance_mm),
            "film_distance_mm": {"thick_lens": self.thick_lens_film_distance_mm,
                                 "exact": self.exact_film_distance_mm},
            "rms_spot_mm": {"thick_lens": num(self.thick_lens_rms_spot_mm),
                            "exact": num(self.exact_rms_spot_mm)},
            "closest_focus_mm": self.closest_focus_mm,
        }
        if self.astigmatic_foci_mm is not None:
            out["astigmatic_foci_mm"] = {k: num(v) for k, v in self.astigmatic_foci_mm.items()}
        return out


def focus(lens: LensPrescription, distance_mm: float) -> FocusResult:
    """Thick-lens and exact real-ray focus for an object ``distance_mm`` from the film.

    For an anamorphic lens the thick-lens answer is the medial focus of its two
    meridians (both reported in ``astigmatic_foci_mm``) and the exact one minimises the
    RMS spot of a 2-D bundle filling its elliptical pupil (module docstring).
    """
    if not (distance_mm > 0):
        raise ParameterError("distance_mm", distance_mm, f"distance_mm={distance_mm:g}: the "
                                                         f"object distance must be positive")
    if lens.is_anamorphic:
        return _anamorphic_focus(lens, float(distance_mm))
    p = paraxial_data(lens)
    thick = thick_lens_film_distance_mm(lens, distance_mm, p)
    exact, spot = exact_film_distance_mm(lens, distance_mm, p, thick)
    return FocusResult(float(distance_mm), float(thick), float(exact), float(spot),
                       float(rms_spot_mm(lens, thick, distance_mm, p)[0]),
                       float(closest_focus_distance_mm(lens, p)))


def _anamorphic_focus(lens: LensPrescription, distance_mm: float) -> FocusResult:
    """:func:`focus` of an anamorphic lens: medial thick-lens focus, 2-D RMS spot."""
    foci = astigmatic_foci_mm(lens, distance_mm)
    p = paraxial_data(lens, primary_meridian(lens))
    thick = _medial_mm(foci)
    exact, spot = exact_film_distance_mm(lens, distance_mm, p, thick)
    closest = closest_focus_distance_mm(lens)
    return FocusResult(distance_mm, float(thick), float(exact), float(spot),
                       float(rms_spot_mm(lens, thick, distance_mm, p)[0]), float(closest),
                       {k: float(v) for k, v in foci.items()})
