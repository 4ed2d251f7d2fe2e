"""POV-Ray's own options on the command line: --library-path (+L), --clock (+K) and
--povray-option, given to every POV-Ray run of a scene and kept in plan.json (issue 13,
item 8), with the real POV-Ray and small images."""

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from povlens.util.images import read_image

from conftest import ROOT

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")

SIZE = ("--width", "32", "--height", "24")

#: A scene whose object comes from an include file in another folder.
INCLUDING_SCENE = """#version 3.7;
global_settings { assumed_gamma 1 }
#include "props.inc"
camera { location <0, 1, -4> look_at <0, 1, 0> right x*image_width/image_height }
light_source { <2, 4, -3> color rgb 1 }
object { Prop }
plane { y, 0 pigment { color rgb 0.5 } }
"""
PROPS = "#declare Prop = sphere { <0, 1, 0>, 1 pigment { color rgb <1, 0.2, 0.2> } }\n"

#: A scene whose sphere moves with the clock (its camera stands still).
CLOCK_SCENE = """#version 3.7;
global_settings { assumed_gamma 1 }
camera { location <0, 1, -4> look_at <0, 1, 0> right x*image_width/image_height }
light_source { <2, 4, -3> color rgb 1 }
sphere { <-1 + 4*clock, 1, 0>, 0.6 pigment { color rgb <1, 0.2, 0.2> } }
plane { y, 0 pigment { checker color rgb 0.2 color rgb 0.8 } }
"""


def povlens(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "povlens", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=600)


@pytest.fixture
def scenes(tmp_path):
    """(scene folder, library folder): main.pov includes props.inc from the library."""
    scene, lib = tmp_path / "scene", tmp_path / "lib"
    scene.mkdir()
    lib.mkdir()
    (scene / "main.pov").write_text(INCLUDING_SCENE)
    (lib / "props.inc").write_text(PROPS)
    (scene / "clock.pov").write_text(CLOCK_SCENE)
    return scene, lib


def notes_of(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith("povlens: note: ")]


@pytest.mark.parametrize("method", ["pinhole", "mesh"])
def test_a_scene_including_a_file_from_another_folder_renders_only_with_library_path(
        scenes, tmp_path, method):
    scene, lib = scenes
    args = ("render", scene / "main.pov", "--lens", "dgauss.50mm", "--method", method,
            "--samples", "2", *SIZE)
    r = povlens(*args, "-o", tmp_path / "without")
    # the scene-camera reader (2) or POV-Ray (3) does not find it, and says so
    assert r.returncode in (2, 3) and "props.inc" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr
    out = tmp_path / "with"
    r = povlens(*args, "-o", out, "--library-path", lib)
    assert r.returncode == 0, r.stderr
    image = read_image(out / "image.exr")
    assert image.shape == (24, 32, 3) and image[12, 16, 0] > 2 * image[12, 16, 2]  # red sphere
    inputs = json.loads((out / "plan.json").read_text())["inputs"]
    assert inputs["library_paths"] == [str(lib)]


