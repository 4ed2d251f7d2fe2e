"""Distribution-3 ray meshes: a coarse UV-mapped smooth mesh2 whose interpolated
rays stand for every pixel's exact real-lens ray (one fixed pupil point per sample).

POV-Ray 3.7.0.10, distribution 3 (docs/reference/povray-mesh-camera.md §3.3; source
tracepixel.cpp, mesh.cpp):

* a pixel's (u, v) is found in the mesh's UV triangles (first face that contains it,
  through a 10 x 10 bin grid); its barycentrics B (from the UVs, double) give
  origin = sum B_k P_k (vertices float32, then the mesh's translate in double) and,
  with ``smooth`` inside the mesh_camera block, direction = normalize(sum B_k N_k)
  (Smooth_Mesh_Normal; mesh2 normal_vectors are normalised when parsed, float32);
* FS#261: rendered pixel (i, j) samples u = i / W', v = 1 - j / H' (its top-left
  corner) with the last column and the first row clamped (half a pixel off).

Workaround used here (3.7.0.x): render W' x H' = (W + 1) x (H + 1) with +EC{W} +SR2
(the last column and row 0 not traced) and drop them; the UV map is built for that
sampling, so output pixel (i, j) = rendered (i, j + 1) samples exactly the image
position (i + jx, j + jy), where (jx, jy) is the sample's sub-pixel offset (shared by
all pixels: accumulation-buffer sampling):

    x = u W' + jx,   y = (1 - v) H' - 1 + jy.

(3.8 fixed FS#254/FS#261 in commit c8911315; its sampling is not measured here, so
``uv_model`` refuses other versions.)
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np

from lensfield import Setup, trace_field


@dataclasses.dataclass(frozen=True)
class UVModel:
    W: int                 # output size
    H: int
    render_w: int          # what POV-Ray renders
    render_h: int
    drop_top: int          # output = render[drop_top:drop_top+H, :W]
    jx: float              # the sample's sub-pixel offset, pixels
    jy: float

    def uv_to_image(self, u, v):
        return u * self.render_w + self.jx, (1.0 - v) * self.render_h - self.drop_top + self.jy

    def image_to_uv(self, x, y):
        return (x - self.jx) / self.render_w, 1.0 - (y + self.drop_top - self.jy) / self.render_h

    def pixel_uv(self):
        """(H, W) u and v POV-Ray samples for each output pixel (measured model)."""
        i = np.arange(self.W, dtype=float)[None, :]
        j = np.arange(self.H, dtype=float)[:, None] + self.drop_top
        return np.broadcast_to(i / self.render_w, (self.H, self.W)), \
            np.broadcast_to(1.0 - j / self.render_h, (self.H, self.W))

    def povray_switches(self):
        from povlens.pov.process import pixel_range_args
        return ([f"+W{self.render_w}", f"+H{self.render_h}"]
                + pixel_range_args(0, self.W, self.render_w, "col")
                + pixel_range_args(self.drop_top, self.render_h, self.render_h, "row"))

    def crop(self, img):
        return img[self.drop_top:self.drop_top + self.H, :self.W]


def uv_model(W: int, H: int, jx: float = 0.5, jy: float = 0.5, version: str = "3.7.0.10"):
    if not version.startswith("3.7.0"):
        raise NotImplementedError("distribution-3 sampling measured on 3.7.0.x only")
    return UVModel(W, H, W + 1, H + 1, 1, jx, jy)


# ---------------------------------------------------------------------------
# grids


@dataclasses.dataclass
class RayMesh:
    uv: np.ndarray          # (V, 2)
    xy: np.ndarray          # (V, 2) image positions of the vertices (pixels)
    origin: np.ndarray      # (V, 3) world origins (scene units)
    normal: np.ndarray      # (V, 3) world unit directions
    faces: np.ndarray       # (F, 3) vertex indices
    geom_ok: np.ndarray     # (V,) the vertex ray exists (else filled in)
    margin: np.ndarray      # (V, S) aperture margins r^2 - h^2 (mm^2)
    grid: tuple | None = None   # (gx, gy, u0) for uniform_uv_grid meshes


def uniform_uv_grid(gx: int, gy: int, model: UVModel):
    """(gx+1)(gy+1) vertices on [u0, 1] x [0, 1]; u0 = -0.25/W' keeps column 0's
    samples (u = 0) strictly inside (UVs above 1 would overrun POV-Ray's bins)."""
    u0 = -0.25 / model.render_w
    u = np.linspace(u0, 1.0, gx + 1)
    v = np.linspace(0.0, 1.0, gy + 1)
    U, V = np.meshgrid(u, v)           # row index = v index
    uv = np.stack([U.ravel(), V.ravel()], 1)
    idx = np.arange((gx + 1) * (gy + 1)).reshape(gy + 1, gx + 1)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    return uv, faces


def fill_missing(values: np.ndarray, ok: np.ndarray, gx: int, gy: int) -> np.ndarray:
    """Vertices without a ray get their nearest grid neighbour's (only vertices whose
    neighbourhood is fully vignetted ever lack one; such faces carry no light)."""
    if ok.all():
        return values
    from scipy.ndimage import distance_transform_edt
    bad = ~ok.reshape(gy + 1, gx + 1)
    _, (ii, jj) = distance_transform_edt(bad, return_indices=True)
    src = (ii * (gx + 1) + jj).ravel()
    return values[src]


def build_mesh(setup: Setup, P_xy, model: UVModel, gx: int, gy: int | None = None,
               area_mm2: float = 1.0) -> RayMesh:
    if gy is None:
        gy = max(1, round(gx * model.H / model.W))
    uv, faces = uniform_uv_grid(gx, gy, model)
    x, y = model.uv_to_image(uv[:, 0], uv[:, 1])
    fld = trace_field(setup, P_xy, x, y, area_mm2)
    ok = fld.geom_ok
    org = fill_missing(fld.world_origin, ok, gx, gy)
    nrm = fill_missing(fld.world_direction, ok, gx, gy)
    return RayMesh(uv, np.stack([x, y], 1), org, nrm, faces, ok, fld.margin,
                   (gx, gy, float(uv[:, 0].min())))


# ---------------------------------------------------------------------------
# encoding: vertices and normals in a scaled camera frame


@dataclasses.dataclass
class Encoded:
    """What the mesh2 holds (local, float32 when parsed) and how the mesh_camera's
    ``mesh { NAME matrix <Mat3 rows, T> }`` maps it to the world: points
    p = q Mat3 + T, normals n = normal Mat3^-T (POV-Ray's MTransNormal), both in double.

    Mat3 = S R with R the camera basis (rows right, up, forward) and S = diag(eps, eps, 1).
    A stored normal is normalize(d_cam S) for the ray direction d_cam (camera frame), so
    the interpolated world direction is normalize(sum_k B_k d_k / |d_k S|): eps = 1 is
    POV-Ray's plain normalised lerp, eps -> 0 weights each vertex by 1/cos(theta_k),
    i.e. interpolates linearly in the gnomonic (tan theta) image plane -- exact for a
    pinhole.  Vertices are the ray origins moved offset_t units along their rays
    (then the camera needs location <0,0,-offset_t>)."""
    q: np.ndarray       # (V, 3)
    n: np.ndarray       # (V, 3) unit
    mat3: np.ndarray    # (3, 3)
    T: np.ndarray       # (3,)
    offset_t: float


def encode(m: RayMesh, basis: np.ndarray, eps: float = 1.0, offset_t: float = 0.0) -> Encoded:
    R = np.asarray(basis, float)
    S = np.array([eps, eps, 1.0])
    p = m.origin + offset_t * m.normal
    T = 0.5 * (p.min(0) + p.max(0))
    q = ((p - T) @ R.T) / S
    n = (m.normal @ R.T) * S
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return Encoded(q, n, S[:, None] * R, T, float(offset_t))


def _fmt_rows(a: np.ndarray, fmt: str) -> str:
    row = "<" + ",".join([fmt] * a.shape[1]) + ">"
    return ",\n".join([row] * len(a)) % tuple(a.ravel().tolist())


def mesh_text(name: str, m: RayMesh, e: Encoded) -> str:
    """``#declare name = mesh2 {...}``: vertex, normal and uv vectors (normal and uv
    indices default to the face indices)."""
    return (f"#declare {name} = mesh2 {{\n"
            f"vertex_vectors {{ {len(e.q)},\n{_fmt_rows(e.q, '%.9g')}\n}}\n"
            f"normal_vectors {{ {len(e.n)},\n{_fmt_rows(e.n, '%.9g')}\n}}\n"
            f"uv_vectors {{ {len(m.uv)},\n{_fmt_rows(m.uv, '%.9g')}\n}}\n"
            f"face_indices {{ {len(m.faces)},\n{_fmt_rows(m.faces, '%d')}\n}}\n"
            f"}}\n")


def camera_text(name: str, e: Encoded, smooth: bool = True) -> str:
    mt = ", ".join("%.17g" % v for v in list(e.mat3.ravel()) + list(e.T))
    loc = f"  location <0, 0, {-e.offset_t:.17g}>\n" if e.offset_t else ""
    return (f"camera {{\n  mesh_camera {{ 1 3 mesh {{ {name} matrix <{mt}> }}"
            f"{' smooth' if smooth else ''} }}\n{loc}}}\n")


# ---------------------------------------------------------------------------
# what POV-Ray computes


def _as_f32(a):
    return np.asarray(a, np.float32).astype(np.float64)


def locate(m: RayMesh, pix_u, pix_v, uv_float32: bool = False):
    if getattr(m, "grid", None) is not None and not uv_float32:
        return locate_uniform(m, pix_u, pix_v)
    return locate_general(m, pix_u, pix_v, uv_float32)


def locate_uniform(m: RayMesh, pix_u, pix_v):
    """locate() for the meshes of uniform_uv_grid (cell (r, c) -> faces r*gx + c (a,b,d)
    and F/2 + r*gx + c (a,d,c)), vectorized; on shared edges it picks the first face
    in order as POV-Ray does, up to rounding of B at exactly 0."""
    gx, gy, u0 = m.grid
    pu, pv = np.asarray(pix_u, float).ravel(), np.asarray(pix_v, float).ravel()
    fu = (pu - u0) / (1.0 - u0) * gx
    fv = pv * gy
    c = np.clip(np.floor(fu).astype(int), 0, gx - 1)
    r = np.clip(np.floor(fv).astype(int), 0, gy - 1)
    su, sv = fu - c, fv - r               # in [0, 1]: a=(0,0) b=(1,0) c=(0,1) d=(1,1)
    upper = su >= sv                      # triangle (a, b, d)
    nf = gx * gy
    face = np.where(upper, r * gx + c, nf + r * gx + c)
    B = np.where(upper[:, None], np.stack([1 - su, su - sv, sv], 1),
                 np.stack([1 - sv, su, sv - su], 1))
    return face, B


def locate_general(m: RayMesh, pix_u, pix_v, uv_float32: bool = False):
    """face (n,) (-1: none) and barycentrics B (n, 3) of each pixel's (u, v): the first
    face in order whose UV triangle contains it (B >= 0), B from the UVs in double."""
    pu, pv = np.asarray(pix_u, float).ravel(), np.asarray(pix_v, float).ravel()
    UV = _as_f32(m.uv) if uv_float32 else m.uv
    n = len(pu)
    face = np.full(n, -1)
    B = np.zeros((n, 3))
    F = m.faces
    uvf = UV[F]                                      # (F, 3, 2)
    lo, hi = uvf.min(1), uvf.max(1)
    # pixels indexed in cells of the median face size; each face (in order: the
    # first that contains a pixel wins) tests the pixels of the cells it overlaps
    du = np.median(hi[:, 0] - lo[:, 0]); dv = np.median(hi[:, 1] - lo[:, 1])
    ci = np.floor(pu / du).astype(int); cj = np.floor(pv / dv).astype(int)
    key = ci * 100003 + cj
    srt = np.argsort(key, kind="stable")
    keys_sorted = key[srt]
    for f in range(len(F)):
        i0, i1 = int(np.floor(lo[f, 0] / du)), int(np.floor(hi[f, 0] / du))
        j0, j1 = int(np.floor(lo[f, 1] / dv)), int(np.floor(hi[f, 1] / dv))
        cand = []
        for ii in range(i0, i1 + 1):
            for jj in range(j0, j1 + 1):
                k = ii * 100003 + jj
                a, b = np.searchsorted(keys_sorted, [k, k + 1])
                if b > a:
                    cand.append(srt[a:b])
        if not cand:
            continue
        c = np.concatenate(cand)
        c = c[face[c] < 0]
        if not len(c):
            continue
        (P1u, P1v), (P2u, P2v), (P3u, P3v) = uvf[f]
        u, v = pu[c], pv[c]
        scale = (P2u - P1u) * (P3v - P1v) - (P3u - P1u) * (P2v - P1v)
        B1 = ((P2u - u) * (P3v - v) - (P3u - u) * (P2v - v)) / scale
        B2 = ((P3u - u) * (P1v - v) - (P1u - u) * (P3v - v)) / scale
        B3 = ((P1u - u) * (P2v - v) - (P2u - u) * (P1v - v)) / scale
        inside = (B1 >= 0) & (B2 >= 0) & (B3 >= 0)
        c = c[inside]
        face[c] = f
        B[c] = np.stack([B1[inside], B2[inside], B3[inside]], 1)
    return face, B


def emulate(m: RayMesh, e: Encoded, model: UVModel, uv_float32: bool = False, loc=None):
    """Origin (H, W, 3), direction (H, W, 3), found (H, W) and face (H, W) POV-Ray
    3.7.0.10 computes for every output pixel (distribution 3, smooth): float32
    vertices and normals, the mesh's matrix applied in double, location.z offset."""
    pix_u, pix_v = model.pixel_uv()
    if loc is None:
        loc = locate(m, pix_u, pix_v, uv_float32)
    face, B = loc
    found = face >= 0
    tri = m.faces[np.where(found, face, 0)]
    q32, n32 = _as_f32(e.q), _as_f32(e.n)
    org = np.einsum("nk,nkd->nd", B, q32[tri]) @ e.mat3 + e.T
    nl = np.einsum("nk,nkd->nd", B, n32[tri])
    d = nl @ np.linalg.inv(e.mat3).T
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    org = org - e.offset_t * d
    sh = np.shape(pix_u)
    return org.reshape(sh + (3,)), d.reshape(sh + (3,)), found.reshape(sh), face.reshape(sh)


def ray_errors(setup: Setup, P_xy, model: UVModel, org, d, found, area_mm2=1.0):
    """Exact rays at every output pixel's sample position vs what POV-Ray traces.

    Returns dict with (H, W) maps: passed, dir_px (angle / pixel angle), orig_mm (distance
    of POV-Ray's origin from the exact ray's line, mm), and the exact field."""
    H, W = model.H, model.W
    jj, ii = np.mgrid[0:H, 0:W].astype(float)
    fld = trace_field(setup, P_xy, ii + model.jx, jj + model.jy, area_mm2)
    ed = fld.world_direction.reshape(H, W, 3)
    eo = fld.world_origin.reshape(H, W, 3)
    cosang = np.clip(np.einsum("hwd,hwd->hw", ed, d), -1, 1)
    ang = np.arccos(cosang)
    # robust small-angle: |cross|
    ang = np.arcsin(np.clip(np.linalg.norm(np.cross(ed, d), axis=-1), 0, 1))
    rel = org - eo
    perp = rel - np.einsum("hwd,hwd->hw", rel, ed)[..., None] * ed
    orig_mm = np.linalg.norm(perp, axis=-1) * setup.placement.mm_per_unit
    return dict(passed=fld.passed.reshape(H, W), found=found, dir_px=ang / setup.pixel_angle,
                orig_mm=orig_mm, weight=fld.weight.reshape(H, W), exact_dir=ed, exact_org=eo)


# ---------------------------------------------------------------------------
# fitted vertex normals


def fit_normals(setup: Setup, P_xy, m: RayMesh, e: Encoded, model: UVModel, sub: int = 4,
                irls: int = 0, area_mm2: float = 1.0) -> Encoded:
    """Least-squares vertex normals: the stored normals n_k minimise
    sum_s |sum_k B_k(s) n_k - t_s|^2 over a grid ``sub`` times finer than the mesh, where
    t_s = normalize(d_s S) is what a vertex at s would store.  POV-Ray normalises the
    n_k when parsing; the fit's lengths are within ~1e-4 of 1, so that changes the
    interpolated direction at second order only.  ``irls`` > 0: that many reweighted
    passes (weights ~ residual) toward the minimax fit."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spl
    gx = len(np.unique(m.uv[:, 0])) - 1
    gy = len(np.unique(m.uv[:, 1])) - 1
    u = np.linspace(m.uv[:, 0].min(), 1.0, gx * sub + 1)
    v = np.linspace(0.0, 1.0, gy * sub + 1)
    U, V = np.meshgrid(u, v)
    su, sv = U.ravel(), V.ravel()
    x, y = model.uv_to_image(su, sv)
    fld = trace_field(setup, P_xy, x, y, area_mm2)
    ok = fld.geom_ok
    face, B = locate(m, su, sv)
    ok &= face >= 0
    R = setup.placement.basis
    S = np.array([e.mat3[0] @ R[0], e.mat3[1] @ R[1], 1.0])     # (eps, eps, 1)
    t = (fld.world_direction @ R.T) * S
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    rows = np.repeat(np.flatnonzero(ok), 3)
    cols = m.faces[face[ok]].ravel()
    vals = B[ok].ravel()
    n_s = len(su)
    A = sp.csr_matrix((vals, (rows, cols)), shape=(n_s, len(m.uv)))[ok]
    tt = t[ok]
    w = np.ones(len(tt))
    # vertices no sample touches keep their interpolated normal (weak prior)
    lam = 1e-6
    n0 = e.n
    for it in range(irls + 1):
        Aw = sp.diags(w) @ A
        M = (Aw.T @ A + lam * sp.identity(A.shape[1])).tocsc()
        lu = spl.splu(M)
        n = np.stack([lu.solve(Aw.T @ tt[:, c] + lam * n0[:, c]) for c in range(3)], 1)
        res = np.linalg.norm(A @ n - tt, axis=1)
        w = (res / res.max() + 1e-3) ** 1.0 if res.max() > 0 else w
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return dataclasses.replace(e, n=n)
