"""Focus from the scene: --focus, the camera's focal_point, its look_at, the depth probe at
the frame's centre or at --focus-at X,Y (every --method), and clear errors where the probe
finds no depth; plan.json records the focus and where it came from."""

from __future__ import annotations

import json
import shutil
import textwrap

import numpy as np
import pytest

from povlens.cli import main
from povlens.lens.film import Film
from povlens.plan.autofocus import pixel_shift_px, window_camera
from povlens.plan.depth_probe import ProbeView, ray_directions
from povlens.plan.schema import PovrayCamera

needs_povray = pytest.mark.skipif(shutil.which("povray") is None,
                                  reason="POV-Ray is not installed")

# Camera at the origin looking along +z (no look_at: 'direction'), inside the solid
# half-space of a backdrop 7 ahead; a wall 3 ahead on the left (x < -0.4); a black
# emissive ball right of the centre.  At 32 x 24 with dgauss.50mm on a 35 mm diagonal
# (hfov about 31 degrees), column 3 sees the wall, the centre the backdrop, pixel
# (29, 12) the ball.
SCENE = textwrap.dedent("""\
    #version 3.7;
    global_settings { assumed_gamma 1 }
    CAMERA
    light_source { <2, 3, -2> color rgb 1 }
    plane { z, 7 pigment { checker rgb 0.9 rgb 0.3 } }
    box { <-10, -10, 3>, <-0.4, 10, 3.5> pigment { rgb 0.6 } }
    sphere { <0.45, 0, 2>, 0.15 pigment { rgb 0 } finish { ambient 1 diffuse 0 } }
    """)
DIRECTION = "camera { location <0, 0, 0> direction z right 1.33*x up y }"


def _convert(tmp_path, camera: str, *args, method: str = "pinhole", scene: str = SCENE):
    (tmp_path / "s.pov").write_text(scene.replace("CAMERA", camera))
    out = tmp_path / "out"
    code = main(["convert", str(tmp_path / "s.pov"), "--lens", "dgauss.50mm", "--width", "32",
                 "--height", "24", "--method", method, "-o", str(out), *args])
    plan = json.loads((out / "plan.json").read_text()) if (out / "plan.json").exists() else None
    return code, plan


@needs_povray
def test_focus_from_the_option(tmp_path):
    code, plan = _convert(tmp_path, "camera { location 0 look_at z aperture 0.1 "
                                    "focal_point <0, 0, 6> }", "--focus", "5")
    assert code == 0
    assert plan["inputs"]["focus"] == 5.0 and plan["inputs"]["focus_from"] == "option"
    assert "depth_probe" not in plan                          # no probe ran


@needs_povray
def test_focus_from_the_cameras_focal_point(tmp_path):
    code, plan = _convert(tmp_path, "camera { location <0, 0, 0> look_at <0, 0, 4> "
                                    "aperture 0.05 focal_point <0.3, 0, 5.5> }",
                          method="focal-blur")
    assert code == 0
    assert plan["inputs"]["focus"] == pytest.approx(np.hypot(0.3, 5.5), rel=1e-12)
    assert plan["inputs"]["focus_from"] == "focal_point"
    assert plan["focus"]["focus_from_camera_mm"] == pytest.approx(1000 * np.hypot(0.3, 5.5))


@needs_povray
def test_focus_from_the_cameras_look_at(tmp_path):
    """A focal_point without focal blur (no aperture) is not a focus: look_at is."""
    code, plan = _convert(tmp_path, "camera { location <0, 0, 0> look_at <0, 0, 4.25> "
                                    "focal_point <0, 0, 6> }", method="mesh")
    assert code == 0
    assert plan["inputs"]["focus"] == 4.25 and plan["inputs"]["focus_from"] == "look_at"


@needs_povray
def test_focus_from_the_depth_probe_at_the_centre(tmp_path, capsys):
    """No focus, focal_point or look_at: the probe's distance at the frame's centre
    (the backdrop, 7 along the axis), with --method auto."""
    code, plan = _convert(tmp_path, DIRECTION, method="auto")
    assert code == 0, capsys.readouterr().err
    assert plan["inputs"]["focus"] == pytest.approx(7.0, rel=3e-3)
    assert plan["inputs"]["focus_from"] == "depth probe at centre"
    f = plan["depth_probe"]["focus"]
    assert f["point_px"] == [16.0, 12.0] and f["rounds"] == 1 and f["surface_pixels"] == 25
    assert "depth_range" in plan["depth_probe"]               # auto's own probe too
    assert not list((tmp_path / "out").glob(".focus.*"))


@needs_povray
@pytest.mark.parametrize("method", ["pinhole", "focal-blur", "mesh"])
def test_focus_at_a_pixel_for_every_method(tmp_path, method):
    code, plan = _convert(tmp_path, DIRECTION, "--focus-at", "3,12", method=method)
    assert code == 0
    assert plan["inputs"]["focus"] == pytest.approx(3.0, rel=3e-3)     # the wall
    assert plan["inputs"]["focus_from"] == "depth probe at 3,12"
    assert plan["inputs"]["focus_at"] == [3, 12]
    f = plan["depth_probe"]["focus"]
    assert f["point_px"] == [3.5, 12.5] and f["last_shift_px"] <= 0.5
    # the final plan's pixel (3, 12) looks at the wall
    cam = PovrayCamera(**{k: tuple(v) if isinstance(v, list) else v
                          for k, v in plan["povray_camera"].items()})
    film = Film(plan["film"]["width_mm"], plan["film"]["height_mm"], 32, 24)
    win, wfilm = window_camera(cam, film, 3.5, 12.5, 1)
    d = ray_directions(ProbeView(win, wfilm, 1000.0, "", 3.0))[0, 0]
    assert d[0] / d[2] * 3.0 < -0.4


