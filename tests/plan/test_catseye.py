"""--method auto with the vignetting applied as a map: the lens's vignetting alone no
longer rules out the views; what the map cannot carry (the cat's eye of out-of-focus
light) is judged on the probe's image."""

import math
import pathlib
import shutil

import numpy as np
import pytest

from povlens.plan.convert import ConvertOptions, convert
from povlens.plan.decision import catseye_px, pupil_cut
from povlens.plan.image_error import catseye_rmse, shift_rmse
from povlens.plan.plan_finish import make_plan_with_lens
from povlens.pupil.illumination import illumination_profile
from povlens.pupil.storage import cached_pupil_table
from povlens.thinlens.model_error import ModelError

ROOT = pathlib.Path(__file__).resolve().parents[2]
PAPER = str(ROOT / "scenes" / "paper.pov")
CHART = str(ROOT / "scenes" / "chart.pov")
needs_povray = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")


def _lens_plan(tmp_path, lens, focus=4.0, w=160, h=120):
    opts = ConvertOptions.of(scene=PAPER, lens=lens, focus=focus, outdir=str(tmp_path / lens),
                          width=w, height=h, method="focal-blur")
    plan, L = make_plan_with_lens(opts)
    table, _ = cached_pupil_table(tmp_path / f"{lens}.npz", L, plan.focus.film_distance_mm,
                                  plan.film.half_diagonal_mm, save=False)
    return plan, table


def _checker(h, w, cell=4):
    y, x = np.mgrid[0:h, 0:w]
    c = (((x // cell) + (y // cell)) % 2).astype(float)
    return np.repeat((0.1 + 0.8 * c)[..., None], 3, axis=2)


def test_pupil_cut_of_the_bundled_lenses(tmp_path):
    """dgauss.50mm's rims cut half the pupil's width at the frame's corner; the
    Cooke triplet's pupil grows off axis and is not cut; the fisheye's is gone beyond
    its image circle."""
    cuts = {}
    for lens in ("dgauss.50mm", "cooke.triplet.50mm", "fisheye.10mm"):
        plan, table = _lens_plan(tmp_path, lens)
        cuts[lens] = pupil_cut(illumination_profile(table, plan.film.half_diagonal_mm))
    d = cuts["dgauss.50mm"]
    assert d["cut"][0] == 0.0 and 0.4 < d["cut"][-1] < 0.6
    assert max(cuts["cooke.triplet.50mm"]["cut"]) < 0.01
    assert cuts["fisheye.10mm"]["cut"][-1] == 1.0
    grid = ((0.0, 0.0), (2.0, 2.0))
    e = ModelError((1e3, 2e3), (0.0, 17.5), 0.0, 0.0, 1.0, 1.0, 0.0, grid, grid, grid, grid,
                   grid, grid)
    assert catseye_px(e, d) == pytest.approx(2.0 * d["cut"][-1])


def test_catseye_rmse_is_zero_in_focus_or_on_a_flat_image_and_grows_with_the_blur(tmp_path):
    plan, table = _lens_plan(tmp_path, "dgauss.50mm")
    model, film = plan.thin_lens, plan.film
    h, w = 48, 64
    img = _checker(h, w)
    focus = np.full((h, w), model.focus_distance_mm)
    assert catseye_rmse(img, film, table, model, focus) == pytest.approx(0.0, abs=1e-12)  # a point
    far = np.full((h, w), np.inf)
    assert catseye_rmse(np.full((h, w, 3), 0.5), film, table, model, far) == pytest.approx(
        0.0, abs=1e-12)                                                  # flat: nothing moves
    near = np.full((h, w), 1500.0)
    e_far, e_near = (catseye_rmse(img, film, table, model, a) for a in (far, near))
    assert 0 < e_far < e_near
    # the same scene through a lens whose pupil is not cut: far less
    plan_t, table_t = _lens_plan(tmp_path, "cooke.triplet.50mm")
    e_cooke = catseye_rmse(img, plan_t.film, table_t, plan_t.thin_lens, near)
    assert e_cooke < 0.5 * e_near
    # and nothing but the defocused corner counts: in focus there, the error drops
    mixed = near.copy()
    r = np.hypot(*np.meshgrid(np.linspace(-1, 1, w), np.linspace(-1, 1, h)))
    mixed[r > 0.8] = model.focus_distance_mm
    assert catseye_rmse(img, film, table, model, mixed) < 0.7 * e_near


@needs_povray
def test_a_sharp_scene_through_a_vignetting_lens_is_a_view_with_the_map(tmp_path):
    """paper.pov through dgauss.50mm (corners at a third of the centre's light) at
    4 m, 160x120: before the map, auto rendered 8 mesh samples for the vignetting
    alone; now the view, with the vignetting applied as a map."""
    plan = convert(ConvertOptions.of(scene=PAPER, lens="dgauss.50mm", focus=4.0,
                                  outdir=str(tmp_path / "a"), width=160, height=120,
                                  method="auto"))
    d = plan.decision
    n = d.numbers
    assert plan.inputs.method in ("pinhole", "focal-blur"), d.reasons
    assert n["min_relative_illumination"] < 0.4
    assert n["image_vignetting_rmse"] > 2 * n["image_shift_rmse"]   # what the old rule saw
    assert n["image_catseye_rmse"] < n["image_shift_rmse"]
    assert any("vignetting: applied as a map" in r for r in d.reasons)
    assert "illumination_profile" in n and n["vignetting"] == "applied as a map"


@needs_povray
def test_a_strongly_defocused_scene_with_a_strong_catseye_is_a_mesh_render(tmp_path):
    """chart.pov focused at 1.5 m, 640x480: its highlights 3..12 m away blur over
    tens of pixels, and dgauss.50mm's rims cut half of each blur disc near the
    corners; the map cannot carry that: mesh.  The Tessar's pupil is hardly cut:
    its cat's eye is no deviation on the same scene."""
    got = {}
    for lens in ("dgauss.50mm", "tessar.50mm"):
        got[lens] = convert(ConvertOptions.of(scene=CHART, lens=lens, focus=1.5,
                                           outdir=str(tmp_path / lens), width=640,
                                           height=480, method="auto")).decision
    d = got["dgauss.50mm"]
    assert d.method == "mesh" and d.samples >= 32, d.reasons       # 15.9 px of blur
    n = d.numbers
    assert n["image_catseye_rmse"] >= n["image_shift_rmse"]
    assert any("cat's-eye shape" in r and r.endswith("a deviation") for r in d.reasons)
    t = got["tessar.50mm"].numbers
    assert t["image_catseye_rmse"] < 0.5 * n["image_catseye_rmse"]
    assert t["image_catseye_rmse"] < t["image_shift_rmse"]
    assert math.isfinite(n["max_catseye_px"]) and n["max_catseye_px"] > 2.0


def test_shift_rmse_and_catseye_rmse_share_their_units(tmp_path):
    """Both are RMSEs of the same image: a checker moved by one probe pixel and the
    same checker seen through strongly clipped kernels are of the same order."""
    plan, table = _lens_plan(tmp_path, "dgauss.50mm")
    img = _checker(48, 64)
    e = catseye_rmse(img, plan.film, table, plan.thin_lens, np.full((48, 64), 1000.0))
    assert 0.05 * shift_rmse(img, 1.0) < e < 2 * shift_rmse(img, 1.0)
