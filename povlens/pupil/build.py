"""Building the exit-pupil table of a lens: where rays from a film point get through.

The table it produces, and how it is sampled, is :class:`povlens.pupil.table.PupilTable`;
the exact probing is :class:`povlens.pupil.prober.PupilProber`.  Frames are those
of :mod:`povlens.lens.coordinates` (camera frame, mm, film at z = 0, lens toward +z).
Everything relies on the lens being rotationally symmetric about the axis (as
pbrt does): the region for a film point at radius r and azimuth phi is the region
for the film point (r, 0) rotated by phi, and that region is symmetric about the
x axis.

Sampling plane
--------------
Rays from a film point are parameterised by where they cross a plane z = z_p
perpendicular to the axis.  povlens uses the **paraxial exit-pupil plane**
(``z_p = film_distance - exit_pupil_position``), pbrt the rear-vertex plane.
Seen from one film point, the pass regions on any two such planes are the
same figure scaled about the film point's foot (the central projection between
parallel planes is a homothety), so the normalised description is the same on
every plane -- ``benchmarks/bench_pupil.py`` shows the same knots and pass
fractions on both -- and the estimate is the same: with cos(theta) = d_z of the
unit ray direction and dA an area on the plane, the solid angle is
cos^3(theta) dA / z_p^2, so

    E(p) / L = integral over the pass region of cos^4(theta) / z_p^2 dA

(the camera measurement equation of Pharr, Jakob & Humphreys, *Physically Based
Rendering*, 3rd ed., §6.4.7, with the rear-vertex distance replaced by z_p).
What the exit-pupil plane adds: there the stop's image is, to first order, the
same disc centred on the axis for every film point, so the region's frame
(centre, half-width, half-height) barely moves with film radius (on the
rear-vertex plane it slides by r (1 - z_rear / z_p)), and ``pupil_point`` is where
the ray crosses the exit pupil, which makes plots and aperture shapes readable.
When the exit pupil lies at or behind the film (z_p < film_distance / 4; never
for the shipped lenses) the rear-vertex plane is used.

Knots
-----
At knot radii r_k the exact boundary of the region (the polygon description of
:mod:`povlens.pupil.table`) is traced along 2M + 1 directions.  The frame comes
from bisected boundary points (so it is smooth in r), and a knot is traced again
in its own frame when the frame it was traced in differs by more than
``RENORMALISE``.

How the tolerance drives the description
----------------------------------------
``tolerance`` is a relative area error: the area between the description and
the exact boundary over the area of the region (computed in the normalised
frame; affine maps keep area ratios).

* M (angles) starts at 16 and doubles (up to 128) until, at the initial knots,
  the chords of the polygon leave at most ``tolerance / 4`` of area error
  against the exact boundary at the mid-angles.
* Radial knots start at 5 evenly spaced film radii.  For every interval the
  exact boundary at its midpoint, traced in the interpolated frame, is compared
  with the interpolated polygon at the vertex angles; an interval whose error
  exceeds ``tolerance`` is split at the midpoint, which becomes a knot.
  Intervals shorter than ``min_interval_mm`` (1e-5 of the half-diagonal) are
  not split, nor any once ``MAX_KNOTS`` knots exist (both only where the pupil
  vanishes or misbehaves; see ``stats``).

Conservativeness comes from measured dilations: every vertex is moved out by
the largest shortfall of the chords measured at its knot's mid-angles and by
twice the largest shortfall measured at the midpoints of its two intervals
(vertex and mid-angles; twice because for a single kink in rho(r) inside an
interval the midpoint sees at least half of the largest error), plus
``SAFETY_MARGIN`` (relative) and twice the bisection bracket.  The tests check
containment against dense brute-force tracing at many film radii for every
shipped lens.

The boundary is the outermost crossing along each direction, which is exact for
star-shaped regions (those of every shipped lens, at every radius probed).  A
region that is not (horns, holes: the F/1 singlet stopped to F/2 far off axis)
is detected -- a blocked probe followed by a passing one -- and reported in
``stats["non_star_shaped_radii"]``; thin features between probe rays can then
be missed.

Vignetting
----------
If no ray from the film edge gets through, the largest film radius with rays
is found by bisection (to 1e-6 of the half-diagonal); the last knot sits there.
Film points beyond it are reported vignetted: ``valid`` False, weight 0, pdf 0.
(Within about a micrometre of that cut-off, where the pupil's area is 1e-5 of
the axial one, the pass fraction falls below 95 %; the table stays
conservative.)
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from povlens.errors import OpticsError, ParameterError
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import LensPrescription
from povlens.pupil.prober import PupilProber, grow_boxes
from povlens.pupil.table import PupilTable

__all__ = ["build_pupil_table", "sampling_plane_z_mm", "PLANES", "DEFAULT_TOLERANCE", "SAFETY_MARGIN",
           "RENORMALISE", "MAX_KNOTS", "MIN_STOP_FRACTION", "check_build_arguments",
           "check_stop_is_resolvable"]

#: Default relative area tolerance of the region description (module docstring).
DEFAULT_TOLERANCE = 0.005
#: Extra outward margin, as a fraction of the region's mean radius.
SAFETY_MARGIN = 0.001
#: Re-trace a knot when its region's frame (centre, half-width, half-height) is this
#: far (relative) from the frame used for the trace.
RENORMALISE = 0.002
#: Refinement stops adding knots beyond this many (pathological pupils, see stats).
MAX_KNOTS = 128
#: Smallest stop diameter, as a fraction of the focal length, a table is built for.
MIN_STOP_FRACTION = 1e-4
#: The planes a table can be sampled on, the default first.
PLANES = ("exit-pupil", "rear-vertex")


def sampling_plane_z_mm(lens: LensPrescription, film_distance_mm: float,
                        plane: str = PLANES[0]) -> tuple[float, str]:
    """z of the sampling plane (camera frame, mm) and the plane actually used.

    Parameters
    ----------
    lens, film_distance_mm : the lens and its rear-vertex-to-film distance (mm).
    plane : "exit-pupil" (default; falls back to "rear-vertex" when the paraxial
        exit pupil lies closer to the film than a quarter of the film distance, or
        behind it) or "rear-vertex".

    Returns
    -------
    (z_p in mm, "exit-pupil" or "rear-vertex").
    """
    if plane == "rear-vertex":
        return float(film_distance_mm), "rear-vertex"
    if plane != "exit-pupil":
        raise ParameterError("plane", plane, f"plane={plane!r}: unknown sampling plane",
                             "use exit-pupil or rear-vertex")
    p = paraxial_data(lens)
    z = film_distance_mm - p.exit_pupil_position
    if not math.isfinite(z) or z < 0.25 * film_distance_mm:
        return float(film_distance_mm), "rear-vertex"
    return float(z), "exit-pupil"


def build_pupil_table(lens: LensPrescription, film_distance_mm: float,
                      film_half_diagonal_mm: float, *, tolerance: float = DEFAULT_TOLERANCE,
                      plane: str = PLANES[0], n_angles: int | None = None,
                      safety_margin: float = SAFETY_MARGIN, initial_knots: int = 5,
                      min_interval_mm: float | None = None, progress=None,
                      metadata: dict | None = None) -> PupilTable:
    """Build the exit-pupil table of ``lens`` with the film ``film_distance_mm`` behind
    the rear vertex, for film points out to ``film_half_diagonal_mm`` from the centre.

    Parameters
    ----------
    lens : the lens, stop included.
    film_distance_mm : rear vertex to film, mm.
    film_half_diagonal_mm : largest film radius the table covers, mm.
    tolerance : relative area error of the region description; sets the angle
        count and the radial knots (module docstring).
    plane : "exit-pupil" (default) or "rear-vertex" sampling plane.
    n_angles : fix M instead of choosing it from the tolerance.
    safety_margin : extra outward margin, relative to the region's size.
    initial_knots : evenly spaced knots to start the refinement from.
    min_interval_mm : intervals this short are not split (default 1e-5 of the
        half-diagonal).
    progress : optional callable taking the number of boundary evaluations just done.
    metadata : extra JSON-able entries saved with the table (e.g. the focus distance).

    Returns
    -------
    PupilTable
        With build statistics in ``stats`` (time, rays traced, errors).

    Raises
    ------
    UsageError
        For bad arguments.
    OpticsError
        When the stop is too small to resolve or no ray from the film centre gets
        through the lens.
    """
    t_start = time.perf_counter()
    check_build_arguments(film_distance_mm, film_half_diagonal_mm, tolerance, n_angles)
    # A shaped stop (iris, mask) breaks the rotational symmetry the table relies on; it
    # only removes rays, so the round stop's regions contain its (conservative), and the
    # field sampler tightens to the shape (povlens.pupil.aperture_domain).
    lens = lens.replace(aperture_shape=None, aperture_shape_row=-1)
    hd = float(film_half_diagonal_mm)
    check_stop_is_resolvable(lens)
    zp, plane_used = sampling_plane_z_mm(lens, float(film_distance_mm), plane)
    prober = PupilProber(lens, film_distance_mm, zp)
    tracer = _KnotTracer(prober, progress)
    min_w = float(min_interval_mm) if min_interval_mm is not None else 1e-5 * hd

    extent = _film_extent(prober, lens, film_distance_mm, hd)
    M, knots, angle_error = _initial_knots(tracer, extent, initial_knots, tolerance, n_angles)
    checks, max_check_error = _refine_knots(tracer, knots, M, tolerance, min_w)
    rs, ks, rho, mean_dilation = _dilate(knots, checks, M, safety_margin)
    axial = _axial_irradiance_factor(ks[0], M, zp)

    stats = {"build_time_s": time.perf_counter() - t_start, "rays_traced": int(prober.rays),
             "boundary_evaluations": int(tracer.evaluations),
             "max_check_area_error": max_check_error,
             "angle_area_error": angle_error, "min_interval_mm": min_w,
             "mean_dilation": mean_dilation,
             "knot_limit_reached": len(knots) >= MAX_KNOTS,
             "non_star_shaped_radii": len(prober.non_star_radii),
             "non_star_shaped_from_mm": (min(prober.non_star_radii) if prober.non_star_radii
                                         else None)}
    meta = dict(metadata or {})
    meta.setdefault("requested_plane", plane)
    return PupilTable(lens, film_distance_mm, hd, zp, plane_used, rs,
                      [k.c for k in ks], [k.sx for k in ks], [k.sy for k in ks], rho,
                      extent.max_film_radius_mm, extent.vignetted_beyond_mm, tolerance,
                      axial, stats, meta)


# ----- phase 0: arguments ---------------------------------------------------------------

def check_build_arguments(film_distance_mm, film_half_diagonal_mm, tolerance,
                           n_angles) -> None:
    """Raise UsageError for a non-positive length, a tolerance outside (0, 1) or a bad M."""
    for name, v in (("film_distance_mm", film_distance_mm),
                    ("film_half_diagonal_mm", film_half_diagonal_mm)):
        if not (isinstance(v, (int, float, np.floating)) and math.isfinite(v) and v > 0):
            raise ParameterError(name, v, f"{name}={v!r}: must be a positive number of mm")
    if not (isinstance(tolerance, (int, float)) and math.isfinite(tolerance)
            and 0 < tolerance < 1):
        raise ParameterError("tolerance", tolerance,
                             f"tolerance={tolerance!r}: must be between 0 and 1 (e.g. 0.005)")
    if n_angles is not None and not (2 <= int(n_angles) <= 4096):
        raise ParameterError("n_angles", n_angles,
                             f"n_angles={n_angles!r}: must be between 2 and 4096")


def check_stop_is_resolvable(lens: LensPrescription) -> None:
    """Refuse a stop so small that its pupil cannot be resolved in float64."""
    pdat = paraxial_data(lens)
    if pdat.stop_diameter < MIN_STOP_FRACTION * abs(pdat.efl):
        raise OpticsError(
            f"{lens.source}: the stop diameter {pdat.stop_diameter:.3g} mm is below "
            f"{MIN_STOP_FRACTION:g} of the focal length; at that size the lens is a pinhole "
            f"whose pupil cannot be resolved in float64 (and diffraction would dominate)",
            f"use stop_diameter_mm={MIN_STOP_FRACTION * abs(pdat.efl):.3g} or more, or render "
            f"with method='pinhole'")


# ----- phase 1: the film radii that have rays ---------------------------------------------

@dataclasses.dataclass(frozen=True)
class _FilmExtent:
    last_knot_mm: float                 # largest radius with rays: the last knot
    max_film_radius_mm: float           # film points beyond this are vignetted
    vignetted_beyond_mm: float | None   # None when rays leave the whole film
    axial_box: np.ndarray               # (4,) box of the passing grid points at r = 0
    end_box: np.ndarray | None          # (4,) the same at the last knot, when bisected


def _film_extent(pr: PupilProber, lens: LensPrescription, film_distance_mm: float,
                 hd: float) -> _FilmExtent:
    """The film radii with rays: the whole film, or up to a bisected vignetting cut-off."""
    _, found0, box0 = pr.interior(np.array([0.0]))
    if not found0[0]:
        raise OpticsError(f"{lens.source}: no ray from the film centre gets through the lens "
                          f"(film distance {film_distance_mm:g} mm)",
                          "check the stop ('f_number' / 'stop_diameter_mm') and the focus")
    _, found_edge, _ = pr.interior(np.array([hd]))
    if found_edge[0]:
        return _FilmExtent(hd, hd, None, box0[0], None)
    lo, hi, hint = 0.0, hd, box0[0]
    while hi - lo > 1e-6 * hd:
        mid = 0.5 * (lo + hi)
        _, f, b = pr.interior(np.array([mid]), hint=grow_boxes(hint))
        if f[0]:
            lo, hint = mid, b[0]
        else:
            hi = mid
    if lo <= 0:
        raise OpticsError(f"{lens.source}: rays get through only at the very film centre")
    return _FilmExtent(lo, hi, hi, box0[0], hint)


# ----- knots: exact boundaries in a frame that follows the region ---------------------------

@dataclasses.dataclass
class _Knot:
    c: float          # centre x (mm)
    sx: float         # half-width along x (mm)
    sy: float         # half-height through the centre (mm)
    rho: np.ndarray   # (2M + 1,) exact normalised boundary at vertex and mid-angles
    res: float        # bisection resolution (normalised)


class _KnotTracer:
    """The prober's exact boundaries, counted for the statistics and reported to
    the progress callback."""

    def __init__(self, prober: PupilProber, progress=None):
        self.prober = prober
        self.tick = progress or (lambda n: None)
        self.evaluations = 0

    def boundary(self, rs, cs, sxs, sys_, M: int, *, report: bool = True):
        out = self.prober.boundary(rs, cs, sxs, sys_, M)
        self.evaluations += len(rs)
        if report:
            self.tick(len(rs))
        return out

    def knots_at(self, rs, cs, sxs, sys_, M: int, first=None):
        """Exact boundaries at radii rs, then the frame is moved to the region: centre
        to the middle of its stretch of the x axis, s_x to its half-width there, s_y
        to its half-height through the centre (all from bisected boundary points, so
        smooth in r), and the boundary traced again (at most twice) if the frame
        moved by more than RENORMALISE.  Smooth frames make smooth rho_j(r).

        ``first``: the (rho, ok, res) of a trace already done in the given frame.
        Returns (c, s_x, s_y, rho (B, 2M + 1), res), one entry per radius.
        """
        pr = self.prober
        rs = np.asarray(rs, dtype=np.float64)
        cs, sxs, sys_ = (np.array(v, dtype=np.float64) for v in (cs, sxs, sys_))
        if first is None:
            rho, ok, res = self.boundary(rs, cs, sxs, sys_, M)
        else:
            rho, ok, res = (np.array(x) for x in first)
        bad = np.nonzero(~ok)[0]
        if bad.size:  # the centre guess is outside the region: grid search
            near = np.stack([cs[bad] - 3 * np.abs(sxs[bad]), cs[bad] + 3 * np.abs(sxs[bad]),
                             np.zeros(bad.size), 3 * np.abs(sys_[bad])], axis=1)
            cs[bad], found, bb = pr.interior(rs[bad], hint=near)
            sxs[bad] = np.where(found, 0.5 * (bb[:, 1] - bb[:, 0]), sxs[bad])
            sys_[bad] = np.where(found, bb[:, 3], sys_[bad])
            rho[bad], ok[bad], res[bad] = self.boundary(rs[bad], cs[bad], sxs[bad], sys_[bad],
                                                        M, report=False)
        for _ in range(2):
            c_new = cs + 0.5 * sxs * (rho[:, 0] - rho[:, -1])
            c_new = np.where(rs > 0, c_new, 0.0)  # on axis the region is centred
            sx_new = 0.5 * sxs * (rho[:, 0] + rho[:, -1])
            sy_new = sys_ * rho[:, M]
            moved = np.maximum.reduce([np.abs(c_new - cs) / np.maximum(sx_new, 1e-300),
                                       np.abs(sx_new / sxs - 1), np.abs(sy_new / sys_ - 1)])
            redo = np.nonzero(ok & (sx_new > 0) & (sy_new > 0) & (moved > RENORMALISE))[0]
            if not redo.size:
                break
            rho2, ok2, res2 = self.boundary(rs[redo], c_new[redo], sx_new[redo], sy_new[redo], M)
            take = redo[ok2]
            cs[take], sxs[take], sys_[take] = c_new[take], sx_new[take], sy_new[take]
            rho[take], res[take] = rho2[ok2], res2[ok2]
        rho[~ok] = 0.0
        return cs, sxs, sys_, rho, res


def _chord_extent(rho_grid: np.ndarray, M: int) -> np.ndarray:
    """Radial extent of the polygon at the 2M + 1 vertex and mid-angles (..., 2M + 1)."""
    a, b = rho_grid[..., :-1], rho_grid[..., 1:]
    h = 0.5 * math.pi / M
    s = a + b
    with np.errstate(invalid="ignore", divide="ignore"):
        mid = np.where(s > 0, 2.0 * a * b * math.cos(h) / np.where(s > 0, s, 1.0), 0.0)
    out = np.empty(rho_grid.shape[:-1] + (2 * M + 1,))
    out[..., 0::2] = rho_grid
    out[..., 1::2] = mid
    return out


def _area_error(exact: np.ndarray, approx: np.ndarray) -> float:
    """Area between two star curves sampled at the same evenly spaced angles over
    [0, pi] (trapezoid rule), relative to the area inside ``exact``.  Affine maps
    keep the ratio, so it may be computed in the normalised frame."""
    w = np.ones(exact.shape[-1])
    w[0] = w[-1] = 0.5
    ref = float(np.sum(w * exact * exact))
    diff = float(np.sum(w * np.abs(exact * exact - approx * approx)))
    if ref <= 0:
        return 0.0 if diff <= 0 else math.inf
    return diff / ref


def _interp(knots: dict, r: float):
    """(c, sx, sy, rho_grid) linearly interpolated between the knots around r."""
    rs = sorted(knots)
    k = int(np.clip(np.searchsorted(rs, r, side="right") - 1, 0, len(rs) - 2))
    a, b = knots[rs[k]], knots[rs[k + 1]]
    t = (r - rs[k]) / (rs[k + 1] - rs[k])
    lerp = lambda x, y: (1 - t) * x + t * y  # noqa: E731
    return lerp(a.c, b.c), lerp(a.sx, b.sx), lerp(a.sy, b.sy), lerp(a.rho[0::2], b.rho[0::2])


# ----- phase 2: initial knots and the angle count M ------------------------------------------

def _initial_knots(tracer: _KnotTracer, extent: _FilmExtent, initial_knots: int,
                   tolerance: float, n_angles: int | None) -> tuple[int, dict, float]:
    """Evenly spaced knots over the film radii with rays, and M: doubled from 16 until
    the chords' area error at these knots is at most tolerance / 4 (or ``n_angles``).

    Returns (M, {radius: _Knot}, the chords' largest area error)."""
    pr = tracer.prober
    r0 = np.linspace(0.0, extent.last_knot_mm, max(2, int(initial_knots)))
    hints = np.repeat(grow_boxes(extent.axial_box), len(r0), axis=0)
    if extent.end_box is not None:
        hints[-1] = grow_boxes(extent.end_box)[0]
    c_g, found_g, bb = pr.interior(r0, hint=hints)
    c_g[0] = 0.0
    sx_g = np.where(found_g, 0.5 * (bb[:, 1] - bb[:, 0]), 1.0)
    sy_g = np.where(found_g, bb[:, 3], 1.0)
    M_choices = [int(n_angles)] if n_angles else [16, 32, 64, 128]
    # The knot where the pupil vanishes (vignetting) is a degenerate sliver: left out.
    n_measured = len(r0) - (extent.vignetted_beyond_mm is not None)
    for M in M_choices:
        c0, sx0, sy0, rho0, res0 = tracer.knots_at(r0, c_g, sx_g, sy_g, M)
        # Area between the chords and the exact boundary (corners, where chords cut
        # most, also get a local dilation for conservativeness).
        ang_err = max(_area_error(rho0[i], _chord_extent(rho0[i, 0::2], M))
                      for i in range(n_measured))
        if ang_err <= 0.25 * tolerance:
            break
        c_g, sx_g, sy_g = c0, sx0, sy0
    knots = {float(r): _Knot(float(c), float(a), float(b), rho, float(res))
             for r, c, a, b, rho, res in zip(r0, c0, sx0, sy0, rho0, res0)}
    return M, knots, ang_err


# ----- phase 3: radial refinement ----------------------------------------------------------

def _refine_knots(tracer: _KnotTracer, knots: dict, M: int, tolerance: float,
                  min_w: float) -> tuple[dict, float]:
    """Split every interval whose midpoint error exceeds ``tolerance``; ``knots`` grows
    in place.  Returns ({(a, b): shortfall (2M + 1,) at the accepted interval's
    midpoint}, the largest accepted error)."""
    checks: dict[tuple[float, float], np.ndarray] = {}
    radii = sorted(knots)
    pending = list(zip(radii[:-1], radii[1:]))
    max_err_accepted = 0.0
    while pending:
        mids = np.array([0.5 * (a + b) for a, b in pending])
        frames = [_interp(knots, m) for m in mids]
        cm, sxm, sym = (np.array([f[i] for f in frames]) for i in range(3))
        rho_m, ok_m, res_m = tracer.boundary(mids, cm, sxm, sym, M)
        nxt, new = [], []
        for i, (a, b) in enumerate(pending):
            splittable = (b - a) > 2 * min_w
            if ok_m[i]:
                approx = _chord_extent(frames[i][3], M)
                # Radial interpolation error, at the vertex angles (the chords' own
                # error is the angular part, set by M and not reduced by splitting).
                err = _area_error(rho_m[i, 0::2], frames[i][3])
                if err <= tolerance or not splittable or len(knots) >= MAX_KNOTS:
                    checks[(a, b)] = rho_m[i] - approx  # the shortfall where > 0
                    max_err_accepted = max(max_err_accepted, err)
                    continue
            # Split: the midpoint becomes a knot (the check trace is its first pass).
            # A short interval whose interpolated centre lies outside the region also
            # gets its midpoint as a knot, without further checks.
            new.append(i)
            if splittable:
                nxt += [(a, float(mids[i])), (float(mids[i]), b)]
        if new:
            new = np.array(new)
            cs, sxs, sys_, rho_n, res_n = tracer.knots_at(
                mids[new], cm[new], sxm[new], sym[new], M,
                first=(rho_m[new], ok_m[new], res_m[new]))
            for m, c, a, b, rho_i, res_i in zip(mids[new], cs, sxs, sys_, rho_n, res_n):
                knots[float(m)] = _Knot(float(c), float(a), float(b), rho_i, float(res_i))
        pending = nxt
    return checks, max_err_accepted


# ----- phase 4: conservative dilation -------------------------------------------------------

def _dilate(knots: dict, checks: dict, M: int, safety_margin: float):
    """Vertices moved out by the measured shortfalls plus the safety margin (normalised
    units).  Returns (radii (K,), knots in order, dilated rho (K, M + 1), mean dilation)."""
    rs = np.array(sorted(knots))
    ks = [knots[r] for r in rs]
    exact = np.array([k.rho for k in ks])          # (K, 2M + 1)
    rho = exact[:, 0::2].copy()
    inv_cos = 1.0 / math.cos(0.5 * math.pi / M)
    dil = np.zeros_like(rho)

    def push(d, short):
        """Raise vertex distances d (M + 1) to cover shortfalls at the 2M + 1 angles."""
        s = np.maximum(short, 0.0)
        d = np.maximum(d, s[0::2])
        mid = s[1::2] * inv_cos
        d[:-1] = np.maximum(d[:-1], mid)
        d[1:] = np.maximum(d[1:], mid)
        return d

    for k in range(len(rs)):
        dil[k] = push(dil[k], exact[k] - _chord_extent(rho[k], M))
    idx = {r: k for k, r in enumerate(rs)}
    for (a, b), short in checks.items():
        for r in (a, b):
            dil[idx[r]] = push(dil[idx[r]], 2.0 * short)
    margin = safety_margin + 2.0 * np.array([k.res for k in ks])
    rho = np.where(rho > 0, rho + dil + margin[:, None], 0.0)
    return rs, ks, rho, float(np.mean(dil + margin[:, None]))


# ----- phase 5: the on-axis irradiance -------------------------------------------------------

def _axial_irradiance_factor(axial: _Knot, M: int, zp: float) -> float:
    """Exact E/L at the film centre from the undilated boundary at r = 0:
    E/L = integral over angles of P^2 / (2 (z^2 + P^2)), P the boundary distance."""
    th = np.arange(2 * M + 1) * (math.pi / (2 * M))
    P = axial.rho * np.hypot(axial.sx * np.cos(th), axial.sy * np.sin(th))
    f_ax = 0.5 * P * P / (zp * zp + P * P)
    return 2.0 * float(np.sum(0.5 * (f_ax[1:] + f_ax[:-1])) * (math.pi / (2 * M)))
