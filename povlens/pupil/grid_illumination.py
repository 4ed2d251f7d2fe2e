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
