"""povlens.pov.sdl.scene_camera: reading the camera of a POV-Ray scene.

The decisive check renders each scene with its own camera and with an
explicit-basis pinhole camera built from the parsed vectors: the two images
must be identical.
"""

from __future__ import annotations

import math
import shutil
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from povlens.pov import process as povray
from povlens.errors import PovlensError
from povlens.util.images import read_image
from povlens.pov.mesh import pinhole_wrapper
from povlens.util.files import write_text
from povlens.pov.sdl.scene_camera import DEFAULT_CAMERA_NOTE, SceneCameraError, parse_scene_camera

REPO = Path(__file__).resolve().parents[3]
HAVE_POVRAY = shutil.which("povray") is not None

BODY = """
light_source { <-5, 10, -8> rgb 1 }
plane { y, 0 pigment { checker rgb 0.9 rgb 0.1 scale 0.5 } }
sphere { <-1.2, 0.6, 0.6>, 0.6 pigment { rgb <1, 0.2, 0.2> } }
sphere { <0.3, 0.6, 3>, 0.6 pigment { rgb <0.2, 1, 0.2> } }
box { <1, 0, 5>, <2, 2, 6> pigment { rgb <0.2, 0.2, 1> } }
sky_sphere { pigment { gradient y color_map { [0 rgb <0.6, 0.7, 1>] [1 rgb <0.1, 0.2, 0.6>] } } }
"""


def _scene(tmp_path, name, text, header="#version 3.7;\nglobal_settings { assumed_gamma 1.0 }\n"):
    p = tmp_path / f"{name}.pov"
    p.write_text(header + text + "\n")
    return p


# Cameras POV-Ray must agree with, pixel for pixel.
RENDER_CASES = {
    "look_at_sky_angle_transforms": """
        camera { location <0, 1.5, -4> look_at <0.5, 0.8, 3> sky <0.2, 1, 0> angle 60
                 right x*image_width/image_height rotate <5, 20, 3> translate <0.3, 0, 0.5> }""",
    "no_look_at": """
        camera { location <0, 1, -3> direction <0, 0, 1.5> right <1.333, 0, 0> up <0, 1, 0>
                 rotate y*15 }""",
    "mirrored_right": "camera { location <0, 1, -3> right <-4/3, 0, 0> look_at <0, 0.8, 0> }",
    "old_version_order": """#version 3.1;
        camera { location <0, 1, -3> look_at <0, 0.5, 2> angle 70 direction z*2 }
        #version 3.7;""",
    "declared_camera": """
        #declare Loc = <0, 1.4, -4>;
        #declare Tgt = Loc + 5*vnormalize(<0.1, -0.2, 1>);
        #declare C = camera { location Loc look_at Tgt angle 45 right x*image_width/image_height }
        camera { C rotate y*-10 }""",
    "matrix_and_items_out_of_order": """
        camera { look_at z location <0, 0, 0> right x*4/3
                 matrix <1,0,0, 0,0.96,-0.28, 0,0.28,0.96, 0,1.3,-3.5> }""",
    "conditionals": """
        #ifndef (CamX) #declare CamX = 0.7; #end
        #if (CamX > 0.5) #declare Ang = 55; #else #declare Ang = 20; #end
        camera { location <CamX, 1.2, -3> look_at <0, (Ang > 50 ? 0.5 : 3), 2> angle Ang }""",
    "last_camera_wins": """
        camera { location <5, 5, 5> look_at 0 }
        /* camera { location <9, 9, 9> } /* nested */ camera { } */
        // camera { location 1 }
        camera { location <-0.5, 1.1, -3> look_at <0, 0.6, 1> angle 40 }""",
}


