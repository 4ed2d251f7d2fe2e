"""POV-Ray ``mesh_camera`` emission: ray meshes and wrapper scenes.

A lens sample is handed to POV-Ray as a ``mesh2`` with exactly one face per
pixel (``mesh_camera`` distribution 0).  Face ``k = j*W + i`` (row ``j`` from the
top, column ``i`` from the left) produces the primary ray of pixel (i, j)
(POV-Ray 3.7.0.10 source, ``CreateCameraRay`` in ``source/backend/render/tracepixel.cpp``):

* origin = the face centroid (POV-Ray computes it from float32 vertices);
* direction = ``normalize(cross(P3 - P1, P2 - P1))`` -- the *opposite* of the
  usual right-hand-rule normal.

Faces are equilateral triangles of circumradius ``s`` whose centroid is the ray's
origin and whose normal is its direction (:func:`_face_vertices`).  Vertices are
written relative to a local origin ``T`` and the mesh is moved into place with
``mesh { NAME translate T }`` inside the camera, which POV-Ray applies in double
precision.  They are written as integers on a grid of q = 2^e scene units, the
finest with every ray vertex below 2^:data:`VERTEX_BITS` steps, and the mesh2 ends
in ``scale q``: POV-Ray holds each parsed integer as a float32 (exact up to 2^24),
applies the power-of-two scale exactly, and normalises the face normal.  Integers
are faster to write and smaller than ``%.9g`` floats at the same accuracy (direction
error about 3e-8 rad; numbers in docs/decisions/pov.md).  The sink triangle, far
from ``T``, is written with ``%.9g`` in grid units.

Rays the lens blocks (vignetting) start inside a small black *sink* sphere
far from the scene, so they count as black in POV-Ray's rays-per-pixel mean.

POV-Ray 3.7.0.x repeats the first face row (FS#254); :func:`render_size`
returns the ``W x (H+1)`` size to render and the number of top rows to drop.

All coordinates are POV-Ray world coordinates (left-handed, +y up) in scene
units.  The wrapper templates live in ``templates/`` at the top of the
repository.  They keep the scene's ``#version``: none before the scene, and 3.7
only around povlens's own statements of a scene that ended below 3.7, restored
after them, since POV-Ray takes gamma handling, ambient under radiosity and the
noise generator from the version at the end of parsing (the templates' comments;
docs/decisions/pov.md).
"""

from __future__ import annotations

import math
import os
import re
from typing import Sequence

import numpy as np

from povlens.errors import PovlensError, UsageError
from povlens.pov.executable import needs_row_workaround, povray_version
from povlens.pov.sdl import TEMPLATE_DIR, pov_string, pov_vector, read_template
from povlens.util.files import write_text

__all__ = [
    "SINK_RADIUS",
    "TEMPLATE_DIR",
    "render_size",
    "default_sink_centre",
    "write_ray_mesh",
    "mesh_camera_block",
    "EYE_NAME",
    "eye_text",
    "mesh_wrapper",
    "focal_blur_wrapper",
    "pinhole_wrapper",
    "photon_map_block",
    "pretrace_block",
    "RADIOSITY_READ_FLAG",
]

#: Radius of the black sink sphere (scene units).  Generous compared with the
#: float32 rounding of a face centroid 1e5 units from the local origin (~8e-3).
SINK_RADIUS = 1.0

#: Default distance of the sink behind the camera (scene units).
SINK_DISTANCE = 1.0e5

#: Ray-mesh vertices are integers on a grid of q = 2^e scene units: the finest
#: grid on which every ray vertex is below 2^VERTEX_BITS steps (module docstring).
VERTEX_BITS = 26

_IDENT = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
_SQRT3_2 = math.sqrt(3.0) / 2.0


# ---------------------------------------------------------------------------
# sizes


