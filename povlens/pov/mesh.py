"""POV-Ray ``mesh_camera`` emission: ray meshes and wrapper scenes.

A lens sample is handed to POV-Ray as a ``mesh2`` with exactly one face per
pixel (``mesh_camera`` distribution 0, reference §2).  Face ``k = j*W + i``
(row ``j`` from the top, column ``i`` from the left) produces the primary ray
of pixel (i, j):

* origin = the face centroid (POV-Ray computes it from float32 vertices);
* direction = ``normalize(cross(P3 - P1, P2 - P1))`` -- the *opposite* of the
  usual right-hand-rule normal (§2.4).

Faces are equilateral triangles of circumradius ``s`` built as in §2.5.
Vertices are written relative to a local origin ``T`` and the mesh is moved into
place with ``mesh { NAME translate T }`` inside the camera, which POV-Ray applies
in double precision (§2.6, §4).  They are written as integers on a grid of
q = 2^e scene units, the finest with every ray vertex below 2^:data:`VERTEX_BITS`
steps, and the mesh2 ends in ``scale q``: POV-Ray holds each parsed integer as a
float32 (exact up to 2^24, rounded above, as any float32), applies the power-of-two
scale exactly in double with the translation, and normalises the face normal.
Integers format three times faster than ``%.9g`` and make a smaller file: at
160x120 (paper.pov, cooke.triplet.50mm) a sample's mesh went from 2.72 to 2.03 MB,
writing it from 76-97 to 50 ms and POV-Ray's CPU time per sample from 0.10 to
0.088 s.  Accuracy (the same sample, against the float64 rays): direction error
max 3.0e-8, RMS 1.1e-8 rad, origin error across the ray max 4.7e-8 units; the
float32 ``%.9g`` vertices of before gave 2.3e-8, 5.7e-9 and 3.5e-8, and the
reference's expectation for mesh2 is about 1e-7 (§4).  The sink triangle, far
from ``T``, is written with ``%.9g`` in grid units.

Rays the lens blocks (vignetting) start inside a small black *sink* sphere
far from the scene (§2.8), so they count as black in POV-Ray's
rays-per-pixel mean.

POV-Ray 3.7.0.x repeats the first face row (FS#254); :func:`render_size`
returns the ``W x (H+1)`` size to render and the number of top rows to drop.

All coordinates are POV-Ray world coordinates (left-handed, +y up) in scene
units.  The wrapper templates live in ``templates/`` at the top of the
repository.
"""

from __future__ import annotations

import math
import os
import re
import string
from pathlib import Path
from typing import Sequence

import numpy as np

from povlens.errors import PovlensError, UsageError
from povlens.pov.process import needs_row_workaround, povray_version
from povlens.util.files import write_text

__all__ = [
    "SINK_RADIUS",
    "TEMPLATE_DIR",
    "render_size",
    "default_sink_centre",
    "write_ray_mesh",
    "mesh_camera_block",
    "mesh_wrapper",
    "focal_blur_wrapper",
    "pinhole_wrapper",
]

#: Folder holding ``mesh_wrapper.pov.tmpl`` and ``focal_blur_wrapper.pov.tmpl``.
TEMPLATE_DIR = Path(__file__).resolve().parents[2] / "templates"

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


# ---------------------------------------------------------------------------
# formatting helpers


def _vec(v: Sequence[float]) -> str:
    """A POV-Ray vector literal with full double precision."""
    a = np.asarray(v, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(a)):
        raise PovlensError(f"cannot write the vector {a.tolist()} to POV-Ray: it is not finite")
    return "<%.17g, %.17g, %.17g>" % tuple(a.tolist())