# Scene constructs as people write them (issue 13): each must give POV-Ray's own image.
# (name -> scene text, keyword arguments of parse_scene_camera, POV-Ray switches)
CONSTRUCT_CASES = {
    "switch_fallthrough_break": ("""
        #declare Shot = 2;
        #switch (Shot)
          #case (1) camera { location <5, 5, 5> look_at 0 } #break
          #range (2, 3) #declare L = <0.4, 1.3, -3.5>;
          #case (9) camera { location L look_at <0, 0.6, 2> angle 50 }
          #if (1) #break #end
          camera { location 9 }
          #else camera { location 8 }
        #end""", {}, ()),
    "if_inside_camera": ("""
        #declare Wide = yes;
        camera { location <0.3, 1.2, -3> #if (Wide) angle 75 #else angle 20 #end
                 #declare Tilt = 8; rotate x*Tilt look_at <0, 0.7, 2> }""", {}, ()),
    "while_and_for": ("""
        #declare I = 0; #declare P = <0, 0.2, -1>;
        #while (I < 4) #declare P = P + <0.1, 0.25, -0.5>; #declare I = I + 1; #end
        #declare S = 0; #for (K, 1, 5, 2) #declare S = S + K; #end
        camera { location P look_at <0, S/9, 3> }""", {}, ()),
    "macro_makes_camera": ("""
        #macro Cam(L, A)
          #local T = L + <0, -0.5, 4>;
          camera { location L look_at T angle A right x*image_width/image_height }
        #end
        Cam(<-0.5, 1.4, -3.2>, 45)""", {}, ()),
    "macro_returns_vector": ("""
        #macro Orbit(R, Deg) <R*sin(radians(Deg)), 1.1, -R*cos(radians(Deg))> #end
        camera { location Orbit(4, 20) look_at <0, 0.5, 1.5> }""", {}, ()),
    "declared_transforms": ("""
        #declare Spin = transform { rotate y*-12 translate <0.2, 0, 0> }
        #declare Lift = transform { translate <0, 0.3, 0> rotate x*5 }
        camera { location <0, 1, -3> look_at <0, 0.6, 2>
                 transform Spin transform { Lift } transform { Spin inverse } }""", {}, ()),
    "vector_forms": ("""
        #declare A = <0.5 -1 1.2>;
        #declare B = <1, 2> + z;
        #declare C = color red 0.3 green 0.6;
        camera { location <A.x, B.y*0.6 + C.green/6, -4 + B.z> up y right 4/3*x
                 look_at vaxis_rotate(<0, 0.5, 3>, y, -10) + vrotate(x*0.1, <0, 0, 90>)
                 sky vnormalize(<0.1, 1, 0>) }""", {}, ()),
    "clock": ("camera { location <clock, 1.2, -3.5 + clock> look_at <0, 0.6, 2> }",
              {"clock": 0.7}, ("+K0.7",)),
    "declares": ("camera { location <0, CamH, -3.5> look_at <0, 0.6, 2> }",
                 {"declares": {"CamH": 1.9}}, ("declare=CamH=1.9",)),
    "no_camera": ("", {}, ()),
}


def _render_pair(tmp_path, name, text, w, h, kwargs, switches):
    """Max |own image - image through the parsed camera| for one scene."""
    scene = _scene(tmp_path, name, BODY + text)
    cam = parse_scene_camera(scene, w, h, **kwargs)
    wrapper = write_text(
        tmp_path / f"{name}_pin.pov",
        pinhole_wrapper(scene.name, cam.location, cam.direction_vector, cam.right_vector,
                        cam.up_vector),
    )  # fmt: skip
    own = povray.render(scene, tmp_path / f"{name}_own.exr", w, h, extra_args=switches)
    pin = povray.render(wrapper, tmp_path / f"{name}_pin.exr", w, h, extra_args=switches)
    return name, float(np.abs(read_image(own) - read_image(pin)).max())


@pytest.mark.skipif(not HAVE_POVRAY, reason="POV-Ray is not installed")
def test_scene_constructs_reproduce_povray(tmp_path):
    w, h = 48, 36
    with ThreadPoolExecutor(2) as pool:
        results = dict(pool.map(lambda kv: _render_pair(tmp_path, kv[0], kv[1][0], w, h, kv[1][1],
                                                        kv[1][2]), CONSTRUCT_CASES.items()))
    assert results == {name: 0.0 for name in CONSTRUCT_CASES}


@pytest.mark.skipif(not HAVE_POVRAY, reason="POV-Ray is not installed")
def test_parsed_camera_reproduces_povray(tmp_path):
    w, h = 48, 36

    def check(item):
        name, text = item
        scene = _scene(tmp_path, name, BODY + text)
        cam = parse_scene_camera(scene, w, h)
        wrapper = write_text(
            tmp_path / f"{name}_pin.pov",
            pinhole_wrapper(scene.name, cam.location, cam.direction_vector, cam.right_vector,
                            cam.up_vector),
        )  # fmt: skip
        own = povray.render(scene, tmp_path / f"{name}_own.exr", w, h)
        pin = povray.render(wrapper, tmp_path / f"{name}_pin.exr", w, h)
        return name, float(np.abs(read_image(own) - read_image(pin)).max())

    with ThreadPoolExecutor(2) as pool:
        results = dict(pool.map(check, RENDER_CASES.items()))
    assert results == {name: 0.0 for name in RENDER_CASES}


