"""Exact probing of the pass region of film points anywhere on the film (not only on +x).

The counterpart of :class:`povlens.pupil.prober.PupilProber` for lenses that are not
rotationally symmetric (anamorphic: cylindrical and toric surfaces), whose pass region
depends on the film point's two coordinates and not on its radius alone.  Camera
frame of :mod:`povlens.lens.coordinates` (mm, film at z = 0, lens toward +z).  Rays
from the film point (f_x, f_y, 0) are parameterised by where they cross the sampling
plane z = z_p; :class:`GridProber` traces them with the exact tracer and finds the
boundary of the region they pass through along ``N`` directions over the whole circle
(the region need not be symmetric about any line): rays at ``RADIAL_SAMPLES`` steps
out to the edge of a disc that provably holds every ray that can pass, the outermost
passing one kept and the crossing bisected to ``BISECTION_RELATIVE`` of its distance.

Frames
------
A region is described in a normalised frame (centre (c_x, c_y), half-width s_x along
x and half-height s_y along y): direction t_k = 2 pi k / N is the plane point
(c_x + rho s_x cos t_k, c_y + rho s_y sin t_k), and the boundary is the largest rho
that passes along it.
"""

from __future__ import annotations

import math

import numpy as np

from povlens.lens.toric import row_sag_range_mm
from povlens.lens.prescription import LensPrescription
from povlens.lens.tracer import trace_from_film
from povlens.pupil.prober import BISECTION_RELATIVE, MAX_BISECTION_STEPS, RADIAL_SAMPLES, TRACE_CHUNK

__all__ = ["GridProber", "rear_sag_range_mm"]


def rear_sag_range_mm(lens: LensPrescription, r_max_mm: float) -> tuple[float, float]:
    """(min, max) sag (mm) of the rear surface over the disc of radius ``r_max_mm``: a
    sphere's or asphere's, or a toric row's over both meridians and the rim
    (:func:`povlens.lens.toric.row_sag_range_mm`)."""
    return row_sag_range_mm(lens, lens.n_surfaces - 1, r_max_mm)


