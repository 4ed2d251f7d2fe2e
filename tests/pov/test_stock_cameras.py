"""Cameras of POV-Ray's own sample scenes (Debian package ``povray-examples``), one or
more scenes for each group of issue 13: every camera type, a ``mesh_camera`` (refused),
a camera in a library include file (``stdcam.inc``, ``screen.inc``), vector forms, a
camera inside ``#switch``, ``#if`` inside the camera, a camera made by a macro, a
declared transform, a scene without a camera.  A few are rendered with POV-Ray's own
camera and with the camera read, which must give the same image.

Skipped where ``povray-examples`` is not installed (``apt-get install povray-examples``).
"""

from __future__ import annotations

import math
import shutil
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from povlens.pov import process as povray
from povlens.pov.sdl import (DEFAULT_CAMERA_NOTE, SceneCameraError, parse_scene_camera,
                             pov_string, pov_vector)
from povlens.util.files import write_text
from povlens.util.images import read_image

EXAMPLES = Path("/usr/share/doc/povray/examples")
pytestmark = pytest.mark.skipif(not (EXAMPLES / "camera" / "fisheye.pov").is_file(),
                                reason="POV-Ray's sample scenes are not installed "
                                       "(apt-get install povray-examples)")
HAVE_POVRAY = shutil.which("povray") is not None
W, H = 48, 36


def _cam(rel: str, **kw):
    return parse_scene_camera(EXAMPLES / rel, W, H, **kw)


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


@pytest.mark.parametrize("rel, projection, location, look_at", [
    ("camera/fisheye.pov", "fisheye", [1, 4, 3], [0, 1, 2]),
    ("camera/orthographic.pov", "orthographic", None, None),
    ("camera/cylinder1.pov", "cylinder 1", None, None),
    ("camera/cylinder4.pov", "cylinder 4", None, None),
    ("camera/ultra_wide_angle.pov", "ultra_wide_angle", None, None),
    ("camera/omnimax.pov", "omnimax", None, None),
    ("camera/panoramic.pov", "panoramic", None, None),
    ("camera/spherical.pov", "spherical", None, None),
])
def test_every_camera_type_gives_its_pose(rel, projection, location, look_at):
    """povlens replaces the projection: it takes the pose and says so."""
    cam = _cam(rel)
    assert cam.projection == projection
    assert cam.hfov_deg is None
    assert any(f"camera type {projection}" in n and "replaces its projection" in n
               for n in cam.replaced)
    np.testing.assert_allclose(np.cross(cam.up, cam.forward), cam.right, atol=1e-12)
    if location is not None:
        np.testing.assert_allclose(cam.location, location)
        np.testing.assert_allclose(cam.forward, _unit(np.subtract(look_at, location)), atol=1e-12)


@pytest.mark.parametrize("rel", ["camera/mesh_camera/meshcam_persp_demo.pov",
                                 "camera/mesh_camera/meshcam_ortho_demo.pov"])
def test_mesh_camera_scenes_are_refused(rel):
    with pytest.raises(SceneCameraError, match="mesh_camera") as info:
        _cam(rel)
    assert "'location'" in info.value.hint


def test_camera_in_stdcam_inc():
    """animations/ambient/ambient.pov has its camera in POV-Ray's stdcam.inc."""
    cam = _cam("animations/ambient/ambient.pov")
    assert cam.source.endswith("stdcam.inc:6")
    np.testing.assert_allclose(cam.location, [-2, 1.75, -5])
    np.testing.assert_allclose(cam.forward, _unit([1.25, -2.25, 5]), atol=1e-12)
    assert cam.hfov_deg == pytest.approx(70)
    assert cam.replaced == []


def test_camera_made_by_screen_inc_macros():
    """incdemo/screen.pov sets its camera with Set_Camera(<25,15,-33>, <2,2,0>, 70) and
    Set_Camera_Sky(<0,1,0.3>), macros of screen.inc that declare a transform and a camera."""
    cam = _cam("incdemo/screen.pov")
    assert "screen.inc" in cam.source
    np.testing.assert_allclose(cam.location, [25, 15, -33])
    np.testing.assert_allclose(cam.forward, _unit([-23, -13, 33]), atol=1e-12)


