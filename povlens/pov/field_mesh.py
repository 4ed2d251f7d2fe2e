"""Field ray meshes: a coarse UV-mapped smooth ``mesh2`` whose interpolated rays stand
for every pixel's exact lens ray of one lens sample (``mesh_camera`` distribution 3).

What POV-Ray 3.7.0.10 computes (docs/reference/povray-mesh-camera.md §3.3; source
``tracepixel.cpp``, ``mesh.cpp``; checked by a direction-readout render in the tests):
a pixel's (u, v) selects the first face whose UV triangle contains it; its
barycentrics B (from the UVs, in double) give origin = sum B_k P_k (float32
vertices, then the mesh's transform) and, with ``smooth`` in the ``mesh_camera``
block, direction = normalize(sum B_k N_k) (normals float32, normalised when parsed,
mapped by the inverse transpose of the transform).

**FS#261 (3.7.0.x).**  Rendered pixel (i, j) samples u = i / W', v = 1 - j / H' (its
top-left corner), the last column and the first row clamped.  So a W x H image is
rendered at W' x H' = (W + 1) x (H + 1) with the last column and row 0 not traced
(``+EC{W} +SR2``) and both dropped; the UV map is built for that sampling, so output
pixel (i, j) samples the image position (i + jx, j + jy), (jx, jy) the sample's
sub-pixel offset: vertex (u, v) carries the ray of x = u W' + jx, y = (1 - v) H' - 1 + jy
(:class:`UVModel`).  POV-Ray 3.8 fixed it (commit c8911315); its sampling was not
measured, so :func:`uv_model` refuses other versions.

**Encoding.**  The mesh is placed by ``matrix <M, T>`` with M = S R: R the camera basis
(rows right, up, forward) and S = diag(eps, eps, 1).  A vertex stores the ray origin
as ((p - T) R^T) / S, and its normal as normalize(d_cam S), so POV-Ray interpolates
normalize(sum_k B_k d_k / |d_k S|): eps = 1 is the plain normalised lerp, eps -> 0
interpolates linearly in the tangent (gnomonic) plane, exact for a pinhole or thin
lens.  Rectilinear lenses want eps = 0.01, the fisheye eps = 1
(docs/decisions/exact-lens-distribution3.md).

**Fitted normals.**  The vertex normals are a least-squares fit to exact rays on a
grid ``FIT_SUBDIVISION`` times finer than the mesh, which halves the largest error
against interpolating the vertex rays.  The error is second order in the face size,
so the grid needed grows with the square root of the image width.
"""

from __future__ import annotations

import dataclasses
import threading

import numpy as np

from povlens.errors import PovlensError
from povlens.lens.film import Film
from povlens.lens.prescription import LensPrescription
from povlens.pov.process import pixel_range_args
from povlens.pupil.field import trace_field

__all__ = ["UVModel", "uv_model", "pass_models", "pass_size", "pass_rows", "deinterleave",
           "FieldMesh", "MeshPoints", "mesh_points", "build_field_meshes", "encode_field_mesh",
           "take_rays",
           "PassMesh", "combine_meshes", "lens_ray_field", "build_field_mesh", "mesh2_text",
           "placement_text", "FIT_SUBDIVISION", "MESH_NAME", "TRANSFORM_NAME", "seen_from"]

#: The fit's sample grid is this many times finer than the mesh.
FIT_SUBDIVISION = 3

MESH_NAME = "PovlensRays"
TRANSFORM_NAME = "PovlensPlace"


