"""--method auto: the pure decision, and 'povlens plan' end to end on a tiny render."""

import json
import math
import pathlib
import subprocess
import sys

import pytest

from povlens.auto_plan import MAX_SAMPLES, MIN_SAMPLES, decide, model_depths
from povlens.convert import ConvertOptions, _make_plan
from povlens.thin_lens import measure_model_error

ROOT = pathlib.Path(__file__).resolve().parent.parent
PAPER = str(ROOT / "scenes" / "paper.pov")
INF = math.inf


def _decide(lens, f_number, focus_m, near_m, far_m, w=48, h=36, **kw):
    """Decision for a depth range [near, far] (m from the entrance pupil), measured model error."""
    plan, L, model, film = _make_plan(ConvertOptions(
        scene=PAPER, lens=lens, focus=focus_m, outdir="unused", f_number=f_number,
        width=w, height=h, method="mesh"))
    c = model.centre_z_mm
    nz, fz = c + 1000 * near_m, c + 1000 * far_m
    err = measure_model_error(L, plan["focus"]["film_distance_mm"], model, film,
                              model_depths(model, nz, fz))
    return decide(near_z_mm=nz, far_z_mm=fz, model=model, model_error=err,
                  pixel_pitch_mm=film.pixel_pitch_mm, **kw)


def test_tiny_stop_gives_pinhole():
    d = _decide("dgauss.50mm", 22, 3, 1, INF)
    assert d["method"] == "pinhole" and d["samples"] == 1
    assert d["numbers"]["max_model_blur_px"] < 0.5
    assert d["reasons"][-1].startswith("-> pinhole")


def test_slow_well_corrected_lens_with_deep_scene_gives_focal_blur():
    d = _decide("tessar.50mm", 8, 3, 0.7, INF, 96, 72)
    n = d["numbers"]
    assert n["max_model_blur_px"] >= 0.5                  # too much blur for a pinhole
    assert d["method"] == "focal-blur", d["reasons"]
    assert MIN_SAMPLES <= d["samples"] <= MAX_SAMPLES


def test_fast_vignetting_lens_gives_mesh_with_samples_growing_with_blur():
    far = _decide("dgauss.50mm", None, 3, 2, 5, 160, 120)
    near = _decide("dgauss.50mm", None, 3, 0.5, 5, 160, 120)
    assert far["method"] == near["method"] == "mesh"
    assert far["numbers"]["min_relative_illumination"] < 0.95
    assert near["numbers"]["max_blur_px"] > far["numbers"]["max_blur_px"]
    assert near["samples"] > far["samples"] >= MIN_SAMPLES
    # the same lens with vignetting not wanted is judged on its other deviations only
    loose = _decide("dgauss.50mm", None, 3, 0.5, 5, 160, 120, vignetting=False, tolerance_px=8)
    assert loose["method"] == "focal-blur"


def test_plan_command_records_the_decision(tmp_path):
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "povlens", "plan", PAPER, "--lens", "dgauss.50mm",
                        "--focus", "7", "--width", "32", "--height", "24", "-o", str(out),
                        "--json"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    printed = json.loads(r.stdout)
    plan = json.loads((out / "plan.json").read_text())
    d = plan["decision"]
    assert plan["inputs"]["requested_method"] == "auto"
    assert plan["inputs"]["method"] == d["method"] == printed["method"]
    assert plan["inputs"]["samples"] == d["samples"]
    assert d["method"] in ("pinhole", "focal-blur", "mesh")
    n = d["numbers"]
    assert 1000 < n["near_distance_mm"] < 20000          # the balls and the floor, metres away
    assert n["far_distance_mm"] is None                  # the sky: infinity (null in JSON)
    assert n["depth_probe"]["background_fraction"] > 0.01
    assert any("relative illumination" in s for s in d["reasons"])
    assert not list(out.glob(".probe.*"))                 # the probe folder is removed
    text = subprocess.run([sys.executable, "-m", "povlens", "plan", PAPER, "--lens",
                           "dgauss.50mm", "--focus", "7", "--width", "32", "--height", "24"],
                          capture_output=True, text=True, timeout=120)
    assert text.returncode == 0, text.stderr
    assert f"method {d['method']}" in text.stdout and "max_distortion_px" in text.stdout