class GridProber:
    """Traces probe rays from film points (f_x, f_y, 0) to points of the plane z = ``plane_z_mm``.

    ``rays`` counts the rays traced; ``non_star_points`` collects the film points whose
    region was found not to be star-shaped about the probing centre.
    """

    def __init__(self, lens: LensPrescription, film_distance_mm: float, plane_z_mm: float):
        self.lens = lens
        self.film_distance_mm = float(film_distance_mm)
        self.zp = float(plane_z_mm)
        self.rays = 0
        self.non_star_points: set[tuple[float, float]] = set()
        rr = float(lens.aperture_radius_mm[-1])
        s_lo, s_hi = rear_sag_range_mm(lens, rr)
        self.z_range = (self.film_distance_mm - s_hi, self.film_distance_mm - s_lo)
        self.rear_radius = rr

    def domain(self, fx, fy) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A disc on the plane holding every ray from (f_x, f_y, 0) that meets the rear
        surface inside its clear aperture (every ray that can pass).

        Returns (centre x (B,), centre y (B,), radius (B,)), mm.
        """
        fx, fy = (np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in (fx, fy))
        lam = np.array([self.zp / self.z_range[1], self.zp / self.z_range[0]])
        mid = 1.0 - 0.5 * (lam[0] + lam[1])          # centres f (1 - lam) of the extremes
        half = 0.5 * abs(lam[1] - lam[0]) * np.hypot(fx, fy)
        R = half + self.rear_radius * lam.max()
        return fx * mid, fy * mid, R * (1.0 + 1e-9) + 1e-9

    def passes(self, fx, fy, px, py) -> np.ndarray:
        """Whether the rays from (f_x, f_y, 0) through plane points (p_x, p_y) get through.

        All four (mm) broadcast together; the result has their shape.
        """
        shape = np.broadcast_shapes(np.shape(fx), np.shape(fy), np.shape(px), np.shape(py))
        fx_b, fy_b, x_b, y_b = (np.broadcast_to(np.asarray(v, dtype=np.float64), shape).ravel()
                                for v in (fx, fy, px, py))
        n = fx_b.size
        out = np.zeros(n, bool)
        for a in range(0, n, TRACE_CHUNK):  # bounded memory
            b = min(a + TRACE_CHUNK, n)
            o = np.zeros((b - a, 3))
            o[:, 0], o[:, 1] = fx_b[a:b], fy_b[a:b]
            d = np.empty((b - a, 3))
            d[:, 0] = x_b[a:b] - fx_b[a:b]
            d[:, 1] = y_b[a:b] - fy_b[a:b]
            d[:, 2] = self.zp
            out[a:b] = trace_from_film(self.lens, self.film_distance_mm, o, d).passed
        self.rays += n
        return out.reshape(shape)

    def interior(self, fx, fy, grid: int = 32):
        """A point inside the pass region of each film point, and the passing grid
        points' box.

        The plane's origin is tried first (on the exit-pupil plane it lies inside the
        pupil of every film point that is not deeply vignetted, however small the stop),
        then a ``grid`` x ``grid`` grid over the domain disc, then a 4x finer grid over
        its middle quarter.  Returns (c_x (B,), c_y (B,), found (B,), box (B, 4): x0, x1,
        y0, y1 of the passing grid points padded by a cell; a small box about the
        origin where only it was found).
        """
        fx, fy = (np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in (fx, fy))
        B = fx.size
        cx, cy, box = np.zeros(B), np.zeros(B), np.zeros((B, 4))
        found = self.passes(fx, fy, 0.0, 0.0)
        dcx, dcy, dR = self.domain(fx, fy)
        small = 1e-3 * dR
        box[found] = np.stack([-small, small, -small, small], 1)[found]
        for scale, n in ((1.0, grid), (0.25, 4 * grid)):
            miss = np.nonzero(~found)[0]
            if not miss.size:
                break
            g = ((np.arange(n) + 0.5) / n * 2.0 - 1.0) * scale
            X = dcx[miss, None, None] + dR[miss, None, None] * g[None, None, :]
            Y = dcy[miss, None, None] + dR[miss, None, None] * g[None, :, None]
            X, Y = np.broadcast_arrays(X, Y)
            ok = self.passes(fx[miss, None, None], fy[miss, None, None], X, Y)
            cell = 2.0 * scale * dR[miss] / n
            for k, b in enumerate(miss):
                if ok[k].any():
                    xs, ys = X[k][ok[k]], Y[k][ok[k]]
                    found[b] = True
                    cx[b], cy[b] = self._centre(fx[b], fy[b], xs, ys)
                    box[b] = [xs.min() - cell[k], xs.max() + cell[k],
                              ys.min() - cell[k], ys.max() + cell[k]]
        return cx, cy, found, box

    def _centre(self, fx, fy, xs, ys) -> tuple[float, float]:
        """A passing point near the middle of passing grid points (their centroid if it
        passes, else the passing point nearest to it)."""
        mx, my = float(xs.mean()), float(ys.mean())
        if self.passes(fx, fy, mx, my):
            return mx, my
        k = int(np.argmin((xs - mx) ** 2 + (ys - my) ** 2))
        return float(xs[k]), float(ys[k])

    def boundary(self, fx, fy, cx, cy, sx, sy, n_dir: int):
        """Exact boundary in the normalised frames of (c_x, c_y, s_x, s_y) along
        ``n_dir`` directions t_k = 2 pi k / n_dir (see :meth:`_boundary`).

        Film points are processed in groups so that memory stays bounded.  Returns
        rho (B, n_dir), centre_ok (B,) and the bisection bracket (B,).
        """
        fx = np.atleast_1d(np.asarray(fx, dtype=np.float64))
        args = [fx] + [np.broadcast_to(np.asarray(v, dtype=np.float64), fx.shape)
                       for v in (fy, cx, cy, sx, sy)]
        group = max(1, (1 << 20) // (n_dir * RADIAL_SAMPLES))
        parts = [self._boundary(*(a[i:i + group] for a in args), n_dir)
                 for i in range(0, fx.size, group)]
        if not parts:
            return np.zeros((0, n_dir)), np.zeros(0, bool), np.zeros(0)
        return tuple(np.concatenate([p[k] for p in parts]) for k in range(3))

    def _boundary(self, fx, fy, cx, cy, sx, sy, n_dir: int):
        """Along (s_x cos t, s_y sin t) from (c_x, c_y): the largest rho that lets a ray
        through, from ``RADIAL_SAMPLES`` steps out to the domain disc's edge (the
        outermost passing one) and bisection.  Returns rho (B, n_dir) (the outer end of
        the bracket, so a little outside), centre_ok (B,) and the largest bracket (B,)."""
        t = np.arange(n_dir) * (2.0 * math.pi / n_dir)
        ux = sx[:, None] * np.cos(t)[None, :]
        uy = sy[:, None] * np.sin(t)[None, :]
        dcx, dcy, dR = self.domain(fx, fy)
        ox, oy = (cx - dcx)[:, None], (cy - dcy)[:, None]
        qa = ux * ux + uy * uy
        qb = ox * ux + oy * uy
        qc = ox * ox + oy * oy - (dR * dR)[:, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            rmax = (-qb + np.sqrt(np.maximum(qb * qb - qa * qc, 0.0))) / qa
        rmax = np.where(np.isfinite(rmax), np.maximum(rmax, 1e-12), 1e-12)
        K = RADIAL_SAMPLES
        s = rmax[..., None] * (np.arange(1, K + 1) / K)
        F = (fx[:, None, None], fy[:, None, None])
        ok = self.passes(*F, cx[:, None, None] + s * ux[..., None],
                         cy[:, None, None] + s * uy[..., None])
        centre_ok = self.passes(fx, fy, cx, cy)
        last = np.where(ok.any(axis=2), K - 1 - np.argmax(ok[..., ::-1], axis=2), -1)
        reentry = np.any(~ok[..., :-1] & ok[..., 1:], axis=2) & centre_ok[:, None]
        self.non_star_points.update((float(a), float(b)) for a, b in
                                    zip(fx[reentry.any(axis=1)], fy[reentry.any(axis=1)]))
        lo = np.where(last >= 0, rmax * (last + 1) / K, 0.0)
        hi = np.where(last >= K - 1, rmax, rmax * (last + 2) / K)
        shape = hi.shape
        ffx, ffy = np.broadcast_to(fx[:, None], shape), np.broadcast_to(fy[:, None], shape)
        ccx, ccy = np.broadcast_to(cx[:, None], shape), np.broadcast_to(cy[:, None], shape)
        for _ in range(MAX_BISECTION_STEPS):
            open_ = (hi - lo > BISECTION_RELATIVE * hi) & (last < K - 1)
            if not open_.any():
                break
            mid = 0.5 * (lo[open_] + hi[open_])
            okm = self.passes(ffx[open_], ffy[open_], ccx[open_] + mid * ux[open_],
                              ccy[open_] + mid * uy[open_])
            lo[open_] = np.where(okm, mid, lo[open_])
            hi[open_] = np.where(okm, hi[open_], mid)
        return hi, centre_ok, np.max(hi - lo, axis=1)
