"""--method auto: the pure decision, and 'povlens plan' end to end on a tiny render."""

import json
import math
import pathlib
import subprocess
import sys

import pytest

from povlens.plan.convert import ConvertOptions
from povlens.plan.decision import MAX_SAMPLES, MIN_SAMPLES, decide, model_depths
from povlens.plan.plan_finish import make_plan_with_lens
from povlens.thinlens.model_error import measure_model_error

ROOT = pathlib.Path(__file__).resolve().parents[2]
PAPER = str(ROOT / "scenes" / "paper.pov")
INF = math.inf


def _decide(lens, f_number, focus_m, near_m, far_m, w=48, h=36, **kw):
    """Decision for a depth range [near, far] (m from the entrance pupil), measured model error."""
    plan, L = make_plan_with_lens(ConvertOptions.of(
        scene=PAPER, lens=lens, focus=focus_m, outdir="unused", f_number=f_number,
        width=w, height=h, method="focal-blur"))
    model, film = plan.thin_lens, plan.film
    c = model.centre_z_mm
    nz, fz = c + 1000 * near_m, c + 1000 * far_m
    err = measure_model_error(L, plan.focus.film_distance_mm, model, film,
                              model_depths(model, nz, fz))
    return decide(near_z_mm=nz, far_z_mm=fz, model=model, model_error=err,
                  pixel_pitch_mm=film.pixel_pitch_mm, **kw)


def test_tiny_stop_gives_pinhole():
    d = _decide("dgauss.50mm", 22, 3, 1, INF)
    assert d.method == "pinhole" and d.samples == 1
    assert d.numbers["max_model_blur_px"] < 0.5
    assert d.reasons[-1].startswith("-> pinhole")


def test_slow_well_corrected_lens_with_deep_scene_gives_focal_blur():
    d = _decide("tessar.50mm", 8, 3, 0.7, INF, 96, 72)
    n = d.numbers
    assert n["max_model_blur_px"] >= 0.5                  # too much blur for a pinhole
    assert d.method == "focal-blur", d.reasons
    assert MIN_SAMPLES <= d.samples <= MAX_SAMPLES


def test_fast_vignetting_lens_gives_mesh_with_samples_growing_with_blur():
    far = _decide("dgauss.50mm", None, 3, 2, 5, 160, 120)
    near = _decide("dgauss.50mm", None, 3, 0.5, 5, 160, 120)
    assert far.method == near.method == "mesh"
    assert far.numbers["min_relative_illumination"] < 0.95
    assert near.numbers["max_blur_px"] > far.numbers["max_blur_px"]
    assert near.samples > far.samples >= MIN_SAMPLES
    # the same lens with vignetting not wanted is judged on its other deviations only
    loose = _decide("dgauss.50mm", None, 3, 0.5, 5, 160, 120, vignetting=False, tolerance_px=8)
    assert loose.method == "focal-blur"


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

    from povlens.plan.convert import convert, make_plan
    opts = ConvertOptions.of(scene=PAPER, lens="dgauss.50mm", focus=4, outdir=str(tmp_path / "a"),
                          width=160, height=120, method="auto")
    plan = convert(opts).to_dict()
    d = plan.pop("decision")
    assert d["method"] != "pinhole"     # a pinhole plan measures no model error of its own
    assert plan.pop("depth_probe")["depth_range"] == d["numbers"]["depth_probe"]
    for k in ("requested_method", "tolerance_px", "auto_samples"):
        plan["inputs"].pop(k)
    again = make_plan(opts.replace(outdir=str(tmp_path / "b"), method=d["method"],
                                          samples=d["samples"])).to_dict()
    assert json.dumps(plan, sort_keys=True) == json.dumps(again, sort_keys=True)
    assert (tmp_path / "a" / "pupil.npz").is_file() and not list((tmp_path / "a").glob(".probe.*"))


def test_auto_certifies_the_field_meshes_once(tmp_path, monkeypatch):
    """The probe's mesh plan, the early samples' plan and the chosen plan share one start
    (lens, focus, film, pupil table): the field-mesh choice is made once, and a plan made
    from scratch for the chosen method certifies the same meshes."""
    import povlens.plan.field_grid as field_grid
    from povlens.plan.convert import convert, make_plan
    calls = []
    choose = field_grid.choose_field_mesh
    monkeypatch.setattr(field_grid, "choose_field_mesh",
                        lambda *a, **k: calls.append(1) or choose(*a, **k))
    opts = ConvertOptions.of(scene=PAPER, lens="dgauss.50mm", focus=1.5,
                             outdir=str(tmp_path / "a"), width=96, height=72, method="auto")
    plan = convert(opts)
    assert plan.inputs.method == "mesh" and plan.field_mesh is not None
    assert len(calls) == 1
    again = make_plan(opts.replace(outdir=str(tmp_path / "b"), method="mesh",
                                   samples=plan.inputs.samples))
    assert len(calls) == 2 and again.field_mesh == plan.field_mesh


