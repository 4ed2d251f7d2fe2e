"""Cross-check of the fast tracer against the reference tracer (``povlens check``).

:func:`check_lens` traces the same rays film -> scene with the vectorized tracer
(:mod:`povlens.lens.tracer`) and with the one-ray-at-a-time reference tracer
(:mod:`povlens.lens.reference_tracer`, a different derivation) and compares them.
This module is pure: it prints nothing and writes no files.

Ray set (camera frame of :mod:`povlens.lens.coordinates`, mm)
--------------------------------------------------
* ``n_film`` film points on z = 0 filling the disc of diameter ``film_diagonal_mm``
  (so any frame of that diagonal is covered): a sunflower (Vogel) spiral with
  radii ``(D/2) sqrt(k / (n_film - 1))``, k = 0 .. n_film-1, i.e. the centre and a
  point at the full half-diagonal are always included.
* ``n_pupil`` target points on the rear-vertex plane z = film_distance_mm filling
  the disc of radius ``pupil_overfill`` (1.2) x the rear clear radius, again a
  Vogel spiral, so that some rays are blocked by the rear aperture itself.
* Every film point is joined to every target: ``n_film * n_pupil`` rays
  (10,240 by default).

Comparison
----------
* Position / direction difference: Euclidean norm of the difference of the
  output origins (mm) / unit directions, over rays that pass *both* tracers.
* Disagreement: the two tracers differ in ``passed`` or in ``blocked_at``.
* A ray is *near an edge* when the reference trace shows that, at some surface it
  met (up to and including the one that blocked it), its hit height was within
  ``EDGE_RTOL`` = 1e-6 relative of that surface's clear radius
  (``|r_hit - r_clear| <= 1e-6 r_clear``), or it came within the reference tracer's
  ``BORDERLINE_TOL`` (1e-6) of another blocking threshold: grazing incidence
  (``|cos_i|`` or the intersection slope ``|F'|`` <= 1e-6), the TIR limit
  (``|1 - sin^2 theta_t|`` <= 1e-6), an axial direction component ``|d_z|`` <= 1e-6
  (turning back), a ray parameter within 0.5e-9 mm of the -1e-9 mm backward
  limit, or Newton non-convergence.  See :mod:`povlens.lens.reference_tracer`.  Rounding can
  legitimately decide such rays either way; a disagreement anywhere else is a bug.
* ``ok``: max position diff <= 1e-9 mm, max direction diff <= 1e-12, and no
  disagreement away from an edge.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from povlens.lens import reference_tracer
from povlens.lens import tracer
from povlens.errors import UsageError
from povlens.lens.film import DEFAULT_FILM_DIAGONAL_MM
from povlens.lens.prescription import LensPrescription

__all__ = ["CheckReport", "Disagreement", "check_lens", "check_rays", "POSITION_TOL_MM",
           "DIRECTION_TOL", "EDGE_RTOL", "DEFAULT_N_FILM", "DEFAULT_N_PUPIL"]

POSITION_TOL_MM = 1e-9
DIRECTION_TOL = 1e-12
#: Relative distance of a hit height to a clear radius counted as "at the edge".
EDGE_RTOL = 1e-6
DEFAULT_N_FILM = 40
DEFAULT_N_PUPIL = 256
DEFAULT_PUPIL_OVERFILL = 1.2
#: At most this many disagreements are listed individually in a report.
MAX_LISTED = 20

_GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))


@dataclasses.dataclass(frozen=True)
class Disagreement:
    """One ray on which the tracers disagree about passing / the blocking surface.

    ray : index into the check's ray set.
    film_point_mm : (x, y, z) origin on the film.  direction : unit (dx, dy, dz).
    fast_blocked_at / reference_blocked_at : surface row, -1 = passed.
    reference_reason : why the reference blocked it ("" if it passed).
    near_edge : see the module doc.  edge_margin : min |r_hit - r_clear| / r_clear.
    borderline : the reference tracer's borderline flag ("" if none).
    """

    ray: int
    film_point_mm: tuple[float, float, float]
    direction: tuple[float, float, float]
    fast_blocked_at: int
    reference_blocked_at: int
    reference_reason: str
    near_edge: bool
    edge_margin: float
    borderline: str

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["film_point_mm"] = list(self.film_point_mm)
        d["direction"] = list(self.direction)
        d["edge_margin"] = _json_float(self.edge_margin)
        return d


@dataclasses.dataclass(frozen=True)
class CheckReport:
    """Result of :func:`check_lens`.  Lengths in mm, directions dimensionless.

    n_rays : rays traced (n_film * n_pupil).
    n_passed_fast / n_passed_reference : rays each tracer let through.
    n_compared : rays passed by both (the ones whose outputs are compared).
    max_position_diff_mm / max_direction_diff : over the compared rays (0 if none).
    worst_position_ray / worst_direction_ray : ray index of those maxima (-1 if none).
    n_disagreements : rays with different (passed, blocked_at).
    n_disagreements_near_edge : of those, how many are near an edge.
    n_near_edge : rays near an edge overall (agreeing or not).
    reference_reasons : blocking reason -> count, from the reference tracer.
    disagreements : the first MAX_LISTED disagreements, away-from-edge ones first.
    warnings : remarks for the user (e.g. nothing passed, so nothing was compared).
    ok : the verdict (see the module doc).
    """

    lens_source: str
    film_distance_mm: float
    film_diagonal_mm: float
    pupil_overfill: float
    n_film: int
    n_pupil: int
    n_rays: int
    n_passed_fast: int
    n_passed_reference: int
    n_compared: int
    max_position_diff_mm: float
    max_direction_diff: float
    worst_position_ray: int
    worst_direction_ray: int
    n_disagreements: int
    n_disagreements_near_edge: int
    n_near_edge: int
    reference_reasons: dict
    disagreements: tuple
    warnings: tuple
    position_tol_mm: float = POSITION_TOL_MM
    direction_tol: float = DIRECTION_TOL

    @property
    def n_disagreements_away_from_edge(self) -> int:
        return self.n_disagreements - self.n_disagreements_near_edge

    @property
    def ok(self) -> bool:
        return (self.max_position_diff_mm <= self.position_tol_mm
                and self.max_direction_diff <= self.direction_tol
                and self.n_disagreements_away_from_edge == 0)

    def to_dict(self) -> dict:
        """JSON-ready dict (plain str / int / float / bool / list / dict; no NaN or inf)."""
        return {
            "lens": self.lens_source,
            "film_distance_mm": float(self.film_distance_mm),
            "film_diagonal_mm": float(self.film_diagonal_mm),
            "pupil_overfill": float(self.pupil_overfill),
            "n_film": self.n_film,
            "n_pupil": self.n_pupil,
            "n_rays": self.n_rays,
            "n_passed_fast": self.n_passed_fast,
            "n_passed_reference": self.n_passed_reference,
            "n_compared": self.n_compared,
            # null only if a tracer produced a non-finite output (see warnings)
            "max_position_diff_mm": _json_float(self.max_position_diff_mm),
            "max_direction_diff": _json_float(self.max_direction_diff),
            "worst_position_ray": self.worst_position_ray,
            "worst_direction_ray": self.worst_direction_ray,
            "n_disagreements": self.n_disagreements,
            "n_disagreements_near_edge": self.n_disagreements_near_edge,
            "n_disagreements_away_from_edge": self.n_disagreements_away_from_edge,
            "n_near_edge": self.n_near_edge,
            "reference_reasons": dict(self.reference_reasons),
            "disagreements": [d.to_dict() for d in self.disagreements],
            "tolerances": {"position_mm": self.position_tol_mm,
                           "direction": self.direction_tol, "edge_rtol": EDGE_RTOL},
            "warnings": list(self.warnings),
            "ok": self.ok,
        }

    def format_text(self) -> str:
        """A few lines for humans."""
        def verdict(value, tol):
            return "ok" if value <= tol else "TOO LARGE"
        reasons = ", ".join(f"{k} {v}" for k, v in sorted(self.reference_reasons.items())) or "none"
        lines = [
            f"tracer check: {self.lens_source}, film at {self.film_distance_mm:.6g} mm",
            f"  rays                {self.n_rays} ({self.n_film} film points over a "
            f"{self.film_diagonal_mm:g} mm diagonal x {self.n_pupil} targets over "
            f"{self.pupil_overfill:g}x the rear clear aperture)",
            f"  passed              {self.n_passed_fast} fast, {self.n_passed_reference} reference "
            f"({self.n_compared} compared)",
            f"  blocked (reference) {reasons}",
            f"  max position diff   {self.max_position_diff_mm:.3g} mm "
            f"(tolerance {self.position_tol_mm:g} mm: {verdict(self.max_position_diff_mm, self.position_tol_mm)})",
            f"  max direction diff  {self.max_direction_diff:.3g} "
            f"(tolerance {self.direction_tol:g}: {verdict(self.max_direction_diff, self.direction_tol)})",
            f"  disagreements       {self.n_disagreements} on pass/block "
            f"({self.n_disagreements_near_edge} near an aperture edge or threshold, "
            f"{self.n_disagreements_away_from_edge} elsewhere); {self.n_near_edge} rays near an edge",
        ]
        for d in self.disagreements:
            fb = "passed" if d.fast_blocked_at < 0 else f"blocked at row {d.fast_blocked_at}"
            rb = ("passed" if d.reference_blocked_at < 0
                  else f"blocked at row {d.reference_blocked_at} ({d.reference_reason})")
            where = "near edge" if d.near_edge else "AWAY FROM EDGES"
            lines.append(f"    ray {d.ray}: film ({d.film_point_mm[0]:.6g}, {d.film_point_mm[1]:.6g}) "
                         f"dir ({d.direction[0]:.6g}, {d.direction[1]:.6g}, {d.direction[2]:.6g}): "
                         f"fast {fb}, reference {rb} [{where}]")
        if self.n_disagreements > len(self.disagreements):
            lines.append(f"    ... {self.n_disagreements - len(self.disagreements)} more")
        lines.extend(f"  warning: {w}" for w in self.warnings)
        lines.append(f"  result: {'OK' if self.ok else 'FAILED'}")
        return "\n".join(lines)


def _json_float(v: float):
    return float(v) if math.isfinite(v) else None


def _vogel_disc(n: int, radius: float, include_rim: bool, phase: float = 0.0) -> np.ndarray:
    """(n, 2) points spread evenly over a disc (sunflower spiral), mm."""
    k = np.arange(n, dtype=np.float64)
    if include_rim:
        r = radius * np.sqrt(k / (n - 1)) if n > 1 else np.zeros(1)
    else:
        r = radius * np.sqrt((k + 0.5) / n)
    a = k * _GOLDEN_ANGLE + phase
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


def check_rays(lens: LensPrescription, film_distance_mm: float, n_film: int = DEFAULT_N_FILM,
               n_pupil: int = DEFAULT_N_PUPIL, film_diagonal_mm: float = DEFAULT_FILM_DIAGONAL_MM,
               pupil_overfill: float = DEFAULT_PUPIL_OVERFILL) -> tuple[np.ndarray, np.ndarray]:
    """The check's ray set: origins (n, 3) on the film (mm) and unit directions (n, 3).

    n = n_film * n_pupil; ray ``i * n_pupil + j`` joins film point i to target j.
    """
    _validate(film_distance_mm, n_film, n_pupil, film_diagonal_mm, pupil_overfill)
    film_xy = _vogel_disc(n_film, 0.5 * film_diagonal_mm, include_rim=True)
    r_rear = float(lens.aperture_radius_mm[-1])
    target_xy = _vogel_disc(n_pupil, pupil_overfill * r_rear, include_rim=False, phase=0.3)
    origins = np.zeros((n_film * n_pupil, 3))
    origins[:, :2] = np.repeat(film_xy, n_pupil, axis=0)
    targets = np.empty_like(origins)
    targets[:, :2] = np.tile(target_xy, (n_film, 1))
    targets[:, 2] = float(film_distance_mm)
    d = targets - origins
    d /= np.linalg.norm(d, axis=1)[:, None]
    return origins, d


def _validate(film_distance_mm, n_film, n_pupil, film_diagonal_mm, pupil_overfill) -> None:
    if not (_is_real(film_distance_mm) and film_distance_mm > 0.0):
        raise UsageError(f"film distance {film_distance_mm!r} mm must be a positive number",
                         "it is the distance from the film to the rear lens vertex")
    for name, v in (("number of film points", n_film), ("number of pupil points", n_pupil)):
        if not _is_whole(v) or v < 1:
            raise UsageError(f"{name} {v!r} must be a whole number >= 1")
    if not (_is_real(film_diagonal_mm) and film_diagonal_mm >= 0.0):
        raise UsageError(f"film diagonal {film_diagonal_mm!r} mm must be a number >= 0")
    if not (_is_real(pupil_overfill) and pupil_overfill > 0.0):
        raise UsageError(f"pupil overfill {pupil_overfill!r} must be a positive number")


def check_lens(lens: LensPrescription, film_distance_mm: float, n_film: int = DEFAULT_N_FILM,
               n_pupil: int = DEFAULT_N_PUPIL, film_diagonal_mm: float = DEFAULT_FILM_DIAGONAL_MM,
               pupil_overfill: float = DEFAULT_PUPIL_OVERFILL) -> CheckReport:
    """Trace ``n_film * n_pupil`` rays film -> scene with both tracers and compare.

    film_distance_mm : film-to-rear-vertex distance (mm).  n_film, n_pupil : see the
    module doc (defaults 40 x 256 = 10,240 rays).  film_diagonal_mm : diameter of
    the disc of film points.  pupil_overfill : target disc radius / rear clear radius.
    Raises :class:`~povlens.errors.UsageError` for invalid parameters.
    """
    _validate(film_distance_mm, n_film, n_pupil, film_diagonal_mm, pupil_overfill)
    n_film, n_pupil = int(n_film), int(n_pupil)
    origins, directions = check_rays(lens, film_distance_mm, n_film, n_pupil,
                                     film_diagonal_mm, pupil_overfill)
    fast = tracer.trace_from_film(lens, film_distance_mm, origins, directions)
    ref = reference_tracer.trace_rays_from_film(lens, film_distance_mm, origins, directions)

    both = fast.passed & ref.passed
    n_compared = int(both.sum())
    if n_compared:
        idx = np.nonzero(both)[0]
        pos = np.linalg.norm(fast.origin_mm[idx] - ref.origin_mm[idx], axis=1)
        dirn = np.linalg.norm(fast.direction[idx] - ref.direction[idx], axis=1)
        # A non-finite difference is the worst possible outcome, never "0".
        pos = np.where(np.isfinite(pos), pos, np.inf)
        dirn = np.where(np.isfinite(dirn), dirn, np.inf)
        kp, kd = int(np.argmax(pos)), int(np.argmax(dirn))
        max_pos, max_dir = float(pos[kp]), float(dirn[kd])
        worst_pos, worst_dir = int(idx[kp]), int(idx[kd])
    else:
        max_pos = max_dir = 0.0
        worst_pos = worst_dir = -1

    near_edge = (ref.edge_margin <= EDGE_RTOL) | (ref.borderline != "")
    disagree = (fast.passed != ref.passed) | (fast.blocked_at != ref.blocked_at)
    n_dis = int(disagree.sum())
    n_dis_edge = int((disagree & near_edge).sum())

    order = np.concatenate([np.nonzero(disagree & ~near_edge)[0],
                            np.nonzero(disagree & near_edge)[0]])[:MAX_LISTED]
    listed = tuple(Disagreement(
        ray=int(i), film_point_mm=tuple(float(v) for v in origins[i]),
        direction=tuple(float(v) for v in directions[i]),
        fast_blocked_at=int(fast.blocked_at[i]), reference_blocked_at=int(ref.blocked_at[i]),
        reference_reason=str(ref.reason[i]), near_edge=bool(near_edge[i]),
        edge_margin=float(ref.edge_margin[i]), borderline=str(ref.borderline[i]))
        for i in order)

    reasons, counts = np.unique(ref.reason[~ref.passed].astype(str), return_counts=True)
    warnings = []
    if n_compared == 0:
        warnings.append("no ray passed both tracers, so no output was compared; "
                        "check the film distance and the stop diameter")
    if max_pos == math.inf or max_dir == math.inf:
        warnings.append("a tracer returned a non-finite ray for a passed ray")

    return CheckReport(
        lens_source=str(lens.source), film_distance_mm=float(film_distance_mm),
        film_diagonal_mm=float(film_diagonal_mm), pupil_overfill=float(pupil_overfill),
        n_film=n_film, n_pupil=n_pupil, n_rays=int(origins.shape[0]),
        n_passed_fast=int(fast.passed.sum()), n_passed_reference=int(ref.passed.sum()),
        n_compared=n_compared, max_position_diff_mm=max_pos, max_direction_diff=max_dir,
        worst_position_ray=worst_pos, worst_direction_ray=worst_dir,
        n_disagreements=n_dis, n_disagreements_near_edge=n_dis_edge,
        n_near_edge=int(near_edge.sum()),
        reference_reasons={str(k): int(v) for k, v in zip(reasons, counts)},
        disagreements=listed, warnings=tuple(warnings))


def _is_whole(v) -> bool:
    try:
        return int(v) == v
    except (TypeError, ValueError, OverflowError):
        return False


def _is_real(v) -> bool:
    try:
        return math.isfinite(v)
    except TypeError:
        return False