def render_size(width: int, height: int, version: str | None = None) -> tuple[int, int, int]:
    """Size to pass to POV-Ray for a ``width`` x ``height`` mesh-camera image.

    Returns ``(render_width, render_height, drop_top_rows)``.  On POV-Ray
    3.7.0.x (``needs_row_workaround``) that is ``(W, H + 1, 1)``: render one
    extra row and drop output row 0 (you may also skip tracing it with
    ``start_row=1``).  Otherwise ``(W, H, 0)``.  ``version`` defaults to the
    installed POV-Ray's.
    """
    if version is None:
        version = povray_version()
    if needs_row_workaround(version):
        return int(width), int(height) + 1, 1
    return int(width), int(height), 0


def default_sink_centre(location: Sequence[float], forward: Sequence[float]) -> np.ndarray:
    """A sink centre ``SINK_DISTANCE`` units behind a camera (shape (3,))."""
    f = np.asarray(forward, dtype=np.float64)
    return np.asarray(location, dtype=np.float64) - SINK_DISTANCE * f / np.linalg.norm(f)


def _check_name(name: str) -> None:
    if not _IDENT.match(name):
        raise UsageError(
            f"bad POV-Ray identifier {name!r} for a mesh",
            "use letters, digits and '_', starting with a letter",
        )


# ---------------------------------------------------------------------------
# the ray mesh


def write_ray_mesh(
    path: str | os.PathLike,
    name: str,
    origin: np.ndarray,
    direction: np.ndarray,
    valid: np.ndarray,
    *,
    sink_centre: Sequence[float],
    circumradius: float = 1.0,
) -> np.ndarray:
    """Write ``#declare name = mesh2 {...}`` encoding one primary ray per pixel.

    Parameters
    ----------
    path : the ``.inc`` file to write (atomically).
    name : the POV-Ray identifier to declare.
    origin : (H, W, 3) float64, ray origins in POV-Ray world coordinates
        (scene units); row 0 is the top of the image.
    direction : (H, W, 3) float64, ray directions (any positive length).
    valid : (H, W) bool; False marks a blocked ray: its face is placed in the
        black sink sphere at ``sink_centre`` ((3,), scene units), so the
        pixel's sample is black.
    circumradius : triangle size ``s`` in scene units (0.5..5 keeps float32
        direction errors near 1e-7).

    Returns
    -------
    np.ndarray
        ``T``, shape (3,), scene units: the mesh is written relative to ``T`` and must
        be used as ``mesh { name translate T }`` (see :func:`mesh_camera_block`).

    Raises
    ------
    PovlensError
        For inconsistent shapes, non-finite valid rays, or rays that float32
        vertices cannot represent (degenerate faces).

    Notes
    -----
    The mesh has exactly ``H*W`` faces in row-major order.  Blocked faces share three
    vertices.
    """
    _check_name(name)
    o, d, ok = _ray_arrays(name, origin, direction, valid)
    s = float(circumradius)
    if not (s > 0 and math.isfinite(s)):
        raise UsageError(f"ray mesh {name}: circumradius must be > 0, got {circumradius}")
    sink = np.asarray(sink_centre, dtype=np.float64).reshape(3)
    h, w = ok.shape
    o, d, ok, norm = _flat_rays(name, o, d, ok)
    idx = np.flatnonzero(ok)
    ov = o[idx]
    dv = d[idx] / norm[idx, None]
    t = _local_origin(ov, sink)
    ray_verts = _face_vertices(ov - t, dv, s)
    sink_tri = _sink_triangle(sink - t, s)
    q, ray_int, sink32 = _vertex_grid(name, ray_verts, sink_tri, s)
    _check_float32_faces(name, ray_int, sink32, q, dv, ov, s)
    faces = _face_indices(len(ok), idx)
    write_text(path, _mesh2_text(name, w, h, ray_int, sink32, faces, q, sink, t))
    return t


