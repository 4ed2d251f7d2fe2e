"""Even aspheres: a conic plus polynomial terms in r^2, their sag, slope and file form.

A row's asphere data is 9 numbers (the row of ``LensPrescription.asphere``, shape
(n_surfaces, 9)): the conic constant k, then the coefficients a2, a4, ..., a16 of
r^2, r^4, ..., r^16 (units mm^(1 - 2i) for a_2i).  With the base curvature c = 1/R
of the row the sag (mm, along the axis, positive toward the film as for a sphere of
radius R > 0) is Zemax's EVENASPH surface::

    z(r) = c r^2 / (1 + sqrt(1 - (1 + k) c^2 r^2)) + a2 r^2 + a4 r^4 + ... + a16 r^16

(PARM 1..8 are a2..a16, CONI is k).  k = 0 is the sphere, -1 the paraboloid, < -1 a
hyperboloid, > 0 an oblate and (-1, 0) a prolate ellipsoid.  The surface exists where
``(1 + k) c^2 r^2 <= 1``.  Its paraxial curvature is ``c + 2 a2``.

In a lens file the data follow a row as a trailing comment (Kolb readers such as pbrt
skip it and see the base sphere)::

    19.865  4.906  1.497  18  81.56   #!asphere k=0 a4=-1.5313e-05 a6=9.4893e-08

Terms left out are 0.  :func:`parse_directive` reads it, :func:`format_directive`
writes it.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["N_ASPHERE", "TERM_NAMES", "DIRECTIVE", "sag_mm", "slope_over_r", "domain_r2_mm2",
           "aspheric_rows", "paraxial_curvature_per_mm", "row_sag", "sag_range_mm",
           "row_domain_radius_mm",
           "parse_directive", "format_directive", "scaled_asphere", "stable_quadric_root"]

#: Numbers per row: k, then a2 .. a16.
N_ASPHERE = 9
#: Their names in a lens file.
TERM_NAMES = ("k",) + tuple(f"a{2 * i}" for i in range(1, N_ASPHERE))
#: The comment that carries a row's asphere data.
DIRECTIVE = "!asphere"


def _poly(coeffs: np.ndarray, r2):
    """sum_i a_2i r^2i (Horner in r^2); coeffs (8,) = a2 .. a16."""
    acc = np.zeros_like(r2)
    for a in coeffs[::-1]:
        acc = (acc + a) * r2
    return acc


def _dpoly_over_r(coeffs: np.ndarray, r2):
    """(d/dr sum_i a_2i r^2i) / r = sum_i 2i a_2i r^(2i - 2)."""
    acc = np.zeros_like(r2)
    for i in range(len(coeffs), 0, -1):
        acc = acc * r2 + 2.0 * i * coeffs[i - 1]
    return acc


def sag_mm(c_per_mm: float, row: np.ndarray, r2_mm2) -> np.ndarray:
    """Sag z(r) (mm) of an even asphere at squared radii ``r2_mm2`` (any shape, mm^2).

    c_per_mm : base curvature 1/R (0: plane).  row : (9,) k, a2 .. a16.  Outside the
    conic's domain ((1 + k) c^2 r^2 > 1) the conic part is taken at its rim (finite);
    callers check :func:`domain_r2_mm2`.
    """
    r2 = np.asarray(r2_mm2, dtype=np.float64)
    k = float(row[0])
    q = np.maximum(1.0 - (1.0 + k) * c_per_mm * c_per_mm * r2, 0.0)
    return c_per_mm * r2 / (1.0 + np.sqrt(q)) + _poly(np.asarray(row[1:], np.float64), r2)


def slope_over_r(c_per_mm: float, row: np.ndarray, r2_mm2) -> np.ndarray:
    """(dz/dr) / r (1/mm) at squared radii ``r2_mm2``: ``c / sqrt(1 - (1 + k) c^2 r^2)
    + sum 2i a_2i r^(2i - 2)``; finite at the axis.  Where the conic's root is 0 or
    negative (its rim and beyond) the result is +-inf (callers check the domain)."""
    r2 = np.asarray(r2_mm2, dtype=np.float64)
    k = float(row[0])
    q = 1.0 - (1.0 + k) * c_per_mm * c_per_mm * r2
    with np.errstate(divide="ignore", invalid="ignore"):
        conic = np.where(q > 0.0, c_per_mm / np.sqrt(np.where(q > 0.0, q, 1.0)),
                         math.copysign(math.inf, c_per_mm) if c_per_mm else 0.0)
    return conic + _dpoly_over_r(np.asarray(row[1:], np.float64), r2)


def domain_r2_mm2(c_per_mm: float, k: float) -> float:
    """Largest r^2 (mm^2) where the conic exists: 1 / ((1 + k) c^2), or inf."""
    g = (1.0 + float(k)) * c_per_mm * c_per_mm
    return 1.0 / g if g > 0.0 else math.inf


def aspheric_rows(lens) -> np.ndarray:
    """(n_surfaces,) bool: the rows whose asphere data are not all zero."""
    a = getattr(lens, "asphere", None)
    if a is None:
        return np.zeros(lens.n_surfaces, dtype=bool)
    return np.any(a != 0.0, axis=1)


def paraxial_curvature_per_mm(lens) -> np.ndarray:
    """(n_surfaces,) paraxial curvatures (1/mm): the base curvature c, plus 2 a2 on
    aspheric rows (the r^2 term bends the surface at the axis; k and a4.. do not)."""
    c = lens.curvature_per_mm
    a = getattr(lens, "asphere", None)
    return c if a is None else c + 2.0 * a[:, 1]


def row_sag(lens, i: int):
    """Function r_mm -> sag (mm) of row ``i`` (sphere or asphere), for any shape of r.
    (Of a toric row: its y-z profile; :func:`povlens.lens.toric.row_sag_xy` is the
    surface.)"""
    c = float(lens.curvature_per_mm[i])
    if not aspheric_rows(lens)[i]:
        def sphere(r_mm):
            r2 = np.asarray(r_mm, dtype=np.float64) ** 2
            return c * r2 / (1.0 + np.sqrt(np.maximum(1.0 - c * c * r2, 0.0)))
        return sphere
    row = lens.asphere[i]
    return lambda r_mm: sag_mm(c, row, np.asarray(r_mm, dtype=np.float64) ** 2)


def sag_range_mm(lens, i: int, r_max_mm: float, n: int = 257) -> tuple[float, float]:
    """(min, max) sag (mm) of row ``i`` over radii 0..``r_max_mm``: the sag at the rim
    and 0 for a sphere; sampled on ``n`` radii for an asphere, whose sag need not be
    monotonic (widened by 1e-9 of its span plus 1e-12 mm).  (Of a toric row: its y-z
    profile's; :func:`povlens.lens.toric.row_sag_range_mm` takes any row.)"""
    sag = row_sag(lens, i)
    if not aspheric_rows(lens)[i]:
        s = float(sag(float(r_max_mm)))
        return min(0.0, s), max(0.0, s)
    z = sag(np.linspace(0.0, float(r_max_mm), n))
    lo, hi = float(z.min()), float(z.max())
    pad = 1e-9 * (hi - lo) + 1e-12
    return lo - pad, hi + pad


def row_domain_radius_mm(lens, i: int) -> float:
    """Radius (mm) where row ``i``'s surface ends: |R| for a sphere, the conic's rim for
    an asphere (inf for a paraboloid, hyperboloid or plane)."""
    c = float(lens.curvature_per_mm[i])
    k = float(lens.asphere[i, 0]) if aspheric_rows(lens)[i] else 0.0
    return math.sqrt(domain_r2_mm2(c, k))


def parse_directive(comment: str, where: str) -> np.ndarray:
    """The (9,) asphere row of a ``!asphere k=.. a4=..`` comment (``#`` removed).

    Raises ValueError with a message that names the bad term (``where`` prefixes it;
    the caller adds file and line).
    """
    body = comment.strip()[len(DIRECTIVE):].split("#", 1)[0]
    row = np.zeros(N_ASPHERE)
    seen = set()
    for tok in body.split():
        name, eq, value = tok.partition("=")
        name = name.strip().lower()
        if not eq or name not in TERM_NAMES:
            raise ValueError(f"{where}'{tok}' is not a term; write k=<conic> and "
                             f"a2=, a4=, ... a16=<coefficient of r^2, r^4, ... r^16>")
        if name in seen:
            raise ValueError(f"{where}'{name}' is given twice")
        try:
            v = float(value)
        except ValueError:
            raise ValueError(f"{where}{name}: '{value}' is not a number") from None
        if not math.isfinite(v):
            raise ValueError(f"{where}{name}: '{value}' is not a finite number")
        seen.add(name)
        row[TERM_NAMES.index(name)] = v
    return row


def format_directive(row: np.ndarray) -> str:
    """``#!asphere k=.. a4=..`` for a (9,) row: k always, the non-zero terms, 17 digits."""
    terms = [f"k={row[0]:.17g}"] + [f"{n}={v:.17g}" for n, v in zip(TERM_NAMES[1:], row[1:])
                                    if v != 0.0]
    return "#" + DIRECTIVE + " " + " ".join(terms)


def scaled_asphere(asphere: np.ndarray | None, factor: float) -> np.ndarray | None:
    """Asphere data of a lens scaled by ``factor`` (all lengths x factor): k stays,
    a_2i is multiplied by factor^(1 - 2i)."""
    if asphere is None:
        return None
    powers = np.arange(N_ASPHERE, dtype=np.float64) * 2.0     # 0 (k), 2, 4, ... 16
    scale = np.where(powers == 0, 1.0, float(factor) ** (1.0 - powers))
    return asphere * scale


def stable_quadric_root(a, B, C, ds):
    """The wanted root t of ``a t^2 + 2 B t + C = 0`` for rays whose sag direction is
    ``ds`` (the vertex branch met in the travel sense), without cancellation (the
    sphere's rule in :mod:`povlens.lens.tracer`, for any quadric of the vertex form).

    Returns
    -------
    t : the root (not finite where the quadric is missed or degenerate).
    D : the discriminant B^2 - a C (< 0: missed).
    same : where B has the sign of the travel sense (the ``-C / (B + sigma sqrt D)`` form).
    """
    D = B * B - a * C
    sqrtD = np.sqrt(np.maximum(D, 0.0))
    sigma = -np.sign(ds)
    same = (np.sign(B) == sigma) | (B == 0.0)
    t = np.where(same, -C / (B + sigma * sqrtD), (sigma * sqrtD - B) / np.where(a != 0, a, 1.0))
    return t, D, same
