"""Toric rows (cylinders, toroids) for the reference tracer: one ray at a time, plain
``float`` arithmetic, sharing no code with :mod:`povlens.lens.toric` (the fast path).

The surface is Zemax's TOROIDAL (see :mod:`povlens.lens.toric` for the definition): the
y-z profile ``z_y(y)`` (conic plus even polynomial, summed term by term here) rotated
about the axis parallel to y through z = R_x.  Here it is written as the rotation itself,

    z(x, y) = R_x - sign(R_x) sqrt((R_x - z_y(y))^2 - x^2)      (R_x finite)
    z(x, y) = z_y(y)                                               (R_x infinite, rx = 0)

and the normal is the gradient of the implicit form ``G = (R_x - z)^2 + x^2 - (R_x -
z_y)^2``, i.e. along ``(-sign(R_x) x, -|R_x - z_y| z_y', sqrt((R_x - z_y)^2 - x^2))``
(for R_x infinite ``(0, -z_y', 1)``), normalised; the profile's slope is the quotient-rule
derivative of the conic part.  The fast tracer uses an algebraically equal curvature form.

Intersection, as the reference tracer does for aspheres: the ray is clipped to the part
inside the cylinder ``r <= rho`` (rho: the clear radius, or less where the surface's
domain ends, estimated here on a grid of heights) and inside the slab of the surface's
sag range (sampled on a polar grid, widened); ``H(t) = sense (s(t) - z(x(t), y(t)))`` is
sampled at ``SAMPLES`` points along it and its first sign change from <= 0 to > 0 is
bisected to float resolution.  A ray already past the surface where it enters the
cylinder is blocked ("aperture"), one that never crosses it ("miss").
"""

from __future__ import annotations

import dataclasses
import math

__all__ = ["ToricSurface", "make_surface", "sag", "unit_normal", "intersect", "SAMPLES"]

#: Points along the ray's window at which H is sampled before bisection.
SAMPLES = 64


@dataclasses.dataclass(frozen=True)
class ToricSurface:
    """One toric row for the reference tracer.

    c_y : curvature (1/mm) of the y-z profile.  coef : (k, a2, .., a16) of the profile.
    r_x : radius of rotation (mm); 0 means infinite (a cylinder flat in x).
    rho_mm : radius of the cylinder searched (clear radius, or where the domain ends).
    sag_lo_mm, sag_hi_mm : the sag range over that disc, widened.
    """

    c_y: float
    coef: tuple
    r_x: float
    rho_mm: float = 0.0
    sag_lo_mm: float = 0.0
    sag_hi_mm: float = 0.0


def _profile(srf: ToricSurface, y: float) -> float | None:
    """z_y(y) (mm), term by term; None beyond the conic's rim."""
    c, k = srf.c_y, srf.coef[0]
    y2 = y * y
    arg = 1.0 - (1.0 + k) * c * c * y2
    if arg < 0.0:
        return None
    z, power = c * y2 / (1.0 + math.sqrt(arg)), y2
    for a in srf.coef[1:]:
        z += a * power
        power *= y2
    return z


def _profile_slope(srf: ToricSurface, y: float) -> float:
    """dz_y/dy (quotient rule on the conic part, then the polynomial's derivative)."""
    c, k = srf.c_y, srf.coef[0]
    y2 = y * y
    w = math.sqrt(max(1.0 - (1.0 + k) * c * c * y2, 0.0))
    if w > 0.0:
        conic = y * (2.0 * c * (1.0 + w) + (1.0 + k) * c ** 3 * y2 / w) / (1.0 + w) ** 2
    else:
        conic = math.copysign(math.inf, c * y) if c * y != 0.0 else 0.0
    poly, power = 0.0, y
    for i, a in enumerate(srf.coef[1:], start=1):
        poly += 2.0 * i * a * power
        power *= y2
    return conic + poly


def sag(srf: ToricSurface, x: float, y: float) -> float | None:
    """z(x, y) (mm) by the rotation itself; None outside the surface's domain."""
    zy = _profile(srf, y)
    if zy is None:
        return None
    if srf.r_x == 0.0:
        return zy
    rho = srf.r_x - zy
    if rho * srf.r_x <= 0.0 or x * x > rho * rho:
        return None
    return srf.r_x - math.copysign(math.sqrt(rho * rho - x * x), srf.r_x)


