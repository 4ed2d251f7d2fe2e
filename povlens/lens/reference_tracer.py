"""Reference real-ray tracer: one ray at a time, written for clarity, not speed.

This module exists to check :mod:`povlens.lens.tracer` (the fast, vectorized tracer).
It shares no tracing code with it and uses a different derivation, so that a
mistake in either shows up as a disagreement (see :mod:`povlens.lens.check`).
Everything per ray is plain Python ``float`` arithmetic with :mod:`math`.

Frames and units
----------------
Camera frame of :mod:`povlens.lens.coordinates`: millimetres, film at z = 0, +z toward the
scene, rear vertex at ``z = film_distance_mm``.  Inside the loop each surface i
uses its local sag coordinates (x, y, s) with ``s = vertex_z_mm[i] - z`` (s grows
toward the film) and the ray direction ``(dx, dy, ds)`` with ``ds = -dz``.

Derivation (differs from the fast tracer on purpose)
---------------------------------------------------
*Intersection.*  The surface is the graph ``s = sag(r) = c r^2 / (1 + sqrt(1 - c^2 r^2))``
over the disc ``c^2 r^2 <= 1`` (the vertex branch of the sphere; c = 1/R).  The ray
is first carried to the vertex tangent plane s = 0 (parameter ``t0 = -s/ds``,
point p0), then Newton's method solves ``F(u) = u ds - sag(|p0_xy + u d_xy|) = 0``
for the remaining parameter u, with ``F'(u) = ds - k (x dx + y dy)`` and
``k = sag'(r)/r = c / sqrt(1 - c^2 r^2)``.  Iteration stops when the Newton step is
below 1e-15 (1 + |u|) mm, or when rounding stalls it below 1e-10 (1 + |u|) mm.

Why this finds the right root.  ``H = sign(c) F`` is concave on the disc (sag is
convex in r for c > 0, r is convex in u), so it has at most two roots.  The wanted
one is the root crossed in the travel sense of an axial ray, ``sign F' = sign ds``
(the same root the fast tracer selects through the sign of ``n . d``): the left
root of H when ``sigma = sign(c) sign(ds) = +1``, the right root otherwise.  Every
root has s = sag(r) of the sign of c, so all roots lie on the sigma side of the
tangent-plane point u = 0, where ``H = -|sag(r0)| <= 0``.  Newton on a concave
function from a point with H <= 0 outside its roots moves monotonically onto the
nearest root, without overshooting.  If F' has the wrong sign at an iterate, or
an iterate leaves the disc, there is no such root: the ray misses the sphere or
would cross it in the wanted sense only on its far branch, and is blocked.

When the tangent-plane point lies outside the disc (steep rays at strongly curved
surfaces) Newton starts instead where the ray enters the clear-radius cylinder on
the sigma side; see :func:`_intersect_from_outside_disc` for that case and for a
clear radius equal to |R| (hemisphere), where the sag slope is infinite at the rim.

*Even aspheres* (:mod:`povlens.lens.asphere`) are met without Newton's method, by
bracketing and bisection: the ray is clipped to the part of it inside the cylinder
r <= min(clear radius, conic rim) and between the sag's extreme values (sampled once
per surface on 513 radii, widened by a margin), ``H(t) = sense (s(t) - z(r(t)))`` is
sampled at ``_ASPHERE_SAMPLES`` points along it, and the first sign change is
bisected to float resolution.  The wanted crossing is that first change if it goes
from H <= 0 to H > 0 (crossed in the travel sense); a ray that is already past the
surface where it enters the cylinder, first crosses it the other way, or never
crosses it is blocked ("aperture" or "miss").  The sag here is summed term by term
(not Horner) and its slope is the conic part's quotient-rule derivative
``(2 c (1 + w) + (1 + k) c^3 r^2 / w) / (1 + w)^2``, w = sqrt(1 - (1 + k) c^2 r^2),
equal to the fast tracer's ``c / w`` only algebraically.

*Toric rows* (cylinders, toroids; :mod:`povlens.lens.reference_toric`) the same way, by
bracketing and bisection of the sag written as the rotation of the y-z profile, with the
normal from the gradient of the implicit surface.

*Normal.*  From the sag derivative: ``N = (-k x, -k y, 1) / sqrt(1 + k^2 r^2)``,
oriented along the travel sense.

*Refraction.*  Snell's law in tangential / normal components: with unit d and N,
``cos_i = N . d``, tangential part ``d_t = d - cos_i N``; the refracted ray keeps the
tangential direction scaled by ``mu = n1/n2``: ``d' = mu d_t + cos_t N`` with
``cos_t = sqrt(1 - mu^2 |d_t|^2)``.  ``mu^2 |d_t|^2 > 1`` is total internal
reflection.

Blocking rules (identical to :mod:`povlens.lens.tracer`)
---------------------------------------------------
A ray is blocked at surface i (``blocked_at = i``) when, at that surface,

* its axial direction is not in the travel sense (``ds`` must be > 0 toward the
  film, < 0 toward the scene) -- on arrival, or after refraction ("turned-back");
* it misses the sphere or would meet it on the far branch ("miss");
* it meets the surface more than ``BACKWARD_TOLERANCE_MM`` = 1e-9 mm behind
  itself ("behind");
* the hit is outside the clear aperture, ``x^2 + y^2 > r_i^2``, at every row
  including apertures ("aperture"); aperture rows (``lens.is_aperture``) only clip;
* it is totally internally reflected ("tir").

An input ray with zero or non-finite direction or non-finite origin is blocked at
the first surface it would meet ("invalid-ray").

Borderline bookkeeping (used by :mod:`povlens.lens.check`)
-----------------------------------------------------
Each traced ray also reports ``edge_margin``, the smallest ``|r_hit - r_i| / r_i``
over the surfaces it met (including the one that blocked it, when a hit point was
found), and ``borderline``, the name of the first threshold it came within
``BORDERLINE_TOL`` of: "grazing" (``cos_i`` or ``|F'|`` below it), "tir"
(``|1 - mu^2 |d_t|^2|`` below it), "turning" (``|ds|`` below it), "behind" (the ray
parameter t within 0.5e-9 mm of the -1e-9 mm limit) or "newton" (no convergence).
A ray whose tangent-plane point lies outside the disc and that is blocked at a
surface whose clear radius equals |R| gets ``edge_margin <= 1e-7`` (see
:func:`_intersect_from_outside_disc`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from povlens.lens import reference_toric
from povlens.lens.aperture_shape import T_MIN
from povlens.lens.coordinates import vertex_z_mm
from povlens.lens.prescription import LensPrescription

__all__ = ["RayTrace", "ReferenceTraceResult", "trace_ray_from_film", "trace_ray_from_scene",
           "trace_rays_from_film", "trace_rays_from_scene", "BACKWARD_TOLERANCE_MM",
           "BORDERLINE_TOL"]

#: A ray that meets a surface more than this far (mm) *behind* itself is blocked.
BACKWARD_TOLERANCE_MM = 1e-9
#: Dimensionless distance to a threshold (cos_i, TIR radicand, axial direction,
#: edge radius relative to the clear radius) below which a ray is "borderline".
BORDERLINE_TOL = 1e-6

_NEWTON_MAX_ITER = 60
_NEWTON_RTOL = 1e-15
_NEWTON_STALL_RTOL = 1e-10
_RIM_RTOL = 1e-7
_ASPHERE_SAMPLES = 64


@dataclasses.dataclass(frozen=True)
class RayTrace:
    """One ray after the lens, camera frame.

    origin_mm : (x, y, z) in mm.  For a passed ray, where it leaves the last
        surface.  For a blocked ray, its last finite state *before* the blocking
        surface: the hit point on the last surface it crossed, or its (sanitized)
        input origin if the first surface blocked it.
    direction : (dx, dy, dz), unit; same convention as ``origin_mm``.
    passed : True if the ray got through every surface.
    blocked_at : index of the blocking surface (prescription row), -1 if passed.
    reason : "" if passed, else one of "invalid-ray", "turned-back", "miss",
        "behind", "aperture", "tir".  (The fast tracer has no reasons; only the
        blocking surface is comparable.  A ray that never comes within the clear
        radius may be labelled "miss" or "aperture".)  An invalid ray gets its finite
        origin components (others 0) and the axial unit direction of travel.
    edge_margin : min over the surfaces met of |r_hit - r_clear| / r_clear
        (dimensionless; ``inf`` if no hit point was found).
    borderline : "" or the first threshold the ray came close to (see module doc).
    """

    origin_mm: tuple[float, float, float]
    direction: tuple[float, float, float]
    passed: bool
    blocked_at: int
    reason: str = ""
    edge_margin: float = math.inf
    borderline: str = ""


@dataclasses.dataclass(frozen=True)
class ReferenceTraceResult:
    """Many rays traced by the reference tracer (same layout as ``tracer.TraceResult``).

    origin_mm : (n, 3) float64, mm, camera frame.
    direction : (n, 3) float64, unit.
    passed : (n,) bool.
    blocked_at : (n,) int64, -1 if passed.
    reason : (n,) object array of str ("" if passed).
    edge_margin : (n,) float64, see :class:`RayTrace`.
    borderline : (n,) object array of str ("" if none).
    """

    origin_mm: np.ndarray
    direction: np.ndarray
    passed: np.ndarray
    blocked_at: np.ndarray
    reason: np.ndarray
    edge_margin: np.ndarray
    borderline: np.ndarray

    def __len__(self) -> int:
        return int(self.passed.shape[0])


@dataclasses.dataclass(frozen=True)
class _Surface:
    index: int
    vertex_z_mm: float
    c: float                 # curvature 1/R, 1/mm (0 = plane)
    r_clear_mm: float        # clear radius
    is_aperture: bool        # clips only
    n_scene_side: float      # refractive index on the scene side (before the row)
    n_film_side: float       # refractive index on the film side (after the row)
    shape: object = None     # ApertureShape of a shaped stop row, else None
    asphere: tuple | None = None   # (k, a2, .., a16) of an aspheric row, else None
    rho_mm: float = 0.0            # asphere: radius searched, min(clear, conic rim)
    sag_range_mm: tuple = (0.0, 0.0)   # asphere: (min, max) sag over r <= rho, widened
    toric: object = None           # reference_toric.ToricSurface of a toric row, else None


def _surfaces(lens: LensPrescription, film_distance_mm: float) -> list[_Surface]:
    zv = vertex_z_mm(lens.thickness_mm, float(film_distance_mm))
    ap = lens.is_aperture
    out = []
    n_prev = 1.0
    for i in range(lens.n_surfaces):
        radius = float(lens.radius_mm[i])
        n_after = float(lens.index_after[i])
        srf = _Surface(index=i, vertex_z_mm=float(zv[i]), c=0.0 if radius == 0.0 else 1.0 / radius,
                       r_clear_mm=0.5 * float(lens.aperture_diameter_mm[i]),
                       is_aperture=bool(ap[i]), n_scene_side=n_prev, n_film_side=n_after,
                       shape=lens.aperture_shape if i == lens.aperture_shape_row else None)
        a = lens.asphere
        coef = tuple(float(v) for v in a[i]) if a is not None else (0.0,) * 9
        r_x = radius if lens.radius_x_mm is None else float(lens.radius_x_mm[i])
        if r_x != radius:            # toric: its terms (if any) shape the y-z profile
            srf = dataclasses.replace(srf, toric=reference_toric.make_surface(
                srf.c, coef, r_x, srf.r_clear_mm))
        elif any(v != 0.0 for v in coef):
            srf = _with_asphere(srf, coef)
        out.append(srf)
        n_prev = n_after
    return out


def _with_asphere(srf: _Surface, coef: tuple) -> _Surface:
    """``srf`` with its asphere data, search radius and widened sag range."""
    c, k = srf.c, coef[0]
    g = (1.0 + k) * c * c
    rho = srf.r_clear_mm if g <= 0.0 else min(srf.r_clear_mm, (1.0 / g) ** 0.5)
    sags = [_asphere_sag(c, coef, (rho * j / 512) ** 2) for j in range(513)]
    lo, hi = min(sags), max(sags)
    margin = 1e-3 * (1.0 + hi - lo)
    return dataclasses.replace(srf, asphere=coef, rho_mm=rho,
                               sag_range_mm=(lo - margin, hi + margin))


def _asphere_sag(c: float, coef: tuple, r2: float) -> float:
    """Even-asphere sag (mm) at squared radius r2, term by term; the conic root is
    clamped at 0 beyond its rim."""
    w = math.sqrt(max(1.0 - (1.0 + coef[0]) * c * c * r2, 0.0))
    z, power = c * r2 / (1.0 + w), r2
    for a in coef[1:]:
        z += a * power
        power *= r2
    return z


def _asphere_slope_over_r(c: float, coef: tuple, r2: float) -> float:
    """(dz/dr) / r of the asphere (quotient rule on the conic part; module doc)."""
    k = coef[0]
    w = math.sqrt(max(1.0 - (1.0 + k) * c * c * r2, 0.0))
    den = 1.0 + w
    conic = ((2.0 * c * den + (1.0 + k) * c ** 3 * r2 / w) / (den * den) if w > 0.0
             else math.copysign(math.inf, c) if c != 0.0 else 0.0)
    poly, power = 0.0, 1.0
    for i, a in enumerate(coef[1:], start=1):
        poly += 2.0 * i * a * power
        power *= r2
    return conic + poly


def _inside_shape(shape, x: float, y: float, radius: float) -> bool:
    """Whether stop point (x, y) mm is open, derived apart from the fast tracer's gauge:
    the iris edge is the chord between the two corners around the point's angle (lines
    intersected), blended toward the circle; the mask by its transmission."""
    if shape.blades is not None and shape.curvature < 1.0:
        n = shape.blades
        start = math.pi / 2 + math.radians(shape.rotation_deg)
        theta = math.atan2(y, x)
        k = math.floor(((theta - start) % (2 * math.pi)) / (2 * math.pi / n))
        a0, a1 = start + 2 * math.pi * k / n, start + 2 * math.pi * (k + 1) / n
        cx0, cy0, cx1, cy1 = (radius * math.cos(a0), radius * math.sin(a0),
                              radius * math.cos(a1), radius * math.sin(a1))
        ux, uy = math.cos(theta), math.sin(theta)
        # rho u = c0 + s (c1 - c0): solve with Cramer's rule for rho.
        ex, ey = cx1 - cx0, cy1 - cy0
        rho_poly = (cx0 * ey - cy0 * ex) / (ux * ey - uy * ex)
        rho = (1.0 - shape.curvature) * rho_poly + shape.curvature * radius
        if x * x + y * y > rho * rho:
            return False
    if shape.mask is not None:
        t = float(shape.transmission(np.array([x]), np.array([y]), radius)[0])
        if t <= T_MIN:
            return False
    return True


class _Blocked(Exception):
    def __init__(self, reason: str):
        self.reason = reason


def _sag(c: float, r2: float) -> float:
    """Sag of the vertex branch at squared radius r2 (caller ensures c^2 r2 <= 1)."""
    return c * r2 / (1.0 + math.sqrt(1.0 - c * c * r2))


class _RayState:
    """Mutable state of one ray in the local sag frame of the current surface."""

    def __init__(self):
        self.edge_margin = math.inf
        self.borderline = ""

    def flag(self, what: str) -> None:
        if not self.borderline:
            self.borderline = what


def _newton(c: float, x0: float, y0: float, dx: float, dy: float, ds: float,
            u: float, st: _RayState) -> float:
    """Solve u ds - sag(|(x0, y0) + u (dx, dy)|) = 0 from the start u (see module doc).

    Returns the root u (mm along the ray from the tangent-plane point).  Raises
    _Blocked("miss") if the wanted root does not exist or Newton does not converge.
    """
    sense = 1.0 if ds > 0.0 else -1.0
    prev_step = math.inf
    for it in range(_NEWTON_MAX_ITER):
        x = x0 + u * dx
        y = y0 + u * dy
        r2 = x * x + y * y
        q = 1.0 - c * c * r2
        if q < 0.0:
            raise _Blocked("miss")          # left the disc: no root on the vertex branch
        root_q = math.sqrt(q)
        f = u * ds - c * r2 / (1.0 + root_q)
        if f == 0.0:
            return u
        k = c / root_q if root_q > 0.0 else math.copysign(math.inf, c)
        fprime = ds - k * (x * dx + y * dy)
        if not math.isfinite(fprime) or abs(fprime) <= BORDERLINE_TOL:
            st.flag("grazing")
        if not (fprime * sense > 0.0):
            raise _Blocked("miss")          # F' has the wrong sign: no wanted root
        step = f / fprime
        u -= step
        a = abs(step)
        if a <= _NEWTON_RTOL * (1.0 + abs(u)):
            return u
        if it >= 3 and a >= 0.5 * prev_step and a <= _NEWTON_STALL_RTOL * (1.0 + abs(u)):
            return u                        # rounding floor reached
        prev_step = a
    st.flag("newton")
    raise _Blocked("miss")


def _cylinder_crossing(x0: float, y0: float, dx: float, dy: float, radius: float,
                       sigma: float) -> float | None:
    """Parameter u where the ray (x0, y0) + u (dx, dy) enters (sigma > 0) or, for
    sigma < 0, last leaves the cylinder x^2 + y^2 = radius^2; None if it never gets
    inside.  The caller guarantees u = 0 is outside the cylinder."""
    a2 = dx * dx + dy * dy
    if a2 == 0.0:
        return None
    b = x0 * dx + y0 * dy
    disc = b * b - a2 * (x0 * x0 + y0 * y0 - radius * radius)
    if disc < 0.0:
        return None
    sq = math.sqrt(disc)
    return (-b - sq) / a2 if sigma > 0.0 else (-b + sq) / a2


def _intersect(srf: _Surface, x: float, y: float, s: float, dx: float, dy: float, ds: float,
               st: _RayState) -> tuple[float, float, float, float]:
    """Hit point (hx, hy, hs) on surface ``srf`` and the ray parameter t (mm)."""
    if srf.toric is not None:
        hit = reference_toric.intersect(srf.toric, x, y, s, dx, dy, ds)
        if isinstance(hit, str):
            raise _Blocked(hit)
        return hit
    if srf.asphere is not None:
        return _intersect_asphere(srf, x, y, s, dx, dy, ds, st)
    c = srf.c
    t0 = -s / ds                       # vertex tangent plane s = 0
    x0, y0 = x + t0 * dx, y + t0 * dy
    if c == 0.0:
        return x0, y0, 0.0, t0
    if c * c * (x0 * x0 + y0 * y0) < 1.0:
        u = _newton(c, x0, y0, dx, dy, ds, 0.0, st)
    else:
        u = _intersect_from_outside_disc(srf, x0, y0, dx, dy, ds, st)
    hx, hy = x0 + u * dx, y0 + u * dy
    hs = _sag(c, hx * hx + hy * hy)
    return hx, hy, hs, t0 + u


def _asphere_window(srf: _Surface, x: float, y: float, s: float, dx: float, dy: float,
                    ds: float) -> tuple[float, float]:
    """Ray parameters [t_a, t_b] inside the cylinder r <= rho and the sag range;
    raises _Blocked("aperture") when empty."""
    lo_s, hi_s = srf.sag_range_mm
    ta, tb = sorted(((lo_s - s) / ds, (hi_s - s) / ds))
    a2 = dx * dx + dy * dy
    if a2 > 0.0:
        b = x * dx + y * dy
        disc = b * b - a2 * (x * x + y * y - srf.rho_mm * srf.rho_mm)
        if disc < 0.0:
            raise _Blocked("aperture")
        sq = math.sqrt(disc)
        ta, tb = max(ta, (-b - sq) / a2), min(tb, (-b + sq) / a2)
    elif x * x + y * y > srf.rho_mm * srf.rho_mm:
        raise _Blocked("aperture")
    if not ta < tb:
        raise _Blocked("aperture")
    return ta, tb


def _intersect_asphere(srf: _Surface, x: float, y: float, s: float, dx: float, dy: float,
                       ds: float, st: _RayState) -> tuple[float, float, float, float]:
    """Hit (hx, hy, hs) on an aspheric ``srf`` and the ray parameter t: the first sign
    change of H along the ray's window, bisected (module doc)."""
    c, coef = srf.c, srf.asphere
    sense = 1.0 if ds > 0.0 else -1.0

    def h(t: float) -> float:
        px, py = x + t * dx, y + t * dy
        return sense * (s + t * ds - _asphere_sag(c, coef, px * px + py * py))

    ta, tb = _asphere_window(srf, x, y, s, dx, dy, ds)
    n = _ASPHERE_SAMPLES
    prev_t, prev_h = ta, h(ta)
    if prev_h > 0.0:
        raise _Blocked("aperture")       # past the surface where it enters the cylinder
    for j in range(1, n + 1):
        t = ta + (tb - ta) * j / n
        ht = h(t)
        if ht > 0.0:
            break
        prev_t, prev_h = t, ht
    else:
        raise _Blocked("miss")
    lo, hi = prev_t, t                   # H(lo) <= 0 < H(hi)
    while True:
        mid = 0.5 * (lo + hi)
        if not lo < mid < hi:
            break
        if h(mid) > 0.0:
            hi = mid
        else:
            lo = mid
    t = lo if h(lo) == 0.0 else 0.5 * (lo + hi)
    hx, hy = x + t * dx, y + t * dy
    r2 = hx * hx + hy * hy
    fprime = ds - _asphere_slope_over_r(c, coef, r2) * (hx * dx + hy * dy)
    if not math.isfinite(fprime) or abs(fprime) <= BORDERLINE_TOL:
        st.flag("grazing")
    return hx, hy, _asphere_sag(c, coef, r2), t


