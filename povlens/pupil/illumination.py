"""The lens's relative illumination across the film, exactly, from the exit-pupil table.

The irradiance a uniform scene of unit radiance gives at the film point (r, 0)
(the camera measurement equation; :mod:`povlens.pupil.build` explains the
sampling plane z = z_p) is

    E(r) / L = integral over the pass region R(r) of cos^4(theta) / z_p^2 dA
             = integral over R(r) of z_p^2 / ((x - r)^2 + y^2 + z_p^2)^2 dx dy,

and the relative illumination is E(r) / E(0): natural (cos^4) and mechanical
(cat's-eye) vignetting together.  It is what a mesh render composited with its
radiometric weights shows (:func:`povlens.rendering.folder_composite.composite_outdir`:
``image *= sum w * exposure / N``, exposure = 1 / (E/L)(0)): the expected weight
of a pixel's samples is E(pixel) / L, since the weights are ``cos^4 / (z_p^2 pdf)``
of the rays that pass.

How it is computed (:func:`illumination_profile`)
-------------------------------------------------
The lens is rotationally symmetric, so E depends on the film radius only: it is
computed at a set of radii and interpolated linearly at each pixel
(:func:`relative_illumination_map`): :data:`GRID_RADII` evenly spaced ones and
the table's knots, and midpoints of every interval where linear interpolation
misses the value there by more than :data:`INTERPOLATION_TOLERANCE` (the radius
where a rim starts to cut is a kink that falls between grid points), bisected
again up to :data:`MAX_REFINEMENTS` times.  At each radius, in the table's
normalised frame (centre (c, 0), half-width s_x, half-height s_y, interpolated
between knots as the table does), the exact boundary of the pass region is found
along :data:`ANGLES` + 1 directions t_k = k pi / ANGLES over the upper half (the
region is symmetric about the x axis): by bisection with the exact tracer between
the centre (which must pass) and 1.05 x the table's largest vertex distance (the
table is conservative, so the boundary lies inside; the bound is checked to be
blocked), to :data:`BISECTION_RELATIVE` of that bound.  Then

    E / L = 2 integral_0^pi dt integral_0^rho*(t) g(c + rho s_x cos t, rho s_y sin t)
            s_x s_y rho d rho,

Gauss-Legendre (:data:`RADIAL_NODES` nodes) along each direction and the
trapezoid rule over the angles; where the trapezoid rule over every other angle
differs by more than 3 x :data:`QUADRATURE_TOLERANCE` (its error is O(h^2) at the
cat's eye's corners) the radius is done again with :data:`ANGLE_REFINE` x the
angles.  This assumes the region is star-shaped about its centre, as the table
does; where that is not known -- the table reports non-star-shaped regions (the
F/1 singlet stopped down, far off axis), the centre or the bound fails its check
(the sliver at a vignetting cut-off), or one of :data:`STAR_CHECKS` points along a
direction inside the boundary is blocked -- the radius falls back to the mesh
render's own estimator, the mean of ``weight * passed`` over
:data:`FALLBACK_SAMPLES` Sobol' points of the table's sampler
(:func:`povlens.pupil.monte_carlo.irradiance_factor`).  Beyond a vignetting cut-off
E is 0.

Accuracy and cost are measured in docs/decisions/planning.md ("Relative
illumination map").

A lens without rotational symmetry (an anamorphic lens, whose table is a
:class:`povlens.pupil.grid_table.GridPupilTable`) has its illumination over the film's x
and y instead (:mod:`povlens.pupil.grid_illumination`): :func:`illumination_profile`,
:func:`profile_record`, :func:`profile_from_record` and :func:`relative_illumination_map`
take and give its :class:`~povlens.pupil.grid_illumination.IlluminationGrid` in place of
the profile, so their callers need not know which.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from povlens.errors import OpticsError
from povlens.pupil.grid_illumination import (IlluminationGrid, grid_from_record, grid_record,
                                             illumination_grid)
from povlens.pupil.prober import PupilProber
from povlens.pupil.monte_carlo import irradiance_factor

__all__ = ["IlluminationProfile", "illumination_profile", "irradiance_at",
           "relative_illumination_map", "profile_record", "profile_from_record",
           "film_radius_grid_mm", "ANGLES", "RADIAL_NODES", "GRID_RADII",
           "BISECTION_RELATIVE", "STAR_CHECKS", "FALLBACK_SAMPLES", "CURVATURE_TOLERANCE",
           "OVERSAMPLE", "QUADRATURE_TOLERANCE", "ANGLE_REFINE", "INTERPOLATION_TOLERANCE",
           "MAX_REFINEMENTS"]

#: Angular intervals over the upper half of the region (trapezoid rule).
ANGLES = 128
#: Relative error of the angular quadrature (estimated against every other angle)
#: above which a radius is done again with ANGLE_REFINE x the angles.
QUADRATURE_TOLERANCE = 3e-5
ANGLE_REFINE = 4
#: Largest error of linear interpolation between the profile's radii, in relative
#: illumination; intervals are bisected until it holds, at most MAX_REFINEMENTS times.
INTERPOLATION_TOLERANCE = 1e-4
MAX_REFINEMENTS = 8
#: Gauss-Legendre nodes along each direction (the integrand is smooth there).
RADIAL_NODES = 12
#: Evenly spaced film radii of the profile, besides the table's knots.
GRID_RADII = 49
#: Bisection stops when the bracket is this fraction of the starting bound.
BISECTION_RELATIVE = 1e-6
#: Points per direction checked to pass inside the found boundary (star-shapedness).
STAR_CHECKS = 4
#: Sobol' points per radius of the fallback estimator (the mesh render's).
FALLBACK_SAMPLES = 1 << 14
#: Pixels whose profile bends more than this over the pixel are averaged over
#: OVERSAMPLE x OVERSAMPLE points (a vignetting cut-off, a kink where a rim starts
#: to cut); the rest take the value at their centre.
CURVATURE_TOLERANCE = 1e-5
OVERSAMPLE = 8


@dataclasses.dataclass(frozen=True)
class IlluminationProfile:
    """The lens's illumination over film radius (all arrays (m,), float64).

    film_radius_mm : radii, increasing, the first 0.
    irradiance_factor : E/L at each radius (irradiance per unit scene radiance).
    relative_illumination : E(r) / E(0), 0 where vignetted.
    radial_width_mm, tangential_width_mm : the pass region's extent on the sampling
        plane along the film point's radius (through the region's centre) and across
        it (twice the largest half-height); 0 where vignetted.
    area_mm2 : the pass region's area on the sampling plane.
    exact : True where the quadrature over the exact boundary was used, False where
        the sampler's estimate was (see the module docstring).
    plane_z_mm : z of the sampling plane.
    vignetted_beyond_mm : film radius beyond which no ray gets through (None: none).
    """

    film_radius_mm: np.ndarray
    irradiance_factor: np.ndarray
    relative_illumination: np.ndarray
    radial_width_mm: np.ndarray
    tangential_width_mm: np.ndarray
    area_mm2: np.ndarray
    exact: np.ndarray
    plane_z_mm: float
    vignetted_beyond_mm: float | None

    def at(self, film_radius_mm) -> np.ndarray:
        """E / E(0) at film radii (any shape, mm), linear between the profile's radii;
        0 beyond a vignetting cut-off and beyond the profile's last radius."""
        r = np.asarray(film_radius_mm, dtype=np.float64)
        out = np.interp(r, self.film_radius_mm, self.relative_illumination, right=0.0)
        return np.where(np.isfinite(r), out, 0.0)

    def to_dict(self) -> dict:
        """JSON-able record: the radii (rounded to 1e-9 mm) and the relative
        illumination (to 1e-7)."""
        return {"film_radius_mm": [round(float(v), 9) for v in self.film_radius_mm],
                "relative_illumination": [round(float(v), 7)
                                          for v in self.relative_illumination],
                "min_relative_illumination": round(float(self.relative_illumination.min()), 7),
                "exact_radii": int(np.count_nonzero(self.exact)),
                "vignetted_beyond_mm": self.vignetted_beyond_mm}


