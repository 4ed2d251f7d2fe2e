"""The relative illumination of a lens without rotational symmetry, over the film's x and y.

The irradiance a uniform scene of unit radiance gives at the film point f (the camera
measurement equation, :mod:`povlens.pupil.illumination`) is

    E(f) / L = integral over the pass region R(f) of z_p^2 / (|p - f|^2 + z_p^2)^2 dA(p),

p on the sampling plane z = z_p.  For an anamorphic lens E depends on f_x and f_y, not on
|f| alone, so it is computed on a grid of film points over one quadrant (the lens is
mirror-symmetric in x and y) and interpolated bilinearly (:class:`IlluminationGrid`).
At each grid point the exact boundary of the pass region is traced along
:data:`ANGLES` directions about the region's centre in the grid table's interpolated
frame (:class:`povlens.pupil.grid_prober.GridProber`), and the integral is done in that
normalised polar frame (:func:`star_irradiance`: Gauss-Legendre along each direction,
the trapezoid rule over the periodic angle).  Where the region is not found
star-shaped about that centre (a centre that is blocked, a blocked point inside the
found boundary), the point takes the table sampler's own estimate, the mean of
``weight * passed`` over :data:`FALLBACK_SAMPLES` Sobol' points
(:func:`povlens.pupil.monte_carlo.irradiance_factor_at`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from povlens.pupil.grid_prober import GridProber
from povlens.pupil.monte_carlo import irradiance_factor_at

__all__ = ["star_irradiance", "IlluminationGrid", "illumination_grid", "irradiance_at_points",
           "grid_record", "grid_from_record", "GRID_POINTS", "ANGLES", "RADIAL_NODES",
           "FALLBACK_SAMPLES"]

#: Gauss-Legendre nodes along each direction (the integrand is smooth there).
RADIAL_NODES = 12
#: Directions about the region's centre (over the whole circle).
ANGLES = 256
#: Grid points per axis of the map over the quadrant.
GRID_POINTS = 17
#: Sobol' points of the fallback estimator (the mesh render's).
FALLBACK_SAMPLES = 1 << 14
#: Points per direction checked to pass inside the found boundary (star-shapedness).
STAR_CHECKS = 4


def star_irradiance(film_xy: np.ndarray, c: np.ndarray, s: np.ndarray, rho: np.ndarray,
                    zp: float) -> np.ndarray:
    """E/L (B,) over star regions: plane points c + rho' (s_x cos t, s_y sin t),
    0 <= rho' <= rho(t), t_k = 2 pi k / A.

    Parameters
    ----------
    film_xy : (B, 2) the film points, mm.
    c, s : (B, 2) the regions' centres and scales on the plane, mm.
    rho : (B, A) boundary distances (normalised) at the A evenly spaced angles.
    zp : z of the sampling plane, mm.
    """
    f = np.asarray(film_xy, dtype=np.float64)
    A = rho.shape[1]
    t = np.arange(A) * (2.0 * math.pi / A)
    x, w = np.polynomial.legendre.leggauss(RADIAL_NODES)
    q, wq = 0.5 * (x + 1.0), 0.5 * w
    dist = rho[..., None] * q                                    # (B, A, Q)
    px = c[:, 0, None, None] + dist * (s[:, 0, None, None] * np.cos(t)[None, :, None])
    py = c[:, 1, None, None] + dist * (s[:, 1, None, None] * np.sin(t)[None, :, None])
    d2 = (px - f[:, 0, None, None]) ** 2 + (py - f[:, 1, None, None]) ** 2 + zp * zp
    g = zp * zp / (d2 * d2)
    inner = np.sum(g * dist * wq, axis=-1) * rho
    return s[:, 0] * s[:, 1] * np.sum(inner, axis=-1) * (2.0 * math.pi / A)


def _boundaries(prober: GridProber, q: np.ndarray, c, s, rho_max, n_angles: int):
    """Exact boundary distances (B, A) about the centres c along t_k = 2 pi k / A in the
    frames s, by bisection between the centre and 1.05 x the table's largest vertex
    distance (the table is conservative); and which points the quadrature may use
    (centre passes, bound blocked, the checked points inside pass)."""
    t = np.arange(n_angles) * (2.0 * math.pi / n_angles)
    ux, uy = s[:, 0, None] * np.cos(t), s[:, 1, None] * np.sin(t)
    shape = ux.shape
    fx, fy = np.broadcast_to(q[:, 0, None], shape), np.broadcast_to(q[:, 1, None], shape)
    cx, cy = np.broadcast_to(c[:, 0, None], shape), np.broadcast_to(c[:, 1, None], shape)
    ok = prober.passes(q[:, 0], q[:, 1], c[:, 0], c[:, 1]) & np.all(s > 0, axis=1) & (rho_max > 0)
    hi = np.broadcast_to((1.05 * rho_max)[:, None], shape).copy()
    ok &= ~np.any(prober.passes(fx, fy, cx + hi * ux, cy + hi * uy), axis=1)
    lo = np.zeros_like(hi)
    for _ in range(20):                               # to 1e-6 of the bound
        mid = 0.5 * (lo + hi)
        p = prober.passes(fx, fy, cx + mid * ux, cy + mid * uy)
        lo, hi = np.where(p, mid, lo), np.where(p, hi, mid)
    f = (np.arange(STAR_CHECKS) + 0.5) / STAR_CHECKS * 0.999
    st = lo[..., None] * f
    inside = prober.passes(fx[..., None], fy[..., None], cx[..., None] + st * ux[..., None],
                           cy[..., None] + st * uy[..., None])
    return 0.5 * (lo + hi), ok & inside.all(axis=(1, 2))


def irradiance_at_points(table, film_xy, *, n_angles: int = 128) -> np.ndarray:
    """E/L (m,) at film points (m, 2) mm of a grid table's lens
    (:class:`povlens.pupil.grid_table.GridPupilTable`): the quadrature over the exact
    boundary (module docstring), the table sampler's estimate where that does not apply,
    0 where the table has no ray (a dark cell, beyond its extent)."""
    f = np.asarray(film_xy, dtype=np.float64).reshape(-1, 2)
    finite = np.all(np.isfinite(f), axis=1)
    q = np.where(finite[:, None], np.abs(f), 0.0)
    c, s, rho, inside = table.frame_at(q)
    inside &= finite
    out = np.zeros(len(f))
    idx = np.nonzero(inside)[0]
    if not idx.size:
        return out
    prober = GridProber(table.lens, table.film_distance_mm, table.plane_z_mm)
    rho_b, ok = _boundaries(prober, q[idx], c[idx], s[idx], rho[idx].max(axis=1), n_angles)
    good = idx[ok]
    out[good] = star_irradiance(q[good], c[good], s[good], rho_b[ok], table.plane_z_mm)
    rest = idx[~ok]
    if rest.size:
        out[rest] = irradiance_factor_at(table, table.lens, table.film_distance_mm, q[rest],
                                         n_samples=FALLBACK_SAMPLES)
    return np.where(np.isfinite(out) & (out > 0), out, 0.0)


@dataclasses.dataclass(frozen=True)
class IlluminationGrid:
    """The lens's illumination over one quadrant of the film (mirrored to the others).

    x_mm : (Gx,) increasing |f_x| of the grid, the first 0; y_mm : (Gy,) likewise.
    relative_illumination : (Gx, Gy) E(f) / E(0), 0 where no ray passes.
    """

    x_mm: np.ndarray
    y_mm: np.ndarray
    relative_illumination: np.ndarray

    def at_xy(self, x, y) -> np.ndarray:
        """E / E(0) at film points (x, y) (any equal shapes, mm; mirrored, so image-plane
        and film coordinates give the same), bilinear between the grid's points; 0
        beyond the grid and where not finite."""
        x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64),
                                   np.asarray(y, dtype=np.float64))
        ax, ay = np.abs(x), np.abs(y)
        ok = np.isfinite(ax) & np.isfinite(ay)
        ok &= (ax <= self.x_mm[-1] * (1 + 1e-9)) & (ay <= self.y_mm[-1] * (1 + 1e-9))
        ax, ay = np.where(ok, ax, 0.0), np.where(ok, ay, 0.0)
        i = np.clip(np.searchsorted(self.x_mm, ax, side="right") - 1, 0, self.x_mm.size - 2)
        j = np.clip(np.searchsorted(self.y_mm, ay, side="right") - 1, 0, self.y_mm.size - 2)
        a = np.clip((ax - self.x_mm[i]) / (self.x_mm[i + 1] - self.x_mm[i]), 0.0, 1.0)
        b = np.clip((ay - self.y_mm[j]) / (self.y_mm[j + 1] - self.y_mm[j]), 0.0, 1.0)
        E = self.relative_illumination
        v = ((1 - a) * (1 - b) * E[i, j] + a * (1 - b) * E[i + 1, j]
             + (1 - a) * b * E[i, j + 1] + a * b * E[i + 1, j + 1])
        return np.where(ok, v, 0.0)

    def to_dict(self) -> dict:
        """JSON-able record (grid to 1e-9 mm, values to 1e-7)."""
        ri = self.relative_illumination
        return {"kind": "grid", "x_mm": [round(float(v), 9) for v in self.x_mm],
                "y_mm": [round(float(v), 9) for v in self.y_mm],
                "relative_illumination": [[round(float(v), 7) for v in row] for row in ri],
                "min_relative_illumination": round(float(ri.min()), 7)}


def illumination_grid(table, n_points: int = GRID_POINTS) -> IlluminationGrid:
    """The relative illumination of a grid table's lens on ``n_points`` x ``n_points``
    evenly spaced film points over the table's quadrant (:func:`irradiance_at_points`).

    Raises
    ------
    OpticsError
        When no ray from the film centre gets through.
    """
    from povlens.errors import OpticsError
    X, Y = table.film_extent_mm
    n = max(2, int(n_points))
    xs, ys = np.linspace(0.0, X, n), np.linspace(0.0, Y, n)
    P = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
    e = irradiance_at_points(table, P).reshape(n, n)
    if not (e[0, 0] > 0 and math.isfinite(e[0, 0])):
        raise OpticsError(f"{table.lens.source}: no ray from the film centre gets through the "
                          f"lens; there is no illumination to normalise by")
    return IlluminationGrid(xs, ys, e / e[0, 0])


def _table_key(table) -> dict:
    """What a grid depends on: the lens (stop included), film distance and the extent."""
    return {"lens_sha256": table.lens.sha256(),
            "film_distance_mm": float(table.film_distance_mm),
            "film_extent_mm": [float(v) for v in table.film_extent_mm]}


def grid_record(grid: IlluminationGrid, table) -> dict:
    """JSON-able record of ``grid`` with the key of the table it was computed from."""
    return {**_table_key(table), **grid.to_dict()}


def grid_from_record(record, table) -> IlluminationGrid | None:
    """The grid of a :func:`grid_record` if made from ``table``'s lens, film distance and
    extent and well formed, else None."""
    if not isinstance(record, dict) or record.get("kind") != "grid":
        return None
    key = _table_key(table)
    try:
        same = (record["lens_sha256"] == key["lens_sha256"]
                and abs(float(record["film_distance_mm"]) - key["film_distance_mm"])
                <= 1e-9 * max(1.0, key["film_distance_mm"])
                and np.allclose(record["film_extent_mm"], key["film_extent_mm"], rtol=1e-9))
        xs = np.asarray(record["x_mm"], dtype=np.float64)
        ys = np.asarray(record["y_mm"], dtype=np.float64)
        ri = np.asarray(record["relative_illumination"], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        return None
    if (not same or xs.ndim != 1 or ys.ndim != 1 or ri.shape != (xs.size, ys.size)
            or xs.size < 2 or ys.size < 2 or not (np.all(np.diff(xs) > 0)
                                                  and np.all(np.diff(ys) > 0))
            or not np.all(np.isfinite(ri)) or np.any(ri < 0)):
        return None
    return IlluminationGrid(xs, ys, ri)
