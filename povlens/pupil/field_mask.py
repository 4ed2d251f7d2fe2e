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

__all__ = ["pass_mask", "field_transmission", "PASS", "FAIL", "UNSURE"]

PASS, FAIL, UNSURE = 1, 2, 3


def _second_difference_bound(grid: np.ndarray) -> float:
    """Largest |second difference| of a (ny, nx) grid along x, y and both diagonals
    (non-finite entries ignored)."""
    out = 0.0
    for a, b, c in [(grid[:, :-2], grid[:, 1:-1], grid[:, 2:]),
                    (grid[:-2], grid[1:-1], grid[2:]),
                    (grid[:-2, :-2], grid[1:-1, 1:-1], grid[2:, 2:]),
                    (grid[:-2, 2:], grid[1:-1, 1:-1], grid[2:, :-2])]:
        with np.errstate(invalid="ignore"):
            d = np.abs(a - 2 * b + c)
        d = d[np.isfinite(d)]
        if d.size:
            out = max(out, float(d.max()))
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
    S = node_margin.shape[2]
    delta = np.array([safety / 8.0 * _second_difference_bound(node_margin[..., i])
                      for i in range(S)])
    cls = _classify(node_margin, delta)
    ccol, crow = _cells_of(pixel_x, node_x), _cells_of(pixel_y, node_y)
    passed = cls[crow[:, None], ccol[None, :]] == PASS
    unsure = np.argwhere(cls == UNSURE)
    traced = 0
    if len(unsure):
        # every cell has the grid's size: one sub-grid for all, traced in one call
        r, c = unsure[:, 0], unsure[:, 1]
        dx = float(np.max(np.diff(node_x)))
        dy = float(np.max(np.diff(node_y)))
        nx, ny = max(1, int(np.ceil(dx / sub_px))), max(1, int(np.ceil(dy / sub_px)))
        x0, x1 = node_x[c], node_x[c + 1]
        y0, y1 = node_y[r], node_y[r + 1]
        fx, fy = np.linspace(0.0, 1.0, nx + 1), np.linspace(0.0, 1.0, ny + 1)
        X = np.broadcast_to(x0[:, None, None] + fx[None, None, :] * (x1 - x0)[:, None, None],
                            (len(r), ny + 1, nx + 1))
        Y = np.broadcast_to(y0[:, None, None] + fy[None, :, None] * (y1 - y0)[:, None, None],
                            (len(r), ny + 1, nx + 1))
        margins = trace(X.ravel(), Y.ravel()).margin_mm2.reshape(len(r), ny + 1, nx + 1, S)
        traced = X.size
        ratio = max(1.0 / nx * dx, 1.0 / ny * dy) / max(dx, dy)
        sub = _classify(margins, delta * ratio * ratio)                       # (n, ny, nx)
        cell_id = np.full(cls.shape, -1)
        cell_id[r, c] = np.arange(len(r))
        cid = cell_id[crow[:, None], ccol[None, :]]
        rows, cols = np.nonzero(cid >= 0)
        k = cid[rows, cols]
        sx = np.clip(((pixel_x[cols] - x0[k]) / (x1 - x0)[k] * nx).astype(np.int64), 0, nx - 1)
        sy = np.clip(((pixel_y[rows] - y0[k]) / (y1 - y0)[k] * ny).astype(np.int64), 0, ny - 1)
        kind = sub[k, sy, sx]
        passed[rows, cols] = kind == PASS
        exact = kind == UNSURE
        if exact.any():
            rr, cc = rows[exact], cols[exact]
            passed[rr, cc] = trace(pixel_x[cc], pixel_y[rr]).passed
            traced += len(rr)
    return passed, {"traced_fraction": traced / passed.size, "unsure_cells": int(len(unsure))}


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
