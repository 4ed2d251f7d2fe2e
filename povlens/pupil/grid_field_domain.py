"""Each film point's pupil ellipse for field lens samples of a lens without rotational symmetry.

The counterpart of :mod:`povlens.pupil.field_domain` for a grid table
(:class:`povlens.pupil.grid_table.GridPupilTable`, an anamorphic lens): the canonical
point q of the unit disc shared by a field sample's film points is mapped, per film
point f = (x, y), onto an ellipse of the sampling plane (camera frame, mm) that holds
f's pass region:

    P(f, q) = c(f) + A(f) q,   c = (x P_cx(s), y P_cy(s)),
    A = [[a_x(s), e], [e, a_y(s)]],   e = (x y / (X Y)) P_e(s),

with s = (s_x, s_y) = ((x / X)^2, (y / Y)^2) (each held below 1 + SATURATION beyond the
table's extent (X, Y), :func:`povlens.pupil.field_domain.saturate`) and P_* polynomials
of total degree :data:`FIT_DEGREE` in s.  c and A are polynomials in x and y, so P is
smooth over the whole film, through both axes, which the interpolated field meshes
need; and mirroring f in x (or y) mirrors its ellipse, as the lens's regions are
mirrored.  P is uniform on the ellipse when q is uniform on the disc, with density
1 / (pi det A): the weight is cos^4(theta) / z_p^2 * pi det A, unbiased because the
ellipse holds the table's (conservative) region.

Fit.  At a grid of film points over the quadrant (:data:`FIT_POINTS` per axis) the
table's polygons give a centre and a shape.  The centres are fitted by least
squares (weighted by the regions' areas) to the centres of the polygons' smallest-area
ellipses (Khachiyan's algorithm, :func:`min_area_ellipses`), the shapes (those ellipses
about the fitted centre, scaled to hold the polygon) entries by asymmetric least squares
from above (:func:`povlens.pupil.field_domain.upper_fit`); then each polygon's largest
gauge |A^-1 (v - c)| in its fitted ellipse is bounded from above by a smooth L(s) of degree
1, and A is scaled by L, by the largest ratio left and by
:data:`povlens.pupil.field_domain.DOMAIN_MARGIN`, checked on a finer grid
(:data:`CHECK_POINTS` per axis, the table's knots included).  Where that fails (A not
positive definite somewhere the map is evaluated, or the ellipses not smaller than the
disc over the film) the domain is the disc about the axis that holds every region
(:func:`grid_bounding_disc_radius_mm`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from povlens.pupil.field_domain import (DOMAIN_MARGIN, SATURATION, FieldDomain, disc_domain,
                                        field_domain, saturate, upper_fit)

__all__ = ["GridFieldDomain", "grid_field_domain", "grid_bounding_disc_radius_mm",
           "min_area_ellipses",
           "field_domain_for", "bounding_disc_for", "domain_from_dict", "FIT_DEGREE",
           "FIT_POINTS", "CHECK_POINTS"]

#: Total degree of the polynomials in (s_x, s_y).
FIT_DEGREE = 3
#: Film points per axis the shapes are fitted at, and the (finer) points the lift holds at.
FIT_POINTS = 13
CHECK_POINTS = 41
#: Relative margin of the bounding disc.
DISC_MARGIN = 2e-3
#: Steps of Khachiyan's algorithm for each polygon's smallest-area ellipse.
MVEE_ITERATIONS = 150


def _basis(sx: np.ndarray, sy: np.ndarray, degree: int) -> np.ndarray:
    """(n, T) the monomials s_x^i s_y^j, i + j <= degree."""
    return np.stack([sx ** i * sy ** j for i in range(degree + 1)
                     for j in range(degree + 1 - i)], axis=1)


@dataclasses.dataclass(frozen=True)
class GridFieldDomain:
    """The ellipse family P(f, q) = c(f) + A(f) q of the module docstring.

    extent_mm : (X, Y), what s = ((x / X)^2, (y / Y)^2) is measured in.
    centre_x, centre_y, axis_x, axis_y, shear : coefficients of P_cx, P_cy, a_x, a_y,
        P_e over the monomials of :func:`_basis` (degree ``degree``).
    efficiency : the smallest share of an ellipse the table's region fills, over the
        fitted points (diagnostic: about the share of a sample's rays that pass).
    """

    extent_mm: tuple[float, float]
    degree: int
    centre_x: tuple[float, ...]
    centre_y: tuple[float, ...]
    axis_x: tuple[float, ...]
    axis_y: tuple[float, ...]
    shear: tuple[float, ...]
    efficiency: float = 0.0

    def _parts(self, film_xy):
        """(f (n, 2), c (n, 2), A (n, 2, 2)) at film points."""
        f = np.asarray(film_xy, dtype=np.float64).reshape(-1, 2)
        X, Y = self.extent_mm
        B = _basis(saturate((f[:, 0] / X) ** 2), saturate((f[:, 1] / Y) ** 2), self.degree)
        c = np.stack([f[:, 0] * (B @ self.centre_x), f[:, 1] * (B @ self.centre_y)], 1)
        e = f[:, 0] * f[:, 1] / (X * Y) * (B @ self.shear)
        A = np.empty((len(f), 2, 2))
        A[:, 0, 0], A[:, 1, 1] = B @ self.axis_x, B @ self.axis_y
        A[:, 0, 1] = A[:, 1, 0] = e
        return f, c, A

    def points_mm(self, film_xy, q) -> np.ndarray:
        """(n, 2) pupil points P(f, q) of film points (n, 2) mm and canonical points q
        (n, 2) or (2,) of the unit disc."""
        f, c, A = self._parts(film_xy)
        q = np.broadcast_to(np.asarray(q, dtype=np.float64), f.shape)
        return c + np.einsum("nij,nj->ni", A, q)

    def area_mm2(self, film_xy) -> np.ndarray:
        """(n,) pi |det A|: the ellipse's area, 1 / density of P."""
        _, _, A = self._parts(film_xy)
        return math.pi * np.abs(np.linalg.det(A))

    def to_dict(self) -> dict:
        return {"kind": "grid", "extent_mm": [float(v) for v in self.extent_mm],
                "degree": int(self.degree),
                **{k: [float(v) for v in getattr(self, k)]
                   for k in ("centre_x", "centre_y", "axis_x", "axis_y", "shear")},
                "efficiency": float(self.efficiency)}

    @classmethod
    def from_dict(cls, d: dict) -> "GridFieldDomain":
        return cls(tuple(float(v) for v in d["extent_mm"]), int(d["degree"]),
                   *(tuple(float(v) for v in d[k])
                     for k in ("centre_x", "centre_y", "axis_x", "axis_y", "shear")),
                   float(d["efficiency"]))


def domain_from_dict(d: dict):
    """A plan's field domain from its record: :class:`GridFieldDomain` (``kind`` grid) or
    :class:`~povlens.pupil.field_domain.FieldDomain`."""
    if isinstance(d, dict) and d.get("kind") == "grid":
        return GridFieldDomain.from_dict(d)
    return FieldDomain.from_dict(d)


def _polygons(table, pts: np.ndarray):
    """Quadrant film points pts (n, 2) with a region: (points kept (m, 2), vertices
    (m, N, 2), areas (m,))."""
    c, s, rho, inside = table.frame_at(pts)
    keep = inside & np.any(rho > 0, axis=1) & np.all(s > 0, axis=1)
    t = np.arange(rho.shape[1]) * (2.0 * math.pi / rho.shape[1])
    V = np.stack([c[keep, 0, None] + s[keep, 0, None] * rho[keep] * np.cos(t),
                  c[keep, 1, None] + s[keep, 1, None] * rho[keep] * np.sin(t)], axis=-1)
    return pts[keep], V, table.area_at(pts[keep])


def _grid_points(table, n: int) -> np.ndarray:
    """(m, 2) film points over the quadrant: n x n evenly spaced and the table's knots."""
    X, Y = table.film_extent_mm
    xs = np.union1d(np.linspace(0.0, X, n), table.knots_x_mm)
    ys = np.union1d(np.linspace(0.0, Y, n), table.knots_y_mm)
    return np.stack(np.meshgrid(xs, ys, indexing="ij"), -1).reshape(-1, 2)


def grid_bounding_disc_radius_mm(table) -> float:
    """R_B (mm): a disc about the axis holding the grid table's region at every film point
    (checked on :data:`CHECK_POINTS` per axis and the knots), enlarged by DISC_MARGIN."""
    _, V, _ = _polygons(table, _grid_points(table, CHECK_POINTS))
    r = float(np.hypot(V[..., 0], V[..., 1]).max()) if len(V) else 0.0
    return r * (1.0 + DISC_MARGIN)


def min_area_ellipses(V: np.ndarray, iterations: int = MVEE_ITERATIONS):
    """The smallest-area ellipses holding point sets V (m, k, 2), by Khachiyan's algorithm
    (all sets at once, a fixed number of steps): (centres (m, 2), shape matrices (m, 2, 2)
    S with the ellipse {c + S q : |q| <= 1}; near-minimal, not yet scaled to hold every
    point exactly)."""
    m, k, d = V.shape[0], V.shape[1], 2
    Q = np.concatenate([V, np.ones((m, k, 1))], axis=2)             # (m, k, 3)
    u = np.full((m, k), 1.0 / k)
    rows = np.arange(m)
    for _ in range(int(iterations)):
        Xm = np.einsum("mki,mk,mkj->mij", Q, u, Q)
        M = np.einsum("mki,mki->mk", Q, np.linalg.solve(Xm, Q.transpose(0, 2, 1))
                      .transpose(0, 2, 1))
        j = np.argmax(M, axis=1)
        Mj = M[rows, j]
        step = (Mj - d - 1.0) / ((d + 1.0) * np.maximum(Mj - 1.0, 1e-300))
        u *= (1.0 - step)[:, None]
        u[rows, j] += step
    c = np.einsum("mk,mki->mi", u, V)
    cov = np.einsum("mk,mki,mkj->mij", u, V, V) - np.einsum("mi,mj->mij", c, c)
    val, vec = np.linalg.eigh(d * cov)
    S = np.einsum("mij,mj,mkj->mik", vec, np.sqrt(np.maximum(val, 1e-300)), vec)
    return c, S


def _shapes(f, V, area, X, Y, degree):
    """The fitted centre coefficients and, per point, the shape A_i (m, 2, 2) holding its
    polygon about the fitted centre: its smallest-area ellipse's, scaled to hold it."""
    B = _basis((f[:, 0] / X) ** 2, (f[:, 1] / Y) ** 2, degree)
    w = np.sqrt(np.maximum(area, 0.0) / max(float(area.max()), 1e-300))
    mc, S = min_area_ellipses(V)
    cx = np.linalg.lstsq(w[:, None] * f[:, :1] * B, w * mc[:, 0], rcond=None)[0]
    cy = np.linalg.lstsq(w[:, None] * f[:, 1:] * B, w * mc[:, 1], rcond=None)[0]
    c = np.stack([f[:, 0] * (B @ cx), f[:, 1] * (B @ cy)], 1)
    d = V - c[:, None, :]
    g = np.linalg.norm(np.linalg.solve(S[:, None], d[..., None])[..., 0], axis=-1).max(axis=1)
    return B, cx, cy, S * g[:, None, None]


def grid_field_domain(table, degree: int = FIT_DEGREE) -> GridFieldDomain | None:
    """The ellipse family holding the grid table's region at every film point (module
    docstring), or None where no such fit holds (the caller takes the disc)."""
    X, Y = table.film_extent_mm
    f, V, area = _polygons(table, _grid_points(table, FIT_POINTS))
    if len(f) < 2 * _basis(np.zeros(1), np.zeros(1), degree).shape[1]:
        return None
    B, cx, cy, A = _shapes(f, V, area, X, Y, degree)
    w = np.sqrt(np.maximum(area, 0.0) / max(float(area.max()), 1e-300))
    ax = upper_fit(w[:, None] * B, w * A[:, 0, 0])
    ay = upper_fit(w[:, None] * B, w * A[:, 1, 1])
    xy = f[:, 0] * f[:, 1] / (X * Y)
    fit_e = np.abs(xy) > 1e-12
    sh = (np.linalg.lstsq(B[fit_e] * xy[fit_e, None], A[fit_e, 0, 1], rcond=None)[0]
          if fit_e.sum() >= B.shape[1] else np.zeros(B.shape[1]))
    dom = GridFieldDomain((X, Y), degree, tuple(cx), tuple(cy), tuple(ax), tuple(ay), tuple(sh))
    return _lifted(table, dom)


def _gauges(dom: GridFieldDomain, f, V) -> np.ndarray | None:
    """(m,) each polygon's largest |A^-1 (v - c)| in its ellipse; None where A is not
    positive definite at some film point."""
    _, c, A = dom._parts(f)
    if not np.all(np.linalg.eigvalsh(A)[:, 0] > 0):
        return None
    d = V - c[:, None, :]
    return np.linalg.norm(np.linalg.solve(A[:, None], d[..., None])[..., 0], axis=-1).max(axis=1)


def _lifted(table, dom: GridFieldDomain) -> GridFieldDomain | None:
    """``dom`` scaled by a smooth L(s) of degree 1 (from above), the largest ratio left and
    the margin, so that every polygon of the finer check grid lies inside; None if the
    family is not positive definite where the map is evaluated or no smaller than the
    disc."""
    X, Y = dom.extent_mm
    f, V, area = _polygons(table, _grid_points(table, CHECK_POINTS))
    gauge = _gauges(dom, f, V)
    if gauge is None:
        return None
    Bl = _basis((f[:, 0] / X) ** 2, (f[:, 1] / Y) ** 2, 1)
    lift = upper_fit(Bl, gauge)
    L = Bl @ lift
    if not np.all(L > 0):
        return None
    lift = lift * float(max((gauge / L).max(), 1.0)) * (1.0 + DOMAIN_MARGIN)
    # the lift's product with each coefficient polynomial (degree + 1 in s)
    mul = _multiply(lift, dom.degree)
    out = GridFieldDomain(dom.extent_mm, dom.degree + 1, _pad(dom.centre_x, dom.degree),
                          _pad(dom.centre_y, dom.degree), mul(dom.axis_x), mul(dom.axis_y),
                          mul(dom.shear))
    probe = np.stack(np.meshgrid(np.linspace(0, X * math.sqrt(1 + SATURATION) * 1.2, 31),
                                 np.linspace(0, Y * math.sqrt(1 + SATURATION) * 1.2, 31),
                                 indexing="ij"), -1).reshape(-1, 2)
    _, _, A = out._parts(probe)
    if not np.all(np.linalg.eigvalsh(A)[:, 0] > 0):
        return None
    rb = grid_bounding_disc_radius_mm(table)
    ell = out.area_mm2(f)
    if np.mean(ell) >= math.pi * rb * rb:
        return None
    return dataclasses.replace(out, efficiency=float((area / ell)[area >= 0.1 * area.max()].min()))


def _monomials(degree: int) -> list[tuple[int, int]]:
    return [(i, j) for i in range(degree + 1) for j in range(degree + 1 - i)]


def _pad(coef, degree: int) -> tuple[float, ...]:
    """Coefficients of degree ``degree`` as those of degree + 1 (the new terms 0)."""
    old = dict(zip(_monomials(degree), coef))
    return tuple(float(old.get(m, 0.0)) for m in _monomials(degree + 1))


def _multiply(lift, degree: int):
    """A function: coefficients of degree ``degree`` -> those of their product with the
    degree-1 polynomial ``lift`` (terms 1, s_y, s_x in :func:`_basis` order)."""
    one, sy, sx = (float(v) for v in lift)

    def mul(coef):
        old = dict(zip(_monomials(degree), coef))
        out = {m: 0.0 for m in _monomials(degree + 1)}
        for (i, j), a in old.items():
            out[(i, j)] += one * a
            out[(i, j + 1)] += sy * a
            out[(i + 1, j)] += sx * a
        return tuple(out[m] for m in _monomials(degree + 1))
    return mul


def field_domain_for(table):
    """The field domain of a plan's table: :func:`grid_field_domain` for a grid table (the
    disc of :func:`grid_bounding_disc_radius_mm` where no ellipses fit), else
    :func:`povlens.pupil.field_domain.field_domain`."""
    if getattr(table, "kind", "radial") != "grid":
        return field_domain(table)
    dom = grid_field_domain(table)
    if dom is None:
        return disc_domain(grid_bounding_disc_radius_mm(table), table.max_film_radius_mm)
    return dom


def bounding_disc_for(table) -> float:
    """R_B (mm) of a plan's table, radial (:func:`povlens.pupil.field.bounding_disc_radius_mm`)
    or grid (:func:`grid_bounding_disc_radius_mm`)."""
    if getattr(table, "kind", "radial") != "grid":
        from povlens.pupil.field import bounding_disc_radius_mm
        return bounding_disc_radius_mm(table)
    return grid_bounding_disc_radius_mm(table)