def _intersect_from_outside_disc(srf: _Surface, x0: float, y0: float, dx: float, dy: float,
                                 ds: float, st: _RayState) -> float:
    """Root u when the tangent-plane point (x0, y0) lies outside the disc c^2 r^2 <= 1.

    With sigma = sign(c) sign(ds) the wanted root lies on the sigma side of u = 0,
    on the chord of the disc.  Let u_e be where the ray enters that chord (disc
    rim, sag slope infinite) and u_s where it enters the clear-radius cylinder.
    H(u_e) > 0 means the ray crosses the rim inside the sphere: the wanted crossing
    is on the far branch (miss).  Otherwise, if H(u_s) > 0 the root lies between
    u_e and u_s, i.e. outside the clear radius (blocked) -- unless the clear radius
    reaches the rim, where it is found by bisection; if H(u_s) <= 0 Newton starts
    at u_s, on the outer side of the wanted root.
    """
    c = srf.c
    sc = 1.0 if c > 0.0 else -1.0
    sigma = sc * (1.0 if ds > 0.0 else -1.0)
    rim = 1.0 / abs(c)

    def h(u: float) -> float:
        xu, yu = x0 + u * dx, y0 + u * dy
        r2 = min(xu * xu + yu * yu, rim * rim)
        return sc * (u * ds - _sag(c, r2))

    u_e = _cylinder_crossing(x0, y0, dx, dy, rim, sigma)
    if u_e is None or u_e * sigma < 0.0:
        raise _Blocked("miss")            # no part of the disc on the wanted side
    if sc * u_e * ds - rim > 0.0:         # H(u_e), with sag(rim) = 1/c
        raise _Blocked("miss")            # far branch
    # Start on the clear-radius cylinder; if it reaches the rim, a hair inside.
    at_rim = srf.r_clear_mm >= rim * (1.0 - _RIM_RTOL)
    r_lim = rim * (1.0 - _RIM_RTOL) if at_rim else srf.r_clear_mm
    u_s = _cylinder_crossing(x0, y0, dx, dy, r_lim, sigma)
    if u_s is None or u_s * sigma <= 0.0:
        if at_rim:                        # the ray only touches the rim annulus
            st.edge_margin = min(st.edge_margin, _RIM_RTOL)
        raise _Blocked("aperture")
    if h(u_s) > 0.0:
        if not at_rim:
            raise _Blocked("aperture")    # the root lies outside the clear radius
        lo, hi = u_e, u_s                 # H(lo) <= 0 < H(hi): bisect
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if mid == lo or mid == hi:
                break
            if h(mid) > 0.0:
                hi = mid
            else:
                lo = mid
        return lo if h(lo) == 0.0 else 0.5 * (lo + hi)
    try:
        return _newton(c, x0, y0, dx, dy, ds, u_s, st)
    except _Blocked:
        if at_rim:                        # roots may hide in the thin rim annulus
            st.edge_margin = min(st.edge_margin, _RIM_RTOL)
        raise