@pytest.mark.skipif(__import__("shutil").which("povray") is None, reason="POV-Ray not installed")
def test_speculative_focal_blur_is_the_final_view(tmp_path):
    """With speculate (povlens render), auto starts the adaptive focal_blur render while
    the probe runs; when the decision is focal-blur, that render is the folder's view,
    identical to rendering the final wrapper afterwards."""
    import numpy as np
    from povlens.plan.convert import convert
    from povlens.util.images import read_image
    from povlens.rendering.driver import render_outdir
    from povlens.rendering.views import render_view
    root = pathlib.Path(__file__).resolve().parents[2]
    base = dict(scene=str(root / "scenes" / "paper.pov"), lens="telephoto.250mm", focus=4.0,
                width=48, height=36, method="auto")
    spec = tmp_path / "spec"
    plan = convert(ConvertOptions.of(outdir=str(spec), speculate=True, **base))
    assert plan.inputs.method == "focal-blur"
    assert (spec / "view-focal-blur.exr").exists()          # rendered during convert
    assert "blur_samples 32, 256" in (spec / "focal_blur.pov").read_text()
    assert not list(spec.glob(".speculative*")) and not list(spec.glob(".*.tmp*"))
    render_outdir(spec, quiet=True)
    plain = tmp_path / "plain"
    convert(ConvertOptions.of(outdir=str(plain), **base))
    assert not (plain / "view-focal-blur.exr").exists()     # convert alone renders nothing
    assert (plain / "focal_blur.pov").read_text().replace(str(plain), "") == \
        (spec / "focal_blur.pov").read_text().replace(str(spec), "")
    render_view(plain, "focal-blur")
    a, b = read_image(spec / "image.exr"), read_image(plain / "image.exr")
    assert a.shape == b.shape
    # POV-Ray's adaptive focal blur is deterministic up to thread scheduling
    assert float(np.mean(np.abs(a - b))) < 0.01


@pytest.mark.skipif(__import__("shutil").which("povray") is None, reason="POV-Ray not installed")
def test_no_speculative_render_when_the_lens_rules_out_the_views(tmp_path):
    """The fisheye distorts far beyond the budget: mesh, and no focal_blur was started
    (its vignetting alone would not rule the views out: they get it as a map)."""
    from povlens.plan.convert import convert
    root = pathlib.Path(__file__).resolve().parents[2]
    out = tmp_path / "d"
    plan = convert(ConvertOptions.of(scene=str(root / "scenes" / "paper.pov"), lens="fisheye.10mm",
                                  focus=4.0, width=48, height=36, method="auto", speculate=True,
                                  outdir=str(out)))
    assert plan.inputs.method == "mesh"
    assert not (out / "view-focal-blur.exr").exists()
    assert not list(out.glob(".speculative*"))


def test_shape_error_is_how_far_the_long_axis_reaches_beyond_the_equivalent_disc():
    """Sampled uniform ellipses: the long-axis extent (4 sqrt(l_max)) minus the
    diameter of the disc of the same RMS radius (2 sqrt(2) rho) is the formula."""
    import numpy as np
    from povlens.plan.decision import shape_error_px
    rng = np.random.default_rng(1)
    u = rng.random(400_000)
    t = rng.random(400_000) * 2 * np.pi
    disc = np.sqrt(u)[:, None] * np.column_stack([np.cos(t), np.sin(t)])   # unit disc
    for a, b in [(1.0, 1.0), (2.0, 1.0), (5.0, 0.5), (3.0, 0.01)]:
        xy = disc * [a, b]
        ev = np.linalg.eigvalsh(np.cov(xy.T))
        rho = np.sqrt(ev.sum())
        blur = 2 * np.sqrt(2) * rho                           # measure_model_error's blur
        e = np.sqrt(ev[1] / ev[0])
        long_extent = 2 * np.abs(xy[:, 0]).max()              # the ellipse's real long axis
        assert float(shape_error_px(blur, e)) == pytest.approx(long_extent - blur,
                                                               abs=2e-3 * blur)
    # round: 0; a line: (sqrt(2) - 1) b at most, never the old (e - 1) b
    assert float(shape_error_px(3.0, 1.0)) == 0.0
    assert float(shape_error_px(3.0, 1e9)) == pytest.approx((math.sqrt(2) - 1) * 3.0)


