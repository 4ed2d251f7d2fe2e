"""Anamorphic surfaces: toroids and cylinders (Zemax's ``TOROIDAL``), their sag, slopes,
domain, file form, and the fast tracer's intersection.

A row is *toric* when its radius in the x-z section, ``LensPrescription.radius_x_mm``,
differs from its radius in the y-z section, ``radius_mm`` (0 = flat in that section).
The surface (sag positive toward the film, mm) is Zemax's TOROIDAL: the y-z profile

    z_y(y) = c_y y^2 / (1 + sqrt(1 - (1 + k) c_y^2 y^2)) + a2 y^2 + a4 y^4 + ... + a16 y^16

(c_y = 1/radius_mm; k and a2 .. a16 the row's ``#!asphere`` terms, all 0 without one)
rotated about the axis parallel to y through (x, z) = (0, R_x), R_x = radius_x_mm
(0: no rotation, a cylinder flat in x).  That is ``(R_x - z)^2 + x^2 = (R_x - z_y)^2``,
evaluated without cancellation as

    z(x, y) = z_y(y) + kappa x^2 / (1 + sqrt(1 - kappa^2 x^2)),
    kappa(y) = c_x / (1 - c_x z_y(y)),      c_x = 1/R_x (0 when flat in x),

kappa being the curvature of the x-section at height y.  Its slopes are
``dz/dx = kappa x / q`` and ``dz/dy = z_y'(y) / q`` with ``q = sqrt(1 - kappa^2 x^2)``.
The surface exists where the profile does (``(1 + k) c_y^2 y^2 <= 1``), the profile stays
on the vertex's side of the rotation axis (``1 - c_x z_y > 0``) and ``kappa^2 x^2 <= 1``.
At the vertex its curvatures are ``c_y + 2 a2`` in y and ``c_x`` in x.

lentil's ``cyl-y`` (cylinder axis along y, curving in x) is radius 0 with R_x = R;
``cyl-x`` (axis along x, curving in y) is radius R with R_x = 0.  A *pure cylinder* (no
profile terms, one of c_x, c_y zero; the y-cylinder may have a conic) is the quadric
``c_x x^2 + c_y y^2 + m s^2 - 2 s = 0`` (m = c_x, or c_y (1 + k) when c_x = 0) and is
intersected in closed form, the stable root chosen as for the sphere
(:mod:`povlens.lens.tracer`).  Any other toric row starts from that quadric's crossing
(exact to second order, and to fourth in x) or, where the ray misses it, from the vertex
tangent plane, and Newton's method on ``F(t) = s(t) - z(x(t), y(t))``,
``F' = d_s - z_x d_x - z_y d_y`` takes it to the surface (``NEWTON_MAX_ITER`` steps at
most, converged below ``NEWTON_RTOL (1 + |t|)`` mm).  A ray that does not converge,
lands outside the domain, meets the surface behind itself or crosses it against the
travel sense is blocked; the unit normal is ``(-z_x, -z_y, 1) / sqrt(1 + z_x^2 + z_y^2)``.

In a lens file a toric row carries ``#!toric rx=R`` (R in mm, 0 = flat in x); the row's
radius column is its y-z section, so Kolb readers that skip the comment see the exact
y-z meridian.  With ``#!asphere`` on the same row the terms are the y-z profile's
(Zemax's TOROIDAL with CONI and its polynomial); a row whose ``rx`` equals its radius is a
sphere (the directive is dropped) unless it also has asphere terms, which is refused
(the surface would be neither the rotationally symmetric asphere nor clearly a toroid).
"""

from __future__ import annotations

import math

import numpy as np

from povlens.lens import asphere as _asph

__all__ = ["DIRECTIVE", "NEWTON_MAX_ITER", "NEWTON_RTOL", "toric_rows", "radius_x_or_y",
           "curvature_x_per_mm", "paraxial_curvatures_per_mm", "row_params", "sag_mm",
           "slopes", "inside_domain", "row_sag_xy", "row_sag_range_mm",
           "row_domain_radius_mm", "intersect", "parse_directive", "format_directive",
           "row_problem", "describe_row"]

