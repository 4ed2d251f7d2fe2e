"""The radiosity pretrace of a field pass is spaced on the scene as the frame's (issue 25).

POV-Ray spaces its pretrace by the size it renders, and a field pass renders the frame
as m x m interleaved tiles side by side; unscaled, the pretrace was 16 times coarser on
the scene at m = 4, and runs computing their own radiosity drew a dot lattice of
period m (docs/decisions/planning.md, "A pattern in runs of their own").  The plan
records the scene's pretrace; each run repeats it scaled to its size."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from povlens.pov.mesh import pretrace_block
from povlens.pov.sdl import parse_scene_camera
from povlens.util.images import read_image
from tests.rendering.test_radiosity_cache import _povlens

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")

RADDEM = Path("/usr/share/doc/povray/examples/animations/raddem/raddem.pov")
CAMERA = "camera { location <0, 1, -4> look_at <0, 0.5, 0> }\n"


@pytest.mark.parametrize("settings, pretrace", [
    ("global_settings { radiosity { } }", (0.08, 0.04)),       # POV-Ray 3.7's defaults
    ("global_settings { radiosity { pretrace_start 0.1 pretrace_end 0.02 count 9 } }",
     (0.1, 0.02)),
    # a later block changes only what it sets
    ("global_settings { radiosity { pretrace_start 0.1 } }\n"
     "global_settings { radiosity { pretrace_end 0.01 } }", (0.1, 0.01)),
    # the stock macro, followed through its #switch
    ('#include "rad_def.inc"\nglobal_settings { radiosity { '
     'Rad_Settings(Radiosity_Fast, off, off) } }', (0.08, 0.02)),
    ("#declare E = 0.03;\nglobal_settings { radiosity { pretrace_end E / 2 } }",
     (0.08, 0.015)),
    # what povlens cannot tell: a name without a value, a branch it cannot decide
    ("global_settings { radiosity { pretrace_start Unknown } }", None),
    ("#if (rand(seed(2)) > 0.5) global_settings { radiosity { pretrace_end 0.01 } } #end",
     None),
    ("global_settings { assumed_gamma 1 }", None),               # no radiosity
])
def test_the_scene_reader_tells_the_pretrace(tmp_path, settings, pretrace):
    scene = tmp_path / "r.pov"
    scene.write_text(settings + "\n" + CAMERA)
    assert parse_scene_camera(scene, 64, 48).radiosity_pretrace == pretrace


def test_the_pretrace_block_scales_only_runs_larger_than_the_frame():
    assert pretrace_block(None, (320, 240), 4) == ""
    text = pretrace_block((0.08, 0.04), (320, 240), 4)
    assert "320 / (4 * max(image_width, image_height))" in text
    assert "#if (4 * max(image_width, image_height) > 321)" in text   # 321: FS#261's column
    assert "#ifndef (PovlensRadiosityRead)" in text       # a run reading samples keeps it
    assert "pretrace_start 0.08 * PovlensPretraceScale" in text


SCENE = """#version 3.7;
global_settings { radiosity { pretrace_start 0.06 pretrace_end 0.03 count 20 } }
camera { location <0, 1, -4> look_at <0, 0.5, 0> }
light_source { <2, 4, -3> rgb 1 }
plane { y, 0 pigment { rgb 0.8 } }
box { -1, 1 pigment { rgb <1, 0.3, 0.3> } translate <0, 1, 1> }
"""


def test_a_field_plan_records_the_pretrace_and_each_run_scales_it(tmp_path):
    scene = tmp_path / "rad.pov"
    scene.write_text(SCENE)
    out = tmp_path / "o"
    _povlens("convert", scene, "--width", "320", "--height", "240", "--lens", "tessar.50mm",
             "--method", "mesh", "--samples", "8", "--f-number", "16", "-o", out)
    plan = json.loads((out / "plan.json").read_text())
    assert plan["field_mesh"]["interleave"] > 1
    assert plan["povray"]["radiosity_pretrace"] == [0.06, 0.03]
    assert any("pretrace_start 0.06 and pretrace_end 0.03 scaled" in n for n in plan["notes"])
    batch = (out / "samples" / "batch_000.pov").read_text()
    assert "pretrace_start 0.06 * PovlensPretraceScale" in batch


def test_a_pretrace_povlens_cannot_tell_renders_passes_the_frames_size(tmp_path):
    scene = tmp_path / "rad.pov"
    scene.write_text(SCENE.replace("pretrace_end 0.03", "pretrace_end Unknown"))
    out = tmp_path / "o"
    _povlens("convert", scene, "--width", "320", "--height", "240", "--lens", "tessar.50mm",
             "--method", "mesh", "--samples", "8", "--f-number", "16", "-o", out)
    plan = json.loads((out / "plan.json").read_text())
    assert plan["field_mesh"]["interleave"] == 1 and plan["povray"]["image_size_read"]
    assert "radiosity_pretrace" not in plan["povray"]
    assert any(n.startswith("radiosity: povlens cannot tell the scene's pretrace_start")
               for n in plan["notes"])
    assert "PovlensPretraceScale" not in (out / "samples" / "batch_000.pov").read_text()


def _phase_spread(image: np.ndarray, m: int) -> float:
    """The spread of the mean brightness of the m x m pixel phases of ``image``'s upper
    back wall (raddem.pov): a dot lattice of period m shows here."""
    h, w = image.shape[:2]
    wall = image[: 70 * h // 480, 80 * w // 640: 250 * w // 640, :3].mean(axis=2)
    means = [wall[i::m, j::m].mean() for i in range(m) for j in range(m)]
    return float(max(means) - min(means))


@pytest.mark.skipif(not RADDEM.is_file(), reason="povray-examples is not installed")
@pytest.mark.parametrize("extra, env", [
    # the default: every run reads the frame's radiosity samples (radiosity.rca)
    ([], None),
    # a radiosity file of the user's own and one pass a run: each computes its own
    # radiosity, its pretrace scaled (without it: spread 0.011)
    (["--povray-option", "Radiosity_File_Name=own.rca"], {"POVLENS_STACK": "1"}),
], ids=["reading-the-frames", "computing-their-own"])
def test_field_passes_draw_no_dot_lattice(tmp_path, extra, env):
    """raddem.pov stopped down: when runs of their own computed their radiosity with the
    scene's pretrace unscaled, tile 0 of every pass came out darker (phase spread 0.011
    of 0.150 here, either way); the per-pixel render spreads 0.0006 at 640x480."""
    out = tmp_path / "o"
    _povlens("render", RADDEM, "--width", "320", "--height", "240", "--lens", "tessar.50mm",
             "--method", "mesh", "--samples", "8", "--f-number", "16", "-q", "-o", out, *extra,
             env=env)
    plan = json.loads((out / "plan.json").read_text())
    m = plan["field_mesh"]["interleave"]
    assert m == 4
    assert (out / "radiosity.rca").is_file() == (not extra)
    if not extra:   # whole: POV-Ray finishes it ~0.1 s after its image, when it was stopped
        lines = (out / "radiosity.rca").read_text().split("\n")
        assert lines[-1] == "" and len(lines) > 100
        assert {len(line.split("\t")) for line in lines[:-1]} == {11}
    image = read_image(out / "image.exr")
    assert 0.1 < image[..., :3].mean() < 0.2
    assert _phase_spread(image, m) < 0.004
