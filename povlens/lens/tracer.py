"""Exact real-ray tracing through a lens system, vectorized over rays.

Frames are those of :mod:`povlens.lens.coordinates` (camera frame, mm, +z toward the scene).

Algorithm (per surface, all rays at once)
-----------------------------------------
Intersection uses the curvature form of the surface, ``c |p|^2 - 2 s = 0`` in
surface-local coordinates (x, y, s), s = vertex_z - z.  Substituting the ray
``p + t d`` gives ``c t^2 + 2 B t + C = 0`` with

    B = c (p . d) - d_s,     C = c |p|^2 - 2 p_s,     D = B^2 - c C.

The wanted root is the one where the ray meets the vertex branch travelling in
the same sense as an axial ray (``n . d`` has the sign of ``d_s`` for the normal
``n = (-c x, -c y, 1 - c s)``), which is

    t = -C / (B + sigma sqrt(D)),   sigma = -sign(d_s),

evaluated as ``(sigma sqrt(D) - B) / c`` when B and sigma have opposite signs,
so that neither form cancels catastrophically (Welford, *Aberrations of Optical
Systems*, ch. 4; Spencer & Murty 1962).  For c = 0 it reduces exactly to the
plane intersection, and for tiny c it converges to it smoothly: R = 1e9 mm
differs from a plane only by its true sag (c r^2 / 2, 5e-8 mm at r = 10 mm).

Refraction is the vector form of Snell's law (Heckbert's form, as in pbrt's
``Refract``): with mu = n1/n2 and cos_i = n . d,

    d' = mu d + (sign(cos_i) sqrt(1 - mu^2 (1 - cos_i^2)) - mu cos_i) n.

Even aspheres (:mod:`povlens.lens.asphere`)
-------------------------------------------
An aspheric row is met by Newton's method on ``F(t) = s(t) - z(r(t))`` (the ray's
sag coordinate minus the surface's), ``F'(t) = d_s - (z'(r)/r) (x d_x + y d_y)``,
all rays at once, started from the ray's crossing of the base conic
``c (x^2 + y^2) + c (1 + k) s^2 - 2 s = 0`` (root chosen as for the sphere) or, where
the ray misses the conic, from the vertex tangent plane.  At most
``ASPHERE_MAX_ITER`` steps; a ray converges when its step is below
``ASPHERE_RTOL (1 + |t|)`` mm.  The unit normal is ``(-k x, -k y, 1) / sqrt(1 + k^2 r^2)``
with ``k = z'(r)/r``.  A ray that does not converge, lands beyond the conic's rim, or
crosses the surface against the travel sense (``F'`` of the wrong sign) is blocked.

Toric rows (cylinders, toroids) are met by :func:`povlens.lens.toric.intersect`: a
cylinder in closed form (a quadric, root chosen as for the sphere), a toroid by Newton's
method as the asphere, with the same blocking rules.

Blocked rays
------------
A ray is blocked at surface i when it misses the sphere (D < 0), meets it
behind itself (t < -1e-9 mm), lands on the far branch (1 - c s <= 0), lands
outside the clear aperture (x^2 + y^2 > r_i^2, also at apertures; at a shaped stop
outside its iris or mask, :mod:`povlens.lens.aperture_shape`), is
totally internally reflected, or turns back (its axial direction reverses or
becomes 0).  Blocked rays are returned with ``passed = False`` and
``blocked_at = i``; their origin and direction are the input origin and the
normalised input direction (finite), so no NaN or inf ever leaves this module.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from povlens.lens.aperture_shape import shape_margin_mm2
from povlens.lens.asphere import (aspheric_rows, domain_r2_mm2, sag_mm, slope_over_r,
                                  stable_quadric_root)
from povlens.lens.coordinates import vertex_z_mm
from povlens.lens.prescription import LensPrescription
from povlens.lens.toric import intersect as toric_intersect, row_params, toric_rows

__all__ = ["TraceResult", "UnclippedTrace", "trace_from_film", "trace_from_scene",
           "trace_unclipped_from_film", "stop_hits_from_film", "BACKWARD_TOLERANCE_MM"]

#: A ray that meets a surface more than this far *behind* itself is blocked.
BACKWARD_TOLERANCE_MM = 1e-9
#: Newton steps at most per aspheric surface, and the relative step of convergence.
ASPHERE_MAX_ITER = 50
ASPHERE_RTOL = 1e-12


@dataclasses.dataclass(frozen=True)
class TraceResult:
    """Rays after the lens, in the camera frame.

    origin_mm : (n, 3) where each passed ray leaves the last surface (blocked
        rays: their input origin).
    direction : (n, 3) unit directions (blocked rays: the input direction).
    passed : (n,) bool.
    blocked_at : (n,) int, index of the surface that blocked the ray, -1 if passed.
    """

    origin_mm: np.ndarray
    direction: np.ndarray
    passed: np.ndarray
    blocked_at: np.ndarray

    def __len__(self) -> int:
        return int(self.passed.shape[0])


def _as_rays(origin_mm, direction):
    o = np.array(origin_mm, dtype=np.float64, copy=True).reshape(-1, 3)
    d = np.array(direction, dtype=np.float64, copy=True).reshape(-1, 3)
    if o.shape != d.shape:
        raise ValueError(f"origin_mm {o.shape} and direction {d.shape} must both be (n, 3)")
    return o, d


def trace_from_film(lens: LensPrescription, film_distance_mm: float, origin_mm, direction
                    ) -> TraceResult:
    """Trace rays from the film side to the scene, rear surface first.

    origin_mm, direction : array-like (n, 3), camera frame; directions need not be
    unit and should point toward +z.  Returns rays leaving the front surface.
    """
    o, d = _as_rays(origin_mm, direction)
    return _trace(lens, film_distance_mm, o, d, toward_film=False)


def trace_from_scene(lens: LensPrescription, film_distance_mm: float, origin_mm, direction
                     ) -> TraceResult:
    """Trace rays from the scene to the film, front surface first.

    Returns rays leaving the rear surface toward the film (-z).
    """
    o, d = _as_rays(origin_mm, direction)
    return _trace(lens, film_distance_mm, o, d, toward_film=True)


def _finite_unit_rays(o: np.ndarray, d: np.ndarray):
    """Unit directions, and which rays are usable (finite origin, finite non-zero
    direction); unusable rays become the axial ray from the origin (finite, flagged)."""
    with np.errstate(all="ignore"):
        norm = np.sqrt(np.einsum("ij,ij->i", d, d))
        ok = np.isfinite(norm) & (norm > 0) & np.all(np.isfinite(o), axis=1)
        d = np.where(ok[:, None], d / np.where(ok, norm, 1.0)[:, None], np.array([0.0, 0.0, 1.0]))
        o = np.where(ok[:, None], o, 0.0)
    return o, d, ok


def _intersect(c: float, vertex_z: float, x, y, z, dx, dy, dz, sense: float):
    """Where rays meet surface (curvature ``c``, vertex at ``vertex_z``): the hit
    point in local (x, y, s) and the rays that miss it, meet it behind themselves,
    land on the far branch or travel against ``sense`` (module docstring)."""
    ps = vertex_z - z
    ds = -dz
    B = c * (x * dx + y * dy + ps * ds) - ds
    C = c * (x * x + y * y + ps * ps) - 2.0 * ps
    D = B * B - c * C
    sqrtD = np.sqrt(np.maximum(D, 0.0))
    sigma = -np.sign(ds)
    same = (np.sign(B) == sigma) | (B == 0.0)
    t = np.where(same, -C / (B + sigma * sqrtD), (sigma * sqrtD - B) / (c if c != 0 else 1.0))
    hx, hy = x + t * dx, y + t * dy
    hs = ps + t * ds
    bad = ((D < 0.0) | ~np.isfinite(t) | (t < -BACKWARD_TOLERANCE_MM)
           | (np.sign(ds) != sense) | (1.0 - c * hs <= 0.0))
    return hx, hy, hs, bad


def _intersect_asphere(c: float, row: np.ndarray, vertex_z: float, x, y, z, dx, dy, dz,
                       sense: float):
    """Where rays meet an even asphere (base curvature ``c``, ``row`` = k, a2 .. a16):
    the hit in local (x, y, s), the rays blocked, and the unit normal (module doc)."""
    ps, ds = vertex_z - z, -dz
    g = c * (1.0 + row[0])
    a = c * (dx * dx + dy * dy) + g * ds * ds
    B = c * (x * dx + y * dy) + g * ps * ds - ds
    C = c * (x * x + y * y) + g * ps * ps - 2.0 * ps
    t, D, same = stable_quadric_root(a, B, C, ds)
    conic_ok = (D >= 0.0) & np.isfinite(t) & (1.0 - g * (ps + t * ds) > 0.0) & ((a != 0) | same)
    t = np.where(conic_ok, t, -ps / ds)           # else: the vertex tangent plane
    done = np.zeros(t.shape, dtype=bool)
    for _ in range(ASPHERE_MAX_ITER):
        hx, hy = x + t * dx, y + t * dy
        r2 = hx * hx + hy * hy
        f = ps + t * ds - sag_mm(c, row, r2)
        fp = ds - slope_over_r(c, row, r2) * (hx * dx + hy * dy)
        step = np.where(done, 0.0, f / fp)
        t = t - step
        done |= np.abs(step) <= ASPHERE_RTOL * (1.0 + np.abs(t))
        if done.all():
            break
    hx, hy, hs = x + t * dx, y + t * dy, ps + t * ds
    r2 = hx * hx + hy * hy
    kappa = slope_over_r(c, row, r2)
    fp = ds - kappa * (hx * dx + hy * dy)
    inv = 1.0 / np.sqrt(1.0 + kappa * kappa * r2)
    bad = (~done | ~np.isfinite(t) | (t < -BACKWARD_TOLERANCE_MM) | (np.sign(ds) != sense)
           | (r2 >= domain_r2_mm2(c, row[0])) | (np.sign(fp) != sense) | ~np.isfinite(inv))
    return hx, hy, hs, bad, (-kappa * hx * inv, -kappa * hy * inv, inv)


def _hit(c: float, row, vertex_z: float, x, y, z, dx, dy, dz, sense: float):
    """Hit point, blocked rays and unit normal at a sphere (``row`` None), an asphere
    (``row`` its 9 terms) or a toric row (``row`` a tuple (c_y, profile, c_x),
    :func:`povlens.lens.toric.intersect`)."""
    if isinstance(row, tuple):
        c_y, profile, c_x = row
        return toric_intersect(c_y, profile, c_x, vertex_z, x, y, z, dx, dy, dz, sense,
                               BACKWARD_TOLERANCE_MM)
    if row is not None:
        return _intersect_asphere(c, row, vertex_z, x, y, z, dx, dy, dz, sense)
    hx, hy, hs, bad = _intersect(c, vertex_z, x, y, z, dx, dy, dz, sense)
    return hx, hy, hs, bad, (-c * hx, -c * hy, 1.0 - c * hs)


def _asphere_row(lens: LensPrescription, i: int):
    """Row ``i``'s asphere data, (c_y, profile, c_x) for a toric row, or None for a
    sphere."""
    if lens.radius_x_mm is not None and toric_rows(lens)[i]:
        return row_params(lens, i)
    return lens.asphere[i] if aspheric_rows(lens)[i] else None


def _refract(mu: float, normal, dx, dy, dz, sense: float):
    """Directions after refraction at the hit points (index ratio ``mu`` = n1/n2, unit
    ``normal`` (nx, ny, ns) in the local frame), and the rays totally reflected or
    turned back."""
    ds = -dz
    nx, ny, ns = normal
    cos_i = nx * dx + ny * dy + ns * ds
    k2 = 1.0 - mu * mu * (1.0 - cos_i * cos_i)
    g = np.sign(cos_i) * np.sqrt(np.maximum(k2, 0.0)) - mu * cos_i
    ex, ey, es = mu * dx + g * nx, mu * dy + g * ny, mu * ds + g * ns
    en = np.sqrt(ex * ex + ey * ey + es * es)
    ex, ey, es = ex / en, ey / en, es / en
    bad = (k2 < 0.0) | (np.sign(es) != sense) | ~np.isfinite(en) | (en == 0.0)
    return ex, ey, -es, bad


@dataclasses.dataclass(frozen=True)
class UnclippedTrace:
    """Rays traced from the film with every clear aperture ignored (camera frame).

    The unclipped ray field continues the lens's rays smoothly across every
    vignetting cut, which is what an interpolated ray mesh needs; the aperture
    margins give the exact verdict of :func:`trace_from_film` without a second trace.

    origin_mm : (n, 3) where each ray leaves the front surface (where ``exists`` is
        False: the last point reached).
    direction : (n, 3) unit directions after the front surface (likewise).
    exists : (n,) bool, the ray meets every surface and refracts (no miss, no total
        reflection), apertures aside.
    margin_mm2 : (n, S) r_i^2 - h_i^2 at surface i (clear radius squared minus the
        hit height squared; > 0 inside the aperture); -inf from the surface where
        the ray stopped existing on.  ``passed`` is the verdict of :func:`trace_from_film`.
    """

    origin_mm: np.ndarray
    direction: np.ndarray
    exists: np.ndarray
    margin_mm2: np.ndarray

    @property
    def passed(self) -> np.ndarray:
        """(n,) the verdict of :func:`trace_from_film`: no margin negative."""
        return self.exists & np.all(self.margin_mm2 >= 0.0, axis=1)


def trace_unclipped_from_film(lens: LensPrescription, film_distance_mm: float, origin_mm,
                              direction) -> UnclippedTrace:
    """Trace rays from the film to the scene as :func:`trace_from_film` does, but
    through every surface whatever its clear aperture, recording the margins.

    origin_mm, direction : array-like (n, 3), camera frame (directions toward +z).
    """
    o, d = _as_rays(origin_mm, direction)
    n, S = o.shape[0], lens.n_surfaces
    zv = vertex_z_mm(lens.thickness_mm, float(film_distance_mm))
    curv, r2max = lens.curvature_per_mm, lens.aperture_radius_mm ** 2
    margin = np.full((n, S), -np.inf)
    o, d, ok = _finite_unit_rays(o, d)
    with np.errstate(all="ignore"):
        x, y, z = o[:, 0].copy(), o[:, 1].copy(), o[:, 2].copy()
        dx, dy, dz = d[:, 0].copy(), d[:, 1].copy(), d[:, 2].copy()
        for i in range(S - 1, -1, -1):
            hx, hy, hs, bad, normal = _hit(curv[i], _asphere_row(lens, i), zv[i], x, y, z,
                                           dx, dy, dz, -1.0)
            bad |= ~ok
            m = (r2max[i] - (hx * hx + hy * hy) if i != lens.aperture_shape_row
                 else shape_margin_mm2(lens, i, hx, hy))
            margin[:, i] = np.where(bad, -np.inf, m)
            if not lens.is_aperture[i]:
                ex, ey, ez, tir = _refract(lens.index_after[i] / lens.index_before[i], normal,
                                           dx, dy, dz, -1.0)
                bad |= tir
                dx, dy, dz = (np.where(bad, dx, ex), np.where(bad, dy, ey),
                              np.where(bad, dz, ez))
            x, y, z = np.where(bad, x, hx), np.where(bad, y, hy), np.where(bad, z, zv[i] - hs)
            ok &= ~bad
    return UnclippedTrace(np.stack([x, y, z], 1), np.stack([dx, dy, dz], 1), ok, margin)


def stop_hits_from_film(lens: LensPrescription, film_distance_mm: float, origin_mm,
                        direction) -> np.ndarray:
    """(n, 2) where rays from the film cross the shaped stop (``lens.aperture_shape_row``;
    x, y mm, camera frame), traced exactly and unclipped through the rows behind it: the
    points whose mask transmission weights the rays.

    origin_mm, direction : (n, 3) camera frame, toward +z.  Rays that do not reach the stop
    get a point far outside it (transmission 0).
    """
    row = lens.aperture_shape_row
    if row < 0:
        raise ValueError("the lens has no shaped aperture stop")
    t = trace_unclipped_from_film(lens.sub_lens(row), film_distance_mm, origin_mm, direction)
    far = 1e6 * max(1.0, float(lens.aperture_radius_mm[row]))
    return np.where(t.exists[:, None], t.origin_mm[:, :2], far)


def _trace(lens: LensPrescription, film_distance_mm: float, o: np.ndarray, d: np.ndarray,
           toward_film: bool) -> TraceResult:
    n = o.shape[0]
    zv = vertex_z_mm(lens.thickness_mm, float(film_distance_mm))
    curv = lens.curvature_per_mm
    r2max = lens.aperture_radius_mm ** 2
    aperture = lens.is_aperture
    n_before, n_after = lens.index_before, lens.index_after

    o, d, ok = _finite_unit_rays(o, d)
    blocked_at = np.full(n, -1, dtype=np.int64)
    blocked_at[~ok] = lens.n_surfaces - 1 if not toward_film else 0

    order = range(lens.n_surfaces) if toward_film else range(lens.n_surfaces - 1, -1, -1)
    # Local sag coordinate s = zv - z; the axial travel sense in s is +1 toward the film.
    sense = 1.0 if toward_film else -1.0
    idx = np.nonzero(ok)[0]
    x, y, z = o[idx, 0].copy(), o[idx, 1].copy(), o[idx, 2].copy()
    dx, dy, dz = d[idx, 0].copy(), d[idx, 1].copy(), d[idx, 2].copy()

    with np.errstate(all="ignore"):
        for i in order:
            if idx.size == 0:
                break
            hx, hy, hs, bad, normal = _hit(curv[i], _asphere_row(lens, i), zv[i], x, y, z,
                                           dx, dy, dz, sense)
            if i == lens.aperture_shape_row:    # a shaped stop (iris, mask): its margin
                bad |= ~(shape_margin_mm2(lens, i, hx, hy) >= 0.0)
            else:
                bad |= hx * hx + hy * hy > r2max[i]
            if not aperture[i]:
                n1, n2 = (n_before[i], n_after[i]) if toward_film else (n_after[i], n_before[i])
                dx, dy, dz, tir = _refract(n1 / n2, normal, dx, dy, dz, sense)
                bad |= tir
            x, y, z = hx, hy, zv[i] - hs
            if bad.any():
                lost = idx[bad]
                blocked_at[lost] = i
                # Keep the last finite state of the lost rays.
                keep = ~bad
                idx = idx[keep]
                x, y, z, dx, dy, dz = x[keep], y[keep], z[keep], dx[keep], dy[keep], dz[keep]

    passed = blocked_at < 0
    out_o = o.copy()
    out_d = d.copy()
    out_o[idx] = np.stack([x, y, z], axis=1)
    out_d[idx] = np.stack([dx, dy, dz], axis=1)
    return TraceResult(out_o, out_d, passed, blocked_at)