def _refract(srf: _Surface, hx: float, hy: float, dx: float, dy: float, ds: float,
             mu: float, sense: float, st: _RayState) -> tuple[float, float, float]:
    """Refracted unit direction (local frame) at the hit (hx, hy) on ``srf``."""
    c = srf.c
    r2 = hx * hx + hy * hy
    q = 1.0 - c * c * r2
    if srf.toric is not None:
        n = reference_toric.unit_normal(srf.toric, hx, hy)
        if n is None:
            raise _Blocked("miss")                          # at the edge of its domain
        nx, ny, ns = n
    elif srf.asphere is not None:
        k = _asphere_slope_over_r(c, srf.asphere, r2)       # sag'(r) / r
        inv = 1.0 / math.sqrt(1.0 + k * k * r2)
        if not math.isfinite(inv) or inv == 0.0:
            raise _Blocked("miss")                          # at the conic's rim
        nx, ny, ns = -k * hx * inv, -k * hy * inv, inv
    elif q > 0.0:
        k = c / math.sqrt(q)                     # sag'(r) / r
        inv = 1.0 / math.sqrt(1.0 + k * k * r2)
        nx, ny, ns = -k * hx * inv, -k * hy * inv, inv   # unit normal, +s side
    else:                                        # exactly on the rim: sag' infinite
        st.flag("grazing")
        g = -math.copysign(1.0, c) / math.sqrt(r2)
        nx, ny, ns = g * hx, g * hy, 0.0
    nx, ny, ns = sense * nx, sense * ny, sense * ns  # along the travel sense
    cos_i = nx * dx + ny * dy + ns * ds
    if abs(cos_i) <= BORDERLINE_TOL:
        st.flag("grazing")
    tx, ty, ts = dx - cos_i * nx, dy - cos_i * ny, ds - cos_i * ns   # tangential part
    sin2_t = mu * mu * (tx * tx + ty * ty + ts * ts)
    if abs(1.0 - sin2_t) <= BORDERLINE_TOL:
        st.flag("tir")
    if sin2_t > 1.0:
        raise _Blocked("tir")
    cos_t = math.copysign(math.sqrt(1.0 - sin2_t), cos_i)
    ex, ey, es = mu * tx + cos_t * nx, mu * ty + cos_t * ny, mu * ts + cos_t * ns
    norm = math.sqrt(ex * ex + ey * ey + es * es)
    if not (norm > 0.0) or not math.isfinite(norm):
        raise _Blocked("turned-back")
    return ex / norm, ey / norm, es / norm