@dataclasses.dataclass(frozen=True)
class UVModel:
    """How POV-Ray samples one tile of a distribution-3 mesh camera for a W x H image.

    A pass of an interleaved render (:func:`pass_models`) renders m x m tiles in one row,
    tile c = ox + m oy holding the image's columns ox, ox + m, ... and rows oy, oy + m,
    ...: its own mesh over the whole film, so neighbouring pixels take different lens
    samples (interleaved sampling, Keller and Heidrich 2001).  In one row, the rendered
    rows of a band of image rows are a band too (``--adaptive``).  m = 1 is one tile,
    the image itself.

    width, height : the output image (pixels).
    render_width, render_height : what POV-Ray renders (W', H').
    drop_top_rows, drop_right_columns : what is cut from the render.
    jitter_px : (jx, jy) the tile's sub-pixel offset.
    stride : m.
    offset : (ox, oy) the tile's first image column and row.
    tile_origin : (I0, J0) the rendered pixel (after the cut) of the tile's first pixel.
    tile_size : (Wc, Hc) the tile's image pixels.
    tile_extent : (Wt, Ht) the rendered pixels each tile is given (Wc <= Wt).
    """

    width: int
    height: int
    render_width: int
    render_height: int
    drop_top_rows: int
    drop_right_columns: int
    jitter_px: tuple[float, float]
    stride: int = 1
    offset: tuple[int, int] = (0, 0)
    tile_origin: tuple[int, int] = (0, 0)
    tile_size: tuple[int, int] | None = None
    tile_extent: tuple[int, int] | None = None

    @property
    def size(self) -> tuple[int, int]:
        """(Wc, Hc)."""
        return self.tile_size if self.tile_size is not None else (self.width, self.height)

    @property
    def extent(self) -> tuple[int, int]:
        return self.tile_extent if self.tile_extent is not None else (self.width, self.height)

    def uv_rect(self) -> tuple[float, float, float, float]:
        """(u0, u1, v0, v1): the tile's UV rectangle, its edges half a pixel outside its
        sample positions (u0 >= -0.25 / W', inside POV-Ray's 10 x 10 bins)."""
        (I0, J0), (Wt, Ht) = self.tile_origin, self.extent
        Wr, Hr, d = self.render_width, self.render_height, self.drop_top_rows
        u0 = max((I0 - 0.5) / Wr, -0.25 / Wr)
        return (u0, (I0 + Wt - 0.5) / Wr, 1.0 - (J0 + Ht - 0.5 + d) / Hr,
                1.0 - (J0 - 0.5 + d) / Hr)

    def uv_to_image(self, u, v):
        """Image position (x, y) (pixels) a UV point stands for."""
        jx, jy = self.jitter_px
        (I0, J0), (ox, oy), m = self.tile_origin, self.offset, self.stride
        X = np.asarray(u) * self.render_width - I0
        Y = (1.0 - np.asarray(v)) * self.render_height - self.drop_top_rows - J0
        return m * X + ox + jx, m * Y + oy + jy

    def pixel_uv(self):
        """(Hc, Wc) u and v POV-Ray samples for each of the tile's pixels."""
        (Wc, Hc), (I0, J0) = self.size, self.tile_origin
        i = np.arange(Wc, dtype=float)[None, :] + I0
        j = np.arange(Hc, dtype=float)[:, None] + J0 + self.drop_top_rows
        return (np.broadcast_to(i / self.render_width, (Hc, Wc)),
                np.broadcast_to(1.0 - j / self.render_height, (Hc, Wc)))

    def columns(self) -> np.ndarray:
        """(Wc,) the image columns of the tile's pixels."""
        return self.offset[0] + self.stride * np.arange(self.size[0])

    def rows(self) -> np.ndarray:
        """(Hc,) the image rows of the tile's pixels."""
        return self.offset[1] + self.stride * np.arange(self.size[1])

    def pixel_positions(self):
        """(Wc,), (Hc,) image x and y where the tile's pixel columns and rows are sampled."""
        jx, jy = self.jitter_px
        return self.columns() + jx, self.rows() + jy

    def povray_switches(self, rows: tuple[int, int] | None = None) -> list[str]:
        """+W/+H and the column and row ranges (film rows ``rows`` [r0, r1), default
        all; one tile only) that render exactly the output pixels."""
        r0, r1 = (0, self.render_height - self.drop_top_rows) if rows is None else rows
        if rows is not None and self.stride != 1:
            raise ValueError("row ranges of an interleaved render are not contiguous")
        return ([f"+W{self.render_width}", f"+H{self.render_height}"]
                + pixel_range_args(0, self.render_width - self.drop_right_columns,
                                   self.render_width, "col")
                + pixel_range_args(r0 + self.drop_top_rows, r1 + self.drop_top_rows,
                                   self.render_height, "row"))


