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
    """(ny, nx) classes of the cells of a (ny+1, nx+1, S) node grid of margins."""
    c = np.stack([margin[:-1, :-1], margin[:-1, 1:], margin[1:, :-1], margin[1:, 1:]], 2)
    finite = np.isfinite(c).all(3)
    sure_pass = np.all(c > delta, axis=(2, 3)) & finite.all(2)
    sure_fail = np.any(np.all(c < -delta, axis=2), axis=2) | ~finite.any(2)
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
        subs = []
        for r, c in unsure:
            x0, x1, y0, y1 = node_x[c], node_x[c + 1], node_y[r], node_y[r + 1]
            sx = np.linspace(x0, x1, max(1, int(np.ceil((x1 - x0) / sub_px))) + 1)
            sy = np.linspace(y0, y1, max(1, int(np.ceil((y1 - y0) / sub_px))) + 1)
            subs.append((r, c, sx, sy))
        X = np.concatenate([np.tile(sx, len(sy))
                            for _, _, sx, sy in subs])
        Y = np.concatenate([np.repeat(sy, len(sx)) for _, _, sx, sy in subs])
        margins = trace(X, Y).margin_mm2
        traced = len(X)
        off = 0
        exact_rows, exact_cols = [], []
        for r, c, sx, sy in subs:
            n = len(sx) * len(sy)
            sub_margin = margins[off:off + n].reshape(len(sy), len(sx), S)
            off += n
            ratio = max(sx[1] - sx[0], sy[1] - sy[0]) / max(node_x[c + 1] - node_x[c],
                                                            node_y[r + 1] - node_y[r])
            sub_cls = _classify(sub_margin, delta * ratio * ratio)
            cols, rows = np.flatnonzero(ccol == c), np.flatnonzero(crow == r)
            if not len(cols) or not len(rows):
                continue
            k = sub_cls[_cells_of(pixel_y[rows], sy)[:, None], _cells_of(pixel_x[cols], sx)[None, :]]
            passed[np.ix_(rows, cols)] = k == PASS
            uj, ui = np.nonzero(k == UNSURE)
            if len(uj):
                exact_rows.append(rows[uj])
                exact_cols.append(cols[ui])
        if exact_rows:
            rr, cc = np.concatenate(exact_rows), np.concatenate(exact_cols)
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