def test_a_relative_library_path_is_kept_absolute_in_the_plan(scenes, tmp_path):
    scene, lib = scenes
    r = povlens("convert", scene / "main.pov", "--lens", "dgauss.50mm", "--method", "pinhole",
                *SIZE, "-o", tmp_path / "out", "--library-path", "lib", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    inputs = json.loads((tmp_path / "out" / "plan.json").read_text())["inputs"]
    assert inputs["library_paths"] == [str(lib)]


def test_the_depth_probe_autofocus_and_speculative_renders_get_the_library_path(scenes, tmp_path):
    # --method auto: the depth probe; --focus-at: the autofocus window probe; cooke's
    # early guess is "either": the speculative focal_blur view and early lens samples
    scene, lib = scenes
    args = (scene / "main.pov", "--lens", "cooke.triplet.50mm", "--focus-at", "16,12", *SIZE)
    r = povlens("plan", *args)
    assert r.returncode in (2, 3) and "props.inc" in r.stderr, r.stderr
    r = povlens("plan", *args, "--library-path", lib)
    assert r.returncode == 0, r.stderr
    out = tmp_path / "auto"
    r = povlens("render", *args, "--library-path", lib, "-o", out)
    assert r.returncode == 0, r.stderr
    plan = json.loads((out / "plan.json").read_text())
    assert plan["inputs"]["focus_from"] == "depth probe at 16,12"
    assert plan["inputs"]["focus"] == pytest.approx(3.0, rel=0.02)   # the sphere's front
    assert (out / "image.exr").exists()


def test_a_camera_in_an_include_file_on_the_library_path_is_read(tmp_path):
    scene, lib = tmp_path / "scene", tmp_path / "lib"
    scene.mkdir()
    lib.mkdir()
    (lib / "cam.inc").write_text("camera { location <1, 2, -5> look_at <1, 2, 0> }\n")
    (scene / "s.pov").write_text('#include "cam.inc"\nsphere { <1, 2, 0>, 1 pigment { rgb 1 } }\n')
    args = ("convert", scene / "s.pov", "--lens", "dgauss.50mm", "--method", "pinhole", *SIZE)
    r = povlens(*args, "-o", tmp_path / "without")
    assert r.returncode == 2 and "cam.inc" in r.stderr, r.stderr
    r = povlens(*args, "-o", tmp_path / "with", "--library-path", lib)
    assert r.returncode == 0, r.stderr
    plan = json.loads((tmp_path / "with" / "plan.json").read_text())
    assert plan["povray_camera"]["location"] == [1.0, 2.0, -5.0]
    assert plan["inputs"]["focus"] == pytest.approx(5.0)           # its look_at


def test_clock_changes_the_image_and_moves_the_scene_camera(scenes, tmp_path):
    scene, _ = scenes
    images = {}
    for clock in ("0", "0.5"):
        out = tmp_path / f"clock{clock}"
        r = povlens("render", scene / "clock.pov", "--lens", "dgauss.50mm", "--method",
                    "pinhole", *SIZE, "--clock", clock, "-o", out)
        assert r.returncode == 0, r.stderr
        images[clock] = read_image(out / "image.exr")
        assert json.loads((out / "plan.json").read_text())["inputs"]["clock"] == float(clock)
    # the sphere moved from x = -1 to x = 1: the left of the frame lost its red
    left = slice(0, 12)
    red = {c: im[8:16, left, 0].mean() - im[8:16, left, 2].mean() for c, im in images.items()}
    assert red["0"] > 0.1 and red["0.5"] < 0.5 * red["0"], red
    # the scene camera is read at the clock, too
    moving = scene / "moving.pov"
    moving.write_text(CLOCK_SCENE.replace("location <0, 1, -4> look_at <0, 1, 0>",
                                          "location <clock, 1, -4> look_at <clock, 1, 0>"))
    r = povlens("convert", moving, "--lens", "dgauss.50mm", "--method", "pinhole", *SIZE,
                "--clock", "0.5", "-o", tmp_path / "moving")
    assert r.returncode == 0, r.stderr
    plan = json.loads((tmp_path / "moving" / "plan.json").read_text())
    assert plan["povray_camera"]["location"] == [0.5, 1.0, -4.0]


@pytest.mark.parametrize("command", ["convert", "plan", "render"])
def test_a_refused_option_exits_2_naming_povray_option(scenes, tmp_path, command):
    scene, _ = scenes
    out = tmp_path / "out"
    r = povlens(command, scene / "clock.pov", "--lens", "dgauss.50mm", *SIZE, "-o", out,
                "--povray-option", "+W320")
    assert r.returncode == 2
    assert "--povray-option '+W320'" in r.stderr and "image width" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr and not out.exists()


def test_bad_library_paths_and_clocks_exit_2_naming_their_options(scenes, tmp_path):
    scene, _ = scenes
    args = ("convert", scene / "clock.pov", "--lens", "dgauss.50mm", *SIZE, "-o", tmp_path / "o")
    r = povlens(*args, "--library-path", tmp_path / "missing")
    assert r.returncode == 2 and "--library-path" in r.stderr and "no such folder" in r.stderr
    r = povlens(*args, "--clock", "inf")
    assert r.returncode == 2 and "--clock" in r.stderr
    r = povlens(*args, "--povray-option=+KFF10")
    assert r.returncode == 2 and "--povray-option" in r.stderr and "--clock" in r.stderr


def test_make_and_render_batch_render_with_the_options_in_plan_json(scenes, tmp_path):
    scene, lib = scenes
    both = scene / "both.pov"
    both.write_text(INCLUDING_SCENE.replace("object { Prop }", "object { Prop translate "
                                            "<4*clock - 1, 0, 0> scale 0.5 }"))
    args = ("--lens", "dgauss.50mm", "--samples", "4", "--batch-size", "2", *SIZE,
            "--library-path", lib, "--clock", "0.5", "--povray-option", "Jitter=off")
    made = tmp_path / "made"
    r = povlens("convert", both, "--method", "mesh", *args, "-o", made)
    assert r.returncode == 0, r.stderr
    inputs = json.loads((made / "plan.json").read_text())["inputs"]
    assert (inputs["library_paths"], inputs["clock"], inputs["povray_options"]) == (
        [str(lib)], 0.5, ["Jitter=off"])
    r = subprocess.run(["make", "-C", str(made), "-j2"], capture_output=True, text=True,
                       cwd=tmp_path, timeout=600)
    assert r.returncode == 0, r.stderr                  # render-batch found props.inc
    again = subprocess.run(["make", "-C", str(made)], capture_output=True, text=True)
    assert again.returncode == 0 and "Nothing to be done" in again.stdout
    rendered = tmp_path / "rendered"
    r = povlens("render", both, "--method", "mesh", *args, "-o", rendered)
    assert r.returncode == 0, r.stderr
    np.testing.assert_array_equal(read_image(made / "image.exr"),
                                  read_image(rendered / "image.exr"))
    # the view of a pinhole folder, too (render-view)
    view = tmp_path / "view"
    assert povlens("convert", both, "--method", "pinhole", *args, "-o", view).returncode == 0
    r = subprocess.run(["make", "-C", str(view)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr


def test_antialiasing_applies_to_the_views_and_not_to_mesh_lens_samples(scenes, tmp_path):
    scene, _ = scenes
    clock = scene / "clock.pov"
    images, notes = {}, {}
    for method in ("pinhole", "mesh"):
        for aa in ((), ("--povray-option", "+A0.0")):
            out = tmp_path / f"{method}{len(aa)}"
            r = povlens("render", clock, "--lens", "dgauss.50mm", "--method", method,
                        "--samples", "2", *SIZE, *aa, "-o", out)
            assert r.returncode == 0, r.stderr
            images[method, bool(aa)] = read_image(out / "image.exr")
            notes[method, bool(aa)] = notes_of(r.stderr)
    assert not np.array_equal(images["pinhole", True], images["pinhole", False])
    np.testing.assert_array_equal(images["mesh", True], images["mesh", False])
    aa_notes = [n for n in notes["mesh", True] if "anti-aliasing" in n]
    assert len(aa_notes) == 1 and "--povray-option '+A0.0'" in aa_notes[0], notes
    assert not any("anti-aliasing" in n for n in notes["pinhole", True])
    saved = json.loads((tmp_path / "mesh2" / "plan.json").read_text())
    assert any("anti-aliasing" in n for n in saved["notes"])


def test_notes_print_once_on_stderr_and_not_with_quiet(tmp_path):
    scene = tmp_path / "blur.pov"
    scene.write_text("camera { location <0, 1, -4> look_at <0, 1, 0> aperture 0.2 "
                     "focal_point <0, 1, 0> blur_samples 8 }\n"
                     "light_source { <2, 4, -3> color rgb 1 }\n"
                     "sphere { <0, 1, 0>, 1 pigment { rgb 1 } }\n")
    base = (scene, "--lens", "dgauss.50mm", *SIZE)
    for command, extra in (("convert", ("--method", "pinhole", "-o", tmp_path / "c")),
                           ("convert", ("--method", "pinhole", "--json", "-o", tmp_path / "j")),
                           ("plan", ()),
                           ("render", ("--method", "pinhole", "-o", tmp_path / "r"))):
        r = povlens(command, *base, *extra)
        assert r.returncode == 0, r.stderr
        notes = notes_of(r.stderr)
        pinhole = [n for n in notes if "method pinhole:" in n]   # its model error: not measured
        assert len(pinhole) == (command != "plan"), (command, r.stderr)
        notes = [n for n in notes if n not in pinhole and "sees 67.2 deg across" not in n]
        assert len(notes) == 1 and "focal blur" in notes[0], (command, r.stderr)
        assert "note:" not in r.stdout.replace('"notes"', "")
    r = povlens("render", *base, "--method", "pinhole", "-q", "-o", tmp_path / "q")
    assert r.returncode == 0 and not notes_of(r.stderr), r.stderr
