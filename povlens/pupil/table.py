"""Exit-pupil sample tables: where rays from a film point get through the lens.

Frames are those of :mod:`povlens.frames` (camera frame, mm, film at z = 0,
lens toward +z).  Everything here relies on the lens being rotationally
symmetric about the axis (as pbrt does): the region for a film point at radius
r and azimuth phi is the region for the film point (r, 0) rotated by phi, and
that region is symmetric about the x axis.

Sampling plane
--------------
Rays from a film point are parameterised by where they cross a plane z = z_p
perpendicular to the axis.  povlens uses the **paraxial exit-pupil plane**
(``z_p = film_distance - exit_pupil_position``), pbrt the rear-vertex plane.
Seen from one film point, the pass regions on any two such planes are the
same figure scaled about the film point's foot (the central projection between
parallel planes is a homothety), so the normalised description below is the
same on every plane -- the benchmark (``benchmarks/bench_pupil.py``) shows the
same knots and pass fractions on both -- and the estimate is the same: with
cos(theta) = d_z of the unit ray direction and dA an area on the plane, the
solid angle is cos^3(theta) dA / z_p^2, so

    E(p) / L = integral over the pass region of cos^4(theta) / z_p^2 dA

(pbrt's camera-measurement equation, ``realistic-camera.md`` §5.4, with the
rear-vertex distance replaced by z_p).  What the exit-pupil plane adds: there
the stop's image is, to first order, the same disc centred on the axis for
every film point, so the region's frame (centre, half-width, half-height)
barely moves with film radius (on the rear-vertex plane it slides by
r (1 - z_rear / z_p)); a fixed-domain sampler, a pbrt-style box or a bounding
disc would be tightest there, and ``pupil_point`` is where the ray crosses the
exit pupil, which makes plots and aperture shapes readable.  When the exit
pupil lies at or behind the film (z_p < film_distance / 4; never for the
shipped lenses) the rear-vertex plane is used.

Shape description
-----------------
For the film point (r, 0) the pass region R(r) on the plane (the intersection
of the images of the stop and of the element rims: a cat's eye off axis) is
described in a normalised frame that follows it: centre (c(r), 0) on the x
axis in the middle of the region's stretch of that axis, half-width s_x(r)
along x and half-height s_y(r) through the centre.  In that frame the region
is a polygon star-shaped about the origin: vertices at the fixed angles
t_j = j pi / M, j = 0..M, at normalised distances rho_j(r), mirrored to the
lower half (2M vertices in all); on the plane a vertex is
(c + s_x rho_j cos t_j, +-s_y rho_j sin t_j).  The frame keeps the polygon
well conditioned when the region becomes a thin sliver (the fisheye near its
vignetting cut-off).  At knot radii r_k the exact boundary is found with the
exact tracer: along each direction, rays at 32 steps out to the edge of a disc
that provably holds every ray that can pass (the rear element's clear aperture
projected onto the plane), the outermost passing one kept and the crossing
bisected to 2e-5 of its distance.  The frame comes from bisected boundary
points (so it is smooth in r), and a knot is traced again in its own frame when
the frame it was traced in differs by more than 0.2 %.  Between knots, c, s_x,
s_y and every rho_j are interpolated linearly in r, so the region, its area and
the sample map are continuous in r: no rings can appear.

The boundary is the outermost crossing along each direction, which is exact for
star-shaped regions (those of every shipped lens, at every radius probed).  A
region that is not (horns, holes: the F/1 singlet stopped to F/2 far off axis)
is detected -- a blocked probe followed by a passing one -- and reported in
``stats["non_star_shaped_radii"]``; thin features between probe rays can then
be missed.

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

Sampling
--------
A point u in [0, 1)^2 is mapped into the polygon by an area-preserving map:
u_1 picks the upper or lower half (tent map, continuous at u_1 = 1/2) and,
through the area CDF of the fan of triangles (centre, V_j, V_j+1), a triangle
and a fraction v along its outer edge; the point is centre + sqrt(u_2) ((1 - v)
V_j + v V_j+1), which is uniform in the triangle.  The pdf is therefore exactly
1 / area.  Per sample, the fan's CDF at the sample's film radius is a quadratic
in the interpolation weight of three per-interval cumulative sums, searched by
vectorized bisection (no per-ray Python loop, O(log M) per sample).

Vignetting
----------
If no ray from the film edge gets through, the largest film radius with rays
is found by bisection (to 1e-6 of the half-diagonal); the last knot sits there.
Film points beyond it are reported vignetted: ``valid`` False, weight 0, pdf 0.
(Within about a micrometre of that cut-off, where the pupil's area is 1e-5 of
the axial one, the pass fraction falls below 95 %; the table stays
conservative.)

Files
-----
``save`` writes an ``.npz`` (atomically: temporary file, then rename) holding
the knots, the lens prescription and a JSON metadata string (lens hash, stop,
film distance, focus, film, tolerance, plane).  :func:`load_if_current`
returns a saved table only when its inputs match.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from povlens.errors import OpticsError, PovlensError, UsageError
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import LensPrescription, sag_mm
from povlens.lens.tracer import trace_from_film

__all__ = ["LensSample", "PupilTable", "build_pupil_table", "sampling_plane_z_mm",
           "load", "load_if_current", "DEFAULT_TOLERANCE", "SAFETY_MARGIN", "plot_pupil_shapes"]

FORMAT_NAME = "povlens-pupil-table"
FORMAT_VERSION = 1
#: Default relative area tolerance of the region description (module docstring).
DEFAULT_TOLERANCE = 0.005
#: Extra outward margin, as a fraction of the region's mean radius.
SAFETY_MARGIN = 0.001
#: Radial samples per angle before the bisection; the bisection's relative precision.
RADIAL_SAMPLES = 32
BISECTION_RELATIVE = 2e-5
MAX_BISECTION_STEPS = 60
#: Re-trace a knot when its region's frame (centre, half-width, half-height) is this
#: far (relative) from the frame used for the trace.
RENORMALISE = 0.002
#: Refinement stops adding knots beyond this many (pathological pupils, see stats).
MAX_KNOTS = 128
#: Rays per call of the tracer (bounds memory).
_TRACE_CHUNK = 1 << 18
#: Film points no further than this fraction beyond the table's range still count as inside.
_RANGE_SLACK = 1e-9


@dataclasses.dataclass(frozen=True)
class LensSample:
    """Rays proposed by a lens sampler for n film points (camera frame, mm).

    film_point : (n, 3) ray origins on the film (z = 0).
    pupil_point : (n, 3) where the ray crosses the sampling plane (may lie inside
        the lens: it only fixes the direction; trace from ``film_point``).
    direction : (n, 3) unit vectors from film_point toward pupil_point.
    pdf_per_mm2 : (n,) density of pupil_point on the sampling plane (0 if not valid).
    weight : (n,) cos^4(theta) / z_p^2 / pdf, the radiometric weight of a ray that
        gets through (multiply by the trace's ``passed``); 0 where not valid.
    valid : (n,) False where the film point is vignetted (no ray gets through) or
        outside the film the sampler was built for.
    """

    film_point: np.ndarray
    pupil_point: np.ndarray
    direction: np.ndarray
    pdf_per_mm2: np.ndarray
    weight: np.ndarray
    valid: np.ndarray

    def __len__(self) -> int:
        return int(self.valid.shape[0])


def finish_sample(film_xy: np.ndarray, px: np.ndarray, py: np.ndarray, plane_z_mm: float,
                  area_mm2: np.ndarray, valid: np.ndarray) -> LensSample:
    """Directions, pdf and weights of rays from film points to plane points (shared by
    the table and the baselines).  Invalid entries get a +z ray, pdf 0 and weight 0
    (film points that are not finite become the film centre: no NaN comes out)."""
    n = film_xy.shape[0]
    finite = np.all(np.isfinite(film_xy), axis=1)
    valid = valid & finite & (area_mm2 > 0) & np.isfinite(px) & np.isfinite(py)
    px = np.where(valid, px, np.where(finite, film_xy[:, 0], 0.0))
    py = np.where(valid, py, np.where(finite, film_xy[:, 1], 0.0))
    film = np.zeros((n, 3))
    film[:, :2] = np.where(finite[:, None], film_xy, 0.0)
    pupil = np.empty((n, 3))
    pupil[:, 0], pupil[:, 1], pupil[:, 2] = px, py, plane_z_mm
    d = pupil - film
    norm = np.sqrt(np.einsum("ij,ij->i", d, d))
    d /= norm[:, None]
    cos = d[:, 2]
    area = np.where(valid, area_mm2, 0.0)
    weight = np.where(valid, cos ** 4 / (plane_z_mm * plane_z_mm) * area, 0.0)
    pdf = np.where(valid, 1.0 / np.where(valid, area, 1.0), 0.0)
    return LensSample(film, pupil, d, pdf, weight, valid)


def _check_sample_args(film_xy, u) -> tuple[np.ndarray, np.ndarray]:
    f = np.asarray(film_xy, dtype=np.float64).reshape(-1, 2)
    uu = np.asarray(u, dtype=np.float64).reshape(-1, 2)
    if f.shape != uu.shape:
        raise ValueError(f"film_xy {f.shape} and u {uu.shape} must both be (n, 2)")
    return f, np.clip(uu, 0.0, np.nextafter(1.0, 0.0))


def _polar(film_xy: np.ndarray):
    r = np.hypot(film_xy[:, 0], film_xy[:, 1])
    ok = (r > 0) & np.isfinite(r)
    safe = np.where(ok, r, 1.0)
    with np.errstate(invalid="ignore"):
        cos_phi = np.where(ok, film_xy[:, 0] / safe, 1.0)
        sin_phi = np.where(ok, film_xy[:, 1] / safe, 0.0)
    return r, cos_phi, sin_phi


def sampling_plane_z_mm(lens: LensPrescription, film_distance_mm: float,
                        plane: str = "exit-pupil") -> tuple[float, str]:
    """z of the sampling plane (camera frame, mm) and the plane actually used.

    ``plane`` is "exit-pupil" (default; falls back to "rear-vertex" when the
    paraxial exit pupil lies closer to the film than a quarter of the film
    distance, or behind it) or "rear-vertex".
    """
    if plane == "rear-vertex":
        return float(film_distance_mm), "rear-vertex"
    if plane != "exit-pupil":
        raise UsageError(f"--plane {plane}: unknown sampling plane",
                         "use exit-pupil or rear-vertex")
    p = paraxial_data(lens)
    z = film_distance_mm - p.exit_pupil_position
    if not math.isfinite(z) or z < 0.25 * film_distance_mm:
        return float(film_distance_mm), "rear-vertex"
    return float(z), "exit-pupil"


#: Smallest stop diameter, as a fraction of the focal length, a table is built for.
MIN_STOP_FRACTION = 1e-4


# ----- exact boundary probing ----------------------------------------------------------

class _Prober:
    """Traces probe rays from film points (r, 0, 0) to points of the sampling plane."""

    def __init__(self, lens: LensPrescription, film_distance_mm: float, plane_z_mm: float):
        self.lens = lens
        self.film_distance_mm = float(film_distance_mm)
        self.zp = float(plane_z_mm)
        self.rays = 0
        self.non_star_radii: set[float] = set()
        rr = float(lens.aperture_radius_mm[-1])
        s = float(sag_mm(lens.curvature_per_mm[-1], np.array(rr)))
        z_a, z_b = self.film_distance_mm, self.film_distance_mm - s
        self.z_range = (min(z_a, z_b), max(z_a, z_b))
        self.rear_radius = rr

    def domain(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A disc (centre x, radius) on the plane holding every ray from (r, 0, 0) that
        meets the rear surface inside its clear aperture (every ray that can pass)."""
        r = np.atleast_1d(np.asarray(r, dtype=np.float64))
        lam = np.array([self.zp / self.z_range[1], self.zp / self.z_range[0]])
        c = r[:, None] * (1.0 - lam[None, :])              # centres of the extreme discs
        rad = self.rear_radius * lam                        # their radii
        cx = 0.5 * (c[:, 0] + c[:, 1])
        R = 0.5 * np.abs(c[:, 1] - c[:, 0]) + rad.max()
        return cx, R * (1.0 + 1e-9) + 1e-9

    def passes(self, r, px, py) -> np.ndarray:
        """Whether the rays from (r, 0, 0) through plane points (px, py) get through."""
        shape = np.broadcast_shapes(np.shape(r), np.shape(px), np.shape(py))
        r_b = np.broadcast_to(r, shape).ravel()
        x_b = np.broadcast_to(px, shape).ravel()
        y_b = np.broadcast_to(py, shape).ravel()
        n = r_b.size
        out = np.zeros(n, bool)
        for a in range(0, n, _TRACE_CHUNK):  # bounded memory
            b = min(a + _TRACE_CHUNK, n)
            o = np.zeros((b - a, 3))
            o[:, 0] = r_b[a:b]
            d = np.empty((b - a, 3))
            d[:, 0] = x_b[a:b] - r_b[a:b]
            d[:, 1] = y_b[a:b]
            d[:, 2] = self.zp
            out[a:b] = trace_from_film(self.lens, self.film_distance_mm, o, d).passed
        self.rays += n
        return out.reshape(shape)

    def interior(self, r, hint: np.ndarray | None = None, grid: int = 32):
        """A point (cx, 0) inside the pass region for each radius, from a coarse grid.

        hint : (B, 4) boxes (x0, x1, y0, y1) searched when the coarse grid over the
        whole domain finds nothing (small regions).  Returns (cx (B,), found (B,),
        bbox (B, 4) of the passing grid points, padded by a cell).
        """
        r = np.atleast_1d(np.asarray(r, dtype=np.float64))
        B = r.size
        dcx, dR = self.domain(r)
        g = (np.arange(grid) + 0.5) / grid * 2.0 - 1.0
        gy = (np.arange(grid // 2) + 0.5) / (grid // 2)
        X = np.broadcast_to(dcx[:, None, None] + dR[:, None, None] * g[None, None, :],
                            (B, grid // 2, grid))
        Y = np.broadcast_to(dR[:, None, None] * gy[None, :, None], (B, grid // 2, grid))
        ok = self.passes(r[:, None, None], X, Y)
        cx = np.zeros(B)
        found = ok.any(axis=(1, 2))
        bbox = np.zeros((B, 4))
        for b in np.nonzero(found)[0]:
            cx[b], bbox[b] = self._centre(r[b], X[b][ok[b]], Y[b][ok[b]],
                                          2.0 * dR[b] / grid, dR[b] / (grid // 2))
        if hint is not None and not found.all():
            miss = np.nonzero(~found)[0]
            h = np.asarray(hint, dtype=np.float64)[miss]
            gx = (np.arange(grid) + 0.5) / grid
            Xh = np.broadcast_to(h[:, 0, None, None]
                                 + (h[:, 1] - h[:, 0])[:, None, None] * gx[None, None, :],
                                 (miss.size, grid, grid))
            Yh = np.broadcast_to(np.maximum(h[:, 3], 0.0)[:, None, None] * gx[None, :, None],
                                 (miss.size, grid, grid))
            okh = self.passes(r[miss, None, None], Xh, Yh)
            for k, b in enumerate(miss):
                if okh[k].any():
                    found[b] = True
                    cx[b], bbox[b] = self._centre(r[b], Xh[k][okh[k]], Yh[k][okh[k]],
                                                  (h[k, 1] - h[k, 0]) / grid,
                                                  max(h[k, 3], 0.0) / grid)
        if not found.all():
            # Small pass regions (a stopped-down lens) slip between the grid points:
            # seed them with the real chief ray, which crosses the centre of the stop.
            from povlens.thinlens.model import chief_ray_aim_mm
            miss = np.nonzero(~found)[0]
            x_rear, ok_aim = chief_ray_aim_mm(self.lens, self.film_distance_mm, r[miss])
            self.rays += 42 * miss.size
            aim = r[miss] + (x_rear - r[miss]) * self.zp / self.film_distance_mm
            ok = ok_aim & self.passes(r[miss], aim, np.zeros(miss.size))
            for k in np.nonzero(ok)[0]:
                b = miss[k]
                found[b] = True
                cell = 1e-6 * max(1.0, dR[b])
                cx[b], bbox[b] = self._centre(r[b], aim[k:k + 1], np.zeros(1), cell, cell)
        return cx, found, bbox

    def _centre(self, r, xs, ys, cell_x, cell_y):
        """A centre on the x axis from passing grid points (their centroid, checked)."""
        bbox = np.array([xs.min() - cell_x, xs.max() + cell_x, 0.0, ys.max() + cell_y])
        cands = np.concatenate([[xs.mean()], np.linspace(xs.min(), xs.max(), 15)])
        ok = self.passes(np.array(r), cands, np.zeros_like(cands))
        if ok[0]:
            return cands[0], bbox
        if ok.any():
            good = cands[ok]
            return 0.5 * (good.min() + good.max()), bbox
        return xs[np.argmin(ys)], bbox

    def boundary(self, r, cx, sx, sy, M: int):
        """Exact boundary in the normalised frame of (cx, sx, sy); see :meth:`_boundary`.
        Radii are processed in groups so that memory stays bounded."""
        r = np.atleast_1d(np.asarray(r, dtype=np.float64))
        cx, sx, sy = (np.broadcast_to(np.asarray(v, dtype=np.float64), r.shape)
                      for v in (cx, sx, sy))
        group = max(1, (1 << 20) // ((2 * M + 1) * RADIAL_SAMPLES))
        if r.size <= group:
            return self._boundary(r, cx, sx, sy, M)
        parts = [self._boundary(r[i:i + group], cx[i:i + group], sx[i:i + group],
                                sy[i:i + group], M) for i in range(0, r.size, group)]
        return tuple(np.concatenate([p[k] for p in parts]) for k in range(3))

    def _boundary(self, r, cx, sx, sy, M: int):
        """Exact boundary in the normalised frame of (cx, sx, sy).

        Along the 2M + 1 directions (sx cos t, sy sin t), t = k pi / (2M), finds
        the largest rho such that (cx + rho sx cos t, rho sy sin t) lets a ray
        through: rays at 32 steps out to the domain edge, the outermost passing one
        kept, then bisection.  Returns rho (B, 2M + 1) (the outer end of the
        bracket, so a little outside), centre_ok (B,) and the bracket width (B,)
        (in the same normalised units).
        """
        r = np.atleast_1d(np.asarray(r, dtype=np.float64))
        cx, sx, sy = (np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in (cx, sx, sy))
        theta = np.arange(2 * M + 1) * (math.pi / (2 * M))
        ux = sx[:, None] * np.cos(theta)[None, :]
        uy = sy[:, None] * np.sin(theta)[None, :]
        dcx, dR = self.domain(r)
        # Parameter of the domain circle along each direction.
        ox = (cx - dcx)[:, None]
        qa = ux * ux + uy * uy
        qb = ox * ux
        qc = ox * ox - (dR * dR)[:, None]
        rmax = (-qb + np.sqrt(np.maximum(qb * qb - qa * qc, 0.0))) / qa
        rmax = np.maximum(rmax, 1e-12)
        K = RADIAL_SAMPLES
        frac = np.arange(1, K + 1) / K
        s = rmax[..., None] * frac
        ok = self.passes(r[:, None, None], cx[:, None, None] + s * ux[..., None], s * uy[..., None])
        centre_ok = self.passes(r, cx, np.zeros_like(cx))
        anyp = ok.any(axis=2)
        last = np.where(anyp, K - 1 - np.argmax(ok[..., ::-1], axis=2), -1)
        # A blocked sample followed by a passing one: the region is not star-shaped
        # about the centre (holes, horns); the outermost crossing is kept, and the
        # film radius is recorded so that the build can say so.
        reentry = np.any(~ok[..., :-1] & ok[..., 1:], axis=2) & centre_ok[:, None]
        self.non_star_radii.update(float(x) for x in r[reentry.any(axis=1)])
        lo = np.where(last >= 0, rmax * (last + 1) / K, 0.0)
        hi = np.where(last >= K - 1, rmax, rmax * (last + 2) / K)
        hi = np.where(last >= K - 1, rmax, hi)
        rr = np.broadcast_to(r[:, None], hi.shape)
        cc = np.broadcast_to(cx[:, None], hi.shape)
        for _ in range(MAX_BISECTION_STEPS):
            # Bisect until the bracket is small relative to the boundary distance
            # itself, so tiny regions (near a vignetting cut-off) are resolved too.
            open_ = (hi - lo > BISECTION_RELATIVE * hi) & (last < K - 1)
            if not open_.any():
                break
            mid = 0.5 * (lo[open_] + hi[open_])
            okm = self.passes(rr[open_], cc[open_] + mid * ux[open_], mid * uy[open_])
            lo[open_] = np.where(okm, mid, lo[open_])
            hi[open_] = np.where(okm, hi[open_], mid)
        return hi, centre_ok, np.max(hi - lo, axis=1)


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


# ----- the table --------------------------------------------------------------------

class SamplerMeasurements:
    """Pass fraction and irradiance estimates shared by every lens sampler."""

    lens: LensPrescription
    film_distance_mm: float

    def pass_fraction(self, film_radius_mm, *, n_samples: int = 1024, seed: int = 0):
        """:class:`povlens.sampling.PassFraction` of this sampler at each film radius."""
        from povlens.pupil.sampling import pass_fraction
        return pass_fraction(self, self.lens, self.film_distance_mm, film_radius_mm,
                             n_samples=n_samples, seed=seed)

    def irradiance_factor(self, film_radius_mm, *, n_samples: int = 4096, seed: int = 0):
        """Estimated E/L at each film radius (:func:`povlens.sampling.irradiance_factor`).

        Remembered per sampler for the radii, sample count and seed (a sampler does
        not change once built): an auto conversion asks for the same radii twice,
        for the plan's model error and again at the depth probe's depths (the
        relative illumination does not depend on depth), ~0.03 s each."""
        from povlens.pupil.sampling import irradiance_factor
        radii = np.atleast_1d(np.asarray(film_radius_mm, dtype=np.float64))
        key = (radii.tobytes(), int(n_samples), int(seed))
        cache = self.__dict__.setdefault("_irradiance_factor_cache", {})
        if key not in cache:
            cache[key] = irradiance_factor(self, self.lens, self.film_distance_mm, radii,
                                           n_samples=n_samples, seed=seed)
        return cache[key].copy()


class PupilTable(SamplerMeasurements):
    """Exit-pupil regions over film radius for one lens, stop, focus and film.

    The region for the film point (r, 0) is the polygon with vertices
    ``(c + s_x rho_j cos t_j, +-s_y rho_j sin t_j)``, t_j = j pi / M, with c, s_x,
    s_y and every rho_j linear in r between knots.

    Attributes (arrays float64):
    film_radius_mm : (K,) knot radii, increasing, the first 0.
    centre_x_mm : (K,) region centres on the rotated x axis (c).
    scale_x_mm, scale_y_mm : (K,) the region's half-width along x and half-height
        through the centre (s_x, s_y): the normalised frame.
    rho : (K, M + 1) normalised vertex distances (dilated: conservative).
    max_film_radius_mm : film points beyond this are vignetted.
    vignetted_beyond_mm : radius beyond which no ray gets through, or None when
        rays leave the whole film.
    plane_z_mm, plane : the sampling plane.
    axial_irradiance_factor : E/L at the film centre from the exact boundary.
    stats : build statistics (time, rays traced, errors).
    metadata : JSON-able dict saved with the table.
    """

    def __init__(self, lens: LensPrescription, film_distance_mm: float,
                 film_half_diagonal_mm: float, plane_z_mm: float, plane: str,
                 film_radius_mm, centre_x_mm, scale_x_mm, scale_y_mm, rho,
                 max_film_radius_mm: float, vignetted_beyond_mm: float | None,
                 tolerance: float, axial_irradiance_factor: float,
                 stats: dict | None = None, metadata: dict | None = None):
        self.lens = lens
        self.film_distance_mm = float(film_distance_mm)
        self.film_half_diagonal_mm = float(film_half_diagonal_mm)
        self.plane_z_mm = float(plane_z_mm)
        self.plane = plane
        self.film_radius_mm = np.asarray(film_radius_mm, dtype=np.float64)
        self.centre_x_mm = np.asarray(centre_x_mm, dtype=np.float64)
        self.scale_x_mm = np.asarray(scale_x_mm, dtype=np.float64)
        self.scale_y_mm = np.asarray(scale_y_mm, dtype=np.float64)
        self.rho = np.asarray(rho, dtype=np.float64)
        self.max_film_radius_mm = float(max_film_radius_mm)
        self.vignetted_beyond_mm = (None if vignetted_beyond_mm is None
                                    else float(vignetted_beyond_mm))
        self.tolerance = float(tolerance)
        self.axial_irradiance_factor = float(axial_irradiance_factor)
        self.stats = dict(stats or {})
        self.metadata = dict(metadata or {})
        K = self.film_radius_mm.size
        if (K < 2 or self.rho.ndim != 2 or self.rho.shape[0] != K or self.rho.shape[1] < 3
                or any(a.shape != (K,) for a in (self.centre_x_mm, self.scale_x_mm,
                                                   self.scale_y_mm))
                or not np.all(np.diff(self.film_radius_mm) > 0)
                or not all(np.all(np.isfinite(a)) for a in (self.centre_x_mm, self.scale_x_mm,
                                                             self.scale_y_mm, self.rho))):
            raise ValueError("a pupil table needs at least two increasing knots with "
                             "matching finite arrays")
        self._prepare()

    # -- derived arrays for sampling
    def _prepare(self) -> None:
        M = self.n_angles
        self._h = math.pi / M
        theta = np.arange(M + 1) * self._h
        self._cos_t, self._sin_t = np.cos(theta), np.sin(theta)
        a, b = self.rho[:-1], self.rho[1:]
        z = np.zeros((a.shape[0], 1))
        # Fan-of-triangles CDF, a quadratic in the interpolation weight t:
        # rho_j rho_j+1 = (1-t)^2 a_j a_j+1 + t (1-t) (a_j b_j+1 + b_j a_j+1) + t^2 b_j b_j+1.
        self._Caa = np.concatenate([z, np.cumsum(a[:, :-1] * a[:, 1:], axis=1)], axis=1)
        self._Cab = np.concatenate([z, np.cumsum(a[:, :-1] * b[:, 1:] + b[:, :-1] * a[:, 1:],
                                                 axis=1)], axis=1)
        self._Cbb = np.concatenate([z, np.cumsum(b[:, :-1] * b[:, 1:], axis=1)], axis=1)

    @property
    def n_knots(self) -> int:
        return int(self.film_radius_mm.size)

    @property
    def n_angles(self) -> int:
        """M: angular intervals on the half plane (the polygon has 2M vertices)."""
        return int(self.rho.shape[1] - 1)

    def _locate(self, r: np.ndarray):
        knots = self.film_radius_mm
        k = np.clip(np.searchsorted(knots, r, side="right") - 1, 0, knots.size - 2)
        with np.errstate(invalid="ignore"):
            t = np.clip((r - knots[k]) / (knots[k + 1] - knots[k]), 0.0, 1.0)
        t = np.where(np.isfinite(t), t, 0.0)
        inside = np.isfinite(r) & (r <= self.max_film_radius_mm * (1 + _RANGE_SLACK)
                                   + _RANGE_SLACK)
        return k, t, inside

    def _frame(self, k, t):
        lerp = lambda a: (1 - t) * a[k] + t * a[k + 1]  # noqa: E731
        return lerp(self.centre_x_mm), lerp(self.scale_x_mm), lerp(self.scale_y_mm)

    def _normalised_total(self, k, t):
        M = self.n_angles
        return ((1 - t) ** 2 * self._Caa[k, M] + t * (1 - t) * self._Cab[k, M]
                + t * t * self._Cbb[k, M])

    def area_mm2(self, film_radius_mm) -> np.ndarray:
        """Area (mm^2) of the sampled region at each film radius; 0 where vignetted."""
        r = np.atleast_1d(np.asarray(film_radius_mm, dtype=np.float64))
        k, t, inside = self._locate(r)
        _, sx, sy = self._frame(k, t)
        area = math.sin(self._h) * sx * sy * self._normalised_total(k, t)
        return np.where(inside, area, 0.0)

    def is_vignetted(self, film_radius_mm) -> np.ndarray:
        """True where no ray from a film point at this radius gets through."""
        return ~(self.area_mm2(film_radius_mm) > 0)

    def _rho_at(self, r: float):
        k, t, inside = self._locate(np.array([float(r)]))
        c, sx, sy = (float(v[0]) for v in self._frame(k, t))
        rho = (1 - t[0]) * self.rho[k[0]] + t[0] * self.rho[k[0] + 1]
        return bool(inside[0]), c, sx, sy, rho

    def region(self, film_radius_mm: float) -> np.ndarray:
        """The polygon (2M, 2) on the plane for the film point (r, 0), counter-clockwise;
        empty (0, 2) where vignetted."""
        inside, c, sx, sy, rho = self._rho_at(film_radius_mm)
        if not inside or not np.any(rho > 0):
            return np.zeros((0, 2))
        up = np.stack([c + sx * rho * self._cos_t, sy * rho * self._sin_t], axis=1)
        low = up[-2:0:-1] * np.array([1.0, -1.0])
        return np.concatenate([up, low])

    def contains(self, film_radius_mm: float, points_xy) -> np.ndarray:
        """Whether plane points (n, 2) (rotated frame: film point on +x) lie in the
        table's region for film radius ``film_radius_mm``."""
        pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
        inside, c, sx, sy, rho = self._rho_at(film_radius_mm)
        if not inside or not (sx > 0 and sy > 0):
            return np.zeros(len(pts), bool)
        M, h = self.n_angles, self._h
        dx, dy = (pts[:, 0] - c) / sx, np.abs(pts[:, 1]) / sy
        dist = np.hypot(dx, dy)
        theta = np.arctan2(dy, dx)
        j = np.clip(np.floor(theta / h).astype(np.int64), 0, M - 1)
        phi = theta - j * h
        a, b = rho[j], rho[j + 1]
        den = a * np.sin(phi) + b * np.sin(h - phi)
        with np.errstate(invalid="ignore", divide="ignore"):
            extent = np.where(den > 0, a * b * math.sin(h) / np.where(den > 0, den, 1.0), 0.0)
        return dist <= extent

    def sample(self, film_xy, u) -> LensSample:
        """Rays for film points ``film_xy`` (n, 2) mm and points ``u`` (n, 2) in [0, 1).

        The pupil point is uniform in the table's region (pdf = 1 / area); the
        map from u is continuous in u and in the film point, and area-preserving.
        """
        f, uu = _check_sample_args(film_xy, u)
        n = f.shape[0]
        M = self.n_angles
        r, cos_phi, sin_phi = _polar(f)
        k, t, inside = self._locate(r)
        w0, w1, w2 = (1 - t) ** 2, t * (1 - t), t * t
        Caa, Cab, Cbb = self._Caa, self._Cab, self._Cbb

        def cdf(j):
            return w0 * Caa[k, j] + w1 * Cab[k, j] + w2 * Cbb[k, j]

        total = cdf(np.full(n, M))
        u1 = uu[:, 0]
        upper = u1 < 0.5
        s = np.clip(np.where(upper, 2.0 * u1, 2.0 - 2.0 * u1), 0.0, np.nextafter(1.0, 0.0))
        target = s * total
        lo = np.zeros(n, dtype=np.int64)
        hi = np.full(n, M, dtype=np.int64)
        while True:  # vectorized bisection for the triangle: O(log M) passes
            open_ = hi - lo > 1
            if not open_.any():
                break
            mid = (lo + hi) // 2
            below = cdf(mid) <= target
            lo = np.where(open_ & below, mid, lo)
            hi = np.where(open_ & ~below, mid, hi)
        j = lo
        c_lo = cdf(j)
        tri = cdf(j + 1) - c_lo
        with np.errstate(invalid="ignore", divide="ignore"):
            v = np.where(tri > 0, (target - c_lo) / np.where(tri > 0, tri, 1.0), 0.0)
        v = np.clip(v, 0.0, 1.0)
        rho_j = (1 - t) * self.rho[k, j] + t * self.rho[k + 1, j]
        rho_j1 = (1 - t) * self.rho[k, j + 1] + t * self.rho[k + 1, j + 1]
        c, sx, sy = self._frame(k, t)
        a = np.sqrt(uu[:, 1])
        qx = a * ((1 - v) * rho_j * self._cos_t[j] + v * rho_j1 * self._cos_t[j + 1])
        qy = a * ((1 - v) * rho_j * self._sin_t[j] + v * rho_j1 * self._sin_t[j + 1])
        lx = c + sx * qx
        ly = np.where(upper, sy * qy, -sy * qy)
        px = cos_phi * lx - sin_phi * ly
        py = sin_phi * lx + cos_phi * ly
        area = math.sin(self._h) * sx * sy * total
        return finish_sample(f, px, py, self.plane_z_mm, area, inside & (total > 0))

    # -- measurements
    def exposure_normalisation(self) -> float:
        """1 / (E/L) at the film centre, from the exact on-axis boundary: the factor
        that gives the frame centre the brightness of a pinhole render."""
        if not self.axial_irradiance_factor > 0:
            raise OpticsError(f"{self.lens.source}: no ray from the film centre gets through")
        return 1.0 / self.axial_irradiance_factor

    # -- files
    def describe(self) -> dict:
        """Metadata: the inputs (for cache checks) and build statistics."""
        p = paraxial_data(self.lens)
        d = dict(self.metadata)
        d.update({
            "format": FORMAT_NAME, "version": FORMAT_VERSION,
            "lens": {"source": self.lens.source, "sha256": self.lens.sha256(),
                     "stop_diameter_mm": p.stop_diameter, "f_number": p.f_number},
            "film_distance_mm": self.film_distance_mm,
            "film": {**(self.metadata.get("film") or {}),
                     "half_diagonal_mm": self.film_half_diagonal_mm},
            "plane": self.plane, "plane_z_mm": self.plane_z_mm,
            "tolerance": self.tolerance,
            "knots": self.n_knots, "angles": self.n_angles,
            "max_film_radius_mm": self.max_film_radius_mm,
            "vignetted_beyond_mm": self.vignetted_beyond_mm,
            "axial_irradiance_factor": self.axial_irradiance_factor,
            "stats": self.stats,
        })
        return d

    def save(self, path) -> Path:
        """Write the table to ``path`` (.npz with JSON metadata), atomically."""
        path = Path(path)
        meta = json.dumps(self.describe(), allow_nan=False, default=_json_default)
        L = self.lens
        buf = io.BytesIO()
        np.savez(buf, film_radius_mm=self.film_radius_mm, centre_x_mm=self.centre_x_mm,
                 scale_x_mm=self.scale_x_mm, scale_y_mm=self.scale_y_mm, rho=self.rho,
                 lens_radius_mm=L.radius_mm, lens_thickness_mm=L.thickness_mm,
                 lens_index_after=L.index_after,
                 lens_aperture_diameter_mm=L.aperture_diameter_mm, lens_abbe_vd=L.abbe_vd,
                 metadata=np.array(meta))
        parent = path.parent if str(path.parent) else Path(".")
        try:
            fd, tmp = tempfile.mkstemp(dir=parent, prefix=f".{path.name}.", suffix=".tmp")
        except OSError as e:
            raise UsageError(f"{path}: cannot write there ({e.strerror})") from None
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(buf.getvalue())
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise
        return path

    _KNOWN_META = {"format", "version", "lens", "film_distance_mm", "plane", "plane_z_mm",
                   "tolerance", "knots", "angles", "max_film_radius_mm",
                   "vignetted_beyond_mm", "axial_irradiance_factor", "stats"}

    @classmethod
    def load(cls, path) -> "PupilTable":
        """Read a table written by :meth:`save`.  Raises PovlensError if it is not one."""
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
        except FileNotFoundError:
            raise UsageError(f"{path}: no such pupil table") from None
        except IsADirectoryError:
            raise UsageError(f"{path}: is a directory, not a pupil table") from None
        except (OSError, ValueError, EOFError) as e:
            raise PovlensError(f"{path}: not a povlens pupil table ({e})") from None
        try:
            meta = json.loads(str(arrays["metadata"]))
            if meta.get("format") != FORMAT_NAME or meta.get("version") != FORMAT_VERSION:
                raise ValueError("unknown format or version")
            lens = LensPrescription(arrays["lens_radius_mm"], arrays["lens_thickness_mm"],
                                    arrays["lens_index_after"],
                                    arrays["lens_aperture_diameter_mm"], arrays["lens_abbe_vd"],
                                    source=meta["lens"]["source"])
            if lens.sha256() != meta["lens"]["sha256"]:
                raise ValueError("the stored lens does not match its hash")
            extra = {k: v for k, v in meta.items() if k not in cls._KNOWN_META}
            return cls(lens, meta["film_distance_mm"], meta["film"]["half_diagonal_mm"],
                       meta["plane_z_mm"], meta["plane"], arrays["film_radius_mm"],
                       arrays["centre_x_mm"], arrays["scale_x_mm"], arrays["scale_y_mm"],
                       arrays["rho"], meta["max_film_radius_mm"], meta["vignetted_beyond_mm"],
                       meta["tolerance"], meta["axial_irradiance_factor"], meta.get("stats"),
                       extra)
        except (KeyError, ValueError, TypeError, AttributeError) as e:
            raise PovlensError(f"{path}: not a povlens pupil table ({e})") from None


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def load(path) -> PupilTable:
    """Read a saved table (see :meth:`PupilTable.load`)."""
    return PupilTable.load(path)


def load_if_current(path, lens: LensPrescription, film_distance_mm: float,
                    film_half_diagonal_mm: float, *, tolerance: float | None = None,
                    plane: str | None = None) -> PupilTable | None:
    """The table saved at ``path`` if it was built for exactly these inputs, else None.

    Inputs compared: the lens's optical content including its stop (the hash of
    the prescription), the film distance (so the focus), the film half-diagonal
    and, when given, the tolerance and the requested sampling plane.  A missing
    or unreadable file gives None.
    """
    path = Path(path)
    if not path.is_file():
        return None
    try:
        table = PupilTable.load(path)
    except PovlensError:
        return None

    def same(a, b):
        return abs(float(a) - float(b)) <= 1e-9 * max(1.0, abs(float(b)))

    if (table.lens.sha256() != lens.sha256()
            or not same(table.film_distance_mm, film_distance_mm)
            or not same(table.film_half_diagonal_mm, film_half_diagonal_mm)
            or (tolerance is not None and not same(table.tolerance, tolerance))
            or (plane is not None and table.metadata.get("requested_plane", table.plane)
                != plane)):
        return None
    table.lens = table.lens.replace(source=lens.source)
    return table


# ----- building ---------------------------------------------------------------------

@dataclasses.dataclass
class _Knot:
    c: float          # centre x (mm)
    sx: float         # half-width along x (mm)
    sy: float         # half-height through the centre (mm)
    rho: np.ndarray   # (2M + 1,) exact normalised boundary at vertex and mid-angles
    res: float        # bisection resolution (normalised)


def _interp(knots: dict, r: float):
    """(c, sx, sy, rho_grid) linearly interpolated between the knots around r."""
    rs = sorted(knots)
    k = int(np.clip(np.searchsorted(rs, r, side="right") - 1, 0, len(rs) - 2))
    a, b = knots[rs[k]], knots[rs[k + 1]]
    t = (r - rs[k]) / (rs[k + 1] - rs[k])
    lerp = lambda x, y: (1 - t) * x + t * y  # noqa: E731
    return lerp(a.c, b.c), lerp(a.sx, b.sx), lerp(a.sy, b.sy), lerp(a.rho[0::2], b.rho[0::2])


def build_pupil_table(lens: LensPrescription, film_distance_mm: float,
                      film_half_diagonal_mm: float, *, tolerance: float = DEFAULT_TOLERANCE,
                      plane: str = "exit-pupil", n_angles: int | None = None,
                      safety_margin: float = SAFETY_MARGIN, initial_knots: int = 5,
                      min_interval_mm: float | None = None, progress=None,
                      metadata: dict | None = None) -> PupilTable:
    """Build the exit-pupil table of ``lens`` with the film ``film_distance_mm`` behind
    the rear vertex, for film points out to ``film_half_diagonal_mm`` from the centre.

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

    Raises UsageError for bad arguments and OpticsError when no ray from the film
    centre gets through the lens.
    """
    t_start = time.perf_counter()
    for name, v in (("film_distance_mm", film_distance_mm),
                    ("film_half_diagonal_mm", film_half_diagonal_mm)):
        if not (isinstance(v, (int, float, np.floating)) and math.isfinite(v) and v > 0):
            raise UsageError(f"{name} = {v!r}: must be a positive number of mm")
    if not (isinstance(tolerance, (int, float)) and math.isfinite(tolerance)
            and 0 < tolerance < 1):
        raise UsageError(f"--tolerance {tolerance!r}: must be between 0 and 1 (e.g. 0.005)")
    if n_angles is not None and not (2 <= int(n_angles) <= 4096):
        raise UsageError(f"n_angles {n_angles!r}: must be between 2 and 4096")
    hd = float(film_half_diagonal_mm)
    pdat = paraxial_data(lens)
    if pdat.stop_diameter < MIN_STOP_FRACTION * abs(pdat.efl):
        raise OpticsError(
            f"{lens.source}: the stop diameter {pdat.stop_diameter:.3g} mm is below "
            f"{MIN_STOP_FRACTION:g} of the focal length; at that size the lens is a pinhole "
            f"whose pupil cannot be resolved in float64 (and diffraction would dominate)",
            f"use --stop-diameter {MIN_STOP_FRACTION * abs(pdat.efl):.3g} or more, or render "
            f"with --method pinhole")
    zp, plane_used = sampling_plane_z_mm(lens, float(film_distance_mm), plane)
    pr = _Prober(lens, film_distance_mm, zp)
    min_w = float(min_interval_mm) if min_interval_mm is not None else 1e-5 * hd
    tick = progress or (lambda n: None)
    n_eval = 0

    # 1. The film radii that have rays.
    _, found0, box0 = pr.interior(np.array([0.0]))
    if not found0[0]:
        raise OpticsError(f"{lens.source}: no ray from the film centre gets through the lens "
                          f"(film distance {film_distance_mm:g} mm)",
                          "check the stop (--f-number / --stop-diameter) and the focus")
    _, found_edge, _ = pr.interior(np.array([hd]))
    end_box = None
    if found_edge[0]:
        r_end, r_valid, vig = hd, hd, None
    else:
        lo, hi, hint = 0.0, hd, box0[0]
        while hi - lo > 1e-6 * hd:
            mid = 0.5 * (lo + hi)
            _, f, b = pr.interior(np.array([mid]), hint=_grow(hint))
            if f[0]:
                lo, hint = mid, b[0]
            else:
                hi = mid
        r_end, r_valid, vig, end_box = lo, hi, hi, hint
        if r_end <= 0:
            raise OpticsError(f"{lens.source}: rays get through only at the very film centre")

    def evaluate(rs, cs, sxs, sys_, M, first=None):
        """Exact boundaries at radii rs, then the frame is moved to the region: centre
        to the middle of its stretch of the x axis, s_x to its half-width there, s_y
        to its half-height through the centre (all from bisected boundary points, so
        smooth in r), and the boundary traced again (at most twice) if the frame
        moved by more than RENORMALISE.  Smooth frames make smooth rho_j(r)."""
        nonlocal n_eval
        rs = np.asarray(rs, dtype=np.float64)
        cs, sxs, sys_ = (np.array(v, dtype=np.float64) for v in (cs, sxs, sys_))
        if first is None:
            rho, ok, res = pr.boundary(rs, cs, sxs, sys_, M)
            n_eval += len(rs)
            tick(len(rs))
        else:
            rho, ok, res = (np.array(x) for x in first)
        bad = np.nonzero(~ok)[0]
        if bad.size:  # the centre guess is outside the region: grid search
            near = np.stack([cs[bad] - 3 * np.abs(sxs[bad]), cs[bad] + 3 * np.abs(sxs[bad]),
                             np.zeros(bad.size), 3 * np.abs(sys_[bad])], axis=1)
            cs[bad], found, bb = pr.interior(rs[bad], hint=near)
            sxs[bad] = np.where(found, 0.5 * (bb[:, 1] - bb[:, 0]), sxs[bad])
            sys_[bad] = np.where(found, bb[:, 3], sys_[bad])
            rho[bad], ok[bad], res[bad] = pr.boundary(rs[bad], cs[bad], sxs[bad], sys_[bad], M)
            n_eval += bad.size
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
            rho2, ok2, res2 = pr.boundary(rs[redo], c_new[redo], sx_new[redo], sy_new[redo], M)
            n_eval += redo.size
            tick(redo.size)
            take = redo[ok2]
            cs[take], sxs[take], sys_[take] = c_new[take], sx_new[take], sy_new[take]
            rho[take], res[take] = rho2[ok2], res2[ok2]
        rho[~ok] = 0.0
        return cs, sxs, sys_, rho, res

    # 2. Initial knots and the angle count M.
    r0 = np.linspace(0.0, r_end, max(2, int(initial_knots)))
    hints = np.repeat(_grow(box0[0]), len(r0), axis=0)
    if end_box is not None:
        hints[-1] = _grow(end_box)[0]
    c_g, found_g, bb = pr.interior(r0, hint=hints)
    c_g[0] = 0.0
    sx_g = np.where(found_g, 0.5 * (bb[:, 1] - bb[:, 0]), 1.0)
    sy_g = np.where(found_g, bb[:, 3], 1.0)
    M_choices = [int(n_angles)] if n_angles else [16, 32, 64, 128]
    for M in M_choices:
        c0, sx0, sy0, rho0, res0 = evaluate(r0, c_g, sx_g, sy_g, M)
        # Area between the chords and the exact boundary (corners, where chords cut
        # most, also get a local dilation below for conservativeness).
        # The knot where the pupil vanishes (vignetting) is a degenerate sliver: left out.
        ang_err = max(_area_error(rho0[i], _chord_extent(rho0[i, 0::2], M))
                      for i in range(len(r0) - (vig is not None)))
        if ang_err <= 0.25 * tolerance:
            break
        c_g, sx_g, sy_g = c0, sx0, sy0

    # 3. Radial refinement: split every interval whose midpoint error exceeds tolerance.
    knots = {float(r): _Knot(float(c), float(a), float(b), rho, float(res))
             for r, c, a, b, rho, res in zip(r0, c0, sx0, sy0, rho0, res0)}
    checks: dict[tuple[float, float], np.ndarray] = {}
    pending = [(float(a), float(b)) for a, b in zip(r0[:-1], r0[1:])]
    max_err_accepted = 0.0
    while pending:
        mids = np.array([0.5 * (a + b) for a, b in pending])
        frames = [_interp(knots, m) for m in mids]
        cm, sxm, sym = (np.array([f[i] for f in frames]) for i in range(3))
        rho_m, ok_m, res_m = pr.boundary(mids, cm, sxm, sym, M)
        n_eval += len(mids)
        tick(len(mids))
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
            cs, sxs, sys_, rho_n, res_n = evaluate(
                mids[new], cm[new], sxm[new], sym[new], M,
                first=(rho_m[new], ok_m[new], res_m[new]))
            for m, c, a, b, rho_i, res_i in zip(mids[new], cs, sxs, sys_, rho_n, res_n):
                knots[float(m)] = _Knot(float(c), float(a), float(b), rho_i, float(res_i))
        pending = nxt

    # 4. Dilation by the measured shortfalls, plus the safety margin (normalised units).
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

    # Exact on-axis irradiance factor from the undilated boundary at r = 0:
    # E/L = integral over angles of P^2 / (2 (z^2 + P^2)), P the boundary distance.
    k0 = ks[0]
    th = np.arange(2 * M + 1) * (math.pi / (2 * M))
    P = exact[0] * np.hypot(k0.sx * np.cos(th), k0.sy * np.sin(th))
    f_ax = 0.5 * P * P / (zp * zp + P * P)
    axial = 2.0 * float(np.sum(0.5 * (f_ax[1:] + f_ax[:-1])) * (math.pi / (2 * M)))

    stats = {"build_time_s": time.perf_counter() - t_start, "rays_traced": int(pr.rays),
             "boundary_evaluations": int(n_eval), "max_check_area_error": max_err_accepted,
             "angle_area_error": ang_err, "min_interval_mm": min_w,
             "mean_dilation": float(np.mean(dil + margin[:, None])),
             "knot_limit_reached": len(knots) >= MAX_KNOTS,
             "non_star_shaped_radii": len(pr.non_star_radii),
             "non_star_shaped_from_mm": (min(pr.non_star_radii) if pr.non_star_radii
                                         else None)}
    meta = dict(metadata or {})
    meta.setdefault("requested_plane", plane)
    return PupilTable(lens, film_distance_mm, hd, zp, plane_used, rs,
                      [k.c for k in ks], [k.sx for k in ks], [k.sy for k in ks], rho,
                      r_valid, vig, tolerance, axial, stats, meta)


def _grow(box: np.ndarray, factor: float = 1.5) -> np.ndarray:
    """Boxes (x0, x1, y0, y1) grown about their centres (y from 0), shape (B, 4)."""
    box = np.atleast_2d(np.asarray(box, dtype=np.float64)).copy()
    cx = 0.5 * (box[:, 0] + box[:, 1])
    hw = 0.5 * (box[:, 1] - box[:, 0]) * factor
    box[:, 0], box[:, 1] = cx - hw, cx + hw
    box[:, 3] = box[:, 3] * factor
    return box


# ----- plotting ---------------------------------------------------------------------

def plot_pupil_shapes(table: PupilTable, path, *, film_radii=None, boxes=None,
                      n_grid: int = 160) -> Path:
    """Draw the table's region at several film radii over the exact pass region.

    Each panel shows, on the sampling plane in the rotated frame (film point on
    +x), the rays that get through (dots, from an n_grid^2 brute-force grid) and
    the table's polygon; ``boxes`` (a :class:`~povlens.pupil_baselines.PbrtBoxes`)
    adds pbrt's box, mapped to this plane.  Written with matplotlib (Agg).
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if film_radii is None:
        film_radii = np.linspace(0.0, table.film_half_diagonal_mm, 6)
    film_radii = [float(r) for r in film_radii]
    n = len(film_radii)
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 4.2 * rows), squeeze=False)
    pr = _Prober(table.lens, table.film_distance_mm, table.plane_z_mm)
    for ax, r in zip(axes.ravel(), film_radii):
        dcx, dR = pr.domain(np.array([r]))
        g = np.linspace(-1, 1, n_grid)
        X, Y = np.meshgrid(dcx[0] + dR[0] * g, dR[0] * g)
        ok = pr.passes(np.array(r), X, Y)
        ext = [X.min(), X.max(), Y.min(), Y.max()]
        ax.imshow(np.where(ok, 1.0, np.nan), origin="lower", extent=ext, cmap="Blues",
                  vmin=0.0, vmax=1.6, interpolation="nearest")
        ax.plot([], [], "s", color="#6fa8dc", label="rays that get through (traced grid)")
        poly = table.region(r)
        if len(poly):
            pc = np.vstack([poly, poly[:1]])
            ax.plot(pc[:, 0], pc[:, 1], "k-", lw=1, label="povlens table")
        if boxes is not None:
            b = boxes.box_on_plane(r, table.plane_z_mm)
            if b is not None:
                x0, x1, y0, y1 = b
                ax.plot([x0, x1, x1, x0, x0], [y0, y0, y1, y1, y0], "r--", lw=1,
                        label="pbrt box")
        state = "vignetted" if table.is_vignetted(r)[0] else (
            f"area {table.area_mm2(r)[0]:.1f} mm$^2$")
        ax.set_title(f"film radius {r:.2f} mm ({state})", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlabel("x on sampling plane (mm)")
        ax.set_ylabel("y (mm)")
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    handles, labels = axes.ravel()[0].get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=8)
    fig.suptitle(f"{Path(table.lens.source).name}: pass region on the {table.plane} plane "
                 f"(z = {table.plane_z_mm:.2f} mm), film point on +x", fontsize=10)
    fig.tight_layout(rect=(0, 0.05, 1, 0.96))
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