def _trace_one(surfaces: list[_Surface], origin, direction, toward_film: bool) -> RayTrace:
    ox, oy, oz = (float(v) for v in origin)
    dx, dy, dz = (float(v) for v in direction)
    order = surfaces if toward_film else surfaces[::-1]
    sense = 1.0 if toward_film else -1.0      # travel sense of s
    st = _RayState()

    norm = math.sqrt(dx * dx + dy * dy + dz * dz)
    if not (math.isfinite(norm) and norm > 0.0 and all(map(math.isfinite, (ox, oy, oz)))):
        o = tuple(v if math.isfinite(v) else 0.0 for v in (ox, oy, oz))
        return RayTrace(o, (0.0, 0.0, -sense), False, order[0].index, "invalid-ray",
                        st.edge_margin, st.borderline)
    dx, dy, dz = dx / norm, dy / norm, dz / norm

    # Camera-frame state of the ray; updated after every surface crossed.
    cur_o, cur_d = (ox, oy, oz), (dx, dy, dz)
    for srf in order:
        try:
            x, y, z = cur_o
            dx, dy, dz = cur_d
            s, ds = srf.vertex_z_mm - z, -dz
            if abs(ds) <= BORDERLINE_TOL:
                st.flag("turning")
            if not (ds * sense > 0.0):
                raise _Blocked("turned-back")
            hx, hy, hs, t = _intersect(srf, x, y, s, dx, dy, ds, st)
            if abs(t + BACKWARD_TOLERANCE_MM) <= 0.5 * BACKWARD_TOLERANCE_MM:
                st.flag("behind")
            r2 = hx * hx + hy * hy
            st.edge_margin = min(st.edge_margin,
                                 abs(math.sqrt(r2) - srf.r_clear_mm) / srf.r_clear_mm)
            if t < -BACKWARD_TOLERANCE_MM:
                raise _Blocked("behind")
            if r2 > srf.r_clear_mm * srf.r_clear_mm:
                raise _Blocked("aperture")
            if srf.shape is not None and not _inside_shape(srf.shape, hx, hy, srf.r_clear_mm):
                raise _Blocked("aperture")
            if not srf.is_aperture:
                n1, n2 = ((srf.n_scene_side, srf.n_film_side) if toward_film
                          else (srf.n_film_side, srf.n_scene_side))
                dx, dy, ds = _refract(srf, hx, hy, dx, dy, ds, n1 / n2, sense, st)
                if abs(ds) <= BORDERLINE_TOL:
                    st.flag("turning")
                if not (ds * sense > 0.0):
                    raise _Blocked("turned-back")
        except _Blocked as b:
            return RayTrace(cur_o, cur_d, False, srf.index, b.reason, st.edge_margin,
                            st.borderline)
        cur_o = (hx, hy, srf.vertex_z_mm - hs)
        cur_d = (dx, dy, -ds)
    return RayTrace(cur_o, cur_d, True, -1, "", st.edge_margin, st.borderline)