def test_vignetting_and_shift_rmse_on_simple_images():
    import numpy as np
    from povlens.plan.image_error import shift_rmse, vignetting_rmse
    img = np.ones((10, 20, 3))
    ri = np.full((10, 20), 0.8)
    assert vignetting_rmse(img, ri) == pytest.approx(0.2)
    assert vignetting_rmse(img, np.ones((10, 20))) == 0.0
    assert shift_rmse(img, 0.5) == 0.0                        # flat: moving changes nothing
    # a vertical step edge: only x moves change it, by f on the one column it crosses
    step = np.zeros((10, 20, 3))
    step[:, 10:] = 1.0
    f = 0.25
    per_x = math.sqrt(f ** 2 / 18)                            # 1 of 18 compared columns
    assert shift_rmse(step, f) == pytest.approx((2 * per_x + 0 + 0) / 4)
    # ramp: every pixel changes by slope x shift
    ramp = np.tile(np.arange(20.0)[None, :, None], (10, 1, 3)) * 0.01
    assert shift_rmse(ramp, 1.5) == pytest.approx(0.5 * 0.015)


def test_probe_skips_the_view_when_the_vignetting_is_not_wanted(tmp_path):
    """--no-vignetting: nothing reads the probe's view, so it is not rendered (two
    POV-Ray processes, not three); the depths are the same as with it."""
    import numpy as np
    from povlens.plan.auto import probe_axial_mm, start_depth_probe
    depths = {}
    for wanted in (True, False):
        out = tmp_path / str(wanted)
        out.mkdir()
        opts = ConvertOptions.of(scene=PAPER, lens="cooke.triplet.50mm", focus=4.0,
                              outdir=str(out), width=96, height=72, method="mesh",
                              vignetting=wanted)
        plan = make_plan_with_lens(opts)[0]
        probe = start_depth_probe(opts, plan.film, plan)
        assert ("view" in probe.renders) is wanted
        depths[wanted] = probe_axial_mm(probe)
        assert (probe.image is not None) is wanted
    np.testing.assert_array_equal(depths[True], depths[False])


def test_probe_renders_the_view_and_the_decision_judges_vignetting_by_it(tmp_path):
    """The probe's view as it is equals a pinhole render at the probe size; a lens
    whose corners lose 12 % (cooke.triplet.50mm) is a deviation on a bright scene
    and none on the same scene made dark at the edges."""
    import numpy as np
    from povlens.plan.auto import probe_size, start_depth_probe
    from povlens.plan.image_error import probe_image_error
    from povlens.util.images import read_image
    from povlens.pov.process import render
    out = tmp_path / "o"
    out.mkdir()
    opts = ConvertOptions.of(scene=PAPER, lens="cooke.triplet.50mm", focus=4.0, outdir=str(out),
                          width=96, height=72, method="mesh")
    plan = make_plan_with_lens(opts)[0]
    model, film = plan.thin_lens, plan.film
    probe = start_depth_probe(opts, film, plan)
    probe.result()
    pw, ph = probe_size(film)
    assert probe.image.shape == (ph, pw, 3)
    (out / "pin.pov").write_text((ROOT / "scenes" / "paper.pov").read_text())
    from povlens.plan.folder_writer import write_folder
    write_folder(out, plan)
    ref = read_image(render(out / "pinhole.pov", out / "pin.exr", pw, ph))[..., :3]
    np.testing.assert_allclose(probe.image, ref, atol=2e-3)
    e = plan.model_error
    bright = probe_image_error(np.ones((ph, pw, 3)) + 0.01 * (np.arange(pw) % 2)[None, :, None],
                               film, e, 0.5)
    assert bright["vignetting_rmse"] > bright["shift_rmse"]     # flat bright: vignetting shows
    dark_edges = probe.image.copy()
    r = np.hypot(*np.meshgrid(np.linspace(-1, 1, pw), np.linspace(-1, 1, ph)))
    dark_edges[r > 0.6] = 0.0
    dark = probe_image_error(dark_edges, film, e, 0.5)
    assert dark["vignetting_rmse"] < 0.2 * bright["vignetting_rmse"]
    # the map carries the vignetting: what decides is what it cannot carry, the cat's eye
    # (a range from 1 m: blurred beyond a pinhole's budget)
    near = model.centre_z_mm + 1000.0
    kw = dict(near_z_mm=near, far_z_mm=near + 10000.0, model=model, model_error=e,
              pixel_pitch_mm=film.pixel_pitch_mm)
    big = decide(**kw, image_error=dict(bright, catseye_rmse=bright["shift_rmse"]))
    small = decide(**kw, image_error=dict(bright, catseye_rmse=0.5 * bright["shift_rmse"]))
    assert "at least the" in " ".join(big.reasons) and big.method == "mesh"
    assert "less than the" in " ".join(small.reasons) and small.method != "mesh"
    assert "applied as a map" in " ".join(small.reasons)


