"""Adaptive mesh sampling: sharp row bands get fewer lens samples (POV-Ray +SR/+ER),
blocked samples are not rendered, unchanged inputs are not rendered again."""

import json
import os
import shutil

import numpy as np
import pytest

from povlens.plan.convert import ConvertOptions, convert
from povlens.plan.schema import PovraySettings
from povlens.util.images import read_image
from povlens.rendering.driver import render_outdir
from povlens.rendering.folder_composite import composite_outdir, sample_weight, samples_per_pixel
from povlens.rendering.mesh_samples import film_row_args, sample_rows

from conftest import ROOT

SCENES = ROOT / "scenes"
pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")


def opts(tmp_path, name, **kw):
    # Focus 1.5 m in paper.pov (everything is 4 m or farther): the far rows at the top
    # are blurred more than the floor rows at the bottom.  An 8.5 mm film makes the blur
    # several pixels at 48 x 36 (5.2..6.1 px: 8 and 16 samples).
    base = dict(scene=str(SCENES / "paper.pov"), lens="dgauss.50mm", focus=1.5,
                film_diagonal_mm=8.5, outdir=str(tmp_path / name), width=48, height=36,
                method="mesh", samples=32, adaptive=True)
    base.update(kw)
    return ConvertOptions.of(**base)


def test_row_args_map_film_rows_to_povray_rows():
    pv = PovraySettings(version="3.7.0.10", render_width=48, render_height=37, drop_top_rows=1)
    assert film_row_args(pv, (0, 36)) == ["+SR2"]                   # the 3.7.0.x extra top row
    assert film_row_args(pv, (8, 24)) == ["+SR10", "+ER25"]         # output rows 9..24 (0-based)
    assert film_row_args(pv, (0, 1)) == ["+SR2", "+ER2"]
    pv = PovraySettings(version="3.8.0", render_width=48, render_height=36, drop_top_rows=0)
    assert film_row_args(pv, (0, 36)) == []
    assert film_row_args(pv, (0, 1)) == [f"+ER{1.5 / 36:.9f}"]      # 1 would mean "all rows"
    assert film_row_args(pv, (16, 36)) == ["+SR17"]


def test_adaptive_plan_has_fewer_pixel_samples_and_correct_counts(tmp_path):
    plan = convert(opts(tmp_path, "a"))
    a = plan.adaptive
    n = plan.inputs.samples
    assert n == max(a.band_samples)
    assert len(set(a.band_samples)) > 1, a
    assert a.pixel_samples < a.uniform_pixel_samples
    # every sample in exactly one batch; samples below n_min render whole frames
    assert sorted(k for b in plan.batches for k in b) == list(range(n))
    for k in range(a.n_min):
        assert sample_rows(plan, k) == (0, 36)
    # N_p of a row is the samples its band needs
    n_p = samples_per_pixel(plan)
    for j, need in enumerate(a.band_samples):
        assert np.all(n_p[j * 8:(j + 1) * 8] >= need)
    assert n_p.sum() * 48 == a.pixel_samples
    # re-converting with the same inputs keeps the plan (rendered samples are kept)
    before = (tmp_path / "a" / "plan.json").read_text()
    convert(opts(tmp_path, "a"))
    assert (tmp_path / "a" / "plan.json").read_text() == before


def _rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)))