def unit_normal(srf: ToricSurface, x: float, y: float) -> tuple[float, float, float] | None:
    """Unit normal (nx, ny, ns) at (x, y), +s at the vertex (the implicit form's
    gradient); None where it does not exist (outside the domain, or at its rim)."""
    zy = _profile(srf, y)
    if zy is None:
        return None
    slope = _profile_slope(srf, y)
    if srf.r_x == 0.0:
        nx, ny, ns = 0.0, -slope, 1.0
    else:
        rho = srf.r_x - zy
        w2 = rho * rho - x * x
        if rho * srf.r_x <= 0.0 or w2 < 0.0:
            return None
        nx, ny, ns = (-x if srf.r_x > 0.0 else x), -abs(rho) * slope, math.sqrt(w2)
    norm = math.sqrt(nx * nx + ny * ny + ns * ns)
    if not (math.isfinite(norm) and norm > 0.0 and ns > 0.0):
        return None
    return nx / norm, ny / norm, ns / norm


def _domain_radius(srf: ToricSurface) -> float:
    """Radius (mm) of the disc about the axis on which the surface exists, estimated on a
    grid of 2049 heights (exact for cylinders)."""
    c, k = srf.c_y, srf.coef[0]
    g = (1.0 + k) * c * c
    y_end = 1.0 / math.sqrt(g) if g > 0.0 else math.inf
    if srf.r_x == 0.0:
        return y_end
    best = abs(srf.r_x)
    span = min(y_end, abs(srf.r_x))
    for j in range(2049):
        y = span * j / 2048
        zy = _profile(srf, y)
        if zy is None or (srf.r_x - zy) * srf.r_x <= 0.0:
            return min(best, y)
        best = min(best, math.hypot(y, srf.r_x - zy))
    return min(best, y_end)


def make_surface(c_y: float, coef: tuple, r_x: float, r_clear_mm: float) -> ToricSurface:
    """A :class:`ToricSurface` with its search radius and widened sag range."""
    srf = ToricSurface(float(c_y), tuple(float(v) for v in coef), float(r_x))
    rho = min(float(r_clear_mm), _domain_radius(srf))
    sags = []
    for i in range(65):
        r = rho * i / 64
        for j in range(33):
            th = 0.5 * math.pi * j / 32
            z = sag(srf, r * math.cos(th), r * math.sin(th))
            if z is not None:
                sags.append(z)
    lo, hi = min(sags), max(sags)
    margin = 1e-3 * (1.0 + hi - lo)
    return dataclasses.replace(srf, rho_mm=rho, sag_lo_mm=lo - margin, sag_hi_mm=hi + margin)


def _window(srf: ToricSurface, x, y, s, dx, dy, ds) -> tuple[float, float] | None:
    """Ray parameters [t_a, t_b] inside the cylinder r <= rho and the sag slab, or None."""
    ta, tb = sorted(((srf.sag_lo_mm - s) / ds, (srf.sag_hi_mm - s) / ds))
    a2 = dx * dx + dy * dy
    if a2 > 0.0:
        b = x * dx + y * dy
        disc = b * b - a2 * (x * x + y * y - srf.rho_mm * srf.rho_mm)
        if disc < 0.0:
            return None
        sq = math.sqrt(disc)
        ta, tb = max(ta, (-b - sq) / a2), min(tb, (-b + sq) / a2)
    elif x * x + y * y > srf.rho_mm * srf.rho_mm:
        return None
    return (ta, tb) if ta < tb else None


def intersect(srf: ToricSurface, x: float, y: float, s: float, dx: float, dy: float,
              ds: float) -> tuple[float, float, float, float] | str:
    """The hit (hx, hy, hs) and ray parameter t (mm) of the ray (x, y, s) + t (dx, dy, ds)
    (local frame, ds != 0 in the travel sense), or the reason it is blocked: "aperture"
    or "miss" (module docstring)."""
    sense = 1.0 if ds > 0.0 else -1.0

    def h(t: float) -> float | None:
        z = sag(srf, x + t * dx, y + t * dy)
        return None if z is None else sense * (s + t * ds - z)

    win = _window(srf, x, y, s, dx, dy, ds)
    if win is None:
        return "aperture"
    ta, tb = win
    prev_t, prev_h = ta, h(ta)
    if prev_h is None or prev_h > 0.0:
        return "aperture" if prev_h is not None else "miss"
    for j in range(1, SAMPLES + 1):
        t = ta + (tb - ta) * j / SAMPLES
        ht = h(t)
        if ht is None:
            return "miss"
        if ht > 0.0:
            break
        prev_t = t
    else:
        return "miss"
    lo, hi = prev_t, t                  # H(lo) <= 0 < H(hi)
    while True:
        mid = 0.5 * (lo + hi)
        if not lo < mid < hi:
            break
        hm = h(mid)
        if hm is None:
            return "miss"
        if hm > 0.0:
            hi = mid
        else:
            lo = mid
    t = lo if h(lo) == 0.0 else 0.5 * (lo + hi)
    hx, hy = x + t * dx, y + t * dy
    z = sag(srf, hx, hy)
    if z is None:
        return "miss"
    return hx, hy, z, t
