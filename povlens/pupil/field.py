"""Field sampling: one pupil point per lens sample, shared by the whole film.

A lens sample of the ray-field method (the distribution-3 ray meshes of
:mod:`povlens.pov.field_mesh`) is one point P on the pupil table's sampling plane
(z = ``plane_z_mm``, camera frame of :mod:`povlens.lens.frames`, mm) and one sub-pixel
offset, both shared by every pixel (accumulation-buffer sampling).  The ray of film
point f runs from f toward P and is traced through the lens.

* **Pupil point.**  P is uniform on a disc of radius R_B (:func:`bounding_disc_radius_mm`)
  containing the table's (dilated, conservative) region at every film radius and
  azimuth, so every ray the lens passes can be drawn: the weight of a passing ray,
  cos^4(theta) / z_p^2 * pi R_B^2, is unbiased (the pupil sampler's weight,
  :func:`povlens.pupil.sampler.finish_sample`, with pdf 1 / (pi R_B^2)).
* **Sample points.**  Sample k takes the k-th point of a scrambled 4-D Sobol sequence:
  dimensions 0-1 the sub-pixel offset (x right, y down, pixels), 2-3 the pupil point
  through the concentric map.
* **Image positions.**  x right from the image's left edge and y down from its top,
  in pixels: pixel (i, j) covers [i, i+1) x [j, j+1).  Film point = (-u, -v) of
  :meth:`povlens.lens.film.Film.image_plane_mm` (the image is inverted on the film).

The ray field is traced *unclipped* (:func:`povlens.lens.tracer.trace_unclipped_from_film`):
smooth across every vignetting cut, which is what an interpolated mesh needs; the
exact verdict comes from its aperture margins.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from povlens.lens.film import Film
from povlens.lens.prescription import LensPrescription
from povlens.lens.tracer import trace_unclipped_from_film
from povlens.pupil.sampling import sobol_points

__all__ = ["FieldRays", "bounding_disc_radius_mm", "field_sample_points", "concentric_disc_mm",
           "image_to_film_mm", "trace_field", "field_weight", "DISC_MARGIN"]

#: Relative margin of the bounding disc over the largest table region radius found.
DISC_MARGIN = 2e-3


def bounding_disc_radius_mm(table, n_radii: int = 257) -> float:
    """R_B (mm): a disc about the axis on the table's sampling plane that contains the
    table's region at every film radius (``n_radii`` radii from 0 to the table's
    largest, knots included), enlarged by :data:`DISC_MARGIN`.

    Parameters
    ----------
    table : :class:`povlens.pupil.table.PupilTable`.

    Returns
    -------
    float
        0 when the table has no region at all (every film point vignetted).
    """
    radii = np.union1d(np.linspace(0.0, table.max_film_radius_mm, n_radii),
                       table.film_radius_mm[table.film_radius_mm <= table.max_film_radius_mm])
    r = 0.0
    for fr in radii:
        poly = table.region(float(fr))
        if len(poly):
            r = max(r, float(np.hypot(poly[:, 0], poly[:, 1]).max()))
    return r * (1.0 + DISC_MARGIN)


def field_sample_points(n_samples: int, seed: int = 0, jitter: bool = True) -> np.ndarray:
    """(N, 4) sample points in [0, 1): the sub-pixel offset (0-1; 0.5 without
    ``jitter``: pixel centres) and the pupil coordinates (2-3) of each lens sample."""
    pts = np.array(sobol_points(max(int(n_samples), 1), 4, seed=seed)[:n_samples], dtype=float)
    if not jitter:
        pts[:, :2] = 0.5
    return pts


def concentric_disc_mm(u, radius_mm: float) -> np.ndarray:
    """Shirley-Chiu concentric map of u in [0, 1)^2 (..., 2) onto the disc of
    ``radius_mm`` (..., 2): uniform, area-preserving, continuous."""
    u = np.asarray(u, dtype=np.float64)
    a, b = 2.0 * u[..., 0] - 1.0, 2.0 * u[..., 1] - 1.0
    first = np.abs(a) > np.abs(b)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(first, a, b)
        phi = np.where(first, math.pi / 4 * (b / a), math.pi / 2 - math.pi / 4 * (a / b))
    zero = (a == 0) & (b == 0)
    r, phi = np.where(zero, 0.0, r), np.where(zero, 0.0, phi)
    return radius_mm * np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)


def image_to_film_mm(film: Film, x, y) -> np.ndarray:
    """Image positions (pixels, any equal shapes) -> film points (..., 2), mm."""
    u, v = film.image_plane_mm(np.asarray(x, float), np.asarray(y, float), 0.0, 0.0)
    return np.stack([-u, -v], axis=-1)


@dataclasses.dataclass(frozen=True)
class FieldRays:
    """Rays of n image positions for one pupil point (camera frame).

    origin_mm, direction : (n, 3) where the unclipped ray leaves the front surface
        and its unit direction (finite everywhere).
    exists : (n,) the unclipped ray exists (meets every surface, no total reflection).
    margin_mm2 : (n, S) aperture margins r_i^2 - h_i^2 (-inf where not reached).
    passed : (n,) the exact verdict of :func:`povlens.lens.tracer.trace_from_film`.
    """

    origin_mm: np.ndarray
    direction: np.ndarray
    exists: np.ndarray
    margin_mm2: np.ndarray
    passed: np.ndarray


def trace_field(lens: LensPrescription, film_distance_mm: float, film: Film, plane_z_mm: float,
                pupil_xy_mm, x, y) -> FieldRays:
    """The rays of image positions (x, y) (pixels, flattened) toward the pupil point
    ``pupil_xy_mm`` (2,) on the plane z = ``plane_z_mm``, traced unclipped."""
    f = image_to_film_mm(film, x, y).reshape(-1, 2)
    n = len(f)
    origin = np.zeros((n, 3))
    origin[:, :2] = f
    direction = np.empty((n, 3))
    direction[:, 0] = pupil_xy_mm[0] - f[:, 0]
    direction[:, 1] = pupil_xy_mm[1] - f[:, 1]
    direction[:, 2] = plane_z_mm
    t = trace_unclipped_from_film(lens, film_distance_mm, origin, direction)
    return FieldRays(t.origin_mm, t.direction, t.exists, t.margin_mm2, t.passed)


def field_weight(film: Film, plane_z_mm: float, pupil_xy_mm, disc_radius_mm: float,
                 jitter_px, passed: np.ndarray) -> np.ndarray:
    """(H, W) float32 radiometric weights of one lens sample at every pixel.

    w = passed * cos^4(theta) / z_p^2 * pi R_B^2, theta the angle of the film-side ray
    (pixel (i, j)'s image position (i + jx, j + jy) toward the pupil point) with the
    axis.  Computed separably (columns x rows) in float32.

    Parameters
    ----------
    film : the film (its pixel counts give H, W).
    plane_z_mm, pupil_xy_mm, disc_radius_mm : the sampling plane, the sample's pupil
        point (2,) and the disc's radius (mm).
    jitter_px : (2,) the sample's sub-pixel offset (x right, y down).
    passed : (H, W) bool, the exact verdict per pixel.
    """
    W, H = film.width_px, film.height_px
    fx = image_to_film_mm(film, np.arange(W) + jitter_px[0], np.zeros(W))[:, 0]
    fy = image_to_film_mm(film, np.zeros(H), np.arange(H) + jitter_px[1])[:, 1]
    zp2 = np.float32(plane_z_mm * plane_z_mm)
    dx2 = ((pupil_xy_mm[0] - fx) ** 2).astype(np.float32)
    dy2 = ((pupil_xy_mm[1] - fy) ** 2).astype(np.float32)
    c2 = zp2 / (dy2[:, None] + dx2[None, :] + zp2)
    w = c2 * c2 * np.float32(math.pi * disc_radius_mm ** 2 / plane_z_mm ** 2)
    w[~np.asarray(passed, bool)] = 0.0
    return w