def test_auto_plan_numbers_equal_a_plan_of_the_chosen_method(tmp_path):
    """convert(auto) reuses the pupil table and model error of its first plan: the plan
    must be what make_plan gives for the chosen method and samples."""
    import dataclasses

    from povlens.convert import convert, make_plan
    opts = ConvertOptions(scene=PAPER, lens="dgauss.50mm", focus=4, outdir=str(tmp_path / "a"),
                          width=40, height=30, method="auto")
    plan = convert(opts)
    d = plan.pop("decision")
    for k in ("requested_method", "tolerance_px", "auto_samples"):
        plan["inputs"].pop(k)
    again = make_plan(dataclasses.replace(opts, outdir=str(tmp_path / "b"), method=d["method"],
                                          samples=d["samples"]))
    assert json.dumps(plan, sort_keys=True) == json.dumps(again, sort_keys=True)
    assert (tmp_path / "a" / "pupil.npz").is_file() and not list((tmp_path / "a").glob(".probe.*"))


@pytest.mark.skipif(__import__("shutil").which("povray") is None, reason="POV-Ray not installed")
def test_speculative_focal_blur_is_the_final_view(tmp_path):
    """With speculate (povlens render), auto starts the adaptive focal_blur render while
    the probe runs; when the decision is focal-blur, that render is the folder's view,
    identical to rendering the final wrapper afterwards."""
    import numpy as np
    from povlens.convert import convert
    from povlens.images import read_image
    from povlens.render import render_outdir, render_view
    root = pathlib.Path(__file__).resolve().parent.parent
    base = dict(scene=str(root / "scenes" / "paper.pov"), lens="telephoto.250mm", focus=4.0,
                width=48, height=36, method="auto")
    spec = tmp_path / "spec"
    plan = convert(ConvertOptions(outdir=str(spec), speculate=True, **base))
    assert plan["inputs"]["method"] == "focal-blur"
    assert (spec / "view-focal-blur.exr").exists()          # rendered during convert
    assert "blur_samples 16, 256" in (spec / "focal_blur.pov").read_text()
    assert not list(spec.glob(".speculative*")) and not list(spec.glob(".*.tmp*"))
    render_outdir(spec, quiet=True)
    plain = tmp_path / "plain"
    convert(ConvertOptions(outdir=str(plain), **base))
    assert not (plain / "view-focal-blur.exr").exists()     # convert alone renders nothing
    assert (plain / "focal_blur.pov").read_text().replace(str(plain), "") == \
        (spec / "focal_blur.pov").read_text().replace(str(spec), "")
    render_view(plain, "focal-blur")
    a, b = read_image(spec / "image.exr"), read_image(plain / "image.exr")
    assert a.shape == b.shape
    # POV-Ray's adaptive focal blur is deterministic up to thread scheduling
    assert float(np.mean(np.abs(a - b))) < 0.01


@pytest.mark.skipif(__import__("shutil").which("povray") is None, reason="POV-Ray not installed")
def test_no_speculative_render_when_the_lens_vignettes(tmp_path):
    from povlens.convert import convert
    root = pathlib.Path(__file__).resolve().parent.parent
    out = tmp_path / "d"
    plan = convert(ConvertOptions(scene=str(root / "scenes" / "paper.pov"), lens="dgauss.50mm",
                                  focus=4.0, width=48, height=36, method="auto", speculate=True,
                                  outdir=str(out)))
    assert plan["inputs"]["method"] == "mesh"
    assert not (out / "view-focal-blur.exr").exists()
    assert not list(out.glob(".speculative*"))