def test_sample_count_is_the_blur_rule_rounded_to_a_power_of_two():
    from povlens.plan.decision import SAMPLES_PER_BLUR_PX, samples_for_blur
    assert samples_for_blur(0.0) == MIN_SAMPLES
    assert samples_for_blur(math.inf) == MAX_SAMPLES and samples_for_blur(1e200) == MAX_SAMPLES
    for b in [0.3, 3.0, 3.6, 4.5, 5.0, 6.1, 7.3, 9.0, 12.0, 15.0, 17.9, 40.0]:
        n = samples_for_blur(b)
        assert MIN_SAMPLES <= n <= MAX_SAMPLES and n & (n - 1) == 0
        raw = math.ceil(SAMPLES_PER_BLUR_PX * b)
        if MIN_SAMPLES < n < MAX_SAMPLES:          # the nearest power of two in log2
            assert abs(math.log2(n) - math.log2(raw)) <= 0.5
    assert samples_for_blur(7.3) == 16               # ceil(2 * 7.3) = 15 -> 16
    assert samples_for_blur(20.7) == 32 and samples_for_blur(23.0) == 64   # 42, 46
    assert samples_for_blur(100.0) == 256 and samples_for_blur(49.9, n_max=100) == 100
    assert samples_for_blur(5.0, n_min=4, n_max=8) == 8


def test_a_catseye_that_takes_most_of_the_budget_prefers_a_minimum_mesh():
    """cooke.triplet.50mm focused at 4 m on a scene 4..100 m away: the thin lens is
    within the budget and the blur under a pixel (the minimum mesh count).  Whether
    focal_blur is chosen depends on the share of the budget what its vignetting map
    cannot carry (the cat's eye) takes in the scene's image; the vignetting itself,
    however large, is applied as a map and does not count."""
    kw = dict(tolerance_px=0.5)
    low = _decide("cooke.triplet.50mm", None, 4, 4, 100, 160, 120,
                  image_error={"vignetting_rmse": 0.9, "catseye_rmse": 0.03,
                               "shift_rmse": 0.1}, **kw)
    assert low.method == "focal-blur", low.reasons
    assert low.numbers["vignetting_floor_share"] == pytest.approx(0.3)
    high = _decide("cooke.triplet.50mm", None, 4, 4, 100, 160, 120,
                   image_error={"vignetting_rmse": 0.0, "catseye_rmse": 0.07,
                                "shift_rmse": 0.1}, **kw)
    assert high.method == "mesh" and high.samples == MIN_SAMPLES, high.reasons
    assert "uses 0.70 of it" in high.reasons[-1]
    # without vignetting wanted there is no floor
    free = _decide("cooke.triplet.50mm", None, 4, 4, 100, 160, 120, vignetting=False,
                   image_error={"vignetting_rmse": 0.07, "catseye_rmse": 0.07,
                                "shift_rmse": 0.1}, **kw)
    assert free.method == "focal-blur"
    # a blur that needs more than the minimum count keeps focal_blur (near 1 m, 6.6 px
    # at 480x360: 16 samples; a 1 px tolerance keeps the thin lens within the budget there)
    deep = _decide("cooke.triplet.50mm", None, 4, 1, 100, 480, 360, tolerance_px=1.0,
                   image_error={"vignetting_rmse": 0.07, "catseye_rmse": 0.07,
                                "shift_rmse": 0.1})
    assert deep.numbers["max_blur_px"] > 6 and deep.method == "focal-blur", deep.reasons


@pytest.mark.parametrize("lens, guess", [("dgauss.50mm", "mesh"), ("fisheye.10mm", "mesh"),
                                         ("cooke.triplet.50mm", "views"),
                                         ("tessar.50mm", "views"),
                                         ("telephoto.250mm", "views"), ("wide", "views")])
def test_early_guess_of_the_bundled_lenses(lens, guess):
    """At 160x120 and 4 m: dgauss.50mm distorts by 0.52 px and the fisheye by 13 px
    at the standard depths (mesh); the others' vignetting is applied as a map."""
    from povlens.plan.plan_finish import make_plan
    from povlens.plan.speculative import early_guess
    opts = ConvertOptions.of(scene=PAPER, lens=lens, focus=4.0, outdir="unused",
                          method="focal-blur", width=160, height=120)
    plan = make_plan(opts)
    assert early_guess(opts, plan) == guess
