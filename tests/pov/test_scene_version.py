"""The wrappers keep the scene's ``#version``: a scene renders through povlens's camera
as POV-Ray renders it through its own.

POV-Ray takes gamma handling, ambient under radiosity and the noise generator from the
version in force at the end of parsing, and reads a scene without ``#version`` as
3.6.2.  The wrappers used to end with ``#version 3.7;`` (and begin with it), which made
every older scene a 3.7 scene; each scene here looks different that way, so the tests
would fail with the old wrappers.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from povlens.pov import process as povray
from povlens.pov.mesh import (default_sink_centre, mesh_wrapper, pinhole_wrapper, render_size,
                              write_ray_mesh)
from povlens.pov.sdl import pov_vector, read_template
from povlens.util.files import write_text
from povlens.util.images import read_image

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray is not installed")

W, H = 48, 36

# An explicit camera basis (POV-Ray's perspective camera), used by the scene's own
# camera and by povlens's wrappers alike: the views are the same by construction.
LOC = np.array([0.0, 1.0, -4.0])
_F = np.array([0.0, -0.4, 4.0]) / np.linalg.norm([0.0, -0.4, 4.0])
RIGHT = np.cross([0.0, 1.0, 0.0], _F)
RIGHT *= (W / H) / np.linalg.norm(RIGHT)
UP = np.cross(_F, RIGHT) / np.linalg.norm(np.cross(_F, RIGHT))
DIRECTION = _F * 1.2

_CAMERA = (f"camera {{ perspective location {pov_vector(LOC)} direction {pov_vector(DIRECTION)}"
           f" right {pov_vector(RIGHT)} up {pov_vector(UP)} }}\n")
_LIT = """light_source { <3, 5, -6> rgb 1 }
sphere { <0, 0.6, 0>, 0.6 pigment { rgb <0.5, 0.3, 0.2> } }
plane { y, 0 pigment { checker rgb 0.2 rgb 0.6 } }
background { rgb <0.2, 0.3, 0.5> }
"""

#: Scenes whose look depends on the language version at the end of parsing.
SCENES = {
    # 3.6 without assumed_gamma: gamma correction off (3.7: on, about 4x brighter here)
    "3.6 no assumed_gamma": "#version 3.6;\n" + _CAMERA + _LIT,
    # no #version at all: read as 3.6.2, gamma correction off as well
    "no #version": _CAMERA + _LIT,
    # 3.6 with radiosity: ambient still lights (3.7 ignores it under radiosity)
    "3.6 ambient with radiosity": "#version 3.6;\n" + """global_settings { assumed_gamma 1.0
  radiosity { count 20 recursion_limit 1 nearest_count 2 error_bound 1.8
              pretrace_start 0.16 pretrace_end 0.08 } }
""" + _CAMERA + """sphere { <0, 0.6, 0>, 0.6 pigment { rgb 1 } finish { ambient 0.8 diffuse 0 } }
plane { y, 0 pigment { rgb 0.5 } finish { ambient 0.4 diffuse 0 } }
background { rgb <0.2, 0.3, 0.5> }
""",
    # 3.1: the original noise generator (3.5 and later: range-corrected)
    "3.1 noise": "#version 3.1;\nglobal_settings { assumed_gamma 1.0 }\n" + _CAMERA + """
plane { z, 2 pigment { bozo scale 0.3 color_map { [0 rgb 0] [1 rgb 1] } }
        finish { ambient 1 diffuse 0 } }
""",
}


def _old_wrapper(text: str) -> str:
    """What the wrappers did before: ``#version 3.7;`` first and last."""
    return "#version 3.7;\n" + text + "#version 3.7;\n"


def _render(path: Path, name: str, **kw) -> np.ndarray:
    out = povray.render(path, path.parent / f"{name}.exr", kw.pop("width", W),
                        kw.pop("height", H), threads=1, **kw)
    return read_image(out)[..., :3]


@pytest.fixture(params=sorted(SCENES))
def scene(request, tmp_path):
    p = tmp_path / "scene.pov"
    p.write_text(SCENES[request.param])
    return p