def _check_version(version: str) -> None:
    if not str(version).startswith("3.7.0"):
        raise PovlensError(f"the field ray meshes are measured on POV-Ray 3.7.0.x only, "
                           f"not {version}", "convert with --ray-mesh pixel")


def uv_model(width: int, height: int, jitter_px=(0.5, 0.5), version: str = "3.7.0.10") -> UVModel:
    """The measured sampling of POV-Ray ``version`` (3.7.0.x only) for one tile, the image."""
    _check_version(version)
    return UVModel(int(width), int(height), int(width) + 1, int(height) + 1, 1, 1,
                   (float(jitter_px[0]), float(jitter_px[1])))


def pass_size(width: int, height: int, stride: int, bands: int = 1) -> tuple[int, int]:
    """(W', H'): what POV-Ray renders for an interleaved pass of m = ``stride``: m^2
    tiles of ceil(W / m) x ceil(H / m) pixels in a row, plus FS#261's column and row;
    ``bands`` passes (lens samples) stacked one under another in one render
    (:mod:`povlens.rendering.sample_stacks`)."""
    m = int(stride)
    return m * m * -(-int(width) // m) + 1, int(bands) * -(-int(height) // m) + 1


def pass_rows(rows: tuple[int, int], stride: int) -> tuple[int, int]:
    """The rendered rows [R0, R1) (after the cut row) that hold the image rows ``rows``
    [r0, r1) of every tile of an interleaved pass of m = ``stride``."""
    m = int(stride)
    return int(rows[0]) // m, -(-int(rows[1]) // m)


def pass_models(width: int, height: int, stride: int, jitters, version: str = "3.7.0.10",
                band: int = 0, bands: int = 1) -> list[UVModel]:
    """The m x m tiles of one interleaved pass (m = ``stride``), tile c = ox + m oy with
    offset (ox, oy) and sub-pixel offset ``jitters[c]``; m = 1 is :func:`uv_model`.

    ``band`` of ``bands``: the pass is band b of a render stacking that many passes one
    under another (its tiles' rendered rows start at b ceil(H / m)); the render's
    rows of band b, cut out, are exactly the pass rendered alone."""
    _check_version(version)
    m, W, H, b = int(stride), int(width), int(height), int(band)
    if not 0 <= b < int(bands):
        raise ValueError(f"band {band} of {bands}")
    if m == 1 and int(bands) == 1:
        return [uv_model(W, H, jitters[0], version)]
    Wt, Ht = -(-W // m), -(-H // m)
    Wr, Hr = pass_size(W, H, m, bands)
    out = []
    for oy in range(m):
        for ox in range(m):
            j = jitters[ox + m * oy]
            out.append(UVModel(W, H, Wr, Hr, 1, 1, (float(j[0]), float(j[1])), m, (ox, oy),
                               ((ox + m * oy) * Wt, b * Ht),
                               (len(range(ox, W, m)), len(range(oy, H, m))), (Wt, Ht)))
    return out


def deinterleave(image: np.ndarray, models: list[UVModel]) -> np.ndarray:
    """The (H, W, C) image of a pass POV-Ray rendered as tiles (``image``: the render
    after its cut row and column)."""
    if len(models) == 1:
        return image
    W, H = models[0].width, models[0].height
    out = np.empty((H, W) + image.shape[2:], dtype=image.dtype)
    for t in models:
        (I0, J0), (Wc, Hc), (ox, oy), m = t.tile_origin, t.size, t.offset, t.stride
        out[oy::m, ox::m] = image[J0:J0 + Hc, I0:I0 + Wc]
    return out


@dataclasses.dataclass(frozen=True)
class FieldMesh:
    """One lens sample's ray mesh, as POV-Ray will read it.

    grid : (gx, gy) faces across and down (2 gx gy triangles).
    uv : (V, 2) vertex UVs, V = (gx+1)(gy+1), row-major from v = 0 (image bottom).
    image_xy : (V, 2) image positions the vertices stand for (pixels).
    vertex : (V, 3) stored vertices; normal : (V, 3) stored unit normals.
    matrix : (4, 3) the mesh's ``matrix`` (rows M then T).
    faces : (F, 3) vertex indices.
    exists : (V,) the vertex had an unclipped ray (else its neighbour's).
    margin_mm2 : (V, S) aperture margins at the vertices.
    fit_error_px : largest angle between a fitted direction and the exact ray at the
        fit's sample points where the lens passes light, in pixels (angle x focal
        length / pixel pitch); 0 where none passes.
    """

    grid: tuple[int, int]
    uv: np.ndarray
    image_xy: np.ndarray
    vertex: np.ndarray
    normal: np.ndarray
    matrix: np.ndarray
    faces: np.ndarray
    exists: np.ndarray
    margin_mm2: np.ndarray
    fit_error_px: float
    eps: float
    rect: tuple[float, float, float, float] = (0.0, 1.0, 0.0, 1.0)

    def node_margins(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Node columns' image x (gx+1,), rows' image y (gy+1,) increasing, and the
        margins (gy+1, gx+1, S) in that row order (for :func:`povlens.pupil.field_mask.pass_mask`)."""
        gx, gy = self.grid
        xs = self.image_xy[: gx + 1, 0]
        ys = self.image_xy[:: gx + 1, 1]
        order = np.argsort(ys)
        m = self.margin_mm2.reshape(gy + 1, gx + 1, -1)[order]
        return xs, ys[order], m


def uv_grid(gx: int, gy: int, model: UVModel) -> tuple[np.ndarray, np.ndarray]:
    """(V, 2) vertex UVs on the tile's :meth:`UVModel.uv_rect` and (F, 3) faces.
    Cell (r, c) holds faces r gx + c (a, b, d) and F/2 + r gx + c (a, d, c)."""
    u0, u1, v0, v1 = model.uv_rect()
    u = np.linspace(u0, u1, gx + 1)
    v = np.linspace(v0, v1, gy + 1)
    U, V = np.meshgrid(u, v)
    idx = np.arange((gx + 1) * (gy + 1)).reshape(gy + 1, gx + 1)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    return np.stack([U.ravel(), V.ravel()], 1), faces


def locate_in_grid(grid: tuple[int, int], rect, pu, pv) -> tuple[np.ndarray, np.ndarray]:
    """Face (n,) and barycentrics (n, 3) of UV points in a :func:`uv_grid` mesh over
    ``rect`` (u0, u1, v0, v1), as POV-Ray picks them (the first face containing the point)."""
    gx, gy = grid
    u0, u1, v0, v1 = rect
    pu, pv = np.asarray(pu, float).ravel(), np.asarray(pv, float).ravel()
    fu = (pu - u0) / (u1 - u0) * gx
    fv = (pv - v0) / (v1 - v0) * gy
    c = np.clip(np.floor(fu).astype(int), 0, gx - 1)
    r = np.clip(np.floor(fv).astype(int), 0, gy - 1)
    su, sv = fu - c, fv - r
    upper = su >= sv
    face = np.where(upper, r * gx + c, gx * gy + r * gx + c)
    B = np.where(upper[:, None], np.stack([1 - su, su - sv, sv], 1),
                 np.stack([1 - sv, su, sv - su], 1))
    return face, B


def _fill_missing(values: np.ndarray, exists: np.ndarray, gx: int, gy: int) -> np.ndarray:
    """Vertices without a ray take their nearest grid neighbour's (only vertices whose
    neighbourhood is fully vignetted lack one; their faces carry no light)."""
    if exists.all() or not exists.any():
        return values
    from scipy.ndimage import distance_transform_edt
    _, (ii, jj) = distance_transform_edt(~exists.reshape(gy + 1, gx + 1), return_indices=True)
    return values[(ii * (gx + 1) + jj).ravel()]


def lens_ray_field(lens: LensPrescription, film_distance_mm: float, film: Film,
                   plane_z_mm: float, pupil_xy_mm):
    """The ray field of one lens sample: ``field(x, y)`` -> :class:`povlens.pupil.field.FieldRays`
    of image positions (pixels) toward the pupil point, traced unclipped."""
    def field(x, y):
        return trace_field(lens, film_distance_mm, film, plane_z_mm, pupil_xy_mm, x, y)
    return field


@dataclasses.dataclass(frozen=True)
class MeshPoints:
    """Where a tile's mesh needs rays: its vertices (UVs ``uv`` (V, 2), faces (F, 3), image
    positions ``x``, ``y`` (V,)) and the fit's finer grid (UVs ``fit_uv`` (n, 2), image
    positions ``fit_x``, ``fit_y``)."""

    uv: np.ndarray
    faces: np.ndarray
    x: np.ndarray
    y: np.ndarray
    fit_uv: np.ndarray
    fit_x: np.ndarray
    fit_y: np.ndarray


def mesh_points(model: UVModel, grid: tuple[int, int]) -> MeshPoints:
    """The vertex and fit sample positions of a tile's ``grid`` (:func:`uv_grid`)."""
    gx, gy = int(grid[0]), int(grid[1])
    uv, faces = uv_grid(gx, gy, model)
    x, y = model.uv_to_image(uv[:, 0], uv[:, 1])
    k = FIT_SUBDIVISION
    rect = model.uv_rect()
    U, V = np.meshgrid(np.linspace(rect[0], rect[1], gx * k + 1),
                       np.linspace(rect[2], rect[3], gy * k + 1))
    fit_uv = np.stack([U.ravel(), V.ravel()], 1)
    fx, fy = model.uv_to_image(fit_uv[:, 0], fit_uv[:, 1])
    return MeshPoints(uv, faces, x, y, fit_uv, fx, fy)