def _ray_arrays(name: str, origin, direction, valid):
    """``origin``, ``direction`` (H, W, 3) float64 and ``valid`` (H, W) bool, or
    :class:`PovlensError` for inconsistent shapes."""
    o = np.asarray(origin, dtype=np.float64)
    d = np.asarray(direction, dtype=np.float64)
    ok = np.asarray(valid, dtype=bool)
    if o.ndim != 3 or o.shape[2] != 3 or d.shape != o.shape or ok.shape != o.shape[:2]:
        raise PovlensError(
            f"ray mesh {name}: expected origin and direction of shape (H, W, 3) and valid of "
            f"shape (H, W); got {o.shape}, {d.shape}, {ok.shape}"
        )
    return o, d, ok


def _flat_rays(name: str, o: np.ndarray, d: np.ndarray, ok: np.ndarray):
    """The rays in row-major pixel order: origins (n, 3), directions (n, 3), valid (n,)
    and direction lengths (n,); :class:`PovlensError` for no pixels or a valid ray
    that is not finite."""
    h, w = ok.shape
    n = h * w
    if n == 0:
        raise PovlensError(f"ray mesh {name}: the image has no pixels")
    o = o.reshape(n, 3)
    d = d.reshape(n, 3)
    ok = ok.reshape(n)
    norm = np.linalg.norm(d, axis=1)
    bad = ok & ~(np.isfinite(o).all(axis=1) & np.isfinite(norm) & (norm > 0))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise PovlensError(
            f"ray mesh {name}: {int(bad.sum())} valid ray(s) have a non-finite origin or a "
            f"zero/non-finite direction (first at row {k // w}, column {k % w})"
        )
    return o, d, ok, norm


def _local_origin(ov: np.ndarray, sink: np.ndarray) -> np.ndarray:
    """The mesh's local origin ``T`` (3,): the centre of the valid origins' bounding
    box (the sink centre if every ray is blocked)."""
    if len(ov):
        return 0.5 * (ov.min(axis=0) + ov.max(axis=0))
    return sink.copy()


