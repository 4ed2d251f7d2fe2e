"""What povlens replaces or ignores of a scene is said once, in the plan's notes (issue 13,
item 7): the camera's projection, focal blur, normal and proportions, the scene's fog in
the depth probe.  Camera proportions follow POV-Ray's rule: the film takes |right|/|up|,
the image keeps its pixels."""

import json
import math
import shutil

import numpy as np
import pytest

from povlens.plan.camera_setup import FRAMING_NOTE_START
from povlens.plan.convert import ConvertOptions, convert
from povlens.plan.plan_finish import PINHOLE_NOTE, make_plan
from povlens.pov.process import render as povray_render
from povlens.rendering.views import render_view
from povlens.util.images import read_image

needs_povray = pytest.mark.skipif(shutil.which("povray") is None,
                                  reason="POV-Ray not installed")

BODY = """light_source { <2, 4, -3> color rgb 1 }
sphere { <0, 1, 0>, 1 pigment { rgb 1 } }
"""


def scene(tmp_path, camera: str, body: str = BODY, name: str = "s.pov"):
    path = tmp_path / name
    path.write_text(f"#version 3.7;\ncamera {{ {camera} }}\n{body}")
    return str(path)


def scene_notes(plan):
    """The plan's notes on the scene: without the note every pinhole plan has and the
    framing note (tests/plan/test_scene_look.py) of a lens that frames otherwise."""
    return [n for n in plan.notes
            if n != PINHOLE_NOTE and not n.startswith(FRAMING_NOTE_START)]


def plan_of(tmp_path, camera: str, body: str = BODY, **kw):
    base = dict(scene=scene(tmp_path, camera, body), lens="dgauss.50mm", focus=4.0,
                outdir=str(tmp_path / "out"), width=32, height=24, method="pinhole")
    base.update(kw)
    return make_plan(ConvertOptions.of(**base))


def test_a_plain_perspective_camera_has_no_notes_and_plan_json_no_notes_key(tmp_path):
    camera = "location <0, 1, -4> look_at <0, 1, 0> right x*image_width/image_height"
    plan = plan_of(tmp_path, camera, method="focal-blur")
    assert [n for n in plan.notes if n.startswith(FRAMING_NOTE_START)] == plan.notes
    # the scene's camera with the lens's field of view: nothing to note
    plan = plan_of(tmp_path, f"angle {plan.povray_camera.hfov_deg} " + camera, method="focal-blur")
    assert plan.notes == []
    assert "notes" not in plan.to_dict()


def test_focal_blur_and_normal_are_noted_once_each(tmp_path):
    plan = plan_of(tmp_path, "location <0, 1, -4> look_at <0, 1, 0> aperture 0.3 "
                             "focal_point <0, 1, 0> blur_samples 8 "
                             "normal { bumps 0.2 scale 0.1 }")
    notes = scene_notes(plan)
    assert len(notes) == 2, plan.notes
    assert "focal blur" in notes[0] and "normal" in notes[1]
    assert plan.to_dict()["notes"] == plan.notes


@pytest.mark.parametrize("kind", ["orthographic", "fisheye", "panoramic", "spherical",
                                  "cylinder 1", "ultra_wide_angle"])
def test_another_camera_type_gives_its_pose_and_a_note(tmp_path, kind):
    plan = plan_of(tmp_path, f"{kind} location <0, 1, -4> look_at <0, 1, 0>")
    assert plan.povray_camera.location == (0.0, 1.0, -4.0)
    assert np.allclose(np.array(plan.povray_camera.direction)
                       / np.linalg.norm(plan.povray_camera.direction), (0, 0, 1))
    assert [n for n in plan.notes if kind in n and "projection" in n], plan.notes


def test_the_notes_round_trip_through_plan_json(tmp_path):
    from povlens.plan.schema import read_plan
    camera = "location <0, 1, -4> look_at <0, 1, 0> aperture 0.3 focal_point <0, 1, 0>"
    plan = convert(ConvertOptions.of(scene=scene(tmp_path, camera), lens="dgauss.50mm",
                                  focus=None, outdir=str(tmp_path / "out"), width=32,
                                  height=24, method="pinhole"))
    saved = json.loads((tmp_path / "out" / "plan.json").read_text())
    assert saved["notes"] == plan.notes and read_plan(tmp_path / "out").notes == plan.notes
    assert plan.inputs.focus_from == "focal_point"