def build_field_mesh(ray_field, placement, model: UVModel, grid: tuple[int, int], eps: float,
                     pixel_angle_rad: float, origin_world=None) -> FieldMesh:
    """Trace and encode the ray mesh of one lens sample's tile.

    ray_field : callable (x (n,), y (n,)) image positions (pixels) -> an object with
        camera-frame ``origin_mm`` (n, 3), unit ``direction`` (n, 3), ``exists``,
        ``margin_mm2`` (n, S) and ``passed`` (:func:`lens_ray_field`; any smooth field,
        a thin lens's in the tests).
    placement : :class:`povlens.pupil.rays.ScenePlacement` (camera frame -> world).
    grid : (gx, gy); eps : the direction encoding's scale (module docstring).
    pixel_angle_rad : the angle of one pixel at the image centre (pitch / focal
        length), the unit of ``fit_error_px``.
    origin_world : (3,) the world point the vertices are stored relative to (the
        matrix's translation; default the middle of the ray origins): the tiles of one
        pass share it (:func:`combine_meshes`).
    """
    pts = mesh_points(model, grid)
    return encode_field_mesh(pts, ray_field(pts.x, pts.y), ray_field(pts.fit_x, pts.fit_y),
                             placement, model, grid, eps, pixel_angle_rad, origin_world)


