"""Per-pixel weights of a distribution-3 sample without tracing every pixel.

The mesh carries the *unvignetted* ray field (lensfield.ghost_trace), so POV-Ray's
colour of a pixel whose exact ray is blocked is meaningless; the composite's weight
w(p) = passed(p) cos^4(theta) / z_p^2 * area_B is what must be exact.  cos(theta) is
analytic (film point -> P).  passed(p) = all_i m_i(p) > 0 with m_i = r_i^2 - h_i^2 the
margin at surface i, a smooth function of the film point wherever the ghost ray
exists.  Per mesh face (the same faces as the ray mesh):

* every surface's margin exceeds +delta_i at its three vertices -> all pixels pass;
* some surface's margin is below -delta_i at all three vertices -> all are blocked;
* otherwise (the cut crosses the face, or a vertex has no ghost ray) the face's
  pixels are traced exactly (povlens.lens.tracer via lensfield.trace_field).

delta_i bounds the linear-interpolation error of m_i over a face: 4 x (1/8) x the
largest second difference of m_i over one cell anywhere on the grid (safety 4).
"""

from __future__ import annotations

import numpy as np

from lensfield import Setup, trace_field
from mesh3 import RayMesh, UVModel, locate


def _second_diff_bound(mg: np.ndarray) -> float:
    """Largest |second difference| of a (gy+1, gx+1) grid along x, y and both diagonals
    (ignoring non-finite entries)."""
    out = 0.0
    for a, b, c in [(mg[:, :-2], mg[:, 1:-1], mg[:, 2:]), (mg[:-2], mg[1:-1], mg[2:]),
                    (mg[:-2, :-2], mg[1:-1, 1:-1], mg[2:, 2:]),
                    (mg[:-2, 2:], mg[1:-1, 1:-1], mg[2:, :-2])]:
        d = np.abs(a - 2 * b + c)
        d = d[np.isfinite(d)]
        if d.size:
            out = max(out, float(d.max()))
    return out


def sample_weights(setup: Setup, P_xy, m: RayMesh, model: UVModel, area_mm2: float,
                   safety: float = 4.0):
    """(H, W) weights of the sample, and stats (fraction of pixels traced exactly)."""
    gx, gy, _ = m.grid
    H, W = model.H, model.W
    S = m.margin.shape[1]
    delta = np.empty(S)
    for i in range(S):
        delta[i] = safety / 8.0 * _second_diff_bound(m.margin[:, i].reshape(gy + 1, gx + 1))
    mf = m.margin[m.faces]                                   # (F, 3, S)
    sure_pass = np.all(mf > delta, axis=(1, 2))
    sure_fail = np.any(np.all(mf < -delta, axis=1), axis=1) | np.all(~np.isfinite(mf).all(2), 1)
    pu, pv = model.pixel_uv()
    face, _ = locate(m, pu, pv)
    face = face.reshape(H, W)
    jj, ii = np.mgrid[0:H, 0:W].astype(float)
    x, y = ii + model.jx, jj + model.jy
    # analytic part: cos^4 / z^2 * area for every pixel
    from lensfield import image_to_film_mm
    f = image_to_film_mm(setup.film, x, y)
    zp = setup.plane_z_mm
    dx, dy = P_xy[0] - f[..., 0], P_xy[1] - f[..., 1]
    cos2 = zp * zp / (dx * dx + dy * dy + zp * zp)
    w = cos2 * cos2 / (zp * zp) * area_mm2
    passed = sure_pass[face]
    unsure = ~sure_pass[face] & ~sure_fail[face]
    if unsure.any():
        fld = trace_field(setup, P_xy, x[unsure], y[unsure], area_mm2)
        passed = passed.copy()
        passed[unsure] = fld.passed
    return np.where(passed, w, 0.0), dict(traced=float(unsure.mean()), delta=delta)


# ---------------------------------------------------------------------------
# faster: separable cell lookup, a finer sub-grid inside the cut cells, exact
# tracing only of the pixels in the sub-cells the cut crosses


PASS, FAIL, UNSURE = 1, 2, 3


