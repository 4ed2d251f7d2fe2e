"""Exact probing of the pass region: which rays from a film point get through the lens.

Camera frame of :mod:`povlens.lens.coordinates` (mm, film at z = 0, lens toward +z).
Rays from the film point (r, 0, 0) are parameterised by where they cross the
sampling plane z = z_p (see :mod:`povlens.pupil.build`); :class:`PupilProber`
traces them with the exact tracer and finds the boundary of the region they
pass through: along each direction from a centre, rays at ``RADIAL_SAMPLES``
steps out to the edge of a disc that provably holds every ray that can pass,
the outermost passing one kept and the crossing bisected to
``BISECTION_RELATIVE`` of its distance.
"""

from __future__ import annotations

import math

import numpy as np

from povlens.lens.chief_ray import chief_ray_aim_mm
from povlens.lens.asphere import sag_range_mm
from povlens.lens.prescription import LensPrescription
from povlens.lens.tracer import trace_from_film

__all__ = ["PupilProber", "grow_boxes", "RADIAL_SAMPLES", "BISECTION_RELATIVE",
           "MAX_BISECTION_STEPS", "TRACE_CHUNK"]

#: Radial samples per angle before the bisection; the bisection's relative precision.
RADIAL_SAMPLES = 32
BISECTION_RELATIVE = 2e-5
MAX_BISECTION_STEPS = 60
#: Rays per call of the tracer (bounds memory).
TRACE_CHUNK = 1 << 18


