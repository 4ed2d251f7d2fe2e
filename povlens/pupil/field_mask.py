"""Which pixels of a field lens sample the lens passes, without tracing every pixel.

The verdict of pixel p is passed(p) = all_i m_i(p) >= 0, with m_i = r_i^2 - h_i^2 the
aperture margin of surface i (:class:`povlens.pupil.field.FieldRays`), a smooth
function of the image position wherever the unclipped ray exists.  Given the margins
at the nodes of a rectangular grid (the ray mesh's vertices), each cell is:

* PASS when every surface's margin exceeds +delta_i at its four corners,
* FAIL when one surface's margin is below -delta_i at all four (or no corner has a
  ray),
* otherwise UNSURE: the vignetting cut crosses it.

delta_i bounds the bilinear-interpolation error of m_i over a cell: ``safety`` x 1/8
x the largest second difference of m_i between neighbouring nodes anywhere on the
grid.  UNSURE cells are resampled on a sub-grid of about ``sub_px`` pixels with the
bound scaled by the square of the size ratio, and the pixels of the sub-cells that
stay UNSURE are traced exactly.  Against a full per-pixel trace this gave 0
mismatching pixels (docs/decisions/exact-lens-distribution3.md); the tests check it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["pass_mask", "pass_masks", "field_transmission", "PASS", "FAIL", "UNSURE"]

PASS, FAIL, UNSURE = 1, 2, 3


def _second_difference_bounds(grid: np.ndarray) -> np.ndarray:
    """(S,) largest |second difference| of each of the (ny, nx, S) grids along x, y and
    both diagonals (non-finite entries ignored; 0 where there is none)."""
    out = np.zeros(grid.shape[-1])
    for a, b, c in [(grid[:, :-2], grid[:, 1:-1], grid[:, 2:]),
                    (grid[:-2], grid[1:-1], grid[2:]),
                    (grid[:-2, :-2], grid[1:-1, 1:-1], grid[2:, 2:]),
                    (grid[:-2, 2:], grid[1:-1, 1:-1], grid[2:, :-2])]:
        if a.size:
            with np.errstate(invalid="ignore"):
                d = np.abs(a - 2 * b + c)
            out = np.maximum(out, np.where(np.isfinite(d), d, 0.0).max(axis=(0, 1)))
    return out


def _classify(margin: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """(..., ny, nx) classes of the cells of (..., ny+1, nx+1, S) node grids of margins."""
    c = np.stack([margin[..., :-1, :-1, :], margin[..., :-1, 1:, :], margin[..., 1:, :-1, :],
                  margin[..., 1:, 1:, :]], -2)                     # (..., ny, nx, 4, S)
    finite = np.isfinite(c).all(-1)
    sure_pass = np.all(c > delta, axis=(-2, -1)) & finite.all(-1)
    sure_fail = np.any(np.all(c < -delta, axis=-2), axis=-1) | ~finite.any(-1)
    return np.where(sure_pass, PASS, np.where(sure_fail, FAIL, UNSURE)).astype(np.int8)


def _cells_of(pos: np.ndarray, edges: np.ndarray) -> np.ndarray:
    return np.clip(np.searchsorted(edges, pos, side="right") - 1, 0, len(edges) - 2)


def pass_mask(node_x: np.ndarray, node_y: np.ndarray, node_margin: np.ndarray,
              pixel_x: np.ndarray, pixel_y: np.ndarray, trace, safety: float = 4.0,
              sub_px: float = 4.0) -> tuple[np.ndarray, dict]:
    """The exact pass/block verdict of every pixel of a field lens sample.

    Parameters
    ----------
    node_x : (nx+1,) increasing image x of the grid's node columns, pixels.
    node_y : (ny+1,) increasing image y of its node rows, pixels.
    node_margin : (ny+1, nx+1, S) aperture margins at the nodes, mm^2 (-inf: no ray).
    pixel_x : (W,) image x where each pixel column is sampled; pixel_y : (H,).
    trace : callable (x (n,), y (n,)) -> object with ``margin_mm2`` (n, S) and
        ``passed`` (n,) (:func:`povlens.pupil.field.trace_field` with the sample's
        pupil point).
    safety, sub_px : the interpolation bound's safety factor; the sub-grid's spacing
        in pixels.

    Returns
    -------
    passed : (H, W) bool.
    stats : {traced_fraction (rays traced / pixels), unsure_cells}.
    """
    return pass_masks([(node_x, node_y, node_margin, pixel_x, pixel_y)],
                      lambda x, y, tile: trace(x, y), safety, sub_px)[0]


class _Tile:
    """One grid's classification on the way (:func:`pass_masks`)."""

    def __init__(self, node_x, node_y, node_margin, pixel_x, pixel_y, safety, sub_px):
        self.node_x, self.node_y, self.pixel_x, self.pixel_y = node_x, node_y, pixel_x, pixel_y
        self.S = node_margin.shape[2]
        self.delta = safety / 8.0 * _second_difference_bounds(node_margin)
        cls = _classify(node_margin, self.delta)
        self.ccol, self.crow = _cells_of(pixel_x, node_x), _cells_of(pixel_y, node_y)
        self.passed = cls[self.crow[:, None], self.ccol[None, :]] == PASS
        unsure = np.argwhere(cls == UNSURE)
        self.n_unsure, self.traced = len(unsure), 0
        if not len(unsure):
            return
        # every cell has the grid's size: one sub-grid for all of them
        r, c = unsure[:, 0], unsure[:, 1]
        dx, dy = float(np.max(np.diff(node_x))), float(np.max(np.diff(node_y)))
        self.nx, self.ny = max(1, int(np.ceil(dx / sub_px))), max(1, int(np.ceil(dy / sub_px)))
        self.ratio = max(dx / self.nx, dy / self.ny) / max(dx, dy)
        self.x0, self.x1, self.y0, self.y1 = node_x[c], node_x[c + 1], node_y[r], node_y[r + 1]
        fx, fy = np.linspace(0.0, 1.0, self.nx + 1), np.linspace(0.0, 1.0, self.ny + 1)
        shape = (len(r), self.ny + 1, self.nx + 1)
        self.sub_x = np.broadcast_to(self.x0[:, None, None] + fx[None, None, :]
                                     * (self.x1 - self.x0)[:, None, None], shape).ravel()
        self.sub_y = np.broadcast_to(self.y0[:, None, None] + fy[None, :, None]
                                     * (self.y1 - self.y0)[:, None, None], shape).ravel()
        cell_id = np.full(cls.shape, -1)
        cell_id[r, c] = np.arange(len(r))
        self.cell_id = cell_id

    def classify_sub(self, margins: np.ndarray) -> None:
        """Sub-cell classes from the sub-grid's margins; the pixels still unsure."""
        n = len(self.x0)
        sub = _classify(margins.reshape(n, self.ny + 1, self.nx + 1, self.S),
                        self.delta * self.ratio * self.ratio)                # (n, ny, nx)
        cid = self.cell_id[self.crow[:, None], self.ccol[None, :]]
        rows, cols = np.nonzero(cid >= 0)
        k = cid[rows, cols]
        sx = np.clip(((self.pixel_x[cols] - self.x0[k]) / (self.x1 - self.x0)[k]
                      * self.nx).astype(np.int64), 0, self.nx - 1)
        sy = np.clip(((self.pixel_y[rows] - self.y0[k]) / (self.y1 - self.y0)[k]
                      * self.ny).astype(np.int64), 0, self.ny - 1)
        kind = sub[k, sy, sx]
        self.passed[rows, cols] = kind == PASS
        exact = kind == UNSURE
        self.exact_rows, self.exact_cols = rows[exact], cols[exact]
        self.traced = len(self.sub_x) + len(self.exact_rows)


