"""The field sampler's pupil domain for an iris: the stop's polygon, not its circle.

Field lens samples (:mod:`povlens.pupil.field`) draw one point P per sample on the table's
sampling plane (camera frame, mm), uniform on a disc of radius R_B that contains every
film point's pass region.  An iris of N blades (:mod:`povlens.lens.aperture_shape`) passes
only the polygon's share of that (0.83 for 6 straight blades), so the disc wastes samples.
The exit-pupil plane holds the stop's image, so there the pass regions of every film point
are about the stop's polygon, scaled and (for an inverting rear group) turned by 180 deg.

Domain.  D = {P : |P| <= rho(theta_P)}, rho = min(R_D q(sigma theta), R_B), with
q(theta) the iris's edge radius over the stop's (:meth:`ApertureShape.boundary_radius_mm`
at R = 1), sigma = +-1 the orientation of the stop's image (``flip``: measured by one ray
from the film centre) and R_B the round stop's bounding disc (so D is never larger).
A point is drawn as P = c(u) rho(theta_c) with c(u) the concentric map onto the unit
disc: the radial scaling keeps the angle, so the density is exactly 1 / (pi rho^2) at P
and the sample's weight uses pi rho^2 in place of pi R_B^2 (unbiased for any R_D whose
D contains every passing point).

R_D is the largest gauge |P| / q of a passing point over film points at 9 radii x 6
azimuths over one blade period (the lens is rotationally symmetric and the iris N-fold),
found on a 64 x 64 grid over each film point's (conservative, round-stop) table region
and refined by bisection outward along the rays through the outermost passing points,
searched again on 5 x 5 film points about the film point of the largest gauge, then
enlarged by :data:`DOMAIN_MARGIN`.  Tests check containment against dense random
tracing at other film points.  Masks keep the disc (their open area need not be a
star about the axis).
"""

from __future__ import annotations

import math

import numpy as np

from povlens.lens.tracer import stop_hits_from_film, trace_from_film

__all__ = ["iris_domain", "iris_point_mm", "iris_scale", "orientation_flip", "DOMAIN_MARGIN"]

#: Relative margin of R_D over the largest gauge found.
DOMAIN_MARGIN = 5e-3


def iris_scale(shape, theta, flip: bool) -> np.ndarray:
    """q(sigma theta): the iris's edge radius over the stop's at plane angle theta."""
    t = np.asarray(theta, dtype=np.float64) + (math.pi if flip else 0.0)
    return shape.boundary_radius_mm(t, 1.0)


def iris_point_mm(shape, flip: bool, domain_radius_mm: float, disc_radius_mm: float,
                  unit_disc_point) -> tuple[np.ndarray, float]:
    """The domain point (2,) mm of a point of the unit disc (2,) (the concentric map's), and
    the domain's radius rho there, min(R_D q(sigma theta), R_B): the density at the point
    is 1 / (pi rho^2)."""
    p = np.asarray(unit_disc_point, dtype=np.float64)
    q = float(iris_scale(shape, math.atan2(p[1], p[0]), flip))
    rho = min(domain_radius_mm * q, disc_radius_mm)
    return p * rho, rho


def _gauge(shape, flip, px, py) -> np.ndarray:
    return np.hypot(px, py) / iris_scale(shape, np.arctan2(py, px), flip)


def _trace_pass(lens, fd, zp, f, px, py) -> np.ndarray:
    n = px.size
    o = np.zeros((n, 3))
    o[:, 0], o[:, 1] = f[0], f[1]
    d = np.stack([px.ravel() - f[0], py.ravel() - f[1], np.full(n, zp)], 1)
    return trace_from_film(lens, fd, o, d).passed


def orientation_flip(lens, film_distance_mm: float, plane_z_mm: float, probe_mm: float) -> bool:
    """Whether the stop's image on the plane is turned 180 deg (a ray from the film centre
    toward (probe, 0) crosses the stop at negative x)."""
    hit = stop_hits_from_film(lens, film_distance_mm, np.zeros((1, 3)),
                              np.array([[probe_mm, 0.0, plane_z_mm]]))
    return bool(hit[0, 0] < 0.0)