def test_adaptive_render_matches_uniform_and_resumes(tmp_path):
    plan = convert(opts(tmp_path, "a"))
    n = plan.inputs.samples
    render_outdir(tmp_path / "a", jobs=2, quiet=True)
    adaptive = read_image(tmp_path / "a" / "image.exr")[..., :3].astype(np.float64)
    rows = plan.sample_rows
    w = sample_weight(tmp_path / "a", n - 1)
    r0, r1 = rows[n - 1]
    assert np.all(w[:r0] == 0) and np.all(w[r1:] == 0) and np.any(w[r0:r1] > 0)
    # unchanged inputs: nothing is rendered again
    mtimes = {f: os.stat(f).st_mtime_ns for f in (tmp_path / "a" / "samples").glob("*.exr")}
    convert(opts(tmp_path, "a"))
    render_outdir(tmp_path / "a", jobs=2, quiet=True)
    assert {f: os.stat(f).st_mtime_ns for f in mtimes} == mtimes

    # the uniform render with the most samples (same seed: adaptive drops some of its
    # samples in the sharp rows), an independent one (another seed) as the reference,
    # and a uniform render with the fewest samples the adaptive plan gives any pixel
    def uniform(name, **kw):
        convert(opts(tmp_path, name, adaptive=False, **kw))
        out = render_outdir(tmp_path / name, jobs=2, quiet=True)
        return read_image(out)[..., :3].astype(np.float64)

    full = uniform("full", samples=n)
    ref = uniform("ref", samples=n, seed=7)
    n_low = int(samples_per_pixel(plan).min())
    low = uniform("low", samples=n_low, seed=3)
    e_drop, e_adaptive = _rmse(adaptive, full), _rmse(adaptive, ref)
    e_full, e_low = _rmse(full, ref), _rmse(low, ref)
    print(f"RMSE adaptive-full {e_drop:.4g}; vs an independent {n}-sample render: adaptive "
          f"{e_adaptive:.4g}, uniform {n} {e_full:.4g}, uniform {n_low} {e_low:.4g}")
    assert e_drop < 0.5 * e_low
    assert e_adaptive < 1.1 * e_full
    # a composite without vignetting works too
    img = composite_outdir(tmp_path / "a", vignetting=False, write=False)
    assert np.all(np.isfinite(img))


def test_blocked_sample_is_not_rendered_and_counts_as_black(tmp_path, monkeypatch):
    import povlens.rendering.mesh_samples as render
    convert(opts(tmp_path, "b", adaptive=False, samples=2, batch_size=2, ray_mesh="pixel"))
    real = render.sample_rays

    def blocked_for_sample_1(lens, fd, film, table, placement, points, rows=None):
        rays = real(lens, fd, film, table, placement, points, rows=rows)
        if blocked_for_sample_1.calls == 1:
            rays = type(rays)(rays.origin, rays.direction, np.zeros_like(rays.valid),
                              np.zeros_like(rays.weight))
        blocked_for_sample_1.calls += 1
        return rays

    blocked_for_sample_1.calls = 0
    monkeypatch.setattr(render, "sample_rays", blocked_for_sample_1)
    render_outdir(tmp_path / "b", jobs=1, quiet=True)
    s = tmp_path / "b" / "samples"
    assert (s / "sample_0000.exr").exists() and not (s / "sample_0001.exr").exists()
    assert (s / "sample_0001.blocked").exists()
    img = composite_outdir(tmp_path / "b", write=False)
    # sample 1 counts in N = 2: the image is half of sample 0's estimate alone
    plan = json.loads((tmp_path / "b" / "plan.json").read_text())
    plan_one = dict(plan, inputs=dict(plan["inputs"], samples=1))
    (tmp_path / "b" / "plan.json").write_text(json.dumps(plan_one))
    img1 = composite_outdir(tmp_path / "b", write=False)
    np.testing.assert_allclose(img, img1 / 2, rtol=1e-6, atol=1e-9)


def test_adaptive_bands_use_the_real_spot_where_it_is_larger_than_the_thin_lens_blur():
    """The f/1 singlet focused at 2 m: its thin-lens blur at 2 m is 0, but its
    spherical aberration makes a spot of many pixels, so every band needs more
    than the floor (before: every band 8 where the decision wanted 256)."""
    from povlens.plan.adaptive import adaptive_rows, real_blur_at, real_blur_model_error
    from povlens.plan.plan_finish import make_plan_with_lens
    o = ConvertOptions.of(scene=str(SCENES / "paper.pov"), lens="singlet.pcx.25mm", focus=2.0,
                       outdir="unused", width=48, height=36, method="mesh", samples=256)
    plan, lens = make_plan_with_lens(o)
    model, film = plan.thin_lens, plan.film
    axial = np.full((12, 16), 2000.0)                       # everything at the focus
    thin = adaptive_rows(model, axial, film, 256)
    assert set(thin.band_samples) == {8}
    err = real_blur_model_error(lens, plan, model, film, axial)
    spot = real_blur_at(err, model, axial)
    assert np.all(spot > 3.0)                               # px: far from sharp
    real = adaptive_rows(model, axial, film, 256, model_error=err)
    assert min(real.band_samples) > 8
    assert min(real.band_blur_px) == pytest.approx(float(spot.max()), rel=1e-9)
