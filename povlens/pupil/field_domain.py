"""Each film point's own pupil domain for field lens samples: a smooth family of ellipses.

A field lens sample (:mod:`povlens.pupil.field`) gives every film point the same
*canonical* point q of the unit disc.  This module maps q, per film point f, onto an
ellipse of the table's sampling plane (camera frame of :mod:`povlens.lens.coordinates`, mm)
that contains f's pass region:

    P(f, q) = c(r) e_r + b(r) q + (a(r) - b(r)) (e_r . q) e_r,

with r = |f|, e_r = f / r the radial direction, c(r) the ellipse's centre along e_r,
a(r) its radial and b(r) its tangential semi-axis.  P is uniform on the ellipse when q is
uniform on the disc, with density 1 / (pi a b): the sample's weight is
cos^4(theta) / z_p^2 * pi a b, unbiased because the ellipse holds every ray the lens
passes (:meth:`povlens.pupil.table.PupilTable.region` is conservative, and the ellipse
holds it).

**Why per film point.**  Off axis, and above all stopped down, a film point's pass region
is a small part of any disc that holds them all, and it moves with the film point (pupil
aberration).  A shared disc then misses most of the frame in every sample, and the few
rays that pass carry large weights: rings, crescents and doubled images at any sample
count a user runs.  The ellipse follows the region: 80-100 % of the rays pass.

**Smooth in f.**  The mesh of :mod:`povlens.pov.field_mesh` interpolates the ray field
of a fixed q over the film, so P must be smooth in f, also through the axis:
c(r) = r P_c(s), b(r) = P_b(s) and a(r) = b(r) + s P_d(s) with s = (r / R)^2 and
polynomials P_c, P_b, P_d, so that c(r) e_r = P_c(s) f and (a - b) e_r e_r^T =
P_d(s) f f^T / R^2 are polynomials in the film coordinates.  (The table's own sampler
turns its region with the film azimuth, which spins a fixed q about the axis.)

**Fit.**  At :data:`N_RADII` film radii (and the table's knots) the table's polygon gives
its x extent's middle (the centre) and its half-width and half-height.  P_c is fitted to
the centres; then, about the fitted centre, each polygon fixes the smallest ellipse of the
polygon's own proportions that holds it (semi-axes A_i, B_i); P_b and P_d are fitted
from above to B_i and A_i by asymmetric least squares (points below the fit count
:data:`UPPER_WEIGHT` times as much), and both are scaled by the largest remaining ratio
A_i / a, B_i / b and :data:`DOMAIN_MARGIN`.  Where that fails (a non-positive axis) the
domain is the disc of :func:`povlens.pupil.field.bounding_disc_radius_mm` about the axis,
which holds every region too.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

__all__ = ["FieldDomain", "field_domain", "disc_domain", "upper_fit", "saturate",
           "DOMAIN_MARGIN", "N_RADII", "FIT_DEGREE", "SATURATION"]

#: Film radii the fit samples (with the table's knots).
N_RADII = 193
#: Degree of the polynomials in s = (r / R)^2.
FIT_DEGREE = 4
#: Relative margin of the ellipses over the largest ratio that holds every polygon.
DOMAIN_MARGIN = 2e-3
#: Beyond the table's last radius R, s = (r / R)^2 saturates below 1 + this.
SATURATION = 0.1
#: Weight of a point the fit passes below, in the asymmetric least squares.
UPPER_WEIGHT = 50.0


@dataclasses.dataclass(frozen=True)
class FieldDomain:
    """The ellipse family P(f, q) of the module docstring.

    radius_mm : R, the film radius that s = (r / R)^2 is measured in.
    centre, tangential, radial_excess : coefficients (lowest power first) of P_c, P_b
        and P_d in s.
    efficiency : the smallest share of an ellipse the table's region fills, over the
        fitted radii (diagnostic: about the share of a sample's rays that pass).
    """

    radius_mm: float
    centre: tuple[float, ...]
    tangential: tuple[float, ...]
    radial_excess: tuple[float, ...]
    efficiency: float

    def _axes(self, film_xy: np.ndarray):
        f = np.asarray(film_xy, dtype=np.float64).reshape(-1, 2)
        s = np.einsum("ij,ij->i", f, f) / (self.radius_mm * self.radius_mm)
        s = saturate(s)
        c = np.polynomial.polynomial.polyval(s, self.centre)
        b = np.polynomial.polynomial.polyval(s, self.tangential)
        d = np.polynomial.polynomial.polyval(s, self.radial_excess)
        return f, s, c, b, d

    def points_mm(self, film_xy, q) -> np.ndarray:
        """(n, 2) pupil points P(f, q) on the sampling plane of film points ``film_xy``
        (n, 2) mm and canonical points ``q`` (n, 2) or (2,) of the unit disc."""
        f, _, c, b, d = self._axes(film_xy)
        q = np.broadcast_to(np.asarray(q, dtype=np.float64), f.shape)
        fq = np.einsum("ij,ij->i", f, q)
        k = c + d * fq / (self.radius_mm * self.radius_mm)
        return k[:, None] * f + b[:, None] * q

    def semi_axes_mm(self, film_xy) -> tuple[np.ndarray, np.ndarray]:
        """(a, b): the radial and tangential semi-axes (n,) mm at the film points."""
        _, s, _, b, d = self._axes(film_xy)
        return b + s * d, b

    def area_mm2(self, film_xy) -> np.ndarray:
        """(n,) pi a b: the ellipse's area, 1 / density of P, at the film points."""
        a, b = self.semi_axes_mm(film_xy)
        return math.pi * np.abs(a * b)

    def to_dict(self) -> dict:
        return {"radius_mm": float(self.radius_mm), "centre": [float(v) for v in self.centre],
                "tangential": [float(v) for v in self.tangential],
                "radial_excess": [float(v) for v in self.radial_excess],
                "efficiency": float(self.efficiency)}

    @classmethod
    def from_dict(cls, d: dict) -> "FieldDomain":
        return cls(float(d["radius_mm"]), tuple(float(v) for v in d["centre"]),
                   tuple(float(v) for v in d["tangential"]),
                   tuple(float(v) for v in d["radial_excess"]), float(d["efficiency"]))


def disc_domain(disc_radius_mm: float, radius_mm: float = 1.0, efficiency: float = 0.0
                ) -> FieldDomain:
    """The disc of radius ``disc_radius_mm`` about the axis, for every film point."""
    return FieldDomain(float(radius_mm) if radius_mm > 0 else 1.0, (0.0,),
                       (float(disc_radius_mm),), (0.0,), float(efficiency))


def _polygon_extents(table, radii):
    """Per radius with a region: (r, x centre, half-width, half-height, polygon, area)."""
    out = []
    for r in radii:
        poly = table.region(float(r))
        if not len(poly):
            continue
        x0, x1 = float(poly[:, 0].min()), float(poly[:, 0].max())
        hx, hy = 0.5 * (x1 - x0), float(np.abs(poly[:, 1]).max())
        if hx > 0 and hy > 0:
            out.append((float(r), 0.5 * (x0 + x1), hx, hy, poly,
                        float(table.area_mm2(float(r))[0])))
    return out


def saturate(s: np.ndarray) -> np.ndarray:
    """s held below 1 + :data:`SATURATION` beyond 1: beyond the table's last film point no
    light passes, and the polynomials are held near their value there
    (s -> 1 + d (1 - exp((1 - s) / d)), continuous with its slope), so the ray field stays
    smooth and bounded where a mesh reaches past the edge."""
    d = SATURATION
    return np.where(s <= 1.0, s, 1.0 + d * (1.0 - np.exp(np.minimum(1.0 - s, 0.0) / d)))


def upper_fit(X: np.ndarray, y: np.ndarray, iterations: int = 12) -> np.ndarray:
    """Least-squares coefficients of X c ~ y that weigh points below the fit
    :data:`UPPER_WEIGHT` times as much (asymmetric least squares)."""
    w = np.ones(len(y))
    coef = np.zeros(X.shape[1])
    for _ in range(iterations):
        sw = np.sqrt(w)
        coef = np.linalg.lstsq(X * sw[:, None], y * sw, rcond=None)[0]
        w = np.where(X @ coef < y, UPPER_WEIGHT, 1.0)
    return coef


def field_domain(table, degree: int = FIT_DEGREE) -> FieldDomain:
    """The ellipse family holding ``table``'s region at every film radius (module
    docstring); the bounding disc where no such fit holds.  ``efficiency`` is the
    smallest share of the domain the table's region fills where the region is at
    least a tenth of its largest.

    Parameters
    ----------
    table : :class:`povlens.pupil.table.PupilTable` (or the band table of
        ``--dispersion``, which holds every wavelength's region).
    degree : degree of the polynomials in s.
    """
    R = float(table.max_film_radius_mm)
    ext = []
    if R > 0:
        knots = table.film_radius_mm[table.film_radius_mm <= R]
        ext = _polygon_extents(table, np.union1d(np.linspace(0.0, R, N_RADII), knots))
    dom = _fitted_domain(table, ext, degree)
    if not ext:
        return dom
    r = np.array([e[0] for e in ext])
    area = np.array([e[5] for e in ext])
    eff = area / dom.area_mm2(np.stack([r, np.zeros_like(r)], 1))
    return dataclasses.replace(dom, efficiency=float(eff[area >= 0.1 * area.max()].min()))


def _fitted_domain(table, ext, degree: int) -> FieldDomain:
    """The ellipse family fitted to the polygons ``ext`` (:func:`_polygon_extents`), or
    the bounding disc."""
    from povlens.pupil.field import bounding_disc_radius_mm
    R = float(table.max_film_radius_mm)
    rb = bounding_disc_radius_mm(table)
    if not (R > 0 and rb > 0):
        return disc_domain(rb, R if R > 0 else 1.0)
    if len(ext) < degree + 2:
        return disc_domain(rb, R)
    r = np.array([e[0] for e in ext])
    cx, hx, hy, area = (np.array([e[i] for e in ext]) for i in (1, 2, 3, 5))
    s = (r / R) ** 2
    powers = np.arange(degree + 1)
    S = s[:, None] ** powers[None, :]
    # the shape: centre, then each radius's tight ellipse of its polygon's proportions,
    # weighted by the region's area (a sliver at a vignetting cut-off hardly counts)
    sw = np.sqrt(np.maximum(area, 0.0) / max(float(area.max()), 1e-300))[:, None]
    centre = np.linalg.lstsq(sw * r[:, None] * S, sw[:, 0] * cx, rcond=None)[0]
    kappa = np.array([float(np.sqrt(((e[4][:, 0] - e[1]) / e[2]) ** 2
                                    + (e[4][:, 1] / e[3]) ** 2).max()) for e in ext])
    tang = upper_fit(sw * S, sw[:, 0] * kappa * hy)
    b_fit = S @ tang
    excess = upper_fit(sw * s[:, None] * S, sw[:, 0] * (kappa * hx - b_fit))
    a_fit = b_fit + s * (S @ excess)
    if not (np.all(a_fit > 0) and np.all(b_fit > 0)):
        return disc_domain(rb, R)
    # the lift: each polygon's largest gauge in its fitted ellipse, bounded from above by
    # a smooth L(s) (times the largest ratio left and the margin)
    c_fit = r * (S @ centre)
    gauge = np.array([float(np.sqrt(((e[4][:, 0] - c) / a) ** 2 + (e[4][:, 1] / b) ** 2).max())
                      for e, c, a, b in zip(ext, c_fit, a_fit, b_fit)])
    Sl = S[:, :3]
    lift = upper_fit(Sl, gauge)
    L = Sl @ lift
    if not np.all(L > 0):
        return disc_domain(rb, R)
    lift = lift * float(max((gauge / L).max(), 1.0)) * (1.0 + DOMAIN_MARGIN)
    tang_l = np.polynomial.polynomial.polymul(lift, tang)
    excess_l = np.polynomial.polynomial.polymul(lift, excess)
    dom = FieldDomain(R, tuple(centre), tuple(tang_l), tuple(excess_l), 0.0)
    # positive axes wherever the map is evaluated (beyond R, s saturates below 1 + d)
    probe = np.linspace(0.0, math.sqrt(1.0 + SATURATION) * R, 257)
    a, b = dom.semi_axes_mm(np.stack([probe, np.zeros_like(probe)], 1))
    if not (np.all(a > 0) and np.all(b > 0)):
        return disc_domain(rb, R)
    # the disc when the ellipses are not smaller over the frame (film area weighted)
    ellipse = dom.area_mm2(np.stack([r, np.zeros_like(r)], 1))
    if np.sum(r * ellipse) >= math.pi * rb * rb * np.sum(r):
        return disc_domain(rb, R)
    return dom
