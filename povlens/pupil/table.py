"""The exit-pupil table: for each film radius, the region of the sampling plane
through which rays from the film get through the lens, and a sampler over it.

Frames are those of :mod:`povlens.lens.coordinates` (camera frame, mm, film at z = 0,
lens toward +z).  The table is built by :func:`povlens.pupil.build.build_pupil_table`
(which also explains the sampling plane and how the tolerance sets the knots), and
stored by :mod:`povlens.pupil.storage`.

Shape description
-----------------
For the film point (r, 0) the pass region R(r) on the plane (the intersection
of the images of the stop and of the element rims: a cat's eye off axis) is
described in a normalised frame that follows it: centre (c(r), 0) on the x
axis in the middle of the region's stretch of that axis, half-width s_x(r)
along x and half-height s_y(r) through the centre.  In that frame the region
is a polygon star-shaped about the origin: vertices at the fixed angles
t_j = j pi / M, j = 0..M, at normalised distances rho_j(r), mirrored to the
lower half (2M vertices in all); on the plane a vertex is
(c + s_x rho_j cos t_j, +-s_y rho_j sin t_j).  The frame keeps the polygon
well conditioned when the region becomes a thin sliver (the fisheye near its
vignetting cut-off).  Between knots, c, s_x, s_y and every rho_j are
interpolated linearly in r, so the region, its area and the sample map are
continuous in r: no rings can appear.  The region for a film point at azimuth
phi is this one rotated by phi (the lens is rotationally symmetric).

Sampling
--------
A point u in [0, 1)^2 is mapped into the polygon by an area-preserving map:
u_1 picks the upper or lower half (tent map, continuous at u_1 = 1/2) and,
through the area CDF of the fan of triangles (centre, V_j, V_j+1), a triangle
and a fraction v along its outer edge; the point is centre + sqrt(u_2) ((1 - v)
V_j + v V_j+1), which is uniform in the triangle.  The pdf is therefore exactly
1 / area.  Per sample, the fan's CDF at the sample's film radius is a quadratic
in the interpolation weight of three per-interval cumulative sums, searched by
vectorized bisection (no per-ray Python loop, O(log M) per sample).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from povlens.errors import OpticsError
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import LensPrescription
from povlens.pupil.sampler_interface import (LensSample, SamplerMeasurements,
                                             check_sample_arguments, finish_sample,
                                             polar_film_coordinates)
from povlens.pupil.table_file import FORMAT_NAME, FORMAT_VERSION, read_table_file, write_table_file

__all__ = ["PupilTable"]

#: Film points no further than this fraction beyond the table's range still count as inside.
_RANGE_SLACK = 1e-9


class PupilTable(SamplerMeasurements):
    """Exit-pupil regions over film radius for one lens, stop, focus and film.

    The region for the film point (r, 0) is the polygon with vertices
    ``(c + s_x rho_j cos t_j, +-s_y rho_j sin t_j)``, t_j = j pi / M, with c, s_x,
    s_y and every rho_j linear in r between knots.

    Attributes (arrays float64):
    film_radius_mm : (K,) knot radii, increasing, the first 0.
    centre_x_mm : (K,) region centres on the rotated x axis (c).
    scale_x_mm, scale_y_mm : (K,) the region's half-width along x and half-height
        through the centre (s_x, s_y): the normalised frame.
    rho : (K, M + 1) normalised vertex distances (dilated: conservative).
    max_film_radius_mm : film points beyond this are vignetted.
    vignetted_beyond_mm : radius beyond which no ray gets through, or None when
        rays leave the whole film.
    plane_z_mm, plane : the sampling plane.
    axial_irradiance_factor : E/L at the film centre from the exact boundary.
    stats : build statistics (time, rays traced, errors).
    metadata : JSON-able dict saved with the table.
    """

    def __init__(self, lens: LensPrescription, film_distance_mm: float,
                 film_half_diagonal_mm: float, plane_z_mm: float, plane: str,
                 film_radius_mm, centre_x_mm, scale_x_mm, scale_y_mm, rho,
                 max_film_radius_mm: float, vignetted_beyond_mm: float | None,
                 tolerance: float, axial_irradiance_factor: float,
                 stats: dict | None = None, metadata: dict | None = None):
        self.lens = lens
        self.film_distance_mm = float(film_distance_mm)
        self.film_half_diagonal_mm = float(film_half_diagonal_mm)
        self.plane_z_mm = float(plane_z_mm)
        self.plane = plane
        self.film_radius_mm = np.asarray(film_radius_mm, dtype=np.float64)
        self.centre_x_mm = np.asarray(centre_x_mm, dtype=np.float64)
        self.scale_x_mm = np.asarray(scale_x_mm, dtype=np.float64)
        self.scale_y_mm = np.asarray(scale_y_mm, dtype=np.float64)
        self.rho = np.asarray(rho, dtype=np.float64)
        self.max_film_radius_mm = float(max_film_radius_mm)
        self.vignetted_beyond_mm = (None if vignetted_beyond_mm is None
                                    else float(vignetted_beyond_mm))
        self.tolerance = float(tolerance)
        self.axial_irradiance_factor = float(axial_irradiance_factor)
        self.stats = dict(stats or {})
        self.metadata = dict(metadata or {})
        K = self.film_radius_mm.size
        if (K < 2 or self.rho.ndim != 2 or self.rho.shape[0] != K or self.rho.shape[1] < 3
                or any(a.shape != (K,) for a in (self.centre_x_mm, self.scale_x_mm,
                                                   self.scale_y_mm))
                or not np.all(np.diff(self.film_radius_mm) > 0)
                or not all(np.all(np.isfinite(a)) for a in (self.centre_x_mm, self.scale_x_mm,
                                                             self.scale_y_mm, self.rho))):
            raise ValueError("a pupil table needs at least two increasing knots with "
                             "matching finite arrays")
        self._prepare()

    # -- derived arrays for sampling
    def _prepare(self) -> None:
        M = self.n_angles
        self._h = math.pi / M
        theta = np.arange(M + 1) * self._h
        self._cos_t, self._sin_t = np.cos(theta), np.sin(theta)
        a, b = self.rho[:-1], self.rho[1:]
        z = np.zeros((a.shape[0], 1))
        # Fan-of-triangles CDF, a quadratic in the interpolation weight t:
        # rho_j rho_j+1 = (1-t)^2 a_j a_j+1 + t (1-t) (a_j b_j+1 + b_j a_j+1) + t^2 b_j b_j+1.
        self._Caa = np.concatenate([z, np.cumsum(a[:, :-1] * a[:, 1:], axis=1)], axis=1)
        self._Cab = np.concatenate([z, np.cumsum(a[:, :-1] * b[:, 1:] + b[:, :-1] * a[:, 1:],
                                                 axis=1)], axis=1)
        self._Cbb = np.concatenate([z, np.cumsum(b[:, :-1] * b[:, 1:], axis=1)], axis=1)

    @property
    def n_knots(self) -> int:
        return int(self.film_radius_mm.size)

    @property
    def n_angles(self) -> int:
        """M: angular intervals on the half plane (the polygon has 2M vertices)."""
        return int(self.rho.shape[1] - 1)

    def _locate(self, r: np.ndarray):
        knots = self.film_radius_mm
        k = np.clip(np.searchsorted(knots, r, side="right") - 1, 0, knots.size - 2)
        with np.errstate(invalid="ignore"):
            t = np.clip((r - knots[k]) / (knots[k + 1] - knots[k]), 0.0, 1.0)
        t = np.where(np.isfinite(t), t, 0.0)
        inside = np.isfinite(r) & (r <= self.max_film_radius_mm * (1 + _RANGE_SLACK)
                                   + _RANGE_SLACK)
        return k, t, inside

    def _frame(self, k, t):
        lerp = lambda a: (1 - t) * a[k] + t * a[k + 1]  # noqa: E731
        return lerp(self.centre_x_mm), lerp(self.scale_x_mm), lerp(self.scale_y_mm)

    def _normalised_total(self, k, t):
        M = self.n_angles
        return ((1 - t) ** 2 * self._Caa[k, M] + t * (1 - t) * self._Cab[k, M]
                + t * t * self._Cbb[k, M])

    def area_mm2(self, film_radius_mm) -> np.ndarray:
        """Area (mm^2) of the sampled region at each film radius; 0 where vignetted."""
        r = np.atleast_1d(np.asarray(film_radius_mm, dtype=np.float64))
        k, t, inside = self._locate(r)
        _, sx, sy = self._frame(k, t)
        area = math.sin(self._h) * sx * sy * self._normalised_total(k, t)
        return np.where(inside, area, 0.0)

    def is_vignetted(self, film_radius_mm) -> np.ndarray:
        """True where no ray from a film point at this radius gets through."""
        return ~(self.area_mm2(film_radius_mm) > 0)

    def _rho_at(self, r: float):
        k, t, inside = self._locate(np.array([float(r)]))
        c, sx, sy = (float(v[0]) for v in self._frame(k, t))
        rho = (1 - t[0]) * self.rho[k[0]] + t[0] * self.rho[k[0] + 1]
        return bool(inside[0]), c, sx, sy, rho

    def region(self, film_radius_mm: float) -> np.ndarray:
        """The polygon (2M, 2) on the plane for the film point (r, 0), counter-clockwise;
        empty (0, 2) where vignetted."""
        inside, c, sx, sy, rho = self._rho_at(film_radius_mm)
        if not inside or not np.any(rho > 0):
            return np.zeros((0, 2))
        up = np.stack([c + sx * rho * self._cos_t, sy * rho * self._sin_t], axis=1)
        low = up[-2:0:-1] * np.array([1.0, -1.0])
        return np.concatenate([up, low])

    def contains(self, film_radius_mm: float, points_xy) -> np.ndarray:
        """Whether plane points (n, 2) (rotated frame: film point on +x) lie in the
        table's region for film radius ``film_radius_mm``."""
        pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
        inside, c, sx, sy, rho = self._rho_at(film_radius_mm)
        if not inside or not (sx > 0 and sy > 0):
            return np.zeros(len(pts), bool)
        M, h = self.n_angles, self._h
        dx, dy = (pts[:, 0] - c) / sx, np.abs(pts[:, 1]) / sy
        dist = np.hypot(dx, dy)
        theta = np.arctan2(dy, dx)
        j = np.clip(np.floor(theta / h).astype(np.int64), 0, M - 1)
        phi = theta - j * h
        a, b = rho[j], rho[j + 1]
        den = a * np.sin(phi) + b * np.sin(h - phi)
        with np.errstate(invalid="ignore", divide="ignore"):
            extent = np.where(den > 0, a * b * math.sin(h) / np.where(den > 0, den, 1.0), 0.0)
        return dist <= extent

    def sample(self, film_xy, u) -> LensSample:
        """Rays for film points ``film_xy`` (n, 2) mm and points ``u`` (n, 2) in [0, 1).

        The pupil point is uniform in the table's region (pdf = 1 / area); the
        map from u is continuous in u and in the film point, and area-preserving.
        """
        f, uu = check_sample_arguments(film_xy, u)
        n = f.shape[0]
        M = self.n_angles
        r, cos_phi, sin_phi = polar_film_coordinates(f)
        k, t, inside = self._locate(r)
        w0, w1, w2 = (1 - t) ** 2, t * (1 - t), t * t
        Caa, Cab, Cbb = self._Caa, self._Cab, self._Cbb

        def cdf(j):
            return w0 * Caa[k, j] + w1 * Cab[k, j] + w2 * Cbb[k, j]

        total = cdf(np.full(n, M))
        u1 = uu[:, 0]
        upper = u1 < 0.5
        s = np.clip(np.where(upper, 2.0 * u1, 2.0 - 2.0 * u1), 0.0, np.nextafter(1.0, 0.0))
        target = s * total
        lo = np.zeros(n, dtype=np.int64)
        hi = np.full(n, M, dtype=np.int64)
        while True:  # vectorized bisection for the triangle: O(log M) passes
            open_ = hi - lo > 1
            if not open_.any():
                break
            mid = (lo + hi) // 2
            below = cdf(mid) <= target
            lo = np.where(open_ & below, mid, lo)
            hi = np.where(open_ & ~below, mid, hi)
        j = lo
        c_lo = cdf(j)
        tri = cdf(j + 1) - c_lo
        with np.errstate(invalid="ignore", divide="ignore"):
            v = np.where(tri > 0, (target - c_lo) / np.where(tri > 0, tri, 1.0), 0.0)
        v = np.clip(v, 0.0, 1.0)
        rho_j = (1 - t) * self.rho[k, j] + t * self.rho[k + 1, j]
        rho_j1 = (1 - t) * self.rho[k, j + 1] + t * self.rho[k + 1, j + 1]
        c, sx, sy = self._frame(k, t)
        a = np.sqrt(uu[:, 1])
        qx = a * ((1 - v) * rho_j * self._cos_t[j] + v * rho_j1 * self._cos_t[j + 1])
        qy = a * ((1 - v) * rho_j * self._sin_t[j] + v * rho_j1 * self._sin_t[j + 1])
        lx = c + sx * qx
        ly = np.where(upper, sy * qy, -sy * qy)
        px = cos_phi * lx - sin_phi * ly
        py = sin_phi * lx + cos_phi * ly
        area = math.sin(self._h) * sx * sy * total
        return finish_sample(f, px, py, self.plane_z_mm, area, inside & (total > 0))

    # -- measurements
    def exposure_normalisation(self) -> float:
        """1 / (E/L) at the film centre, from the exact on-axis boundary: the factor
        that gives the frame centre the brightness of a pinhole render."""
        if not self.axial_irradiance_factor > 0:
            raise OpticsError(f"{self.lens.source}: no ray from the film centre gets through")
        return 1.0 / self.axial_irradiance_factor

    # -- files
    def describe(self) -> dict:
        """Metadata: the inputs (for cache checks) and build statistics."""
        p = paraxial_data(self.lens)
        d = dict(self.metadata)
        d.update({
            "format": FORMAT_NAME, "version": FORMAT_VERSION,
            "lens": {"source": self.lens.source, "sha256": self.lens.sha256(),
                     "stop_diameter_mm": p.stop_diameter, "f_number": p.f_number},
            "film_distance_mm": self.film_distance_mm,
            "film": {**(self.metadata.get("film") or {}),
                     "half_diagonal_mm": self.film_half_diagonal_mm},
            "plane": self.plane, "plane_z_mm": self.plane_z_mm,
            "tolerance": self.tolerance,
            "knots": self.n_knots, "angles": self.n_angles,
            "max_film_radius_mm": self.max_film_radius_mm,
            "vignetted_beyond_mm": self.vignetted_beyond_mm,
            "axial_irradiance_factor": self.axial_irradiance_factor,
            "stats": self.stats,
        })
        return d

    def save(self, path) -> Path:
        """Write the table to ``path`` (:mod:`povlens.pupil.table_file`), atomically."""
        arrays = {"film_radius_mm": self.film_radius_mm, "centre_x_mm": self.centre_x_mm,
                  "scale_x_mm": self.scale_x_mm, "scale_y_mm": self.scale_y_mm,
                  "rho": self.rho}
        return write_table_file(path, arrays, self.lens, self.describe())

    @classmethod
    def load(cls, path) -> "PupilTable":
        """Read a table written by :meth:`save`.  Raises PovlensError if it is not one."""
        return read_table_file(path, cls)