def build_field_meshes(ray_field, placement, models: list[UVModel], grid: tuple[int, int],
                       eps: float, pixel_angle_rad: float, origin_world=None) -> list[FieldMesh]:
    """:func:`build_field_mesh` of every tile of a pass, each stage's rays traced in one
    call: ``ray_field(x, y, tile)`` traces image positions of the tiles ``tile`` (n,)
    (indices into ``models``).  The tiles share ``origin_world`` (default the first
    one's: the passes of one stacked render share the first pass's)."""
    pts = [mesh_points(m, grid) for m in models]
    tile_v = np.concatenate([np.full(len(p.x), i) for i, p in enumerate(pts)])
    tile_f = np.concatenate([np.full(len(p.fit_x), i) for i, p in enumerate(pts)])
    rays_v = ray_field(np.concatenate([p.x for p in pts]), np.concatenate([p.y for p in pts]),
                       tile_v)
    rays_f = ray_field(np.concatenate([p.fit_x for p in pts]),
                       np.concatenate([p.fit_y for p in pts]), tile_f)
    out, origin = [], origin_world
    # tile i's rays are a contiguous run of each call's: slices, not masks
    ends_v, ends_f = np.cumsum([len(p.x) for p in pts]), np.cumsum([len(p.fit_x) for p in pts])
    for i, (m, p) in enumerate(zip(models, pts)):
        sel_v = slice(ends_v[i] - len(p.x), ends_v[i])
        sel_f = slice(ends_f[i] - len(p.fit_x), ends_f[i])
        mesh = encode_field_mesh(p, take_rays(rays_v, sel_v), take_rays(rays_f, sel_f),
                                 placement, m, grid, eps, pixel_angle_rad, origin)
        origin = mesh.matrix[3]
        out.append(mesh)
    return out