class PupilProber:
    """Traces probe rays from film points (r, 0, 0) to points of the plane z = ``plane_z_mm``.

    ``rays`` counts the rays traced; ``non_star_radii`` collects the film radii
    whose region was found not to be star-shaped about the probing centre.
    """

    def __init__(self, lens: LensPrescription, film_distance_mm: float, plane_z_mm: float):
        self.lens = lens
        self.film_distance_mm = float(film_distance_mm)
        self.zp = float(plane_z_mm)
        self.rays = 0
        self.non_star_radii: set[float] = set()
        rr = float(lens.aperture_radius_mm[-1])
        s_lo, s_hi = sag_range_mm(lens, lens.n_surfaces - 1, rr)   # sphere or asphere
        self.z_range = (self.film_distance_mm - s_hi, self.film_distance_mm - s_lo)
        self.rear_radius = rr

    def domain(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A disc on the plane holding every ray from (r, 0, 0) that meets the rear
        surface inside its clear aperture (every ray that can pass).

        Returns (centre x (B,), radius (B,)), mm, for the B radii ``r``.
        """
        r = np.atleast_1d(np.asarray(r, dtype=np.float64))
        lam = np.array([self.zp / self.z_range[1], self.zp / self.z_range[0]])
        c = r[:, None] * (1.0 - lam[None, :])              # centres of the extreme discs
        rad = self.rear_radius * lam                        # their radii
        cx = 0.5 * (c[:, 0] + c[:, 1])
        R = 0.5 * np.abs(c[:, 1] - c[:, 0]) + rad.max()
        return cx, R * (1.0 + 1e-9) + 1e-9

    def passes(self, r, px, py) -> np.ndarray:
        """Whether the rays from (r, 0, 0) through plane points (px, py) get through.

        ``r``, ``px`` and ``py`` (mm) broadcast together; the result has their shape.
        """
        shape = np.broadcast_shapes(np.shape(r), np.shape(px), np.shape(py))
        r_b = np.broadcast_to(r, shape).ravel()
        x_b = np.broadcast_to(px, shape).ravel()
        y_b = np.broadcast_to(py, shape).ravel()
        n = r_b.size
        out = np.zeros(n, bool)
        for a in range(0, n, TRACE_CHUNK):  # bounded memory
            b = min(a + TRACE_CHUNK, n)
            o = np.zeros((b - a, 3))
            o[:, 0] = r_b[a:b]
            d = np.empty((b - a, 3))
            d[:, 0] = x_b[a:b] - r_b[a:b]
            d[:, 1] = y_b[a:b]
            d[:, 2] = self.zp
            out[a:b] = trace_from_film(self.lens, self.film_distance_mm, o, d).passed
        self.rays += n
        return out.reshape(shape)

    def interior(self, r, hint: np.ndarray | None = None, grid: int = 32):
        """A point (cx, 0) inside the pass region for each radius, from a coarse grid.

        hint : (B, 4) boxes (x0, x1, y0, y1) searched when the coarse grid over the
        whole domain finds nothing (small regions).  Returns (cx (B,), found (B,),
        bbox (B, 4) of the passing grid points, padded by a cell).
        """
        r = np.atleast_1d(np.asarray(r, dtype=np.float64))
        B = r.size
        dcx, dR = self.domain(r)
        g = (np.arange(grid) + 0.5) / grid * 2.0 - 1.0
        gy = (np.arange(grid // 2) + 0.5) / (grid // 2)
        X = np.broadcast_to(dcx[:, None, None] + dR[:, None, None] * g[None, None, :],
                            (B, grid // 2, grid))
        Y = np.broadcast_to(dR[:, None, None] * gy[None, :, None], (B, grid // 2, grid))
        ok = self.passes(r[:, None, None], X, Y)
        cx = np.zeros(B)
        found = ok.any(axis=(1, 2))
        bbox = np.zeros((B, 4))
        for b in np.nonzero(found)[0]:
            cx[b], bbox[b] = self._centre(r[b], X[b][ok[b]], Y[b][ok[b]],
                                          2.0 * dR[b] / grid, dR[b] / (grid // 2))
        if hint is not None and not found.all():
            miss = np.nonzero(~found)[0]
            h = np.asarray(hint, dtype=np.float64)[miss]
            gx = (np.arange(grid) + 0.5) / grid
            Xh = np.broadcast_to(h[:, 0, None, None]
                                 + (h[:, 1] - h[:, 0])[:, None, None] * gx[None, None, :],
                                 (miss.size, grid, grid))
            Yh = np.broadcast_to(np.maximum(h[:, 3], 0.0)[:, None, None] * gx[None, :, None],
                                 (miss.size, grid, grid))
            okh = self.passes(r[miss, None, None], Xh, Yh)
            for k, b in enumerate(miss):
                if okh[k].any():
                    found[b] = True
                    cx[b], bbox[b] = self._centre(r[b], Xh[k][okh[k]], Yh[k][okh[k]],
                                                  (h[k, 1] - h[k, 0]) / grid,
                                                  max(h[k, 3], 0.0) / grid)
        if not found.all():
            # Small pass regions (a stopped-down lens) slip between the grid points:
            # seed them with the real chief ray, which crosses the centre of the stop.
            miss = np.nonzero(~found)[0]
            x_rear, ok_aim = chief_ray_aim_mm(self.lens, self.film_distance_mm, r[miss])
            self.rays += 42 * miss.size
            aim = r[miss] + (x_rear - r[miss]) * self.zp / self.film_distance_mm
            ok = ok_aim & self.passes(r[miss], aim, np.zeros(miss.size))
            for k in np.nonzero(ok)[0]:
                b = miss[k]
                found[b] = True
                cell = 1e-6 * max(1.0, dR[b])
                cx[b], bbox[b] = self._centre(r[b], aim[k:k + 1], np.zeros(1), cell, cell)
        return cx, found, bbox

    def _centre(self, r, xs, ys, cell_x, cell_y):
        """A centre on the x axis from passing grid points (their centroid, checked)."""
        bbox = np.array([xs.min() - cell_x, xs.max() + cell_x, 0.0, ys.max() + cell_y])
        cands = np.concatenate([[xs.mean()], np.linspace(xs.min(), xs.max(), 15)])
        ok = self.passes(np.array(r), cands, np.zeros_like(cands))
        if ok[0]:
            return cands[0], bbox
        if ok.any():
            good = cands[ok]
            return 0.5 * (good.min() + good.max()), bbox
        return xs[np.argmin(ys)], bbox

    def boundary(self, r, cx, sx, sy, M: int):
        """Exact boundary in the normalised frame of (cx, sx, sy), see :meth:`_boundary`.

        Radii are processed in groups so that memory stays bounded.  Returns
        rho (B, 2M + 1), centre_ok (B,) and the bisection bracket (B,).
        """
        r = np.atleast_1d(np.asarray(r, dtype=np.float64))
        cx, sx, sy = (np.broadcast_to(np.asarray(v, dtype=np.float64), r.shape)
                      for v in (cx, sx, sy))
        group = max(1, (1 << 20) // ((2 * M + 1) * RADIAL_SAMPLES))
        if r.size <= group:
            return self._boundary(r, cx, sx, sy, M)
        parts = [self._boundary(r[i:i + group], cx[i:i + group], sx[i:i + group],
                                sy[i:i + group], M) for i in range(0, r.size, group)]
        return tuple(np.concatenate([p[k] for p in parts]) for k in range(3))

    def _boundary(self, r, cx, sx, sy, M: int):
        """Exact boundary in the normalised frame of (cx, sx, sy).

        Along the 2M + 1 directions (sx cos t, sy sin t), t = k pi / (2M), finds
        the largest rho such that (cx + rho sx cos t, rho sy sin t) lets a ray
        through: rays at 32 steps out to the domain edge, the outermost passing one
        kept, then bisection.  Returns rho (B, 2M + 1) (the outer end of the
        bracket, so a little outside), centre_ok (B,) and the bracket width (B,)
        (in the same normalised units).
        """
        r = np.atleast_1d(np.asarray(r, dtype=np.float64))
        cx, sx, sy = (np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in (cx, sx, sy))
        theta = np.arange(2 * M + 1) * (math.pi / (2 * M))
        ux = sx[:, None] * np.cos(theta)[None, :]
        uy = sy[:, None] * np.sin(theta)[None, :]
        dcx, dR = self.domain(r)
        # Parameter of the domain circle along each direction.
        ox = (cx - dcx)[:, None]
        qa = ux * ux + uy * uy
        qb = ox * ux
        qc = ox * ox - (dR * dR)[:, None]
        rmax = (-qb + np.sqrt(np.maximum(qb * qb - qa * qc, 0.0))) / qa
        rmax = np.maximum(rmax, 1e-12)
        K = RADIAL_SAMPLES
        frac = np.arange(1, K + 1) / K
        s = rmax[..., None] * frac
        ok = self.passes(r[:, None, None], cx[:, None, None] + s * ux[..., None], s * uy[..., None])
        centre_ok = self.passes(r, cx, np.zeros_like(cx))
        anyp = ok.any(axis=2)
        last = np.where(anyp, K - 1 - np.argmax(ok[..., ::-1], axis=2), -1)
        # A blocked sample followed by a passing one: the region is not star-shaped
        # about the centre (holes, horns); the outermost crossing is kept, and the
        # film radius is recorded so that the build can say so.
        reentry = np.any(~ok[..., :-1] & ok[..., 1:], axis=2) & centre_ok[:, None]
        self.non_star_radii.update(float(x) for x in r[reentry.any(axis=1)])
        lo = np.where(last >= 0, rmax * (last + 1) / K, 0.0)
        hi = np.where(last >= K - 1, rmax, rmax * (last + 2) / K)
        hi = np.where(last >= K - 1, rmax, hi)
        rr = np.broadcast_to(r[:, None], hi.shape)
        cc = np.broadcast_to(cx[:, None], hi.shape)
        for _ in range(MAX_BISECTION_STEPS):
            # Bisect until the bracket is small relative to the boundary distance
            # itself, so tiny regions (near a vignetting cut-off) are resolved too.
            open_ = (hi - lo > BISECTION_RELATIVE * hi) & (last < K - 1)
            if not open_.any():
                break
            mid = 0.5 * (lo[open_] + hi[open_])
            okm = self.passes(rr[open_], cc[open_] + mid * ux[open_], mid * uy[open_])
            lo[open_] = np.where(okm, mid, lo[open_])
            hi[open_] = np.where(okm, hi[open_], mid)
        return hi, centre_ok, np.max(hi - lo, axis=1)


def grow_boxes(box: np.ndarray, factor: float = 1.5) -> np.ndarray:
    """Search boxes for :meth:`PupilProber.interior`, grown by ``factor``.

    Parameters
    ----------
    box : (B, 4) or (4,) boxes (x0, x1, y0, y1) on the plane, mm.
    factor : growth of the half-width about the centre and of y1 (y0 stays at 0).

    Returns
    -------
    (B, 4) grown copies.
    """
    box = np.atleast_2d(np.asarray(box, dtype=np.float64)).copy()
    cx = 0.5 * (box[:, 0] + box[:, 1])
    hw = 0.5 * (box[:, 1] - box[:, 0]) * factor
    box[:, 0], box[:, 1] = cx - hw, cx + hw
    box[:, 3] = box[:, 3] * factor
    return box