def pass_masks(grids, trace, safety: float = 4.0, sub_px: float = 4.0
               ) -> list[tuple[np.ndarray, dict]]:
    """:func:`pass_mask` of several grids at once (the tiles of an interleaved pass), each
    stage's rays traced in one call: ``grids`` is a list of (node_x, node_y, node_margin,
    pixel_x, pixel_y), ``trace(x, y, tile)`` traces image positions of the tiles ``tile``
    (n,) (indices into ``grids``)."""
    tiles = [_Tile(*g, safety, sub_px) for g in grids]
    todo = [i for i, t in enumerate(tiles) if t.n_unsure]

    def traced(xs, ys):
        tile = np.concatenate([np.full(len(x), i) for i, x in zip(todo, xs)])
        out = trace(np.concatenate(xs), np.concatenate(ys), tile)
        return np.split(np.arange(len(tile)), np.cumsum([len(x) for x in xs])[:-1]), out

    if todo:
        parts, out = traced([tiles[i].sub_x for i in todo], [tiles[i].sub_y for i in todo])
        for i, idx in zip(todo, parts):
            tiles[i].classify_sub(out.margin_mm2[idx])
        todo = [i for i in todo if len(tiles[i].exact_rows)]
    if todo:
        t = tiles
        parts, out = traced([t[i].pixel_x[t[i].exact_cols] for i in todo],
                            [t[i].pixel_y[t[i].exact_rows] for i in todo])
        for i, idx in zip(todo, parts):
            t[i].passed[t[i].exact_rows, t[i].exact_cols] = out.passed[idx]
    return [(t.passed, {"traced_fraction": t.traced / t.passed.size,
                        "unsure_cells": int(t.n_unsure)}) for t in tiles]


def field_transmission(lens, film_distance_mm: float, film, plane_z_mm: float, pupil_xy_mm,
                       x, y, passed: np.ndarray) -> np.ndarray:
    """(H, W) float32 transmission of a mask stop for one field lens sample (``pupil_xy_mm``
    its pupil point (2,), or a :class:`povlens.pupil.field.PupilMap`): each passing
    pixel's ray, from its image position toward the pupil point, traced exactly to the stop
    (:func:`povlens.lens.tracer.stop_hits_from_film`; not interpolated from the grid, so a
    mask feature finer than a mesh cell is still seen), 0 where blocked.

    x : (W,) image x of the pixel columns; y : (H,) of the rows (pixels, as the weights'
    :func:`povlens.pupil.field.field_weight`).  passed : (H, W) bool.
    """
    from povlens.lens.tracer import stop_hits_from_film
    from povlens.pupil.field import image_to_film_mm
    out = np.zeros(passed.shape, np.float32)
    rows, cols = np.nonzero(passed)
    if not len(rows) or lens.aperture_shape is None or lens.aperture_shape.mask is None:
        out[rows, cols] = 1.0
        return out
    f = image_to_film_mm(film, np.asarray(x, float)[cols], np.asarray(y, float)[rows])
    origin = np.zeros((len(rows), 3))
    origin[:, :2] = f
    P = pupil_xy_mm(f) if callable(pupil_xy_mm) else np.asarray(pupil_xy_mm, float)[None, :]
    direction = np.empty((len(rows), 3))
    direction[:, 0] = P[:, 0] - f[:, 0]
    direction[:, 1] = P[:, 1] - f[:, 1]
    direction[:, 2] = plane_z_mm
    hits = stop_hits_from_film(lens, film_distance_mm, origin, direction)
    row = lens.aperture_shape_row
    out[rows, cols] = lens.aperture_shape.transmission(hits[:, 0], hits[:, 1],
                                                        float(lens.aperture_radius_mm[row]))
    return out