def take_rays(rays, sel):
    """The rays ``sel`` (a slice, a boolean or index array) of a
    :class:`povlens.pupil.field.FieldRays`."""
    return dataclasses.replace(rays, origin_mm=rays.origin_mm[sel], direction=rays.direction[sel],
                               exists=rays.exists[sel], margin_mm2=rays.margin_mm2[sel],
                               passed=rays.passed[sel])


def encode_field_mesh(pts: MeshPoints, rays, fit_rays, placement, model: UVModel,
                      grid: tuple[int, int], eps: float, pixel_angle_rad: float,
                      origin_world=None) -> FieldMesh:
    """The ray mesh of a tile from its rays at ``pts`` (vertices, then the fit's grid)."""
    gx, gy = int(grid[0]), int(grid[1])
    R = placement.basis
    S = np.array([eps, eps, 1.0])
    direction = _fill_missing(rays.direction, rays.exists, gx, gy)
    origin = _fill_missing(rays.origin_mm, rays.exists, gx, gy)
    p = placement.points_to_world(origin)
    T = 0.5 * (p.min(0) + p.max(0)) if origin_world is None else np.asarray(origin_world, float)
    vertex = ((p - T) @ R.T) / S
    normal = direction * S
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    normal, err = _fit_normals(pts, fit_rays, model, (gx, gy), normal, S, pixel_angle_rad)
    matrix = np.vstack([S[:, None] * R, T])
    vertex = _separate_filled(vertex, pts.faces, rays.exists)
    return FieldMesh((gx, gy), pts.uv, np.stack([pts.x, pts.y], 1), vertex, normal, matrix,
                     pts.faces, rays.exists, rays.margin_mm2, err, float(eps), model.uv_rect())


@dataclasses.dataclass(frozen=True)
class PassMesh:
    """The tiles of one pass as the one ``mesh2`` POV-Ray reads: vertex, normal and UV
    vectors and faces of every tile in turn, and their shared ``matrix`` (4, 3)."""

    vertex: np.ndarray
    normal: np.ndarray
    uv: np.ndarray
    faces: np.ndarray
    matrix: np.ndarray


def combine_meshes(meshes: list[FieldMesh]) -> PassMesh:
    """One :class:`PassMesh` of tiles built with the same ``origin_world`` and encoding."""
    m0 = meshes[0]
    if any(not np.array_equal(m.matrix, m0.matrix) for m in meshes[1:]):
        raise ValueError("the tiles of one pass must share their matrix")
    offsets = np.cumsum([0] + [len(m.vertex) for m in meshes[:-1]])
    return PassMesh(np.concatenate([m.vertex for m in meshes]),
                    np.concatenate([m.normal for m in meshes]),
                    np.concatenate([m.uv for m in meshes]),
                    np.concatenate([m.faces + o for m, o in zip(meshes, offsets)]), m0.matrix)