def test_camera_proportions_set_the_film_as_povray_does(tmp_path):
    # right 4/3 x, up y on a 32x18 (16:9) image: POV-Ray shows the 4:3 frame on 16:9
    plan = plan_of(tmp_path, "location <0, 1, -4> look_at <0, 1, 0> right 4/3*x up y",
                   width=32, height=18)
    film = plan.film
    assert film.width_mm / film.height_mm == pytest.approx(4 / 3)
    assert math.hypot(film.width_mm, film.height_mm) == pytest.approx(35.0)
    cam = plan.povray_camera
    assert np.linalg.norm(cam.right) / np.linalg.norm(cam.up) == pytest.approx(4 / 3)
    notes = [n for n in scene_notes(plan) if "proportions" in n]
    assert len(notes) == 1 and "as POV-Ray does" in notes[0], plan.notes  # one, povlens's
    # proportions within 1 % (right x*1.33) keep the image's, with square pixels
    plan = plan_of(tmp_path, "location <0, 1, -4> look_at <0, 1, 0> right 1.33*x up y")
    assert plan.film.width_mm / plan.film.height_mm == pytest.approx(32 / 24)
    assert scene_notes(plan) == []


def test_film_size_keeps_its_own_proportions_and_says_so(tmp_path):
    plan = plan_of(tmp_path, "location <0, 1, -4> look_at <0, 1, 0> right 2*x up y",
                   film_size_mm=(36.0, 27.0))
    assert (plan.film.width_mm, plan.film.height_mm) == (36.0, 27.0)
    notes = [n for n in scene_notes(plan) if "proportions" in n]
    assert len(notes) == 1 and "film_size_mm=36,27" in notes[0], plan.notes


def test_options_instead_of_the_scene_camera_give_no_camera_notes(tmp_path):
    plan = plan_of(tmp_path, "orthographic location <0, 1, -4> look_at <0, 1, 0> right 3*x",
                   location=(0.0, 1.0, -4.0), look_at=(0.0, 1.0, 0.0))
    assert scene_notes(plan) == []


def _extent_ratio(image: np.ndarray) -> float:
    """Columns over rows spanned by the bright disc of ``image``."""
    lit = image[..., :3].mean(axis=2) > 0.5
    cols, rows = np.flatnonzero(lit.any(axis=0)), np.flatnonzero(lit.any(axis=1))
    return (cols[-1] - cols[0] + 1) / (rows[-1] - rows[0] + 1)


@needs_povray
def test_the_pinhole_view_is_stretched_as_povrays_own_render(tmp_path):
    # a white sphere on black, seen by a 4:3 camera on a 96x54 (16:9) image: POV-Ray
    # and povlens both draw it 4/3 times as wide as tall
    body = ("sphere { <0, 0, 0>, 0.5 pigment { rgb 1 } finish { emission 1 diffuse 0 } }\n")
    path = scene(tmp_path, "location <0, 0, -5> look_at <0, 0, 0> right 4/3*x up y angle 25",
                 body)
    own = povray_render(path, tmp_path / "own.exr", 96, 54)
    plan = convert(ConvertOptions.of(scene=path, lens="dgauss.50mm", focus=5.0,
                                  outdir=str(tmp_path / "out"), width=96, height=54,
                                  method="pinhole"))
    view = render_view(tmp_path / "out", "pinhole")
    expected = (96 / 54) / (4 / 3)
    assert _extent_ratio(read_image(own)) == pytest.approx(expected, rel=0.08)
    assert _extent_ratio(read_image(view)) == pytest.approx(expected, rel=0.08)
    assert any("proportions" in n for n in plan.notes)


@needs_povray
def test_the_scene_fog_is_noted_when_the_depth_probe_ran(tmp_path):
    body = BODY + "fog { distance 30 color rgb 0.5 }\nplane { y, 0 pigment { rgb 0.5 } }\n"
    camera = "location <0, 1, -4> look_at <0, 1, 0> right x*image_width/image_height"
    opts = dict(scene=scene(tmp_path, camera, body), lens="dgauss.50mm",
                width=32, height=24, method="pinhole")
    probed = convert(ConvertOptions.of(**opts, focus=None, focus_at=(16, 12),
                                    outdir=str(tmp_path / "probed")))
    fog = [n for n in scene_notes(probed) if "fog" in n]
    assert len(fog) == 1 and "depth probe does not see it" in fog[0], probed.notes
    assert probed.depth_probe is not None
    plain = convert(ConvertOptions.of(**opts, focus=4.0, outdir=str(tmp_path / "plain")))
    assert scene_notes(plain) == []              # no probe ran: nothing was ignored