def _classify(mg: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Cells of a (ny+1, nx+1, S) node grid of margins: PASS where every surface's
    margin exceeds delta at all 4 corners, FAIL where one surface's is below -delta
    at all 4 (or no corner has a ghost ray), else UNSURE."""
    c = np.stack([mg[:-1, :-1], mg[:-1, 1:], mg[1:, :-1], mg[1:, 1:]], 2)   # (ny, nx, 4, S)
    fin = np.isfinite(c).all(3)
    sp = np.all(c > delta, axis=(2, 3))
    sf = np.any(np.all(c < -delta, axis=2), axis=2) | ~fin.any(2)
    return np.where(sp, PASS, np.where(sf, FAIL, UNSURE)).astype(np.int8)


def _cells_of(pos: np.ndarray, edges: np.ndarray) -> np.ndarray:
    return np.clip(np.searchsorted(edges, pos, side="right") - 1, 0, len(edges) - 2)


def sample_weights_fast(setup: Setup, P_xy, m: RayMesh, model: UVModel, area_mm2: float,
                        safety: float = 4.0, sub_px: float = 4.0):
    from lensfield import image_to_film_mm
    gx, gy, _ = m.grid
    H, W = model.H, model.W
    S = m.margin.shape[1]
    mg = m.margin.reshape(gy + 1, gx + 1, S)
    delta = np.array([safety / 8.0 * _second_diff_bound(mg[..., i]) for i in range(S)])
    xe = m.xy[: gx + 1, 0]                       # image x of the node columns
    ye = m.xy[:: gx + 1, 1]                      # image y of the node rows (decreasing v)
    order = np.argsort(ye)
    ye_s = ye[order]                             # increasing y
    mg_s = mg[order]
    cls0 = _classify(mg_s, delta)                # (gy, gx), rows by increasing y
    px = np.arange(W) + model.jx
    py = np.arange(H) + model.jy
    ccol, crow = _cells_of(px, xe), _cells_of(py, ye_s)
    passed = cls0[crow[:, None], ccol[None, :]] == PASS
    traced = 0
    unsure = np.argwhere(cls0 == UNSURE)
    if len(unsure):
        # sub-grids of the unsure cells: nodes every ~sub_px pixels, one ghost trace
        jobs, nodes = [], []
        for r, c in unsure:
            x0, x1, y0, y1 = xe[c], xe[c + 1], ye_s[r], ye_s[r + 1]
            kx = max(1, int(np.ceil((x1 - x0) / sub_px))); ky = max(1, int(np.ceil((y1 - y0) / sub_px)))
            sx, sy = np.linspace(x0, x1, kx + 1), np.linspace(y0, y1, ky + 1)
            jobs.append((r, c, sx, sy, len(nodes) and sum(len(n[0]) for n in nodes)))
            X, Y = np.meshgrid(sx, sy)
            nodes.append((X.ravel(), Y.ravel()))
        NX = np.concatenate([n[0] for n in nodes]); NY = np.concatenate([n[1] for n in nodes])
        fld = trace_field(setup, P_xy, NX, NY, area_mm2)
        off = 0
        exact_x, exact_y, exact_at = [], [], []
        for (r, c, sx, sy, _), (X, _) in zip(jobs, nodes):
            n = len(X)
            sm = fld.margin[off:off + n].reshape(len(sy), len(sx), S)
            off += n
            hsub = max(sx[1] - sx[0], sy[1] - sy[0]) / max(xe[c + 1] - xe[c], ye_s[r + 1] - ye_s[r])
            cls = _classify(sm, delta * hsub * hsub)
            cols = np.flatnonzero(ccol == c); rows = np.flatnonzero(crow == r)
            if not len(cols) or not len(rows):
                continue
            sc, sr = _cells_of(px[cols], sx), _cells_of(py[rows], sy)
            k = cls[sr[:, None], sc[None, :]]
            passed[np.ix_(rows, cols)] = k == PASS
            uj, ui = np.nonzero(k == UNSURE)
            if len(uj):
                exact_at.append((rows[uj], cols[ui]))
        if exact_at:
            rr = np.concatenate([a[0] for a in exact_at]); cc = np.concatenate([a[1] for a in exact_at])
            f2 = trace_field(setup, P_xy, px[cc], py[rr], area_mm2)
            passed[rr, cc] = f2.passed
            traced = len(rr)
        traced += len(NX)
    # cos^4 / z_p^2 * area, separable in film x (columns) and y (rows)
    f = image_to_film_mm(setup.film, px, np.zeros(W))[:, 0]
    g = image_to_film_mm(setup.film, np.zeros(H), py)[:, 1]
    zp = setup.plane_z_mm
    dx2 = ((P_xy[0] - f) ** 2).astype(np.float32)
    dy2 = ((P_xy[1] - g) ** 2).astype(np.float32)
    c2 = np.float32(zp * zp) / (dy2[:, None] + dx2[None, :] + np.float32(zp * zp))
    w = c2 * c2 * np.float32(area_mm2 / zp ** 2)
    w[~passed] = 0
    return w, dict(traced=traced / (W * H), rays=traced, unsure_cells=len(unsure))
