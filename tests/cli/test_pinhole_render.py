"""``povlens render --method pinhole`` renders the view and skips what only the lens's
blur needs (issue 14): no model error (it says so), no depth probe, and no exit-pupil
table unless the vignetting map wants one."""

import json
import shutil
import subprocess
import sys

import pytest

from conftest import ROOT

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")


def test_pinhole_render_writes_the_image_and_no_pupil_table(tmp_path):
    out = tmp_path / "o"
    r = subprocess.run([sys.executable, "-m", "povlens", "render", "scenes/paper.pov", "--lens",
                        "dgauss.50mm", "--method", "pinhole", "--width", "24", "--height", "18",
                        "--no-vignetting", "-o", str(out)],
                       capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    assert (out / "image.exr").is_file() and (out / "image.png").is_file()
    assert not (out / "pupil.npz").exists() and not list(out.glob(".probe.*"))
    assert "model error: not measured" in r.stdout
    plan = json.loads((out / "plan.json").read_text())
    assert plan["model_error"] == {} and plan["inputs"]["focus_from"] == "look_at"
    assert "depth_probe" not in plan
    assert "povlens: note: method pinhole: the thin-lens model's error was not measured" \
        in r.stderr