def _face_vertices(rel: np.ndarray, dv: np.ndarray, s: float) -> np.ndarray:
    """Vertices (3m, 3) of the faces whose centroids are ``rel`` (m, 3) and whose
    POV-Ray normals ``cross(P3 - P1, P2 - P1)`` point along the unit ``dv`` (m, 3):
    ``P1 = o + s a``, ``P2,3 = o + s(-a/2 -+ (sqrt(3)/2) b)`` with orthonormal a, b,
    ``cross(a, b) = d``."""
    helper = np.where(np.abs(dv[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    a = np.cross(helper, dv)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = np.cross(dv, a)
    p1 = rel + s * a
    p2 = rel + s * (-0.5 * a - _SQRT3_2 * b)
    p3 = rel + s * (-0.5 * a + _SQRT3_2 * b)
    return np.stack([p1, p2, p3], axis=1).reshape(-1, 3)


def _sink_triangle(sr: np.ndarray, s: float) -> np.ndarray:
    """The face (3, 3) every blocked pixel shares, centred on the sink ``sr`` (relative
    to ``T``).  Its direction is irrelevant, so it lies across the two smallest
    coordinates of the sink, where float32 keeps the most precision."""
    ia, ib = np.argsort(np.abs(sr))[:2]
    ea, eb = np.eye(3)[ia], np.eye(3)[ib]
    return np.array([sr + s * ea, sr + s * (-0.5 * ea - _SQRT3_2 * eb),
                     sr + s * (-0.5 * ea + _SQRT3_2 * eb)])


def _vertex_grid(name: str, ray_verts: np.ndarray, sink_tri: np.ndarray, s: float):
    """The grid step ``q`` (scene units, a power of two), the ray vertices as integer
    grid steps (3m, 3) and the sink triangle in grid units as float32 (3, 3)."""
    span = max(float(np.abs(ray_verts).max()) if len(ray_verts) else 0.0, s)
    q = math.ldexp(1.0, math.ceil(math.log2(span)) - VERTEX_BITS)
    ray_int = np.rint(ray_verts / q).astype(np.int64)
    sink_grid = sink_tri / q
    with np.errstate(over="ignore"):
        sink32 = sink_grid.astype(np.float32)
    if not np.all(np.isfinite(sink32)):
        raise PovlensError(
            f"ray mesh {name}: ray origins or the sink centre are too far from each other "
            "for POV-Ray's float32 mesh vertices",
            "keep the sink centre within about 1e6 scene units of the camera",
        )
    return q, ray_int, sink32


def _check_float32_faces(name: str, ray_int: np.ndarray, sink32: np.ndarray, q: float,
                         dv: np.ndarray, ov: np.ndarray, s: float) -> None:
    """Check what POV-Ray will compute from the float32 vertices: no degenerate face,
    ray directions within 1e-4 rad of ``dv``."""
    # what POV-Ray holds: float32 of each parsed value, times q (exact: a power of two)
    verts = np.concatenate([ray_int.astype(np.float32), sink32]).astype(np.float64) * q
    tri = verts.reshape(-1, 3, 3)
    normal = np.cross(tri[:, 2] - tri[:, 0], tri[:, 1] - tri[:, 0])
    area2 = np.linalg.norm(normal, axis=1)
    expected = 1.5 * math.sqrt(3.0) * s * s
    if np.any(area2 < 0.5 * expected):
        raise PovlensError(
            f"ray mesh {name}: some faces are degenerate in float32 "
            f"(ray origins span up to {np.abs(verts).max():.3g} units from the local origin "
            f"with triangles of size {s:g})",
            "use a larger circumradius or move the sink centre closer to the camera",
        )
    if len(dv):
        ndir = normal[:-1] / area2[:-1, None]
        err = np.linalg.norm(ndir - dv, axis=1).max()
        if err > 1e-4:
            raise PovlensError(
                f"ray mesh {name}: float32 vertices change ray directions by up to {err:.2g} rad "
                f"(ray origins span {np.ptp(ov, axis=0).max():.3g} units, triangle size {s:g})",
                "use a larger circumradius",
            )


def _face_indices(n: int, idx: np.ndarray) -> np.ndarray:
    """Vertex indices (n, 3) of the n faces: valid face m -> vertices 3m..3m+2,
    blocked faces -> the sink triangle written after them."""
    nv = 3 * len(idx)
    faces = np.empty((n, 3), dtype=np.int64)
    faces[:] = np.arange(nv, nv + 3)
    faces[idx] = 3 * np.arange(len(idx))[:, None] + np.arange(3)
    return faces


def _mesh2_text(name: str, w: int, h: int, ray_int: np.ndarray, sink32: np.ndarray,
                faces: np.ndarray, q: float, sink: np.ndarray, t: np.ndarray) -> str:
    """The ``#declare name = mesh2 {...}`` text: integer ray vertices, the sink
    triangle, the faces, ``scale q``."""
    n_valid = len(ray_int) // 3
    n = len(faces)
    rows = ["<%d,%d,%d>,<%d,%d,%d>,<%d,%d,%d>,\n"] * n_valid
    vtext = "".join(rows) % tuple(ray_int.reshape(-1).tolist())
    vtext += "<%.9g,%.9g,%.9g>,<%.9g,%.9g,%.9g>,<%.9g,%.9g,%.9g>" % tuple(
        sink32.astype(np.float64).reshape(-1).tolist())
    ftext = ",\n".join(["<%d,%d,%d>"] * n) % tuple(faces.reshape(-1).tolist())
    return (
        f"// povlens ray mesh: {w} x {h} pixels, {n} faces in row-major order (row 0 = top);\n"
        f"// {n - n_valid} blocked rays start in the sink sphere at {pov_vector(sink)}.\n"
        f"// Vertices in steps of {q:.17g} units (scale); use as: mesh {{ {name} translate {pov_vector(t)} }}\n"
        f"#declare {name} = mesh2 {{\n"
        f"vertex_vectors {{ {3 * n_valid + 3},\n{vtext}\n}}\n"
        f"face_indices {{ {n},\n{ftext}\n}}\n"
        f"scale {q:.17g}\n"
        f"}}\n"
    )


# ---------------------------------------------------------------------------
# camera blocks and wrapper scenes


#: The identifier of a lens sample's mesh-camera ``location`` in its ``.inc``.
EYE_NAME = "PovlensEye"


def eye_text(eye_world, name: str = EYE_NAME) -> str:
    """``#declare NAME = <x, y, z>;``: a mesh camera's ``location``, the scene camera's,
    from which POV-Ray measures radiosity's reuse distances (the batch templates;
    :func:`povlens.pov.field_mesh.seen_from` for what it does to field meshes)."""
    x, y, z = (float(v) for v in eye_world)
    return f"#declare {name} = <{x:.17g}, {y:.17g}, {z:.17g}>;\n"


def mesh_camera_block(
    mesh_names: Sequence[str],
    translate: Sequence[float] | Sequence[Sequence[float]],
    rays_per_pixel: int,
) -> str:
    """The ``camera { mesh_camera { RPP 0 mesh {NAME translate T} ... } }`` text.

    ``translate`` is one (3,) vector for all meshes or one per mesh, shape
    (len(mesh_names), 3) -- the values returned by :func:`write_ray_mesh`.
    POV-Ray averages ``rays_per_pixel`` rays per pixel, ray r from mesh r
    (distribution 0), in its working colour space: use ``assumed_gamma 1.0``
    for a linear mean.
    """
    names = list(mesh_names)
    if not names:
        raise UsageError("mesh_camera needs at least one mesh")
    for nm in names:
        _check_name(nm)
    rpp = int(rays_per_pixel)
    if not 1 <= rpp <= len(names):
        raise UsageError(
            f"rays_per_pixel = {rays_per_pixel} with {len(names)} mesh(es)",
            "POV-Ray's distribution 0 needs 1 <= rays per pixel <= number of meshes",
        )
    tr = np.asarray(translate, dtype=np.float64)
    if tr.shape == (3,):
        tr = np.broadcast_to(tr, (len(names), 3))
    if tr.shape != (len(names), 3):
        raise UsageError(f"translate must have shape (3,) or ({len(names)}, 3), got {tr.shape}")
    meshes = "\n".join(f"    mesh {{ {nm} translate {pov_vector(t)} }}" for nm, t in zip(names, tr))
    return f"camera {{\n  mesh_camera {{\n    {rpp} 0\n{meshes}\n  }}\n}}\n"


def _gamma_block(assumed_gamma: float | None) -> str:
    if assumed_gamma is None:
        return "// (the scene's own assumed_gamma is kept)"
    return f"global_settings {{ assumed_gamma {float(assumed_gamma):.9g} }}"


def mesh_wrapper(
    scene_include: str | os.PathLike,
    mesh_includes: Sequence[str | os.PathLike],
    mesh_names: Sequence[str],
    translate: Sequence[float] | Sequence[Sequence[float]],
    rays_per_pixel: int,
    *,
    sink_centre: Sequence[float],
    sink_radius: float = SINK_RADIUS,
    assumed_gamma: float | None = None,
) -> str:
    """Text of a wrapper ``.pov`` rendering the scene through ray meshes.

    ``scene_include`` and ``mesh_includes`` are file names as POV-Ray should
    see them from its working directory (the wrapper's folder): keep them
    relative where possible and pass the scene's folder to
    :func:`povlens.pov.process.render` as a library path.  ``assumed_gamma`` (e.g.
    1.0) is set *before* the scene, overriding the scene's own (POV-Ray keeps the
    first ``assumed_gamma`` it reads; docs/decisions/pov.md);
    ``None`` keeps the scene's.  The sink sphere (centre ``sink_centre``,
    radius ``sink_radius``, scene units) is black, casts no shadow and is not
    reflected.  The scene keeps its own ``#version`` (module docstring).
    """
    camera = mesh_camera_block(mesh_names, translate, rays_per_pixel)
    includes = "\n".join(f"#include {pov_string(p)}" for p in mesh_includes)
    return read_template("mesh_wrapper.pov.tmpl").substitute(
        global_settings=_gamma_block(assumed_gamma),
        scene_include=pov_string(scene_include),
        sink_centre=pov_vector(sink_centre),
        sink_radius="%.9g" % float(sink_radius),
        mesh_includes=includes,
        camera=camera,
    )


#: Declared (``Declare=NAME=1``) for a field pass's run that reads radiosity samples
#: (``+RFI``): it keeps the scene's pretrace (:func:`pretrace_block`).
RADIOSITY_READ_FLAG = "PovlensRadiosityRead"


def pretrace_block(pretrace: tuple[float, float] | None, frame_size: tuple[int, int],
                   stride: int) -> str:
    """SDL that repeats a scene's radiosity pretrace scaled to the size a field pass's run
    renders ("" when ``pretrace`` is None), unless the run reads radiosity samples.

    POV-Ray 3.7 spaces the pretrace by the larger side of the image it renders
    (``pretrace_start`` x max(+W, +H) pixels, down to ``pretrace_end``'s, at least 1), and
    a field pass's run renders m x m tiles of 1/m the frame's scale side by side (and
    stacks of passes under one another: :func:`povlens.pov.field_mesh.pass_size`).
    Unscaled, its pretrace is m x max(W', H') / max(W, H) times coarser on the scene than
    the frame's (16 times for m = 4): a run computing its own radiosity then fills the
    cache in the final trace tile by tile, the first tile before the rest have samples
    to share -- a dot lattice of period m on ``raddem.pov`` stopped down
    (docs/decisions/planning.md, "A pattern in runs of their own").  Scaled by
    max(W, H) / (m max(+W, +H)), read from ``image_width`` and ``image_height`` as the
    run is parsed, every tile's pretrace is the author's on the scene.  That traces m^2
    times the frame's pretrace pixels, so a run that reads radiosity samples made
    before it (declaring :data:`RADIOSITY_READ_FLAG`; they are complete) keeps the
    scene's own, as does a run the frame's size (+1, POV-Ray's extra row and column).
    A later ``radiosity`` block changes only the items it sets (measured: ``count`` kept).

    Parameters
    ----------
    pretrace : the scene's (pretrace_start, pretrace_end), fractions.
    frame_size : (W, H) of the film, pixels.
    stride : m, the pass's interleave.
    """
    if pretrace is None:
        return ""
    start, end = (float(v) for v in pretrace)
    side, m = max(int(frame_size[0]), int(frame_size[1])), int(stride)
    return (f"#declare PovlensPretraceScale = {side} / ({m} * max(image_width, image_height));\n"
            f"#if ({m} * max(image_width, image_height) > {side + 1})\n"
            f"  #ifndef ({RADIOSITY_READ_FLAG})\n"
            f"    global_settings {{ radiosity {{ pretrace_start {start!r} * PovlensPretraceScale\n"
            f"                                   pretrace_end {end!r} * PovlensPretraceScale }} }}\n"
            f"  #end\n"
            f"#end")


def photon_map_block(settings: str, action: str, file_expr: str, flag: str) -> str:
    """SDL that repeats a scene's photons settings with ``save_file`` or ``load_file``
    when ``flag`` is declared (POV-Ray's ``Declare=FLAG=...``; "" when ``settings`` is
    empty).

    A second ``global_settings { photons { ... } }`` after the scene replaces the
    scene's photons settings whole (measured on POV-Ray 3.7.0.10: ``glassthing.pov``
    shot 95 photons instead of 29,127 with a bare ``save_file``), so the scene's own
    items are repeated before the file name; the map then loads into an image
    identical to the scene's own (RMSE 0).

    Parameters
    ----------
    settings : the photons block's items (``SceneCamera.photon_settings``).
    action : ``"save_file"`` or ``"load_file"``.
    file_expr : an SDL string expression naming the file.
    flag : the name that switches the block on.
    """
    if not settings:
        return ""
    if action not in ("save_file", "load_file"):
        raise ValueError(f"action {action!r}: save_file or load_file")
    _check_name(flag)
    return (f"#ifdef ({flag}) global_settings {{ photons {{ {settings} {action} {file_expr} }} }}"
            f" #end")


def _perspective(
    template_vars: dict,
    scene_include,
    location,
    direction,
    right,
    up,
    assumed_gamma,
    photons: str = "",
) -> str:
    return read_template("focal_blur_wrapper.pov.tmpl").substitute(
        photons=photons,
        global_settings=_gamma_block(assumed_gamma),
        scene_include=pov_string(scene_include),
        location=pov_vector(location),
        direction=pov_vector(direction),
        right=pov_vector(right),
        up=pov_vector(up),
        **template_vars,
    )


def focal_blur_wrapper(
    scene_include: str | os.PathLike,
    location: Sequence[float],
    direction: Sequence[float],
    right: Sequence[float],
    up: Sequence[float],
    *,
    aperture: float,
    focal_distance: float,
    blur_samples: int,
    max_blur_samples: int | None = None,
    confidence: float | None = None,
    variance: float | None = None,
    assumed_gamma: float | None = None,
) -> str:
    """Wrapper ``.pov`` text: the scene through POV-Ray's own thin-lens blur.

    ``location`` (3,), ``direction``/``right``/``up`` (3,) are world vectors
    (scene units) used verbatim: pixel (i, j) looks along ``D + x0 R + y0 U``.
    ``aperture`` is POV-Ray's value, i.e. **twice** the lens diameter
    (``TraceRayWithFocalBlur`` in POV-Ray 3.7's ``tracepixel.cpp`` offsets rays by
    ``aperture/2`` times a point of a disc of radius 0.5); the focal plane is perpendicular to ``direction`` at
    ``focal_distance``; ``blur_samples N, N`` fixes N samples per pixel.
    With ``max_blur_samples`` M > N, POV-Ray samples adaptively: at least N,
    then more until its ``confidence`` / ``variance`` test passes or M are shot
    (POV-Ray 3.7 documentation, "Focal Blur"; both default to POV-Ray's own).
    """
    aperture = float(aperture)
    fdist = float(focal_distance)
    n = int(blur_samples)
    m = n if max_blur_samples is None else int(max_blur_samples)
    if not (aperture > 0 and fdist > 0 and 1 <= n <= m):
        raise UsageError(
            f"focal blur needs aperture > 0, focal distance > 0 and 1 <= blur samples <= "
            f"max blur samples; got {aperture}, {fdist}, {blur_samples}, {max_blur_samples}"
        )
    if confidence is not None and not 0 < confidence < 1:
        raise UsageError(f"focal blur confidence must be in (0, 1), got {confidence}")
    if variance is not None and not variance > 0:
        raise UsageError(f"focal blur variance must be > 0, got {variance}")
    d = np.asarray(direction, dtype=np.float64)
    fp = np.asarray(location, dtype=np.float64) + fdist * d / np.linalg.norm(d)
    blur = (
        f"  aperture {aperture:.17g}\n"
        f"  focal_point {pov_vector(fp)}\n"
        f"  blur_samples {n}, {m}\n"
        + (f"  confidence {float(confidence):.9g}\n" if confidence is not None else "")
        + (f"  variance {float(variance):.9g}\n" if variance is not None else "")
    )
    return _perspective({"blur": blur}, scene_include, location, direction, right, up, assumed_gamma)


def pinhole_wrapper(
    scene_include: str | os.PathLike,
    location: Sequence[float],
    direction: Sequence[float],
    right: Sequence[float],
    up: Sequence[float],
    *,
    assumed_gamma: float | None = None,
    photons: str = "",
) -> str:
    """Wrapper ``.pov`` text: the scene through a pinhole perspective camera.

    Same vectors as :func:`focal_blur_wrapper`, without focal blur.  The scene keeps
    its own ``#version`` (module docstring); text appended to the wrapper is read
    under the scene's version.  ``photons``: SDL placed right after the scene
    (:func:`photon_map_block`).
    """
    return _perspective({"blur": ""}, scene_include, location, direction, right, up,
                        assumed_gamma, photons)