def test_vectors_without_commas():
    cam = _cam("textures/pigments/skies/s_cloud1.pov")  # look_at <0 20 0>
    np.testing.assert_allclose(cam.location, [0, 1, -100])
    np.testing.assert_allclose(cam.forward, _unit([0, 19, 100]), atol=1e-12)


def test_camera_inside_switch_in_an_include():
    """incdemo/glasses: the #switch in sample.inc picks the camera (case 3 for glass.pov)."""
    cam = _cam("incdemo/glasses/glass.pov")
    assert cam.source.endswith("sample.inc:119")
    np.testing.assert_allclose(cam.location, [0, 40, -60])
    assert _cam("incdemo/glasses/samp_demo.pov").source != cam.source


def test_if_inside_the_camera_and_focal_blur_note():
    cam = _cam("advanced/chess2.pov")
    np.testing.assert_allclose(cam.location, [59, 20, -55])
    assert cam.aperture == pytest.approx(2.25)
    assert any("focal blur" in n for n in cam.replaced)


def test_camera_made_by_a_macro():
    """incdemo/math.pov: GraphSetup() makes an orthographic camera scaled by macros."""
    cam = _cam("incdemo/math.pov")
    assert cam.projection == "orthographic"
    np.testing.assert_allclose(cam.location, [0, 0, -1])
    np.testing.assert_allclose(cam.forward, [0, 0, 1], atol=1e-12)


def test_declared_transform():
    """camera/shear.pov: 'transform Shear' with a declared transform, then rotate."""
    cam = _cam("camera/shear.pov")
    z = 25 - (10 - 1) / 25  # the shear moves <0, 1, 25> to z = 25 - S_angle
    s = math.sqrt(0.5)  # ... then rotate y*45
    np.testing.assert_allclose(cam.location, [z * s, 1, z * s], rtol=1e-12)
    assert any("proportions" in n for n in cam.replaced)  # the shear stretches 'up'


def test_scene_without_a_camera_gets_povray_default():
    cam = _cam("incdemo/strings.pov")
    assert DEFAULT_CAMERA_NOTE in cam.replaced
    np.testing.assert_allclose(cam.location, [0, 0, 0])
    np.testing.assert_allclose(cam.forward, [0, 0, 1])
    np.testing.assert_allclose(cam.right_vector, [1.33, 0, 0])


def test_animation_reads_at_a_given_clock():
    a = _cam("animations/clockd/clockd.pov")
    b = _cam("animations/clockd/clockd.pov", clock=0.5)
    np.testing.assert_allclose(a.location, b.location)  # its camera does not move
    assert not any("clock" in n for n in a.replaced)


# Scenes rendered with their own camera and through the camera read (type, vectors).
RENDERED = ["animations/ambient/ambient.pov", "incdemo/screen.pov", "camera/shear.pov",
            "incdemo/glasses/glass.pov", "textures/pigments/skies/s_cloud1.pov",
            "incdemo/math.pov", "templates/Basic_Scenes/Orthographic_isometric.pov"]


def _own_and_read(tmp_path: Path, rel: str) -> tuple[str, float]:
    scene = EXAMPLES / rel
    cam = _cam(rel)
    name = rel.replace("/", "_")[:-4]
    own = write_text(tmp_path / f"{name}_own.pov", f"#include {pov_string(scene)}\n")
    vectors = " ".join(f"{k} {pov_vector(v)}" for k, v in [
        ("location", cam.location), ("direction", cam.direction_vector),
        ("right", cam.right_vector), ("up", cam.up_vector)])
    read = write_text(tmp_path / f"{name}_read.pov", (
        f"#include {pov_string(scene)}\n#declare PV = version;\n#if (PV < 3.7) #version 3.7; #end\n"
        f"camera {{ {cam.projection} {vectors} }}\n#if (PV < 3.7) #version PV; #end\n"))
    images = [povray.render(p, p.with_suffix(".exr"), W, H, library_paths=[scene.parent])
              for p in (own, read)]
    return rel, float(np.abs(read_image(images[0]) - read_image(images[1])).max())


@pytest.mark.skipif(not HAVE_POVRAY, reason="POV-Ray is not installed")
def test_read_cameras_reproduce_povray(tmp_path):
    with ThreadPoolExecutor(2) as pool:
        results = dict(pool.map(lambda rel: _own_and_read(tmp_path, rel), RENDERED))
    assert results == {rel: 0.0 for rel in RENDERED}