@needs_povray
def test_focus_at_a_background_pixel_is_a_clear_error(tmp_path, capsys):
    scene = SCENE.replace("plane { z, 7", "plane { y, -1")     # a floor under an open sky
    code, plan = _convert(tmp_path, DIRECTION, "--focus-at", "16,0", scene=scene)
    err = capsys.readouterr().err
    assert code == 2 and plan is None
    assert "--focus-at" in err and "background" in err and "Traceback" not in err
    assert not list((tmp_path / "out").glob(".focus.*"))


@needs_povray
def test_focus_at_a_black_emissive_pixel_is_a_clear_error(tmp_path, capsys):
    code, plan = _convert(tmp_path, DIRECTION, "--focus-at", "29,12")
    err = capsys.readouterr().err
    assert code == 2 and plan is None
    assert "cannot measure" in err and "emissive" in err


def test_focus_at_outside_the_image_and_with_focus_are_refused(tmp_path, capsys):
    code, plan = _convert(tmp_path, DIRECTION, "--focus-at", "32,0")
    assert code == 2 and plan is None
    assert "--focus-at 32,0: outside the 32x24 image" in capsys.readouterr().err
    with pytest.raises(SystemExit):                            # argparse: not both
        _convert(tmp_path, DIRECTION, "--focus-at", "3,3", "--focus", "2")


def test_window_camera_shoots_the_images_rays_and_the_shift_of_a_point():
    cam = PovrayCamera((1.0, 2.0, 3.0), (0.0, 0.0, 2.0), (1.6, 0.0, 0.0), (0.0, 1.2, 0.0),
                       0.0, 1.0, 40.0)
    film = Film(36.0, 27.0, 40, 30)
    full = ray_directions(ProbeView(cam, film, 1.0, "", 1.0))
    win, wfilm = window_camera(cam, film, 7.5, 20.5, 5)       # pixels 5..9, 18..22
    part = ray_directions(ProbeView(win, wfilm, 1.0, "", 1.0))
    np.testing.assert_allclose(part, full[18:23, 5:10], atol=1e-12)
    assert pixel_shift_px(cam, cam, film, 7.5, 20.5) == pytest.approx(0.0, abs=1e-9)
    wider = PovrayCamera(cam.location, cam.direction, (1.76, 0.0, 0.0), (0.0, 1.32, 0.0),
                         0.0, 1.0, 44.0)                       # 10 % wider field
    # the centre never moves; a point 12.5 px left of it moves by 10 % of that
    assert pixel_shift_px(cam, wider, film, 20.0, 15.0) == pytest.approx(0.0, abs=1e-9)
    assert pixel_shift_px(cam, wider, film, 7.5, 15.0) == pytest.approx(1.25, rel=1e-9)


# Nothing at the centre of the frame: the camera looks along +z at empty sky; one lit
# box stands off to the left, 4 ahead.
OFF_CENTRE = textwrap.dedent("""\
    #version 3.7;
    global_settings { assumed_gamma 1 }
    CAMERA
    light_source { <0, 3, -2> color rgb 1 }
    box { <-1.2, -0.3, 4>, <-0.6, 0.3, 4.5> pigment { rgb 0.8 } }
    """)


@needs_povray
def test_autofocus_takes_the_lit_surface_nearest_to_an_empty_centre(tmp_path):
    code, plan = _convert(tmp_path, DIRECTION, scene=OFF_CENTRE, method="focal-blur")
    assert code == 0
    assert "nearest lit surface" in plan["inputs"]["focus_from"]
    assert plan["inputs"]["focus"] == pytest.approx(4.0, rel=0.03)


@needs_povray
def test_autofocus_with_nothing_in_the_frame_uses_the_default_distance(tmp_path):
    empty = "#version 3.7;\nCAMERA\nlight_source { <0, 3, -2> color rgb 1 }\n"
    code, plan = _convert(tmp_path, DIRECTION, scene=empty, method="focal-blur")
    assert code == 0
    assert plan["inputs"]["focus_from"].startswith("default distance (no depth")
    assert plan["inputs"]["focus"] == pytest.approx(5.0)
    assert "depth_probe" in plan                              # the probe ran


def test_a_pinhole_plan_without_a_focus_runs_no_depth_probe(tmp_path, monkeypatch):
    """A pinhole render has no blur to focus: a camera without focal_point or look_at
    gets the typical 5 m, and the plan says so, with no probe (issue 14)."""
    import povlens.plan.autofocus as autofocus

    def no_probe(*args, **kw):
        raise AssertionError("the depth probe ran")
    monkeypatch.setattr(autofocus, "start_probe", no_probe)
    code, plan = _convert(tmp_path, DIRECTION)                # method pinhole
    assert code == 0
    assert plan["inputs"]["focus"] == 5.0
    assert plan["inputs"]["focus_from"] == autofocus.PINHOLE_FOCUS_FROM
    assert "depth_probe" not in plan
    notes = [n for n in plan["notes"] if "no depth probe ran" in n]
    assert len(notes) == 1 and "field of view" in notes[0], plan["notes"]
    assert not list((tmp_path / "out").glob(".focus.*"))