def _degenerate(vertex: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) faces POV-Ray drops: zero cross product of its float32 vertices."""
    q = vertex.astype(np.float32).astype(np.float64)
    a, b, c = q[faces[:, 0]], q[faces[:, 1]], q[faces[:, 2]]
    return np.all(np.cross(a - b, c - b) == 0.0, axis=1)


def _separate_filled(vertex: np.ndarray, faces: np.ndarray, exists: np.ndarray) -> np.ndarray:
    """Move vertices that took a neighbour's ray (:func:`_fill_missing`) off their
    neighbours, a little at random (fixed seed), until no face is degenerate: POV-Ray
    drops degenerate faces, and their pixels would get no ray.  Such vertices lie
    where the lens passes no light.  Refuses a mesh whose own rays make a degenerate
    face (rays of neighbouring image positions starting at one point)."""
    rng = np.random.default_rng(0)
    scale = max(float(np.ptp(vertex[exists], axis=0).max()) if exists.any() else 1.0, 1e-9)
    vertex = vertex.copy()
    for _ in range(8):
        bad = _degenerate(vertex, faces)
        if not bad.any():
            return vertex
        movable = np.zeros(len(vertex), bool)
        movable[faces[bad].ravel()] = True
        movable &= ~exists
        if not movable.any():
            break
        vertex[movable] += rng.uniform(-1, 1, (int(movable.sum()), 3)) * 1e-4 * scale
    raise PovlensError("a field ray mesh has degenerate faces: the rays of neighbouring "
                       "image positions start at the same point (an ideal thin lens?)",
                       "start the rays a little along their directions, or render with "
                       "--ray-mesh pixel")


def _fit_normals(pts: MeshPoints, rays, model, grid, normal0, S, pixel_angle_rad):
    """Least-squares vertex normals n minimising sum_s |sum_k B_k(s) n_k - t_s|^2 over a
    grid FIT_SUBDIVISION times finer than the mesh (``rays`` at ``pts.fit_uv``; t_s =
    normalize(d_s S), what a vertex at s would store), wherever the unclipped ray
    exists (the field is smooth across vignetting cuts, so fitting it all is as good
    where light passes, and every tile of every pass shares the factorisation:
    :func:`_fit_solver`); and the largest angle left where the lens passes light, in
    pixels.  Vertices no sample touches keep their own ray (weak prior)."""
    use = rays.exists
    if not use.any():
        return normal0, 0.0
    face, B = locate_in_grid(grid, model.uv_rect(), pts.fit_uv[use, 0], pts.fit_uv[use, 1])
    t = rays.direction[use] * S
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    n = _fit_solver(tuple(grid), use, face, B, pts.faces, len(normal0)).solve(t, normal0)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    # what POV-Ray traces at the fit's samples: normalize(sum B n) mapped back by S^-1
    ok = rays.passed[use]
    if not ok.any():
        return n, 0.0
    tri = pts.faces[face[ok]]
    d = (np.einsum("nk,nkd->nd", B[ok], n.astype(np.float32).astype(float)[tri])) / S
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    err = np.arcsin(np.clip(np.linalg.norm(np.cross(d, rays.direction[use][ok]), axis=1), 0, 1))
    return n, float(err.max() / pixel_angle_rad)


_FIT_SOLVERS: dict = {}
_FIT_SOLVERS_LOCK = threading.Lock()
#: The ridge weight of the fit: vertices no fit sample touches keep their own ray.
FIT_RIDGE = 1e-6
#: Fits of at most this many vertices are solved densely (numpy's Cholesky): a render
#: of up to 640x480 then never imports scipy.sparse (0.13 s of a 2.4 s render, most of
#: what the mesh path adds to POV-Ray's own start-up); larger grids factorise sparsely.
DENSE_FIT_VERTICES = 600


class _FitSystem:
    """The normal equations (A^T A + lam I) n = A^T t + lam n0 of the fit, factorised
    once: ``A`` (samples x vertices) holds each fit sample's barycentric weights ``B``
    at its face's three vertices ``tri``."""

    def __init__(self, tri: np.ndarray, B: np.ndarray, n_v: int):
        self.tri, self.B, self.n_v = tri, B, n_v
        if n_v <= DENSE_FIT_VERTICES:
            # A^T A summed from each sample's 3 x 3 outer product; L^-1 of its Cholesky
            # factor (condition sqrt of the system's) makes each solve two products
            flat = (tri[:, :, None] * n_v + tri[:, None, :]).ravel()
            w = (B[:, :, None] * B[:, None, :]).ravel()
            M = np.bincount(flat, w, minlength=n_v * n_v).reshape(n_v, n_v)
            M[np.diag_indices(n_v)] += FIT_RIDGE
            self.l_inv = np.linalg.inv(np.linalg.cholesky(M))
            self.lu = None
        else:
            import scipy.sparse as sp
            import scipy.sparse.linalg as spl
            A = sp.csr_matrix((B.ravel(), (np.repeat(np.arange(len(B)), 3), tri.ravel())),
                              shape=(len(B), n_v))
            At = A.T.tocsr()
            self.lu = spl.splu((At @ A + FIT_RIDGE * sp.identity(n_v)).tocsc())

    def solve(self, t: np.ndarray, normal0: np.ndarray) -> np.ndarray:
        """(V, 3) vertex normals (unnormalised) fitting the targets ``t`` (S, 3)."""
        rhs = FIT_RIDGE * np.asarray(normal0, dtype=np.float64)
        for k in range(3):          # A^T t, vertex slot by slot
            for c in range(3):
                rhs[:, c] += np.bincount(self.tri[:, k], self.B[:, k] * t[:, c],
                                         minlength=self.n_v)
        if self.lu is not None:
            return self.lu.solve(rhs)
        return self.l_inv.T @ (self.l_inv @ rhs)


