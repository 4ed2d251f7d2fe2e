"""The render folder a conversion writes (povlens.plan.folder_writer): plan.json, the
wrappers, a Makefile that renders it and then has nothing to do, and what a changed plan
drops.  With the real POV-Ray, small images."""

import json
import shutil
import subprocess

import numpy as np
import pytest

from povlens.plan.convert import convert
from povlens.rendering.driver import render_outdir
from povlens.util.images import read_image

from conftest import ROOT, paper_options

SCENES = ROOT / "scenes"
pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")


def test_convert_writes_plan_wrappers_and_makefile(tmp_path):
    before = (SCENES / "paper.pov").read_bytes()
    plan = convert(paper_options(tmp_path))
    out = tmp_path / "out"
    for name in ("plan.json", "pinhole.pov", "focal_blur.pov", "Makefile",
                 "samples/batch_000.pov", "samples/batch_001.pov"):
        assert (out / name).exists(), name
    saved = json.loads((out / "plan.json").read_text())
    assert saved["batches"] == [[0, 2], [1, 3]]        # dealt round-robin
    cam = saved["povray_camera"]
    # focal_blur aperture is twice the entrance-pupil diameter, in scene units (m)
    assert cam["aperture"] == pytest.approx(2 * 24.8051e-3, rel=1e-4)
    assert saved["model_error"]["max_distortion_px"] >= 0
    assert "#include" in (out / "focal_blur.pov").read_text()
    # the scene itself is untouched
    assert (SCENES / "paper.pov").read_bytes() == before
    assert plan.focus.film_distance_mm > plan.lens.efl_mm * 0.7


def test_make_renders_and_a_second_make_does_nothing(tmp_path):
    convert(paper_options(tmp_path))
    out = tmp_path / "out"
    r = subprocess.run(["make", "-C", str(out), "-j2"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    img = read_image(out / "image.exr")
    assert img.shape == (36, 48, 3) and np.isfinite(img).all() and img.mean() > 0.05
    assert (out / "image.png").exists()
    again = subprocess.run(["make", "-C", str(out)], capture_output=True, text=True)
    assert again.returncode == 0 and "Nothing to be done" in again.stdout


def test_changed_inputs_drop_stale_samples_and_exposure(tmp_path):
    convert(paper_options(tmp_path, samples=2, batch_size=2))
    out = tmp_path / "out"
    render_outdir(out, jobs=1, quiet=True)
    assert (out / "exposure.txt").exists() and (out / "pupil.npz").exists()
    e_f2 = float((out / "exposure.txt").read_text())
    convert(paper_options(tmp_path, samples=2, batch_size=2, f_number=4.0))   # the stop changed
    assert not (out / "exposure.txt").exists()
    assert not list((out / "samples").glob("sample_*.exr"))
    render_outdir(out, jobs=1, quiet=True)
    # exposure = 1 / (E/L) at the centre, and E/L goes as 1/N^2: f/2.03 -> f/4 is ~3.9x
    assert float((out / "exposure.txt").read_text()) == pytest.approx(e_f2 * (4.0 / 2.03) ** 2,
                                                                      rel=0.15)