#: The comment that carries a row's x-z radius.
DIRECTIVE = "!toric"
#: Newton steps at most per toric surface, and the relative step of convergence.
NEWTON_MAX_ITER = 50
NEWTON_RTOL = 1e-12
#: Azimuths (over a quarter turn; the surface is even in x and in y) and radii sampled
#: for a toric row's sag range.
_RANGE_ANGLES, _RANGE_RADII = 33, 129


def toric_rows(lens) -> np.ndarray:
    """(n_surfaces,) bool: the rows whose x-z radius differs from their y-z radius."""
    rx = getattr(lens, "radius_x_mm", None)
    if rx is None:
        return np.zeros(lens.n_surfaces, dtype=bool)
    return np.asarray(rx) != lens.radius_mm


def radius_x_or_y(lens) -> np.ndarray:
    """(n_surfaces,) x-z radii (mm, 0 = flat): ``radius_x_mm``, or ``radius_mm`` when the
    lens is rotationally symmetric."""
    rx = getattr(lens, "radius_x_mm", None)
    return lens.radius_mm if rx is None else np.asarray(rx)


def _inverse(r: np.ndarray) -> np.ndarray:
    r = np.asarray(r, dtype=np.float64)
    with np.errstate(divide="ignore"):
        return np.where(r == 0.0, 0.0, 1.0 / np.where(r == 0.0, 1.0, r))


def curvature_x_per_mm(lens) -> np.ndarray:
    """(n_surfaces,) vertex curvatures 1/R_x (1/mm; 0 flat in x) of the rows' x-z sections
    (for a rotationally symmetric row its base curvature 1/R)."""
    return _inverse(radius_x_or_y(lens))


def paraxial_curvatures_per_mm(lens, meridian: str) -> np.ndarray:
    """(n_surfaces,) paraxial curvatures (1/mm) in ``meridian`` ("x" or "y").

    "y": the base curvature plus twice the r^2 (on toric rows y^2) coefficient, as
    :func:`povlens.lens.asphere.paraxial_curvature_per_mm`.  "x": the same on
    rotationally symmetric rows, 1/R_x on toric rows (their profile terms are in y).
    """
    c = _asph.paraxial_curvature_per_mm(lens)
    if meridian == "y":
        return c
    if meridian != "x":
        raise ValueError(f"meridian={meridian!r}: give 'x' or 'y'")
    return np.where(toric_rows(lens), curvature_x_per_mm(lens), c)


def row_params(lens, i: int) -> tuple[float, np.ndarray, float]:
    """(c_y, profile (9,) = k, a2 .. a16, c_x) of row ``i`` (1/mm; zeros: no terms)."""
    a = getattr(lens, "asphere", None)
    row = np.zeros(_asph.N_ASPHERE) if a is None else np.asarray(a[i], dtype=np.float64)
    return (float(lens.curvature_per_mm[i]), row, float(curvature_x_per_mm(lens)[i]))


def _profile(c_y: float, row: np.ndarray, y):
    """(z_y, dz_y/dy) of the y-z profile at ``y`` (mm); clamped at the conic's rim."""
    y2 = y * y
    return _asph.sag_mm(c_y, row, y2), y * _asph.slope_over_r(c_y, row, y2)


def _kappa(c_x: float, zy):
    """Curvature (1/mm) of the x-section at profile sag ``zy``."""
    return c_x / (1.0 - c_x * zy) if c_x != 0.0 else np.zeros_like(zy)


