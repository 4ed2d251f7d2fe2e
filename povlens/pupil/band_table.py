"""An exit-pupil table that holds the pass region of every wavelength of a band.

``--dispersion`` on per-pixel meshes traces each lens sample at its own wavelength
through the pupil table built for the d line.  The pass region moves and grows a
little with the wavelength, so the d-line table could miss rays that pass at the
band's ends and the render would be biased dark there.  The band table is the d-line
table with each knot's polygon scaled about its centre (``rho`` times a factor >= 1)
until it holds what passes at the band's ends; the pupils change monotonically with
the index (docs/decisions/dispersion.md, "Pupil disc"), so the ends bound
the band.  Sampling stays uniform over the (larger) region with pdf 1 / area, so the
estimate stays unbiased; the price is the extra area (the factor squared).

Frames: the table's rotated plane frame (film point on +x; :mod:`povlens.pupil.table`).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from povlens.lens.prescription import LensPrescription
from povlens.lens.tracer import trace_from_film
from povlens.pupil.table import PupilTable

__all__ = ["band_dilation", "band_table"]

#: Relative margin added to the measured factors (the probe grid is finite).
BAND_MARGIN = 0.01


def _extent(rho: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """The star polygon's normalised radius at angles ``theta`` in [0, pi] (the same
    edge formula as :meth:`PupilTable.contains`)."""
    M = rho.size - 1
    h = math.pi / M
    j = np.clip(np.floor(theta / h).astype(np.int64), 0, M - 1)
    phi = theta - j * h
    a, b = rho[j], rho[j + 1]
    den = a * np.sin(phi) + b * np.sin(h - phi)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, a * b * math.sin(h) / np.where(den > 0, den, 1.0), 0.0)


def _needed_scale(table: PupilTable, lenses: Sequence[LensPrescription], r: float,
                  n_angles: int, n_rho: int, reach: float) -> float:
    """The factor the d-line polygon at film radius ``r`` needs to hold what passes one
    of ``lenses`` (1 where nothing falls outside; 1 where the d line is vignetted:
    such film points stay vignetted).

    Per probe angle: the outermost passing point of a radial grid (normalised radii out
    to ``reach``, further if rays pass there), then its boundary bisected to 1/256 of
    the grid step."""
    inside, c, sx, sy, rho = table._rho_at(r)
    if not inside or not (sx > 0 and sy > 0) or not np.any(rho > 0):
        return 1.0
    theta = np.linspace(0.0, math.pi, int(n_angles))
    dq = reach / int(n_rho)
    q = (np.arange(int(n_rho)) + 1) * dq

    def passes(lens, t, qq):
        x, y = c + sx * qq * np.cos(t), sy * qq * np.sin(t)
        origin = np.zeros((x.size, 3))
        origin[:, 0] = r
        direction = np.column_stack([x - r, y, np.full(x.size, table.plane_z_mm)])
        return trace_from_film(lens, table.film_distance_mm, origin, direction).passed

    need = 1.0
    for lens in lenses:
        T, Q = np.meshgrid(theta, q, indexing="ij")
        passed = passes(lens, T.ravel(), Q.ravel()).reshape(T.shape)
        if not passed.any():
            continue
        if passed[:, -1].any():                      # the grid did not reach the edge
            return _needed_scale(table, lenses, r, n_angles, n_rho, 2.0 * reach)
        rows = np.flatnonzero(passed.any(axis=1))
        last = passed.shape[1] - 1 - np.argmax(passed[rows, ::-1], axis=1)
        lo, hi = q[last], q[last] + dq               # passes at lo, not at hi
        for _ in range(8):
            mid = 0.5 * (lo + hi)
            ok = passes(lens, theta[rows], mid)
            lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
        extent = _extent(rho, theta[rows])
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(extent > 0, hi / extent, np.inf)
        need = max(need, float(ratio.max()))
    return need


def band_dilation(table: PupilTable, band_lenses: Sequence[LensPrescription], *,
                  n_angles: int = 64, n_rho: int = 32, margin: float = BAND_MARGIN) -> np.ndarray:
    """Per-knot factors (K,) >= 1 by which ``table``'s polygons must grow to hold the
    pass regions of ``band_lenses`` (the lens at the band's end wavelengths).

    Parameters
    ----------
    table : the d-line table (its film distance and sampling plane are used).
    band_lenses : the lens at other wavelengths (:func:`povlens.lens.dispersion.lens_at_wavelength`).
    n_angles, n_rho : the probe grid per film radius (angles over [0, pi], normalised
        radii out to twice the region, further if rays still pass there), whose
        outermost passing point per angle is then bisected.
    margin : relative margin on the measured factors.

    Returns
    -------
    (K,) float64
        Factor of knot k: what its own radius and the midpoints to its neighbours need
        (the table interpolates ``rho`` linearly, so both ends of an interval holding
        the midpoint's need hold it between), times ``1 + margin``.
    """
    lenses = [lens.replace(aperture_shape=None, aperture_shape_row=-1) for lens in band_lenses]
    rs = table.film_radius_mm
    at_knot = np.array([_needed_scale(table, lenses, float(r), n_angles, n_rho, 2.0)
                        for r in rs])
    mids = 0.5 * (rs[:-1] + rs[1:])
    at_mid = np.array([_needed_scale(table, lenses, float(r), n_angles, n_rho, 2.0)
                       for r in mids])
    need = at_knot.copy()
    need[:-1] = np.maximum(need[:-1], at_mid)
    need[1:] = np.maximum(need[1:], at_mid)
    return np.where(need > 1.0, need * (1.0 + margin), 1.0)


def band_table(table: PupilTable, factors) -> PupilTable:
    """``table`` with knot k's polygon scaled by ``factors[k]`` about its centre.

    The axial irradiance factor (the exposure) stays the d line's: the spectral
    composite is normalised so that the image's exposure matches the d-line render.

    Raises
    ------
    ValueError
        If ``factors`` does not hold one finite factor >= 1 per knot.
    """
    f = np.asarray(factors, dtype=np.float64)
    if f.shape != (table.n_knots,) or not np.all(np.isfinite(f)) or np.any(f < 1.0):
        raise ValueError(f"band_table: {f.shape[0] if f.ndim == 1 else f.shape} factors for "
                         f"{table.n_knots} knots; each must be finite and >= 1")
    meta = dict(table.metadata, band_dilation_max=float(f.max()))
    return PupilTable(table.lens, table.film_distance_mm, table.film_half_diagonal_mm,
                      table.plane_z_mm, table.plane, table.film_radius_mm, table.centre_x_mm,
                      table.scale_x_mm, table.scale_y_mm, table.rho * f[:, None],
                      table.max_film_radius_mm, table.vignetted_beyond_mm, table.tolerance,
                      table.axial_irradiance_factor, table.stats, meta)