def _pov_string(s: str | os.PathLike) -> str:
    """A POV-Ray string literal (for #include file names)."""
    s = os.fspath(s)
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


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

    origin : (H, W, 3) float64, ray origins in POV-Ray world coordinates
        (scene units); row 0 is the top of the image.
    direction : (H, W, 3) float64, ray directions (any positive length).
    valid : (H, W) bool; False marks a blocked ray: its face is placed in the
        black sink sphere at ``sink_centre`` ((3,), scene units), so the
        pixel's sample is black.
    circumradius : triangle size ``s`` in scene units (0.5..5 keeps float32
        direction errors near 1e-7, reference §4).

    The mesh has exactly ``H*W`` faces in row-major order.  Blocked faces
    share three vertices.  The file is written atomically.

    Returns ``T``, shape (3,): the mesh is written relative to ``T`` and must
    be used as ``mesh { name translate T }`` (see :func:`mesh_camera_block`).

    Raises :class:`PovlensError` for inconsistent shapes, non-finite valid
    rays, or rays that float32 vertices cannot represent (degenerate faces).
    """
    _check_name(name)
    o = np.asarray(origin, dtype=np.float64)
    d = np.asarray(direction, dtype=np.float64)
    ok = np.asarray(valid, dtype=bool)
    if o.ndim != 3 or o.shape[2] != 3 or d.shape != o.shape or ok.shape != o.shape[:2]:
        raise PovlensError(
            f"ray mesh {name}: expected origin and direction of shape (H, W, 3) and valid of "
            f"shape (H, W); got {o.shape}, {d.shape}, {ok.shape}"
        )
    s = float(circumradius)
    if not (s > 0 and math.isfinite(s)):
        raise UsageError(f"ray mesh {name}: circumradius must be > 0, got {circumradius}")
    sink = np.asarray(sink_centre, dtype=np.float64).reshape(3)
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
    idx = np.flatnonzero(ok)
    ov = o[idx]
    dv = d[idx] / norm[idx, None]

    # Local origin: centre of the valid origins' bounding box.
    if len(idx):
        t = 0.5 * (ov.min(axis=0) + ov.max(axis=0))
    else:
        t = sink.copy()

    # Orthonormal a, b with cross(a, b) = d, per face (reference §2.5).
    helper = np.where(np.abs(dv[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    a = np.cross(helper, dv)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = np.cross(dv, a)
    rel = ov - t
    p1 = rel + s * a
    p2 = rel + s * (-0.5 * a - _SQRT3_2 * b)
    p3 = rel + s * (-0.5 * a + _SQRT3_2 * b)

    # The sink face (shared by every blocked pixel); its direction is
    # irrelevant, so it lies across the two smallest coordinates of the sink,
    # where float32 keeps the most precision.
    sr = sink - t
    ia, ib = np.argsort(np.abs(sr))[:2]
    ea, eb = np.eye(3)[ia], np.eye(3)[ib]
    sink_tri = np.array([sr + s * ea, sr + s * (-0.5 * ea - _SQRT3_2 * eb), sr + s * (-0.5 * ea + _SQRT3_2 * eb)])

    # Integer vertices on a grid of q = 2^e scene units (``scale q`` in the mesh2):
    # ray vertices stay below 2^VERTEX_BITS grid steps (see the module docstring).
    ray_verts = np.stack([p1, p2, p3], axis=1).reshape(-1, 3)
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
    # what POV-Ray holds: float32 of each parsed value, times q (exact: a power of two)
    verts = np.concatenate([ray_int.astype(np.float32), sink32]).astype(np.float64) * q

    # Check what POV-Ray will compute from the float32 vertices (§2.3, §2.4).
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
    if len(idx):
        ndir = normal[:-1] / area2[:-1, None]
        err = np.linalg.norm(ndir - dv, axis=1).max()
        if err > 1e-4:
            raise PovlensError(
                f"ray mesh {name}: float32 vertices change ray directions by up to {err:.2g} rad "
                f"(ray origins span {np.ptp(ov, axis=0).max():.3g} units, triangle size {s:g})",
                "use a larger circumradius",
            )

    # Face indices: valid face m -> vertices 3m..3m+2, blocked -> the sink triangle.
    nv = 3 * len(idx)
    faces = np.empty((n, 3), dtype=np.int64)
    faces[:] = np.arange(nv, nv + 3)
    faces[idx] = 3 * np.arange(len(idx))[:, None] + np.arange(3)

    rows = ["<%d,%d,%d>,<%d,%d,%d>,<%d,%d,%d>,\n"] * len(idx)
    vtext = "".join(rows) % tuple(ray_int.reshape(-1).tolist())
    vtext += "<%.9g,%.9g,%.9g>,<%.9g,%.9g,%.9g>,<%.9g,%.9g,%.9g>" % tuple(
        sink32.astype(np.float64).reshape(-1).tolist())
    ftext = ",\n".join(["<%d,%d,%d>"] * n) % tuple(faces.reshape(-1).tolist())
    text = (
        f"// povlens ray mesh: {w} x {h} pixels, {n} faces in row-major order (row 0 = top);\n"
        f"// {n - len(idx)} blocked rays start in the sink sphere at {_vec(sink)}.\n"
        f"// Vertices in steps of {q:.17g} units (scale); use as: mesh {{ {name} translate {_vec(t)} }}\n"
        f"#declare {name} = mesh2 {{\n"
        f"vertex_vectors {{ {nv + 3},\n{vtext}\n}}\n"
        f"face_indices {{ {n},\n{ftext}\n}}\n"
        f"scale {q:.17g}\n"
        f"}}\n"
    )
    write_text(path, text)
    return t


# ---------------------------------------------------------------------------
# camera blocks and wrapper scenes


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
    meshes = "\n".join(f"    mesh {{ {nm} translate {_vec(t)} }}" for nm, t in zip(names, tr))
    return f"camera {{\n  mesh_camera {{\n    {rpp} 0\n{meshes}\n  }}\n}}\n"


def _template(name: str) -> string.Template:
    path = TEMPLATE_DIR / name
    try:
        return string.Template(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise PovlensError(
            f"cannot read the povlens template {path}: {exc.strerror or exc}",
            "reinstall povlens from its source tree (the templates folder is missing)",
        ) from None


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
    :func:`povlens.povray.render` as a library path.  ``assumed_gamma`` (e.g.
    1.0) is set *before* the scene, overriding the scene's own (reference §6);
    ``None`` keeps the scene's.  The sink sphere (centre ``sink_centre``,
    radius ``sink_radius``, scene units) is black, casts no shadow and is not
    reflected.
    """
    camera = mesh_camera_block(mesh_names, translate, rays_per_pixel)
    includes = "\n".join(f"#include {_pov_string(p)}" for p in mesh_includes)
    return _template("mesh_wrapper.pov.tmpl").substitute(
        global_settings=_gamma_block(assumed_gamma),
        scene_include=_pov_string(scene_include),
        sink_centre=_vec(sink_centre),
        sink_radius="%.9g" % float(sink_radius),
        mesh_includes=includes,
        camera=camera,
    )


def _perspective(
    template_vars: dict,
    scene_include,
    location,
    direction,
    right,
    up,
    assumed_gamma,
) -> str:
    return _template("focal_blur_wrapper.pov.tmpl").substitute(
        global_settings=_gamma_block(assumed_gamma),
        scene_include=_pov_string(scene_include),
        location=_vec(location),
        direction=_vec(direction),
        right=_vec(right),
        up=_vec(up),
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
    (reference §7.4); the focal plane is perpendicular to ``direction`` at
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
        f"  focal_point {_vec(fp)}\n"
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
) -> str:
    """Wrapper ``.pov`` text: the scene through a pinhole perspective camera.

    Same vectors as :func:`focal_blur_wrapper`, without focal blur.
    """
    return _perspective({"blur": ""}, scene_include, location, direction, right, up, assumed_gamma)