def test_basis_and_fov(tmp_path):
    cam = parse_scene_camera(
        _scene(tmp_path, "s", "camera { location <1, 2, 3> look_at <1, 2, 13> angle 90 }")
    )
    np.testing.assert_allclose(cam.location, [1, 2, 3])
    np.testing.assert_allclose(cam.forward, [0, 0, 1])
    np.testing.assert_allclose(cam.right, [1, 0, 0])
    np.testing.assert_allclose(cam.up, [0, 1, 0])
    assert cam.hfov_deg == pytest.approx(90.0)
    # |right| = 1.33 (default), direction rescaled so that the angle is 90 degrees
    assert np.linalg.norm(cam.direction_vector) == pytest.approx(1.33 / 2)
    assert cam.vfov_deg == pytest.approx(math.degrees(2 * math.atan(1 / 1.33)))
    assert cam.projection == "perspective" and cam.source.endswith("s.pov:3")


def test_defaults_without_look_at(tmp_path):
    cam = parse_scene_camera(_scene(tmp_path, "d", "camera { location <0, 1, -3> }"))
    np.testing.assert_allclose(cam.forward, [0, 0, 1])
    assert cam.hfov_deg == pytest.approx(math.degrees(2 * math.atan(0.5 * 1.33)))
    assert cam.look_at is None


def test_sky_tilts_the_basis(tmp_path):
    cam = parse_scene_camera(
        _scene(tmp_path, "k", "camera { location 0 look_at z*10 sky <1, 1, 0> }")
    )
    s = math.sqrt(0.5)
    np.testing.assert_allclose(cam.right, [s, -s, 0], atol=1e-12)
    np.testing.assert_allclose(cam.up, [s, s, 0], atol=1e-12)
    np.testing.assert_allclose(np.cross(cam.up, cam.forward), cam.right, atol=1e-12)