def iris_domain(lens, film_distance_mm: float, table, grid: int = 64, n_radii: int = 9,
                n_azimuths: int = 6) -> tuple[float, bool, dict]:
    """R_D (mm), flip, and stats {gauge_points, film_points} for a lens with an iris.

    Parameters
    ----------
    lens : the lens with ``aperture_shape`` (blades) at its stop.
    film_distance_mm : rear vertex to film, mm.
    table : the plan's :class:`povlens.pupil.table.PupilTable` (round-stop regions).
    grid, n_radii, n_azimuths : the search's resolution (module docstring).
    """
    shape, zp = lens.aperture_shape, table.plane_z_mm
    flip = orientation_flip(lens, film_distance_mm, zp, 0.1 * table.region(0.0)[:, 0].max())
    period = 2.0 * math.pi / shape.blades
    r_max = table.max_film_radius_mm
    radii = np.linspace(0.0, r_max, n_radii)
    film = [(r, phi) for r in radii
            for phi in (np.arange(n_azimuths) * period / n_azimuths if r > 0 else [0.0])]
    found = [(_film_point_gauge(lens, film_distance_mm, table, shape, flip, r, phi, grid), r, phi)
             for r, phi in film]
    # a second, finer pass about the film point of the largest gauge
    g0, r0, phi0 = max(found)
    dr, dphi = r_max / max(n_radii - 1, 1), period / n_azimuths
    finer = [(r, phi) for r in np.clip(r0 + dr * np.linspace(-1, 1, 5), 0.0, r_max)
             for phi in phi0 + dphi * np.linspace(-1, 1, 5)]
    best = max([g0] + [_film_point_gauge(lens, film_distance_mm, table, shape, flip, r, phi,
                                         grid) for r, phi in finer])
    return best * (1.0 + DOMAIN_MARGIN), flip, {"film_points": len(film) + len(finer),
                                                "grid": grid}


def _film_point_gauge(lens, fd, table, shape, flip, r, phi, grid) -> float:
    """Largest gauge of a passing point for the film point at radius r, azimuth phi:
    a grid over its round-stop table region (rotated to phi), then :func:`_refine`."""
    poly = table.region(float(r))
    if not len(poly):
        return 0.0
    zp = table.plane_z_mm
    c, s = math.cos(phi), math.sin(phi)
    reg = poly @ np.array([[c, s], [-s, c]])       # rotated by phi
    f = np.array([r * c, r * s])
    lo, hi = reg.min(0), reg.max(0)
    gx = np.linspace(lo[0], hi[0], grid)
    gy = np.linspace(lo[1], hi[1], grid)
    X, Y = np.meshgrid(gx, gy)
    ok = _trace_pass(lens, fd, zp, f, X.ravel(), Y.ravel())
    if not ok.any():
        return 0.0
    px, py = X.ravel()[ok], Y.ravel()[ok]
    g = _gauge(shape, flip, px, py)
    top = np.argsort(g)[-16:]
    return max(float(g.max()), _refine(lens, fd, zp, f, px[top], py[top], g[top],
                                       2.0 * math.hypot(gx[1] - gx[0], gy[1] - gy[0]),
                                       shape, flip))


def _refine(lens, fd, zp, f, px, py, g, step_mm, shape, flip) -> float:
    """Largest gauge along the rays from the axis through passing points (px, py):
    bisection of the scale t in [1, 1 + step / |P|] (24 halvings)."""
    norm = np.hypot(px, py)
    lo = np.ones_like(px)
    hi = 1.0 + step_mm / np.maximum(norm, 1e-12)
    for _ in range(24):
        mid = 0.5 * (lo + hi)
        ok = _trace_pass(lens, fd, zp, f, px * mid, py * mid)
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    return float(np.max(g * lo))