def _table_key(table) -> dict:
    """What a profile depends on: the lens (stop included), film distance and film."""
    return {"lens_sha256": table.lens.sha256(),
            "film_distance_mm": float(table.film_distance_mm),
            "film_half_diagonal_mm": float(table.film_half_diagonal_mm)}


def _is_grid(table) -> bool:
    return getattr(table, "kind", "radial") == "grid"


def profile_record(profile: IlluminationProfile, table) -> dict:
    """JSON-able record of ``profile`` (:meth:`IlluminationProfile.to_dict`) with the
    key of the ``table`` it was computed from, for :func:`profile_from_record` (an
    :class:`IlluminationGrid`'s: :func:`~povlens.pupil.grid_illumination.grid_record`)."""
    if isinstance(profile, IlluminationGrid):
        return grid_record(profile, table)
    return {**_table_key(table), **profile.to_dict()}


def _same(a, b) -> bool:
    if isinstance(b, str):
        return a == b
    try:
        return abs(float(a) - float(b)) <= 1e-9 * max(1.0, abs(float(b)))
    except (TypeError, ValueError):
        return False


def profile_from_record(record, table) -> IlluminationProfile | None:
    """The profile of a :func:`profile_record` if it was made from ``table``'s lens,
    film distance and film and is well formed, else None.  Only the radii and the
    relative illumination come back (the widths and areas are 0: a map needs only
    these).  For a grid table, its :class:`IlluminationGrid` (or None) instead."""
    if _is_grid(table):
        return grid_from_record(record, table)
    if not isinstance(record, dict) or any(not _same(record.get(k), v)
                                           for k, v in _table_key(table).items()):
        return None
    try:
        r = np.asarray(record["film_radius_mm"], dtype=np.float64)
        ri = np.asarray(record["relative_illumination"], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        return None
    if (r.ndim != 1 or r.shape != ri.shape or r.size < 2 or r[0] != 0.0
            or not np.all(np.diff(r) > 0) or not np.all(np.isfinite(ri)) or np.any(ri < 0)):
        return None
    zero = np.zeros_like(r)
    return IlluminationProfile(r, ri, ri, zero, zero, zero, np.ones(r.size, bool),
                               float(table.plane_z_mm), table.vignetted_beyond_mm)


def film_radius_grid_mm(table, max_radius_mm: float | None = None,
                        n_grid: int = GRID_RADII) -> np.ndarray:
    """The radii :func:`illumination_profile` evaluates: ``n_grid`` evenly spaced from
    0 to ``max_radius_mm`` (default the table's film half-diagonal), the table's knots
    in that range, and, at a vignetting cut-off inside it, the last radius with rays
    and the cut-off itself (where E is 0).  Sorted, unique, (m,) mm."""
    hd = float(table.film_half_diagonal_mm if max_radius_mm is None else max_radius_mm)
    if not (hd > 0 and math.isfinite(hd)):
        raise ValueError(f"max_radius_mm={max_radius_mm!r}: must be a positive number of mm")
    cut = table.vignetted_beyond_mm
    last = float(table.film_radius_mm[-1])
    end = hd if cut is None else min(hd, last)
    r = [np.linspace(0.0, end, max(2, int(n_grid))),
         table.film_radius_mm[table.film_radius_mm <= end]]
    if cut is not None and cut <= hd:
        r.append([cut])
    r = np.unique(np.concatenate(r))
    # a knot and a grid radius a rounding apart (e.g. 8.114656880000001 and
    # 8.11465688) would be bisected into duplicates, which plan.json's record (to
    # 1e-9 mm) cannot order: keep one
    return r[np.concatenate([[True], np.diff(r) > 1e-9])]


def _frames(table, r: np.ndarray):
    """The table's normalised frame (c, s_x, s_y) and the largest (dilated) vertex
    distance at radii ``r``, interpolated between knots as the table does."""
    knots = table.film_radius_mm
    c = np.interp(r, knots, table.centre_x_mm)
    sx = np.interp(r, knots, table.scale_x_mm)
    sy = np.interp(r, knots, table.scale_y_mm)
    rho_max = np.max([np.interp(r, knots, col) for col in table.rho.T], axis=0)
    return c, sx, sy, rho_max


def _boundaries(prober: PupilProber, r, c, sx, sy, rho_max, n_angles: int):
    """Exact boundary distances (B, A + 1) in the normalised frames along
    t_k = k pi / A, and which radii the quadrature may use (centre passes, bound
    blocked, the checked points inside pass)."""
    t = np.arange(n_angles + 1) * (math.pi / n_angles)
    ux = sx[:, None] * np.cos(t)[None, :]
    uy = sy[:, None] * np.sin(t)[None, :]
    rr = np.broadcast_to(r[:, None], ux.shape)
    cc = np.broadcast_to(c[:, None], ux.shape)
    ok = prober.passes(r, c, np.zeros_like(c)) & (sx > 0) & (sy > 0) & (rho_max > 0)
    hi = np.broadcast_to((1.05 * rho_max)[:, None], ux.shape).copy()
    ok &= ~np.any(prober.passes(rr, cc + hi * ux, hi * uy), axis=1)
    lo = np.zeros_like(hi)
    steps = math.ceil(math.log2(1.0 / BISECTION_RELATIVE))
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        p = prober.passes(rr, cc + mid * ux, mid * uy)
        lo = np.where(p, mid, lo)
        hi = np.where(p, hi, mid)
    rho = 0.5 * (lo + hi)
    f = (np.arange(STAR_CHECKS) + 0.5) / STAR_CHECKS * 0.999
    s = lo[..., None] * f
    inside = prober.passes(rr[..., None], cc[..., None] + s * ux[..., None], s * uy[..., None])
    ok &= inside.all(axis=(1, 2))
    return t, rho, ok


def _quadrature(r, c, sx, sy, rho, t, zp: float) -> np.ndarray:
    """E/L (B,) over the star regions rho (B, A + 1) in the frames (c, s_x, s_y)."""
    x, w = np.polynomial.legendre.leggauss(RADIAL_NODES)
    q = 0.5 * (x + 1.0)                                          # nodes on [0, 1]
    wq = 0.5 * w
    dist = rho[..., None] * q                                    # (B, A+1, Q)
    px = c[:, None, None] + dist * (sx[:, None, None] * np.cos(t)[None, :, None])
    py = dist * (sy[:, None, None] * np.sin(t)[None, :, None])
    d2 = (px - r[:, None, None]) ** 2 + py ** 2 + zp * zp
    g = zp * zp / (d2 * d2)
    inner = np.sum(g * dist * wq, axis=-1) * rho                 # integral of g rho d rho
    wt = np.full(t.size, t[1] - t[0])
    wt[0] = wt[-1] = 0.5 * (t[1] - t[0])
    return 2.0 * sx * sy * np.sum(inner * wt, axis=-1)


def _evaluate(prober: PupilProber, table, r: np.ndarray, n_angles: int):
    """E/L at radii ``r`` (B,) by the quadrature, refined in angle where it is not
    converged; returns (E (B,), exact (B,), rho (B, A + 1), t (A + 1,), frames)."""
    c, sx, sy, rho_max = _frames(table, r)
    t, rho, ok = _boundaries(prober, r, c, sx, sy, rho_max, n_angles)
    e = np.zeros(r.size)
    if ok.any():
        e[ok] = _quadrature(r[ok], c[ok], sx[ok], sy[ok], rho[ok], t, prober.zp)
        # the trapezoid rule's error at the cat's eye's corners is O(h^2): compare with
        # every other angle, and redo with ANGLE_REFINE x the angles where it shows
        half = _quadrature(r[ok], c[ok], sx[ok], sy[ok], rho[ok][:, ::2], t[::2], prober.zp)
        again = np.zeros(r.size, bool)
        again[ok] = np.abs(e[ok] - half) / 3.0 > QUADRATURE_TOLERANCE * e[ok]
        if again.any():
            i = np.nonzero(again)[0]
            t2, rho2, ok2 = _boundaries(prober, r[i], c[i], sx[i], sy[i], rho_max[i],
                                        ANGLE_REFINE * n_angles)
            e[i[ok2]] = _quadrature(r[i[ok2]], c[i[ok2]], sx[i[ok2]], sy[i[ok2]], rho2[ok2],
                                    t2, prober.zp)
            ok[i[~ok2]] = False
            rho[i] = rho2[:, ::ANGLE_REFINE]
    return e, ok, rho, t, (c, sx, sy)


def _refine_radii(r: np.ndarray, ri: np.ndarray, evaluate) -> tuple[np.ndarray, list]:
    """Midpoints of intervals where the linear interpolation of ``ri`` misses the value
    there by more than :data:`INTERPOLATION_TOLERANCE`, bisected again up to
    :data:`MAX_REFINEMENTS` times.  ``evaluate(radii)`` returns their relative
    illumination and anything to keep; returns the radii added and what evaluate kept."""
    added, kept = [], []
    todo = np.arange(r.size - 1)
    lo, hi, vlo, vhi = r[todo], r[todo + 1], ri[todo], ri[todo + 1]
    for _ in range(MAX_REFINEMENTS):
        if lo.size == 0:
            break
        mid = 0.5 * (lo + hi)
        v, extra = evaluate(mid)
        added.append(mid)
        kept.append(extra)
        bad = np.abs(v - 0.5 * (vlo + vhi)) > INTERPOLATION_TOLERANCE
        lo, hi, vlo, vhi, mid, v = lo[bad], hi[bad], vlo[bad], vhi[bad], mid[bad], v[bad]
        lo, hi = np.concatenate([lo, mid]), np.concatenate([mid, hi])
        vlo, vhi = np.concatenate([vlo, v]), np.concatenate([v, vhi])
    return (np.concatenate(added) if added else np.zeros(0)), kept


def illumination_profile(table, max_radius_mm: float | None = None, *,
                         n_grid: int = GRID_RADII, n_angles: int = ANGLES
                         ) -> IlluminationProfile:
    """The exact illumination of ``table``'s lens over film radius (module docstring).

    Parameters
    ----------
    table : :class:`povlens.pupil.table.PupilTable` (its lens, film distance, frames).
    max_radius_mm : largest film radius needed, mm (default the table's film
        half-diagonal; a film's corner is its half-diagonal).
    n_grid : evenly spaced radii to start from, besides the table's knots; intervals
        where linear interpolation is not within :data:`INTERPOLATION_TOLERANCE` are
        bisected (the onset of a rim's cut is a kink that falls between them).
    n_angles : angular intervals over the half region (more where not converged).

    Returns
    -------
    IlluminationProfile

    Raises
    ------
    OpticsError
        When no ray from the film centre gets through (nothing to normalise by).

    A grid table (an anamorphic lens) gives its
    :class:`~povlens.pupil.grid_illumination.IlluminationGrid` over its whole extent
    instead (``max_radius_mm``, ``n_grid`` and ``n_angles`` do not apply).
    """
    if _is_grid(table):
        return illumination_grid(table)
    r0 = film_radius_grid_mm(table, max_radius_mm, n_grid)
    lens, zp = table.lens, table.plane_z_mm
    cut = table.vignetted_beyond_mm
    prober = PupilProber(lens, table.film_distance_mm, zp)

    def evaluate(r):
        return _irradiance(prober, table, r, int(n_angles))

    e0, ok0, w0 = evaluate(r0)
    if not (e0[0] > 0 and math.isfinite(e0[0])):
        raise OpticsError(f"{lens.source}: no ray from the film centre gets through the lens; "
                          f"there is no illumination to normalise by")
    r_add, kept = _refine_radii(r0, e0 / e0[0],
                                lambda r: (lambda out: (out[0] / e0[0], out))(evaluate(r)))
    r = np.concatenate([r0, r_add])
    e = np.concatenate([e0] + [k[0] for k in kept])
    ok = np.concatenate([ok0] + [k[1] for k in kept])
    widths = [np.concatenate([w0[i]] + [k[2][i] for k in kept]) for i in range(3)]
    order = np.argsort(r, kind="stable")
    r, e, ok = r[order], e[order], ok[order]
    radial, tangential, area = (w[order] for w in widths)
    return IlluminationProfile(r, e, e / e[0], radial, tangential, area, ok, float(zp), cut)


def _irradiance(prober: PupilProber, table, r: np.ndarray, n_angles: int):
    """(E/L (B,), exact (B,), (radial width, tangential width, area)) at radii ``r``:
    the quadrature where it applies, the sampler's estimate elsewhere, 0 beyond a
    vignetting cut-off."""
    cut = table.vignetted_beyond_mm
    dark = np.zeros(r.size, bool) if cut is None else r >= cut
    e, ok, rho, t, (c, sx, sy) = _evaluate(prober, table, r, n_angles)
    ok &= ~dark & (not table.stats.get("non_star_shaped_radii"))   # star shapes only
    rest = ~ok & ~dark
    if rest.any():
        e[rest] = irradiance_factor(table, table.lens, table.film_distance_mm, r[rest],
                                    n_samples=FALLBACK_SAMPLES)
    e = np.where(np.isfinite(e) & (e > 0) & ~dark, e, 0.0)
    return e, ok, _widths(table, r, ok, rho, t, sx, sy)


def irradiance_at(table, film_radius_mm, *, n_angles: int = ANGLES) -> np.ndarray:
    """E/L (irradiance per unit scene radiance) at film radii (any shape, mm), each
    computed as :func:`illumination_profile` computes its radii (no interpolation):
    the quadrature over the exact boundary, or the sampler's estimate where that
    does not apply; 0 beyond a vignetting cut-off.  Same shape as the input."""
    r = np.asarray(film_radius_mm, dtype=np.float64)
    flat = np.abs(r.reshape(-1))
    ok = np.isfinite(flat)
    out = np.zeros(flat.size)
    if ok.any():
        prober = PupilProber(table.lens, table.film_distance_mm, table.plane_z_mm)
        out[ok] = _irradiance(prober, table, flat[ok], int(n_angles))[0]
    return out.reshape(r.shape)


def _widths(table, r, ok, rho, t, sx, sy):
    """(radial width, tangential width, area) of the found regions (0 where not
    found exactly: the table's area there)."""
    rho_ok = np.where(ok[:, None], rho, 0.0)
    radial = sx * (rho_ok[:, 0] + rho_ok[:, -1])
    tangential = 2.0 * sy * np.max(rho_ok * np.sin(t)[None, :], axis=1)
    dt = t[1] - t[0]
    area = np.where(ok, sx * sy * np.sum(rho_ok[:, :-1] * rho_ok[:, 1:], axis=1) * math.sin(dt),
                    table.area_mm2(r))
    return radial, tangential, area


def _pixel_radii(film_width_mm, film_height_mm, width_px, height_px, shift_mm=(0.0, 0.0)):
    """(H, W) film radius (mm) of the pixel centres (frame centre at ``shift_mm``,
    image plane: x right, y up)."""
    cols = (np.arange(width_px) + 0.5) / width_px - 0.5
    rows = 0.5 - (np.arange(height_px) + 0.5) / height_px
    return np.hypot(cols[None, :] * film_width_mm + shift_mm[0],
                    rows[:, None] * film_height_mm + shift_mm[1])


def relative_illumination_map(source, film_width_mm: float, film_height_mm: float,
                              width_px: int, height_px: int, *,
                              pixel_average: bool = True,
                              shift_mm: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """E(pixel) / E(centre) for a film of ``width_px`` x ``height_px`` pixels.

    Parameters
    ----------
    source : a :class:`povlens.pupil.table.PupilTable` (the profile is computed,
        :func:`illumination_profile`) or an :class:`IlluminationProfile`.
    film_width_mm, film_height_mm : the film's size (mm), centred on the axis unless
        shifted.
    width_px, height_px : W and H.
    pixel_average : the mean over each pixel's area, as a mesh render with jittered
        film points composites it (default); False: the value at the pixel centre
        (a render without jitter).  Only pixels where the profile bends measurably
        over the pixel (:data:`CURVATURE_TOLERANCE`) differ; they are averaged over
        :data:`OVERSAMPLE` ^ 2 points.
    shift_mm : lens shift (x right, y up on the image plane, mm;
        :class:`povlens.lens.film.Film`): the frame's centre lies that far off the axis.

    Returns
    -------
    ndarray
        (H, W) float64 >= 0 (1 on the axis, 0 where vignetted; above 1 only where
        a lens's pupil grows off axis), row 0 at the top.  Pixel (i, j) has its
        centre at film radius hypot(((i + 1/2) / W - 1/2) w, ((j + 1/2) / H - 1/2) h)
        (the film's inversion does not change radii), plus the shift.
    """
    w_mm, h_mm = float(film_width_mm), float(film_height_mm)
    sx, sy = (float(v) for v in shift_mm)
    W, H = int(width_px), int(height_px)
    if not (w_mm > 0 and h_mm > 0 and math.isfinite(w_mm) and math.isfinite(h_mm)):
        raise ValueError(f"film {film_width_mm!r} x {film_height_mm!r} mm: must be positive")
    if W < 1 or H < 1:
        raise ValueError(f"image {width_px} x {height_px} pixels: must be at least 1 x 1")
    if _is_grid(source):
        source = illumination_grid(source)
    if isinstance(source, IlluminationGrid):     # over x and y; bilinear, so a pixel's mean
        cols = (np.arange(W) + 0.5) / W - 0.5    # is its centre's value within a cell
        rows = 0.5 - (np.arange(H) + 0.5) / H
        return np.maximum(source.at_xy(cols[None, :] * w_mm + sx, rows[:, None] * h_mm + sy),
                          0.0)
    profile = source if isinstance(source, IlluminationProfile) else illumination_profile(
        source, math.hypot(0.5 * w_mm + abs(sx), 0.5 * h_mm + abs(sy)))
    r = _pixel_radii(w_mm, h_mm, W, H, (sx, sy))
    out = profile.at(r)
    if pixel_average:
        h = 0.5 * math.hypot(w_mm / W, h_mm / H)           # half the pixel's diagonal
        bend = np.abs(profile.at(r + h) + profile.at(np.maximum(r - h, 0.0)) - 2.0 * out)
        rows, cols = np.nonzero(bend > CURVATURE_TOLERANCE)
        if rows.size:
            f = (np.arange(OVERSAMPLE) + 0.5) / OVERSAMPLE
            x = ((cols[:, None, None] + f[None, None, :]) / W - 0.5) * w_mm + sx
            y = (0.5 - (rows[:, None, None] + f[None, :, None]) / H) * h_mm + sy
            out[rows, cols] = profile.at(np.hypot(x, y)).mean(axis=(1, 2))
    return np.maximum(out, 0.0)