def test_rotate_convention(tmp_path):
    """rotate y*90 turns a camera looking along +z to look along +x."""
    cam = parse_scene_camera(_scene(tmp_path, "r", "camera { location <0, 1, 0> rotate y*90 }"))
    np.testing.assert_allclose(cam.forward, [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(cam.right, [0, 0, -1], atol=1e-12)


def test_focal_blur_settings_and_image_size(tmp_path):
    cam = parse_scene_camera(
        _scene(
            tmp_path,
            "f",
            """camera { location <0, 1, -5> look_at <0, 1, 0> right x*image_width/image_height
                        aperture 0.4 focal_point <0, 1, 2> blur_samples 10, 37 confidence 0.9 }""",
        ),
        image_width=200,
        image_height=100,
    )
    assert cam.aperture == pytest.approx(0.4)
    assert cam.focal_distance == pytest.approx(7.0)
    assert np.linalg.norm(cam.right_vector) == pytest.approx(2.0)


def test_camera_in_local_include(tmp_path):
    (tmp_path / "cams").mkdir()
    (tmp_path / "cams" / "cam.inc").write_text(
        "#declare H = 1.7;\ncamera { location <0, H, -2> look_at <0, H, 0> }\n"
    )
    scene = _scene(tmp_path, "i", '#include "colors.inc"\n#include "cams/cam.inc"\nsphere { 0, 1 }')
    cam = parse_scene_camera(scene)
    np.testing.assert_allclose(cam.location, [0, 1.7, -2])
    assert "cam.inc" in cam.source


@pytest.mark.parametrize(
    "name, text, fragment, hint",
    [
        ("missing_include", '#include "povlens_nowhere.inc"\nsphere { 0, 1 }', "povlens_nowhere.inc",
         "library_paths"),
        ("macro", "#macro MyCam(L) camera { location L look_at 0 } #end\nMyCam(<0,1,-3>*Foo)",
         "'Foo' is not defined", "declares"),
        ("unknown_if", "#if (Foo > 1) camera { location 1 } #else camera { location 2 } #end", "#if",
         "declares={'Foo'"),
        ("function", "camera { location <0,1,-3> look_at <0, f_noise3d(1,2,3), 0> }", "f_noise3d", ""),
        ("undefined", "camera { location CamPos look_at 0 }", "CamPos", "declares={'CamPos'"),
        ("bad_declare", "#declare P = MyMacro(3);\ncamera { location P look_at 0 }", "'P'", ""),
        ("loop", "#declare I=0; #while (I<rand(seed(1))) #declare I=I+1; #end\ncamera { location <I,1,-3> }",
         "#while", ""),
        ("transform_id", "#declare T = transform { rotate y*Spin }\ncamera { location 1 transform T }",
         "'T'", "declares={'Spin'"),
        ("mesh_camera", "camera { mesh_camera { 1 0 mesh { M } } }", "mesh_camera", ""),
        ("directive", "camera { location <0,1,-3> #if (Wide) look_at 0 #end }", "#if", "declares={'Wide'"),
        ("image_width", "camera { location 1 right x*image_width/image_height }", "image_width",
         "image_width and image_height"),
        ("error", '#if (clock = 0) #error "render with +KFF" #end camera { }', "+KFF", ""),
    ],
)
def test_unreadable_cameras_give_clear_errors(tmp_path, name, text, fragment, hint):
    """The message names the construct and its place; the hint says what to pass (API
    parameter names, not command-line flags) and how to give the camera explicitly."""
    scene = _scene(tmp_path, name, text)
    with pytest.raises(SceneCameraError) as info:
        parse_scene_camera(scene)
    err = info.value
    assert isinstance(err, PovlensError)
    assert fragment in str(err)
    assert f"{name}.pov" in str(err)
    assert "'location'" in err.hint and "'look_at'" in err.hint and "'sky'" in err.hint
    assert hint in err.hint
    assert "--" not in err.hint  # API parameters, not command-line flags


def test_missing_scene_file(tmp_path):
    with pytest.raises(PovlensError, match="does not exist"):
        parse_scene_camera(tmp_path / "nope.pov")


@pytest.mark.parametrize("scene, height", [("paper.pov", 1.5), ("chart.pov", 1.5)])
def test_bundled_scenes(scene, height):
    cam = parse_scene_camera(REPO / "scenes" / scene, 160, 120)
    assert cam.location[1] == pytest.approx(height)
    assert cam.projection == "perspective"
    assert 30 < cam.hfov_deg < 70


def test_unreadable_camera_is_skipped_when_a_later_one_wins(tmp_path):
    scene = _scene(
        tmp_path,
        "later",
        """camera { location Unknown normal { bumps 0.2 scale <1, 2, 3> } look_at 0 }
        #declare M = mesh2 { vertex_vectors { 3, <0,0,0>, <1,0,0>, <0,1,0> }
                             face_indices { 1, <0,1,2> } }
        object { M translate <1, 2, 3> }
        camera { location <0, 2, -5> look_at <0, 1, 0> }""",
    )
    cam = parse_scene_camera(scene)
    np.testing.assert_allclose(cam.location, [0, 2, -5])
    assert cam.source.endswith("later.pov:7")


def test_what_the_lens_replaces_is_said(tmp_path):
    """Another projection, focal blur, a camera normal and proportions other than the
    image's each get a note; a plain perspective camera gets none."""
    cam = parse_scene_camera(_scene(tmp_path, "n", """
        camera { orthographic location <0, 1, -5> look_at 0 right 2*x up y
                 aperture 0.4 focal_point <0, 0, 1> blur_samples 20 normal { bumps 0.1 } }"""),
        image_width=40, image_height=30)
    assert cam.projection == "orthographic" and len(cam.replaced) == 4
    assert "camera type orthographic" in cam.replaced[0]
    assert "focal blur (aperture 0.4" in cam.replaced[1]
    assert "normal" in cam.replaced[2]
    assert "|right|/|up| = 2" in cam.replaced[3] and "40x30" in cam.replaced[3]
    plain = parse_scene_camera(_scene(tmp_path, "p", "camera { location <0, 1, -5> look_at 0 }"),
                               image_width=40, image_height=30)
    assert plain.replaced == []


def test_scene_without_camera_and_clock_notes(tmp_path):
    none = parse_scene_camera(_scene(tmp_path, "none", "sphere { 0, 1 }"))
    assert none.replaced == [DEFAULT_CAMERA_NOTE]
    np.testing.assert_allclose(none.location, [0, 0, 0])
    np.testing.assert_allclose(none.direction_vector, [0, 0, 1])
    np.testing.assert_allclose(none.right_vector, [1.33, 0, 0])  # POV-Ray's Camera::Init
    moving = _scene(tmp_path, "moving", "camera { location <clock*10, 1, -5> look_at 0 }")
    assert any("moves with clock" in n for n in parse_scene_camera(moving).replaced)
    at = parse_scene_camera(moving, clock=0.5)
    np.testing.assert_allclose(at.location, [5, 1, -5])
    assert at.replaced == []
    still = _scene(tmp_path, "still", "#declare T = clock; camera { location <0, 1, -5> }")
    assert parse_scene_camera(still).replaced == []