def trace_ray_from_film(lens: LensPrescription, film_distance_mm: float, origin,
                        direction) -> RayTrace:
    """Trace one ray from the film side to the scene (rear surface first).

    origin : 3 floats, mm, camera frame.  direction : 3 floats, need not be unit,
    should point toward +z.  Returns the ray leaving the front surface.
    """
    return _trace_one(_surfaces(lens, film_distance_mm), origin, direction, toward_film=False)


def trace_ray_from_scene(lens: LensPrescription, film_distance_mm: float, origin,
                         direction) -> RayTrace:
    """Trace one ray from the scene to the film (front surface first).

    origin : 3 floats, mm, camera frame.  direction : 3 floats, should point toward
    -z.  Returns the ray leaving the rear surface toward the film.
    """
    return _trace_one(_surfaces(lens, film_distance_mm), origin, direction, toward_film=True)


def _trace_many(lens, film_distance_mm, origins, directions, toward_film) -> ReferenceTraceResult:
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    if o.shape != d.shape:
        raise ValueError(f"origins {o.shape} and directions {d.shape} must both be (n, 3)")
    surfaces = _surfaces(lens, film_distance_mm)
    rays = [_trace_one(surfaces, oi, di, toward_film) for oi, di in zip(o.tolist(), d.tolist())]
    n = len(rays)
    return ReferenceTraceResult(
        origin_mm=np.array([r.origin_mm for r in rays], dtype=np.float64).reshape(n, 3),
        direction=np.array([r.direction for r in rays], dtype=np.float64).reshape(n, 3),
        passed=np.array([r.passed for r in rays], dtype=bool),
        blocked_at=np.array([r.blocked_at for r in rays], dtype=np.int64),
        reason=np.array([r.reason for r in rays], dtype=object),
        edge_margin=np.array([r.edge_margin for r in rays], dtype=np.float64),
        borderline=np.array([r.borderline for r in rays], dtype=object),
    )


def trace_rays_from_film(lens: LensPrescription, film_distance_mm: float, origins,
                         directions) -> ReferenceTraceResult:
    """Loop of :func:`trace_ray_from_film` over (n, 3) origins (mm) and directions."""
    return _trace_many(lens, film_distance_mm, origins, directions, toward_film=False)


def trace_rays_from_scene(lens: LensPrescription, film_distance_mm: float, origins,
                          directions) -> ReferenceTraceResult:
    """Loop of :func:`trace_ray_from_scene` over (n, 3) origins (mm) and directions."""
    return _trace_many(lens, film_distance_mm, origins, directions, toward_film=True)