def sag_mm(c_y: float, row: np.ndarray, c_x: float, x, y) -> np.ndarray:
    """Sag z(x, y) (mm) of a toric surface at points (x, y) (any equal shapes, mm).

    c_y, c_x : vertex curvatures (1/mm) in the y-z and x-z sections.  row : (9,) the
    profile's k, a2 .. a16.  Outside the domain the square roots are clamped at 0 (the
    value is finite but meaningless; callers check :func:`inside_domain`).
    """
    x = np.asarray(x, dtype=np.float64)
    zy, _ = _profile(c_y, row, np.asarray(y, dtype=np.float64))
    with np.errstate(all="ignore"):
        kap = _kappa(c_x, zy)
        q = np.sqrt(np.maximum(1.0 - kap * kap * x * x, 0.0))
        return zy + kap * x * x / (1.0 + q)


def slopes(c_y: float, row: np.ndarray, c_x: float, x, y) -> tuple[np.ndarray, np.ndarray]:
    """(dz/dx, dz/dy) of a toric surface at (x, y) (mm; parameters as :func:`sag_mm`);
    +-inf at the rim of the domain."""
    x = np.asarray(x, dtype=np.float64)
    zy, dzy = _profile(c_y, row, np.asarray(y, dtype=np.float64))
    with np.errstate(all="ignore"):
        kap = _kappa(c_x, zy)
        q = np.sqrt(np.maximum(1.0 - kap * kap * x * x, 0.0))
        return kap * x / q, dzy / q