def test_pinhole_wrapper_renders_the_scene_as_povray_does(scene):
    own = _render(scene, "own")
    text = pinhole_wrapper("scene.pov", LOC, DIRECTION, RIGHT, UP)
    pin = _render(write_text(scene.parent / "pin.pov", text), "pin")
    assert np.abs(pin - own).max() < 1e-3
    old = _render(write_text(scene.parent / "old.pov", _old_wrapper(text)), "old")
    assert np.abs(old - own).mean() > 0.05      # the scene shows the difference


def test_mesh_wrappers_render_the_scene_as_povray_does(scene):
    """The ray-mesh wrapper and the batch template (mesh_camera, 3.7 syntax) on an older
    scene: a pinhole ray mesh gives POV-Ray's own image."""
    folder = scene.parent
    own = _render(scene, "own")
    x0 = (np.arange(W)[None, :] + 0.5) / W - 0.5
    y0 = 0.5 - (np.arange(H)[:, None] + 0.5) / H
    x0, y0 = np.broadcast_arrays(x0, y0)
    dirs = DIRECTION + x0[..., None] * RIGHT + y0[..., None] * UP
    origin = np.broadcast_to(LOC, dirs.shape).copy()
    sink = default_sink_centre(LOC, DIRECTION)
    rw, rh, drop = render_size(W, H)
    t = write_ray_mesh(folder / "rays.inc", "Rays", origin, dirs, np.ones((H, W), bool),
                       sink_centre=sink)
    wrapper = write_text(folder / "mesh.pov",
                         mesh_wrapper("scene.pov", ["rays.inc"], ["Rays"], t, 1, sink_centre=sink))
    mesh = _render(wrapper, "mesh", width=rw, height=rh, start_row=drop or None)[drop:]

    t = write_ray_mesh(folder / "sample_0000.inc", "PovlensRays", origin, dirs,
                       np.ones((H, W), bool), sink_centre=sink)
    with open(folder / "sample_0000.inc", "a") as f:
        f.write(f"#declare PovlensTranslate = {pov_vector(t)};\n")
        f.write(f"#declare PovlensEye = {pov_vector(LOC)};\n")   # the scene camera's
    from povlens.plan.render_folder import RenderFolder
    batch = write_text(folder / "batch.pov", read_template("mesh_batch.pov.tmpl").substitute(
        RenderFolder.mesh_include_names(), scene_include='"scene.pov"',
        sink_centre=pov_vector(sink), sink_radius="1", photons=""))
    frame = _render(batch, "batch", width=rw, height=rh, start_row=drop or None,
                    extra_args=["Declare=PovlensFrame=0"])[drop:]
    for img in (mesh, frame):
        diff = np.abs(img - own).max(axis=2)
        assert np.median(diff) < 1e-3 and np.mean(diff > 1e-2) < 0.02


STOCK = Path("/usr/share/doc/povray/examples/advanced/blocks/stackernight.pov")


@pytest.mark.skipif(not STOCK.is_file(), reason="povray-examples is not installed")
def test_stock_36_radiosity_scene_is_not_black(tmp_path):
    """stackernight.pov (#version 3.6, lit by ambient under radiosity) rendered entirely
    black through the old wrappers."""
    w, h = 64, 48
    loc, look = np.array([0.0, 7.0, -21.0]), np.array([0.0, 4.5, -10.0])
    forward = (look - loc) / np.linalg.norm(look - loc)     # direction z*CamZoom, CamZoom=1
    right = np.cross([0.0, 1.0, 0.0], forward)
    right *= (w / h) / np.linalg.norm(right)                 # right x*image_width/image_height
    up = np.cross(forward, right) / np.linalg.norm(np.cross(forward, right))
    lib = [STOCK.parent]                                     # stacks.inc, makestacks.inc
    own = read_image(povray.render(STOCK, tmp_path / "own.exr", w, h, threads=1,
                                   library_paths=lib))[..., :3]
    text = pinhole_wrapper(STOCK, loc, forward, right, up)
    pin = read_image(povray.render(write_text(tmp_path / "pin.pov", text), tmp_path / "pin.exr",
                                   w, h, threads=1, library_paths=lib))[..., :3]
    old = read_image(povray.render(write_text(tmp_path / "old.pov", _old_wrapper(text)),
                                   tmp_path / "old.exr", w, h, threads=1,
                                   library_paths=lib))[..., :3]
    assert own.mean() > 0.05 and old.max() < 0.02          # black through the old wrapper
    assert np.abs(pin - own).mean() < 0.02 * own.mean()
