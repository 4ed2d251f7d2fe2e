"""The exit-pupil table over the film's two coordinates, for lenses without rotational symmetry.

An anamorphic lens (cylindrical or toric surfaces, :attr:`LensPrescription.radius_x_mm`)
is not rotationally symmetric: the pass region of a film point depends on its x and y,
not on its radius alone, so the radial table of :mod:`povlens.pupil.table` (one region
per radius, turned to the film point's azimuth) does not describe it.  Such a lens is
still mirror-symmetric in the x-z and y-z planes: the region of the film point
(-f_x, f_y) is the region of (f_x, f_y) mirrored in x (and likewise in y).  This table
therefore describes the regions over one quadrant of the film, f_x, f_y >= 0, on a
tensor grid of film points (knots ``knots_x_mm`` x ``knots_y_mm``), and mirrors them.
It is built by :func:`povlens.pupil.grid_build.build_grid_pupil_table`, stored like the
radial table (:mod:`povlens.pupil.table_file`, format ``povlens-pupil-grid``) and
chosen for anamorphic lenses by :func:`povlens.pupil.storage.cached_pupil_table`
(rotationally symmetric lenses keep the radial table).

Frames are those of :mod:`povlens.lens.coordinates` (camera frame, mm, film at z = 0,
lens toward +z); plane points are on the sampling plane z = ``plane_z_mm``
(:func:`povlens.pupil.build.sampling_plane_z_mm`).

Shape description
-----------------
At grid node (i, j) the region is a polygon star-shaped about its centre
(c_x, c_y), in the normalised frame of half-width s_x and half-height s_y: vertices at
the fixed angles t_k = 2 pi k / N, k = 0..N-1, at normalised distances rho_k, so a
vertex is (c_x + s_x rho_k cos t_k, c_y + s_y rho_k sin t_k).  Within a grid cell,
c_x, c_y, s_x, s_y and every rho_k are interpolated bilinearly in (f_x, f_y), so the
region, its area and the sample map are continuous over the quadrant (no seams between
cells).  The rho are dilated at build time so that the interpolated polygon contains
every ray that passes from every film point of the cell (measured by exact tracing at
the cells' centres and edges' midpoints; the tests check it by brute force).

Sampling
--------
As the radial table: the polygon is a fan of N triangles (centre, V_k, V_k+1) and
u_1 picks a triangle and a fraction v along its outer edge through the area CDF, the
point is centre + sqrt(u_2) ((1 - v) V_k + v V_k+1), uniform in the triangle, so the
pdf is exactly 1 / area.  With bilinear weights w_p (p over the cell's four corners)
the triangle areas are sums of w_p w_q rho^p_k rho^q_k+1: quadratic in the weights,
so the CDF is the weights' 10 products times 10 per-cell cumulative sums, and the
triangle is found by vectorized bisection (no per-ray Python loop).  The point found in
the quadrant's frame is mirrored to the film point's quadrant.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from povlens.errors import OpticsError
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import LensPrescription
from povlens.pupil.sampler_interface import (LensSample, SamplerMeasurements,
                                             check_sample_arguments, finish_sample)
from povlens.pupil.table_file import (GRID_FORMAT_NAME, GRID_FORMAT_VERSION,
                                      read_grid_table_file, write_table_file)

__all__ = ["GridPupilTable", "GRID_FORMAT_NAME", "GRID_FORMAT_VERSION", "frame_extent_mm",
           "CORNER_PAIRS"]

#: Film points no further than this fraction beyond the table's extent still count as inside.
_RANGE_SLACK = 1e-9
#: The cell's corners p = 0..3 are nodes (i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1);
#: the products w_p w_q of their bilinear weights, p <= q, in the order of the CDF's sums.
CORNER_PAIRS = tuple((p, q) for p in range(4) for q in range(p, 4))


def frame_extent_mm(film) -> tuple[float, float]:
    """(X, Y): the largest |f_x| and |f_y| (mm) of the frame of ``film``
    (:class:`povlens.lens.film.Film`, its shift included): the quadrant a grid table
    must cover."""
    return (0.5 * float(film.width_mm) + abs(float(film.shift_x_mm)),
            0.5 * float(film.height_mm) + abs(float(film.shift_y_mm)))


def _bilinear_weights(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, 4) bilinear weights of the four corners for cell coordinates a, b in [0, 1]."""
    return np.stack([(1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b], axis=1)


class GridPupilTable(SamplerMeasurements):
    """Exit-pupil regions over a grid of film points of one quadrant, for one lens, stop,
    focus and film extent (module docstring).

    Attributes (arrays float64):
    knots_x_mm : (Kx,) increasing film x of the grid's columns, the first 0.
    knots_y_mm : (Ky,) increasing film y of its rows, the first 0.
    centre_mm : (Kx, Ky, 2) region centres (c_x, c_y) on the plane.
    scale_mm : (Kx, Ky, 2) the normalised frame's (s_x, s_y).
    rho : (Kx, Ky, N) normalised vertex distances (dilated: conservative).
    cell_dark : (Kx - 1, Ky - 1) bool, True for cells where no ray gets through.
    film_extent_mm : (X, Y), the quadrant covered: |f_x| <= X, |f_y| <= Y.
    plane_z_mm, plane : the sampling plane.
    axial_irradiance_factor : E/L at the film centre from the exact boundary.
    stats, metadata : build statistics; JSON-able dict saved with the table.
    """

    kind = "grid"

    def __init__(self, lens: LensPrescription, film_distance_mm: float, film_extent_mm,
                 plane_z_mm: float, plane: str, knots_x_mm, knots_y_mm, centre_mm, scale_mm,
                 rho, cell_dark, tolerance: float, axial_irradiance_factor: float,
                 stats: dict | None = None, metadata: dict | None = None):
        self.lens = lens
        self.film_distance_mm = float(film_distance_mm)
        X, Y = (float(v) for v in film_extent_mm)
        self.film_extent_mm = (X, Y)
        self.plane_z_mm, self.plane = float(plane_z_mm), plane
        self.knots_x_mm = np.asarray(knots_x_mm, dtype=np.float64)
        self.knots_y_mm = np.asarray(knots_y_mm, dtype=np.float64)
        self.centre_mm = np.asarray(centre_mm, dtype=np.float64)
        self.scale_mm = np.asarray(scale_mm, dtype=np.float64)
        self.rho = np.asarray(rho, dtype=np.float64)
        self.cell_dark = np.asarray(cell_dark, dtype=bool)
        self.tolerance = float(tolerance)
        self.axial_irradiance_factor = float(axial_irradiance_factor)
        self.stats = dict(stats or {})
        self.metadata = dict(metadata or {})
        kx, ky = self.knots_x_mm.size, self.knots_y_mm.size
        arrays = (self.centre_mm, self.scale_mm, self.rho)
        if (kx < 2 or ky < 2 or self.centre_mm.shape != (kx, ky, 2)
                or self.scale_mm.shape != (kx, ky, 2) or self.rho.ndim != 3
                or self.rho.shape[:2] != (kx, ky) or self.rho.shape[2] < 4
                or self.cell_dark.shape != (kx - 1, ky - 1)
                or not (np.all(np.diff(self.knots_x_mm) > 0)
                        and np.all(np.diff(self.knots_y_mm) > 0))
                or not all(np.all(np.isfinite(a)) for a in arrays)):
            raise ValueError("a grid pupil table needs at least 2 x 2 increasing knots with "
                             "matching finite arrays")
        self._prepare()

    # -- the film it covers (the names of the radial table's, for shared callers)
    @property
    def film_half_diagonal_mm(self) -> float:
        """hypot(X, Y): the farthest film point the table covers, mm."""
        return math.hypot(*self.film_extent_mm)

    @property
    def max_film_radius_mm(self) -> float:
        return self.film_half_diagonal_mm

    #: No single film radius beyond which every film point is dark: ``cell_dark`` says
    #: where light is cut off.
    vignetted_beyond_mm = None

    @property
    def n_angles(self) -> int:
        """N: the polygon's vertices (over the whole circle)."""
        return int(self.rho.shape[2])

    @property
    def n_knots(self) -> int:
        """The grid's nodes, Kx Ky (the radial table's count of knots)."""
        return int(self.knots_x_mm.size * self.knots_y_mm.size)

    @property
    def grid_shape(self) -> tuple[int, int]:
        return int(self.knots_x_mm.size), int(self.knots_y_mm.size)

    def _prepare(self) -> None:
        N = self.n_angles
        self._h = 2.0 * math.pi / N
        t = np.arange(N + 1) * self._h
        self._cos_t, self._sin_t = np.cos(t), np.sin(t)
        corners = self._cell_corner_rho()                     # (C, 4, N)
        nxt = np.roll(corners, -1, axis=2)
        sums = []
        for p, q in CORNER_PAIRS:
            prod = corners[:, p] * nxt[:, q]
            if p != q:
                prod = prod + corners[:, q] * nxt[:, p]
            sums.append(prod)
        prods = np.stack(sums, axis=1)                        # (C, 10, N)
        zero = np.zeros(prods.shape[:2] + (1,))
        self._cum = np.concatenate([zero, np.cumsum(prods, axis=2)], axis=2)   # (C, 10, N+1)

    def _cell_corner_rho(self) -> np.ndarray:
        """(cells, 4, N) the rho of each cell's four corners (cell = i (Ky - 1) + j)."""
        r = self.rho
        c = np.stack([r[:-1, :-1], r[1:, :-1], r[:-1, 1:], r[1:, 1:]], axis=2)
        return c.reshape(-1, 4, self.n_angles)

    # -- locating film points
    def _locate(self, film_xy: np.ndarray):
        """Cell, bilinear weights (n, 4), node indices (n, 4), inside (n,) and the signs
        (n, 2) that mirror the quadrant to each film point."""
        f = np.asarray(film_xy, dtype=np.float64).reshape(-1, 2)
        finite = np.all(np.isfinite(f), axis=1)
        q = np.where(finite[:, None], np.abs(f), 0.0)
        sign = np.where(f < 0, -1.0, 1.0)
        out = []
        for k, knots in ((0, self.knots_x_mm), (1, self.knots_y_mm)):
            i = np.clip(np.searchsorted(knots, q[:, k], side="right") - 1, 0, knots.size - 2)
            a = np.clip((q[:, k] - knots[i]) / (knots[i + 1] - knots[i]), 0.0, 1.0)
            out.append((i, a))
        (i, a), (j, b) = out
        X, Y = self.film_extent_mm
        inside = (finite & (q[:, 0] <= X * (1 + _RANGE_SLACK) + _RANGE_SLACK)
                  & (q[:, 1] <= Y * (1 + _RANGE_SLACK) + _RANGE_SLACK))
        ky = self.knots_y_mm.size
        cell = i * (ky - 1) + j
        nodes = np.stack([i * ky + j, (i + 1) * ky + j, i * ky + j + 1, (i + 1) * ky + j + 1], 1)
        inside &= ~self.cell_dark.reshape(-1)[cell]
        return cell, _bilinear_weights(a, b), nodes, inside, sign

    def _frame(self, w: np.ndarray, nodes: np.ndarray):
        """Interpolated (c (n, 2), s (n, 2))."""
        c = self.centre_mm.reshape(-1, 2)[nodes]             # (n, 4, 2)
        s = self.scale_mm.reshape(-1, 2)[nodes]
        return np.einsum("np,npk->nk", w, c), np.einsum("np,npk->nk", w, s)

    def _pair_weights(self, w: np.ndarray) -> np.ndarray:
        """(n, 10) the products w_p w_q of :data:`CORNER_PAIRS`."""
        return np.stack([w[:, p] * w[:, q] for p, q in CORNER_PAIRS], axis=1)

    def _rho_interp(self, w: np.ndarray, nodes: np.ndarray) -> np.ndarray:
        """(n, N) interpolated vertex distances."""
        return np.einsum("np,npk->nk", w, self.rho.reshape(-1, self.n_angles)[nodes])

    # -- the regions
    def frame_at(self, film_xy):
        """The interpolated description at film points (n, 2), in the frame of their
        quadrant (f_x, f_y >= 0; mirror the plane points by the film point's signs):
        (centre (n, 2), scale (n, 2), rho (n, N) at the angles t_k = 2 pi k / N, inside
        (n,)).  Dark cells and points outside the table have inside False."""
        cell, w, nodes, inside, _ = self._locate(film_xy)
        c, s = self._frame(w, nodes)
        return c, s, self._rho_interp(w, nodes), inside

    def area_at(self, film_xy) -> np.ndarray:
        """(n,) area (mm^2) of the sampled region at film points (n, 2); 0 where dark
        or outside the table."""
        cell, w, nodes, inside, _ = self._locate(film_xy)
        _, s = self._frame(w, nodes)
        total = np.einsum("nc,nc->n", self._pair_weights(w), self._cum[cell, :, -1])
        area = 0.5 * math.sin(self._h) * s[:, 0] * s[:, 1] * total
        return np.where(inside, area, 0.0)

    def region_at(self, film_xy) -> np.ndarray:
        """The polygon (N, 2) on the plane for one film point (2,) (mirrored to its
        quadrant); empty (0, 2) where dark or outside the table."""
        f = np.asarray(film_xy, dtype=np.float64).reshape(1, 2)
        cell, w, nodes, inside, sign = self._locate(f)
        rho = self._rho_interp(w, nodes)[0]
        if not inside[0] or not np.any(rho > 0):
            return np.zeros((0, 2))
        c, s = self._frame(w, nodes)
        poly = np.stack([c[0, 0] + s[0, 0] * rho * self._cos_t[:-1],
                         c[0, 1] + s[0, 1] * rho * self._sin_t[:-1]], axis=1)
        return poly * sign[0]

    def contains_at(self, film_xy, points_xy) -> np.ndarray:
        """Whether plane points (n, 2) lie in the table's region of one film point (2,)."""
        pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
        f = np.asarray(film_xy, dtype=np.float64).reshape(1, 2)
        cell, w, nodes, inside, sign = self._locate(f)
        c, s = self._frame(w, nodes)
        if not inside[0] or not np.all(s[0] > 0):
            return np.zeros(len(pts), bool)
        rho = self._rho_interp(w, nodes)[0]
        N, h = self.n_angles, self._h
        q = pts * sign[0]                                    # into the quadrant's frame
        dx, dy = (q[:, 0] - c[0, 0]) / s[0, 0], (q[:, 1] - c[0, 1]) / s[0, 1]
        theta = np.mod(np.arctan2(dy, dx), 2.0 * math.pi)
        j = np.clip(np.floor(theta / h).astype(np.int64), 0, N - 1)
        phi = theta - j * h
        a, b = rho[j], rho[(j + 1) % N]
        den = a * np.sin(phi) + b * np.sin(h - phi)
        with np.errstate(invalid="ignore", divide="ignore"):
            extent = np.where(den > 0, a * b * math.sin(h) / np.where(den > 0, den, 1.0), 0.0)
        return np.hypot(dx, dy) <= extent

    def is_vignetted_at(self, film_xy) -> np.ndarray:
        """(n,) True where the table proposes no ray (dark cell, outside the table)."""
        return ~(self.area_at(film_xy) > 0)

    # -- sampling
    def sample(self, film_xy, u) -> LensSample:
        """Rays for film points ``film_xy`` (n, 2) mm and points ``u`` (n, 2) in [0, 1).

        The pupil point is uniform in the table's region of the film point (pdf =
        1 / area); the map from u is continuous in u (on the torus) and, within a
        quadrant, in the film point, and area-preserving.
        """
        f, uu = check_sample_arguments(film_xy, u)
        n, N = f.shape[0], self.n_angles
        cell, w, nodes, inside, sign = self._locate(f)
        pw = self._pair_weights(w)
        cum = self._cum

        def cdf(k):
            return np.einsum("nc,nc->n", pw, cum[cell, :, k])

        total = cdf(np.full(n, N))
        target = uu[:, 0] * total
        lo, hi = np.zeros(n, dtype=np.int64), np.full(n, N, dtype=np.int64)
        while True:  # vectorized bisection for the triangle: O(log N) passes
            open_ = hi - lo > 1
            if not open_.any():
                break
            mid = (lo + hi) // 2
            below = cdf(mid) <= target
            lo = np.where(open_ & below, mid, lo)
            hi = np.where(open_ & ~below, mid, hi)
        k = lo
        c_lo = cdf(k)
        tri = cdf(k + 1) - c_lo
        with np.errstate(invalid="ignore", divide="ignore"):
            v = np.clip(np.where(tri > 0, (target - c_lo) / np.where(tri > 0, tri, 1.0), 0.0),
                        0.0, 1.0)
        rn = self.rho.reshape(-1, N)
        rho_k = np.einsum("np,np->n", w, rn[nodes, k[:, None]])
        rho_k1 = np.einsum("np,np->n", w, rn[nodes, ((k + 1) % N)[:, None]])
        c, s = self._frame(w, nodes)
        a = np.sqrt(uu[:, 1])
        qx = a * ((1 - v) * rho_k * self._cos_t[k] + v * rho_k1 * self._cos_t[k + 1])
        qy = a * ((1 - v) * rho_k * self._sin_t[k] + v * rho_k1 * self._sin_t[k + 1])
        px = sign[:, 0] * (c[:, 0] + s[:, 0] * qx)
        py = sign[:, 1] * (c[:, 1] + s[:, 1] * qy)
        area = 0.5 * math.sin(self._h) * s[:, 0] * s[:, 1] * total
        return finish_sample(f, px, py, self.plane_z_mm, area, inside & (total > 0))

    # -- measurements
    def exposure_normalisation(self) -> float:
        """1 / (E/L) at the film centre, from the exact on-axis boundary."""
        if not self.axial_irradiance_factor > 0:
            raise OpticsError(f"{self.lens.source}: no ray from the film centre gets through")
        return 1.0 / self.axial_irradiance_factor

    # -- files
    def describe(self) -> dict:
        """Metadata: the inputs (for cache checks) and build statistics."""
        p = paraxial_data(self.lens)
        d = dict(self.metadata)
        d.update({
            "format": GRID_FORMAT_NAME, "version": GRID_FORMAT_VERSION,
            "lens": {"source": self.lens.source, "sha256": self.lens.sha256(),
                     "stop_diameter_mm": p.stop_diameter, "f_number": p.f_number},
            "film_distance_mm": self.film_distance_mm,
            "film": {**(self.metadata.get("film") or {}),
                     "extent_mm": list(self.film_extent_mm),
                     "half_diagonal_mm": self.film_half_diagonal_mm},
            "plane": self.plane, "plane_z_mm": self.plane_z_mm, "tolerance": self.tolerance,
            "grid": list(self.grid_shape), "angles": self.n_angles,
            "dark_cells": int(self.cell_dark.sum()),
            "axial_irradiance_factor": self.axial_irradiance_factor, "stats": self.stats,
        })
        return d

    def save(self, path) -> Path:
        """Write the table to ``path`` (:mod:`povlens.pupil.table_file`), atomically."""
        arrays = {"knots_x_mm": self.knots_x_mm, "knots_y_mm": self.knots_y_mm,
                  "centre_mm": self.centre_mm, "scale_mm": self.scale_mm, "rho": self.rho,
                  "cell_dark": self.cell_dark}
        return write_table_file(path, arrays, self.lens, self.describe())

    @classmethod
    def load(cls, path) -> "GridPupilTable":
        """Read a table written by :meth:`save`.  Raises PovlensError if it is not one."""
        return read_grid_table_file(path, cls)
