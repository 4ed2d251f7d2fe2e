"""Field sampling: one canonical lens sample per tile, shared by the tile's pixels.

A lens sample of the ray-field method (the distribution-3 ray meshes of
:mod:`povlens.pov.field_mesh`) is, for each tile of a pass (every m-th pixel in x and
y, :func:`povlens.pov.field_mesh.pass_models`), one canonical point q of the unit disc
and one sub-pixel offset, shared by the tile's pixels.  Film point f takes its own pupil
point P(f, q) on the pupil table's sampling plane (z = ``plane_z_mm``, camera frame of
:mod:`povlens.lens.coordinates`, mm): q mapped onto f's ellipse of
:mod:`povlens.pupil.field_domain` (:class:`PupilMap`).  The ray of film point f runs from
f toward P and is traced through the lens.

* **Pupil point.**  P is uniform on an ellipse containing f's (dilated, conservative)
  table region, so every ray the lens passes can be drawn: the weight of a passing ray,
  cos^4(theta) / z_p^2 * pi a b, is unbiased (the pupil sampler's weight,
  :func:`povlens.pupil.sampler_interface.finish_sample`, with pdf 1 / (pi a b)).  The map is
  smooth in f, so a fixed q gives a smooth ray field a coarse mesh carries.
* **Sample points.**  Pass k takes the k-th point X_k of a scrambled 4-D Sobol sequence:
  dimensions 0-1 the sub-pixel offset (x right, y down, pixels), 2-3 q through the
  concentric map; tile c adds its own shift d_c (mod 1, a Cranley-Patterson rotation,
  :func:`tile_shifts`), so each pixel's samples over the passes are a stratified set,
  and the m x m neighbours of a pass take m^2 different ones.
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
from povlens.pupil.monte_carlo import sobol_points

__all__ = ["FieldRays", "PupilMap", "bounding_disc_radius_mm", "field_sample_points",
           "tile_shifts", "tile_points", "concentric_disc_mm", "image_to_film_mm", "trace_field",
           "field_weight", "DISC_MARGIN"]

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


def tile_shifts(stride: int, seed: int = 0) -> np.ndarray:
    """(m^2, 4) the Cranley-Patterson shifts of the m x m tiles of a pass, tile c = ox + m oy:
    0 for m = 1; else the first m^2 points of a scrambled Sobol' sequence (another seed than
    the passes'), consecutive points, far apart, going to neighbouring tiles."""
    m = int(stride)
    if m == 1:
        return np.zeros((1, 4))
    return np.array(sobol_points(1 << (m * m - 1).bit_length(), 4, seed=seed + 7919)[:m * m])


def tile_points(base: np.ndarray, stride: int, seed: int = 0) -> np.ndarray:
    """(m^2, 4) the sample points of the tiles of one pass whose point is ``base`` (4,)."""
    return np.mod(np.asarray(base, float)[None, :] + tile_shifts(stride, seed), 1.0)


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
class PupilMap:
    """The pupil point of every film point for one tile's lens sample: P(f) =
    ``domain.points_mm(f, q)`` (:class:`povlens.pupil.field_domain.FieldDomain`).

    domain : the ellipse family; q : (2,) the canonical point of the unit disc.
    """

    domain: object
    q: tuple[float, float]

    def __call__(self, film_xy) -> np.ndarray:
        """(n, 2) pupil points of film points (n, 2), mm."""
        return self.domain.points_mm(film_xy, np.asarray(self.q, float))

    def area_mm2(self, film_xy) -> np.ndarray:
        """(n,) the area the pupil points are uniform on (1 / their density), mm^2."""
        return self.domain.area_mm2(film_xy)


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


def _pupil_points(pupil, f: np.ndarray) -> np.ndarray:
    """(n, 2) the pupil points of film points f: a :class:`PupilMap`'s, or one fixed
    point (2,) for all."""
    if callable(pupil):
        return pupil(f)
    return np.broadcast_to(np.asarray(pupil, dtype=np.float64), f.shape)


def trace_field(lens: LensPrescription, film_distance_mm: float, film: Film, plane_z_mm: float,
                pupil, x, y) -> FieldRays:
    """The rays of image positions (x, y) (pixels, flattened) toward their pupil points
    on the plane z = ``plane_z_mm`` (``pupil``: a :class:`PupilMap`, or one point (2,)
    mm for all), traced unclipped."""
    f = image_to_film_mm(film, x, y).reshape(-1, 2)
    n = len(f)
    origin = np.zeros((n, 3))
    origin[:, :2] = f
    P = _pupil_points(pupil, f)
    direction = np.empty((n, 3))
    direction[:, 0] = P[:, 0] - f[:, 0]
    direction[:, 1] = P[:, 1] - f[:, 1]
    direction[:, 2] = plane_z_mm
    t = trace_unclipped_from_film(lens, film_distance_mm, origin, direction)
    return FieldRays(t.origin_mm, t.direction, t.exists, t.margin_mm2, t.passed)


def field_weight(film: Film, plane_z_mm: float, pupil, jitter_px, passed: np.ndarray,
                 columns=None, rows=None) -> np.ndarray:
    """(h, w) float32 radiometric weights of one tile's lens sample at its pixels.

    w = passed * cos^4(theta) / z_p^2 * A, theta the angle of the film-side ray (the
    pixel's image position (i + jx, j + jy) toward its pupil point) with the axis and A
    the area the pupil points are uniform on (the :class:`PupilMap`'s ellipse).

    Parameters
    ----------
    film : the film.
    plane_z_mm : the sampling plane (mm).
    pupil : the tile's :class:`PupilMap`.
    jitter_px : (2,) the sample's sub-pixel offset (x right, y down).
    passed : (h, w) bool, the exact verdict per pixel.
    columns, rows : (w,), (h,) the image columns and rows of the pixels (default all).
    """
    W, H = film.width_px, film.height_px
    cols = np.arange(W) if columns is None else np.asarray(columns)
    rws = np.arange(H) if rows is None else np.asarray(rows)
    x = np.broadcast_to(cols[None, :] + float(jitter_px[0]), (len(rws), len(cols)))
    y = np.broadcast_to(rws[:, None] + float(jitter_px[1]), (len(rws), len(cols)))
    ok = np.asarray(passed, bool)
    w = np.zeros(ok.shape, np.float32)
    if not ok.any():
        return w
    f = image_to_film_mm(film, x[ok], y[ok])
    P, area = pupil(f), pupil.area_mm2(f)
    zp2 = plane_z_mm * plane_z_mm
    c2 = zp2 / (np.einsum("ij,ij->i", P - f, P - f) + zp2)
    w[ok] = (c2 * c2 * area / zp2).astype(np.float32)
    return w