def _fit_solver(grid, use: np.ndarray, face, B, faces, n_v: int) -> _FitSystem:
    """The fit's factorised system: the same for every tile whose fit samples exist at
    the same places (kept for the last few grids)."""
    import hashlib
    key = (grid, n_v, hashlib.sha1(np.packbits(use).tobytes()).hexdigest())
    with _FIT_SOLVERS_LOCK:     # the lead's and its companions' threads build meshes at once
        if key not in _FIT_SOLVERS:
            if len(_FIT_SOLVERS) >= 8:
                _FIT_SOLVERS.pop(next(iter(_FIT_SOLVERS)))
            _FIT_SOLVERS[key] = _FitSystem(faces[face], B, n_v)
        return _FIT_SOLVERS[key]


def _rows(a: np.ndarray, fmt: str) -> str:
    row = "<" + ",".join([fmt] * a.shape[1]) + ">"
    return ",\n".join([row] * len(a)) % tuple(a.ravel().tolist())


def mesh2_text(mesh: FieldMesh | PassMesh, name: str = MESH_NAME) -> str:
    """``#declare NAME = mesh2 {...}``: vertex, normal and UV vectors (their indices
    default to the face indices)."""
    return (f"#declare {name} = mesh2 {{\n"
            f"vertex_vectors {{ {len(mesh.vertex)},\n{_rows(mesh.vertex, '%.9g')}\n}}\n"
            f"normal_vectors {{ {len(mesh.normal)},\n{_rows(mesh.normal, '%.9g')}\n}}\n"
            f"uv_vectors {{ {len(mesh.uv)},\n{_rows(mesh.uv, '%.9g')}\n}}\n"
            f"face_indices {{ {len(mesh.faces)},\n{_rows(mesh.faces, '%d')}\n}}\n}}\n")


def seen_from(mesh: PassMesh, eye_world) -> PassMesh:
    """The mesh for a camera whose ``location`` is ``eye_world`` (3,), drawing the
    same rays.

    POV-Ray measures radiosity's reuse distances from the camera's ``location``
    (``to_eye`` in ``RadiosityFunction::GatherLight``), which a mesh camera leaves at
    the world origin unless given, so its radiosity would follow the distance from
    the origin, not from the lens (a sample per pixel where the scene's own camera
    reuses them).  But a mesh camera also moves each ray's origin by ``location.z``
    along the interpolated vertex normal, in mesh space (reference §2.3).  So each
    vertex is moved back by ``location.z`` times its own normal: the interpolated
    origin then lands where it was, up to the normalisation of the interpolated
    normal (below 1e-7 of ``location.z`` across a face of an eps = 0.01 mesh, and
    along the ray with eps = 1).  The common part, ``location.z`` along the mesh's
    z axis, goes into the matrix's translation, so the float32 vertices stay small.
    Depends only on the mesh and the eye, so a pass is the same bits in any stack.
    """
    lz = float(np.asarray(eye_world, float)[2])
    axis = np.array([0.0, 0.0, 1.0])
    matrix = mesh.matrix.copy()
    matrix[3] = mesh.matrix[3] - lz * (axis @ mesh.matrix[:3])
    return dataclasses.replace(mesh, vertex=mesh.vertex - lz * (mesh.normal - axis),
                               matrix=matrix)


def placement_text(mesh: FieldMesh | PassMesh, name: str = TRANSFORM_NAME) -> str:
    """``#declare NAME = transform { matrix <...> }`` placing the mesh in the world
    (in double precision)."""
    values = ", ".join("%.17g" % v for v in mesh.matrix.ravel())
    return f"#declare {name} = transform {{ matrix <{values}> }}\n"
