"""A field-mesh camera carries the scene camera's location (issue 25): POV-Ray measures
radiosity's reuse distances from the camera's ``location``, which a mesh camera leaves
at the world origin.  A field mesh (distribution 3) is built so that the location moves
no ray; POV-Ray 3.7.0 moves no per-pixel (distribution 0) ray by it."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from povlens.cli import main
from povlens.pov.field_mesh import PassMesh, seen_from
from povlens.util.images import read_image

needs_povray = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")

#: The radiosity room of test_radiosity_cache.py lit by a spot on the floor beside the
#: red wall (its light is mostly indirect), moved far from the world origin: a mesh
#: camera at the origin would reuse its radiosity samples over 200 times the distances
#: the scene's own camera does.
FAR_ROOM = """#version 3.7;
global_settings { assumed_gamma 1 %s }
#declare Far = <600, 0, 400>;
camera { location <0, 1.2, -3.5> + Far look_at <0, 0.8, 0> + Far }
light_source { <1, 3, -2> + Far rgb 1 spotlight point_at <-1.5, 0, 0> + Far radius 15 falloff 25 }
box { <-2, 0, -4>, <2, 3, 2> inverse pigment { rgb 0.8 } translate Far }
box { <-2, 0, -4>, <-1.99, 3, 2> pigment { rgb <0.9, 0.1, 0.1> } translate Far }
sphere { <0.3, 0.5, 0.2>, 0.5 pigment { rgb <0.2, 0.8, 0.3> } translate Far }
"""
RADIOSITY = ("radiosity { pretrace_start 0.08 pretrace_end 0.02 count 60 nearest_count 5 "
             "error_bound 0.8 recursion_limit 1 }")
ARGS = ["--width", "96", "--height", "72", "--lens", "dgauss.50mm", "--samples", "4", "-q"]


def _emulated_origins(mesh: PassMesh, eye_z: float, rng) -> np.ndarray:
    """World ray origins POV-Ray computes on random points of the faces: the
    barycentric point, moved by location.z along the normalised interpolated normal
    (mesh space), then placed by the matrix."""
    b = rng.dirichlet([1, 1, 1], len(mesh.faces))
    tri = mesh.faces
    p = np.einsum("fk,fkd->fd", b, mesh.vertex[tri])
    n = np.einsum("fk,fkd->fd", b, mesh.normal[tri])
    p = p + eye_z * n / np.linalg.norm(n, axis=1, keepdims=True)
    return p @ mesh.matrix[:3] + mesh.matrix[3]


@pytest.mark.parametrize("eps", [0.01, 1.0])
def test_the_eye_moves_no_ray_origin_off_its_ray(eps):
    rng = np.random.default_rng(3)
    gx, gy = 6, 4
    u, v = np.meshgrid(np.linspace(0, 1, gx + 1), np.linspace(0, 1, gy + 1))
    uv = np.stack([u.ravel(), v.ravel()], 1)
    idx = np.arange(len(uv)).reshape(gy + 1, gx + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([b, d, c], 1)])
    S = np.array([eps, eps, 1.0])
    direction = np.stack([0.6 * (uv[:, 0] - 0.5), 0.45 * (uv[:, 1] - 0.5), np.ones(len(uv))], 1)
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    normal = direction * S
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    vertex = np.stack([uv[:, 0] * 0.02, uv[:, 1] * 0.015, np.zeros(len(uv))], 1) / S
    R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    mesh = PassMesh(vertex, normal, uv, faces, np.vstack([S[:, None] * R, [5.0, -2.0, 40.0]]))
    eye = np.array([3.0, 1.0, -37.0])
    moved = seen_from(mesh, eye)
    want = _emulated_origins(mesh, 0.0, np.random.default_rng(9))
    got = _emulated_origins(moved, eye[2], np.random.default_rng(9))
    # what is left lies along the world ray (MTransNormal: the inverse transpose)
    n = np.einsum("fk,fkd->fd", np.random.default_rng(9).dirichlet([1, 1, 1], len(faces)),
                  normal[faces])
    world_dir = n @ np.linalg.inv(mesh.matrix[:3]).T
    world_dir /= np.linalg.norm(world_dir, axis=1, keepdims=True)
    off = got - want
    across = off - np.sum(off * world_dir, axis=1, keepdims=True) * world_dir
    # eps = 0.01: the interpolated normal's normalisation, below 1e-7 of location.z
    # (faces spanning 0.1 rad here); eps = 1: the matrix is a rotation, all along the ray
    assert np.abs(across).max() < (1e-7 if eps < 1 else 1e-12) * abs(eye[2])
    assert np.abs(off).max() < (1e-6 if eps < 1 else 1e-2) * abs(eye[2])
    # the common part went into the matrix: vertices move by location.z (n - z) only
    spread = np.abs(normal - [0, 0, 1]).max()
    assert np.abs(moved.vertex).max() <= np.abs(vertex).max() + abs(eye[2]) * spread + 1e-12


def _render(tmp_path, name, settings, method="mesh", extra=()):
    scene = tmp_path / "far.pov"
    scene.write_text(FAR_ROOM % settings)
    out = tmp_path / name
    assert main(["render", str(scene), *ARGS, "--method", method, *extra, "-o", str(out)]) == 0
    return read_image(out / "image.exr")[..., :3].astype(float)


def _at_the_origin(monkeypatch):
    """The mesh cameras as they were: at the origin, the field mesh as traced."""
    import povlens.rendering.field_samples as fs
    import povlens.rendering.mesh_samples as ms
    monkeypatch.setattr(fs, "seen_from", lambda mesh, eye: mesh)
    monkeypatch.setattr(fs, "eye_text", lambda eye: "#declare PovlensEye = <0, 0, 0>;\n")
    monkeypatch.setattr(ms, "pixel_mesh_eye", lambda plan: (0.0, 0.0, 0.0))


@needs_povray
@pytest.mark.parametrize("ray_mesh", ["field", "pixel"])
def test_without_radiosity_the_eye_changes_no_pixel(tmp_path, monkeypatch, ray_mesh):
    extra = ["--ray-mesh", ray_mesh]
    with_eye = _render(tmp_path, "eye", "", extra=extra)
    _at_the_origin(monkeypatch)
    at_origin = _render(tmp_path, "origin", "", extra=extra)
    assert with_eye.max() > 0.05
    if ray_mesh == "pixel":             # the same bits: POV-Ray 3.7.0 moves no ray
        assert np.array_equal(with_eye, at_origin)
    assert np.abs(with_eye - at_origin).max() < 2e-3
    assert np.abs(with_eye - at_origin).mean() < 1e-5


@needs_povray
@pytest.mark.parametrize("ray_mesh", ["field", "pixel"])
def test_radiosity_is_reused_as_the_scene_camera_reuses_it(tmp_path, monkeypatch, ray_mesh):
    """focal_blur's camera sits at the scene's location: the mesh render now takes the
    radiosity its author set up, where the mesh camera at the origin reused samples
    across the room (field meshes, two runs: mean 1.7-2.0 % off focal_blur's against
    8-11 %, RMSE 0.0041 against 0.0086-0.0093; per-pixel meshes, three runs: 0.2-0.3 %
    against 1.4-2.9 %; POV-Ray's threads make radiosity vary a little from run to run).
    Every lens sample computes its own radiosity (a radiosity file named in the POV-Ray
    options): samples shared from the pinhole view, which the first samples choose when
    it pays (timing), were computed from the scene's eye and would hide where the mesh
    camera sits (a CI run: 0.009 % off focal_blur's mean at the origin)."""
    extra = ["--ray-mesh", ray_mesh, "--povray-option", "Radiosity_File_Name=own.rca"]
    fb = _render(tmp_path, "fb", RADIOSITY, method="focal-blur")
    with_eye = _render(tmp_path, "eye", RADIOSITY, extra=extra)
    _at_the_origin(monkeypatch)
    at_origin = _render(tmp_path, "origin", RADIOSITY, extra=extra)
    e_eye = abs(with_eye.mean() - fb.mean()) / fb.mean()
    e_origin = abs(at_origin.mean() - fb.mean()) / fb.mean()
    assert e_eye < 0.04
    # field passes, their pretrace spaced as the frame's (pov.mesh.pretrace_block), six
    # runs: means 0.15-0.79 % off against 0.27-3.1 %, one of them the wrong way round
    # (focal_blur's own radiosity varies as much), RMSE 0.0027 against 0.0075-0.0080
    if ray_mesh == "pixel":
        assert e_origin > 2 * e_eye
    rmse_eye = np.sqrt(((with_eye - fb) ** 2).mean())
    # per-pixel meshes, three runs: RMSE 0.0044 against 0.0053-0.0072
    assert rmse_eye < (0.5 if ray_mesh == "field" else 1.0) * np.sqrt(((at_origin - fb) ** 2).mean())
