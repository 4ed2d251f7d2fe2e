"""The start of a plan (povlens.plan.plan_start) at far focus: ``--focus inf`` and the
API's ``math.inf`` focus at infinity (a collimated beam), a far distance focuses as
exactly, and the plan reads back with its focus at infinity.  Conversions only (no
lens samples rendered), small images."""

import json
import math
import subprocess
import sys

import pytest

import povlens
from povlens.plan.schema import read_plan

from conftest import ROOT

SCENE = str(ROOT / "scenes" / "paper.pov")
SMALL = dict(width=48, height=36, samples=2)


def test_focus_at_infinity_through_the_api(tmp_path):
    plan = povlens.convert(SCENE, lens="dgauss.50mm", outdir=tmp_path / "inf", focus=math.inf,
                           method="mesh", **SMALL)
    at_inf = povlens.focus("dgauss.50mm", math.inf)
    assert plan.inputs.focus == math.inf
    assert plan.focus.film_distance_mm == pytest.approx(at_inf.exact_film_distance_mm, abs=1e-9)
    again = read_plan(tmp_path / "inf")                 # JSON has no inf: null reads back
    assert again.inputs.focus == math.inf and again.focus.focus_from_camera_mm == math.inf
    far = povlens.convert(SCENE, lens="dgauss.50mm", outdir=tmp_path / "far", focus=1e6,
                          method="mesh", **SMALL)        # 1000 km in metres
    # Newton: 1000 km moves the image by f^2 / z = 2.5e-6 mm, no more
    assert far.focus.film_distance_mm == pytest.approx(plan.focus.film_distance_mm, abs=5e-6)
    assert far.focus.rms_spot_mm == pytest.approx(plan.focus.rms_spot_mm, rel=0.01)


def test_focus_inf_on_the_command_line(tmp_path):
    out = tmp_path / "o"
    r = subprocess.run([sys.executable, "-m", "povlens", "convert", SCENE, "--lens",
                        "dgauss.50mm", "--focus", "inf", "--method", "focal-blur",
                        "--samples", "4", "--width", "48", "--height", "36", "-o", str(out)],
                       capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "focus inf m" in r.stdout
    assert json.loads((out / "plan.json").read_text())["inputs"]["focus"] is None
    assert read_plan(out).inputs.focus == math.inf


@pytest.mark.parametrize("text", ["0", "-1", "nan"])
def test_a_focus_that_is_no_distance_is_refused(tmp_path, text):
    from povlens.cli import main
    assert main(["convert", SCENE, "--lens", "dgauss.50mm", f"--focus={text}", "-o",
                 str(tmp_path / "o")]) == 2