def inside_domain(c_y: float, row: np.ndarray, c_x: float, x, y) -> np.ndarray:
    """Where (x, y) (mm) lies strictly inside the surface's domain (module docstring)."""
    y = np.asarray(y, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    zy, _ = _profile(c_y, row, y)
    with np.errstate(all="ignore"):
        ok = y * y < _asph.domain_r2_mm2(c_y, row[0]) if c_y != 0.0 else np.ones(y.shape, bool)
        if c_x != 0.0:
            kap = _kappa(c_x, zy)
            ok = ok & (1.0 - c_x * zy > 0.0) & (kap * kap * x * x < 1.0)
    return ok


def row_sag_xy(lens, i: int):
    """Function (x_mm, y_mm) -> sag (mm) of row ``i``, any kind of row, any equal shapes."""
    if not toric_rows(lens)[i]:
        sag = _asph.row_sag(lens, i)
        return lambda x, y: sag(np.hypot(x, y))
    c_y, row, c_x = row_params(lens, i)
    return lambda x, y: sag_mm(c_y, row, c_x, x, y)


def row_sag_range_mm(lens, i: int, r_max_mm: float) -> tuple[float, float]:
    """(min, max) sag (mm) of row ``i`` over the disc of radius ``r_max_mm``: as
    :func:`povlens.lens.asphere.sag_range_mm` for a rotationally symmetric row; a toric
    row's sampled on a polar grid (its two meridians and the rim included) and widened
    by 1e-9 of its span plus 1e-12 mm."""
    if not toric_rows(lens)[i]:
        return _asph.sag_range_mm(lens, i, r_max_mm)
    r = np.linspace(0.0, float(r_max_mm), _RANGE_RADII)[:, None]
    th = np.linspace(0.0, 0.5 * math.pi, _RANGE_ANGLES)[None, :]
    z = row_sag_xy(lens, i)(r * np.cos(th), r * np.sin(th))
    lo, hi = float(z.min()), float(z.max())
    pad = 1e-9 * (hi - lo) + 1e-12
    return lo - pad, hi + pad


def row_domain_radius_mm(lens, i: int) -> float:
    """Radius (mm) of the largest disc about the axis on which row ``i``'s surface exists
    (:func:`povlens.lens.asphere.row_domain_radius_mm` for a rotationally symmetric row):
    for a toric row the smaller of the profile's extent in y and the least distance
    ``sqrt(y^2 + (R_x - z_y)^2)`` to the edge ``|x| = |R_x - z_y(y)|``, searched on a grid
    and refined by golden section (exact for cylinders: |R_x|, or the profile's rim)."""
    if not toric_rows(lens)[i]:
        return _asph.row_domain_radius_mm(lens, i)
    c_y, row, c_x = row_params(lens, i)
    y_end = math.sqrt(_asph.domain_r2_mm2(c_y, row[0])) if c_y != 0.0 else math.inf
    if c_x == 0.0:
        return y_end
    r_x = 1.0 / c_x
    span = min(y_end, abs(r_x))

    def edge(y):
        zy = _asph.sag_mm(c_y, row, np.asarray(y, dtype=np.float64) ** 2)
        ok = 1.0 - c_x * zy > 0.0
        return np.where(ok, np.hypot(y, r_x - zy), np.nan)

    y = np.linspace(0.0, span, 1025)
    e = edge(y)
    bad = np.flatnonzero(np.isnan(e))
    if bad.size:                      # the profile crosses the rotation axis: ends there
        y_end, e = float(y[bad[0]]), e[:bad[0]]
    k = int(np.argmin(e))
    lo, hi = float(y[max(k - 1, 0)]), float(y[min(k + 1, len(e) - 1)])
    for _ in range(60):               # golden section on the bracket around the minimum
        a, b = hi - 0.618 * (hi - lo), lo + 0.618 * (hi - lo)
        if edge(a) < edge(b):
            hi = b
        else:
            lo = a
    best = min(float(e[k]), float(edge(0.5 * (lo + hi))))
    return min(best, y_end)


def _quadric_hit(c_y, k, c_x, x, y, ps, dx, dy, ds):
    """The ray parameter of the approximating quadric ``c_x x^2 + c_y y^2 + m s^2 - 2 s``
    (exact for a pure cylinder) by the stable root, whether it exists, and ``m``."""
    m = c_x if c_x != 0.0 else c_y * (1.0 + k)
    a = c_x * dx * dx + c_y * dy * dy + m * ds * ds
    B = c_x * x * dx + c_y * y * dy + m * ps * ds - ds
    C = c_x * x * x + c_y * y * y + m * ps * ps - 2.0 * ps
    t, D, same = _asph.stable_quadric_root(a, B, C, ds)
    ok = (D >= 0.0) & np.isfinite(t) & (1.0 - m * (ps + t * ds) > 0.0) & ((a != 0) | same)
    return t, ok, m


def intersect(c_y: float, row: np.ndarray, c_x: float, vertex_z: float, x, y, z, dx, dy,
              dz, sense: float, backward_tolerance_mm: float):
    """Where rays meet a toric surface (module docstring), all rays at once.

    Parameters
    ----------
    c_y, row, c_x : the surface (:func:`row_params`).
    vertex_z : camera-frame z (mm) of its vertex.
    x, y, z, dx, dy, dz : (n,) ray origins (mm) and unit directions, camera frame.
    sense : +1 toward the film, -1 toward the scene (the travel sense of s = vertex_z - z).
    backward_tolerance_mm : a hit more than this far behind the ray is blocked.

    Returns
    -------
    hx, hy, hs : (n,) hit points in the local frame (mm; s toward the film).
    bad : (n,) bool, the rays blocked (module docstring).
    normal : tuple of three (n,) arrays, the unit normal (nx, ny, ns), +s at the vertex.
    """
    ps, ds = vertex_z - z, -dz
    t, ok, m = _quadric_hit(c_y, float(row[0]), c_x, x, y, ps, dx, dy, ds)
    pure = not np.any(row[1:] != 0.0) and (c_x == 0.0 or c_y == 0.0)
    if pure:                                   # an exact quadric: closed form
        done = ok
    else:
        t, done = _newton(c_y, row, c_x, x, y, ps, dx, dy, ds, np.where(ok, t, -ps / ds))
    hx, hy, hs = x + t * dx, y + t * dy, ps + t * ds
    if pure:
        nx, ny, ns = -c_x * hx, -c_y * hy, 1.0 - m * hs
        inside = ok
    else:
        fx, fy = slopes(c_y, row, c_x, hx, hy)
        nx, ny, ns = -fx, -fy, np.ones_like(fx)
        inside = inside_domain(c_y, row, c_x, hx, hy) & (np.sign(ds - fx * dx - fy * dy) == sense)
    inv = 1.0 / np.sqrt(nx * nx + ny * ny + ns * ns)
    bad = (~done | ~inside | ~np.isfinite(t) | (t < -backward_tolerance_mm)
           | (np.sign(ds) != sense) | ~np.isfinite(inv))
    return hx, hy, hs, bad, (nx * inv, ny * inv, ns * inv)


def _newton(c_y, row, c_x, x, y, ps, dx, dy, ds, t):
    """Newton's method on F(t) = s(t) - z(x(t), y(t)) from ``t``: (t, converged)."""
    done = np.zeros(t.shape, dtype=bool)
    for _ in range(NEWTON_MAX_ITER):
        hx, hy = x + t * dx, y + t * dy
        fx, fy = slopes(c_y, row, c_x, hx, hy)
        f = ps + t * ds - sag_mm(c_y, row, c_x, hx, hy)
        step = np.where(done, 0.0, f / (ds - fx * dx - fy * dy))
        t = t - step
        done |= np.abs(step) <= NEWTON_RTOL * (1.0 + np.abs(t))
        if done.all():
            break
    return t, done


def parse_directive(comment: str, where: str) -> float:
    """R_x (mm, 0 = flat in x) of a ``!toric rx=R`` comment (``#`` removed).

    Raises ValueError naming what is wrong (``where`` prefixes it; the caller adds file
    and line).
    """
    body = comment.strip()[len(DIRECTIVE):].split("#", 1)[0].split()
    usage = ("write '#!toric rx=R' with R the radius (mm) of the x-z section, 0 for "
             "flat in x; the row's radius column is its y-z section")
    if len(body) != 1:
        shown = "nothing" if not body else repr(" ".join(body))
        raise ValueError(f"{where}{shown} given; {usage}")
    name, eq, value = body[0].partition("=")
    if name.strip().lower() != "rx" or not eq:
        raise ValueError(f"{where}'{body[0]}' is not rx=<radius>; {usage}")
    try:
        v = float(value)
    except ValueError:
        raise ValueError(f"{where}rx: '{value}' is not a number; {usage}") from None
    if not math.isfinite(v):
        raise ValueError(f"{where}rx: '{value}' is not a finite number; {usage}")
    return v


def format_directive(radius_x_mm: float) -> str:
    """``#!toric rx=R`` (17 significant digits: reading it back is exact)."""
    return f"#{DIRECTIVE} rx={radius_x_mm:.17g}"


def row_problem(radius_mm: float, radius_x_mm: float, profile, air_both_sides: bool
                ) -> str | None:
    """Why a row with these radii (mm), profile terms (9 floats or None) and media cannot
    be a toric row, or None when it can (or is not toric)."""
    aspheric = profile is not None and any(float(v) != 0.0 for v in profile)
    if radius_x_mm == radius_mm:
        if aspheric and radius_mm != 0.0:
            return (f"its x-z radius equals its y-z radius ({radius_mm:g} mm) and it has "
                    f"asphere terms: a toroid of equal radii with an aspheric profile is "
                    f"not rotationally symmetric; povlens cannot tell which is meant")
        return None
    if radius_mm == 0.0 and air_both_sides:
        return ("it is a plane in air on both sides (an aperture row) with an x-z radius, "
                "which would bend no light")
    return None


def describe_row(radius_mm: float, radius_x_mm: float) -> str:
    """A toric row in words: ``cylinder (x-z radius 4.45 mm, flat in y)``."""
    if radius_mm == 0.0:
        return f"cylinder (x-z radius {radius_x_mm:g} mm, flat in y)"
    if radius_x_mm == 0.0:
        return f"cylinder (y-z radius {radius_mm:g} mm, flat in x)"
    return f"toroid (y-z radius {radius_mm:g} mm, x-z radius {radius_x_mm:g} mm)"
