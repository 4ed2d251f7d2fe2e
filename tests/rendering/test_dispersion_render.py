"""``--dispersion``: wavelengths of lens samples, spectral compositing, and real
POV-Ray renders at 160 x 120 through a strongly dispersive test lens (a plano-convex
singlet of a fictional V_d = 12 glass, the stop 10 mm behind it: ~4 px of lateral
colour at 0.6 of the field)."""

import math
import os
import subprocess
import sys

import numpy as np
import pytest

from povlens.cli import main
from povlens.errors import PovlensError
from povlens.lens.dispersion import BAND_NM, chief_landing_mm
from povlens.plan.schema import read_plan
from povlens.rendering import spectral
from povlens.rendering.composite import accumulate_samples, measurement_image
from povlens.rendering.folder_inputs import lens_for
from povlens.util.images import read_image, write_exr

from conftest import ROOT

LENS = """# test lens: plano-convex singlet, fictional glass V_d {vd}, stop 10 mm behind it
25\t6\t1.6\t30\t{vd}
1e6\t10\t1\t30\t0
0\t0\t0\t4\t0
"""
EDGE = """// a white emissive half-plane right of x = 0.9 at 4 m, black elsewhere
camera { perspective location <0, 0, 0> look_at <0, 0, 1> }
background { rgb 0 }
box { <0.9, -10, 4>, <20, 10, 4.01> pigment { rgb 1 } finish { emission 1 diffuse 0 ambient 0 } }
"""
GREY = """// a uniform grey emissive card filling the view at 4 m
camera { perspective location <0, 0, 0> look_at <0, 0, 1> }
background { rgb 0 }
box { <-20, -20, 4>, <20, 20, 4.01> pigment { rgb 0.5 } finish { emission 1 diffuse 0 ambient 0 } }
"""
SIZE = ["--width", "160", "--height", "120", "--focus", "4", "--method", "mesh"]


def povlens(*args):
    return subprocess.run([sys.executable, "-m", "povlens", *map(str, args)],
                          capture_output=True, text=True, cwd=ROOT, env=dict(os.environ),
                          timeout=600)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("dispersion")
    for name, text in (("lens.dat", LENS.format(vd=12)), ("flat.dat", LENS.format(vd="inf")),
                       ("edge.pov", EDGE), ("grey.pov", GREY)):
        (d / name).write_text(text)
    return d


def render(files, scene, lens, out, *extra):
    r = povlens("render", files / scene, "--lens", files / lens, *SIZE, "-o", files / out,
                *extra)
    assert r.returncode == 0, r.stderr
    return read_image(files / out / "image.exr")[..., :3].astype(np.float64), r.stderr


# ----- wavelengths and colour weights ------------------------------------------------

def test_wavelengths_are_stratified_prefix_stable_and_in_the_band():
    lam = spectral.sample_wavelength_nm(np.arange(81))
    assert np.all((lam >= BAND_NM[0]) & (lam <= BAND_NM[1]))
    np.testing.assert_array_equal(spectral.sample_wavelength_nm(np.arange(9)), lam[:9])
    assert not np.array_equal(spectral.sample_wavelength_nm(np.arange(9), seed=1), lam[:9])
    # 81 = 3^4 samples: one in each of the 81 quantiles of p(lambda)
    u = np.sort((spectral._radical_inverse_3(np.arange(81)) + 0.5) % 1.0)
    np.testing.assert_array_equal(np.floor(u * 81), np.arange(81))


def test_colour_weights_integrate_to_one_and_factors_average_to_one():
    lam = np.arange(BAND_NM[0], BAND_NM[1] + 0.5, 1.0)
    w = spectral.colour_weights(lam)
    assert np.all(w >= 0)
    np.testing.assert_allclose(np.trapezoid(w, lam, axis=0) if hasattr(np, "trapezoid")
                               else np.trapz(w, lam, axis=0), 1.0, rtol=1e-9)
    # blue, green, red peak in that order
    peaks = lam[np.argmax(w, axis=0)]
    assert peaks[2] < peaks[1] < peaks[0]
    f = spectral.channel_factors(16)
    np.testing.assert_allclose(f.mean(axis=0), 1.0, rtol=1e-12)


def test_spectral_composite_keeps_grey_exactly_grey(tmp_path):
    rng = np.random.default_rng(0)
    paths, weights = [], []
    for k in range(8):          # grey images, weights that differ per sample and pixel
        p = tmp_path / f"s{k}.exr"
        write_exr(p, np.full((6, 5, 3), 0.25, np.float32))
        paths.append(p)
        weights.append(rng.random((6, 5)) * (rng.random((6, 5)) > 0.3))
    f = spectral.channel_factors(8)
    total, wsum = accumulate_samples(paths, weights, channel_weights=f)
    assert wsum.shape == (6, 5, 4)
    img = measurement_image(total, wsum, np.full(6, 8.0), 2.0)
    plain_total, plain_w = accumulate_samples(paths, weights)
    expect = np.where(plain_w > 0, 0.25, 0.0) * plain_w * 2.0 / 8.0
    for c in range(3):
        np.testing.assert_allclose(img[..., c], expect, rtol=1e-6, atol=1e-12)


def test_missing_colour_science_is_a_clear_error(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))     # a cache is no colour-science
    spectral._tables.cache_clear()
    monkeypatch.setitem(sys.modules, "colour", None)
    with pytest.raises(PovlensError, match="colour-science"):
        spectral.sample_wavelength_nm(0)
    spectral._tables.cache_clear()


# ----- renders -------------------------------------------------------------------------

def _mean_edge(profile, plateau):
    """Mean edge position (px, from the window's start) of a rising edge."""
    return float(np.sum(1.0 - profile / plateau))


@pytest.mark.parametrize("ray_mesh", ["field", "pixel"])
def test_edge_shows_the_tracers_lateral_colour(files, ray_mesh):
    out = f"edge-{ray_mesh}"
    img, _ = render(files, "edge.pov", "lens.dat", out, "--dispersion", "--samples", "32",
                    "--ray-mesh", ray_mesh)
    plan = read_plan(files / out)
    assert (plan.field_mesh is None) == (ray_mesh == "pixel")
    assert plan.inputs.dispersion and plan.dispersion["rendered"]
    rows = img[54:66].mean(axis=0)                       # (W, 3) around the middle row
    g = rows[:, 1]
    edge_col = int(np.argmax(g > 0.5 * g.max()))
    lo, hi = edge_col - 12, edge_col + 12
    # the plateau (vignetting, achromatic) from a line fit right of the fringes
    x = np.arange(hi, min(hi + 8, img.shape[1]))
    fit = np.polyfit(x, g[x], 1)
    plateau = np.polyval(fit, np.arange(lo, hi))
    pos = [_mean_edge(rows[lo:hi, c], plateau) for c in range(3)]
    measured = pos[2] - pos[0]                           # blue edge minus red edge, px
    # predicted: the channels' colour-weighted mean landing of the edge's object point
    lens = lens_for(plan)
    pitch = plan.film.pixel_pitch_mm
    r_mm = (edge_col + 0.5 - plan.film.width_px / 2) * pitch
    lam = np.arange(BAND_NM[0], BAND_NM[1] + 0.5, 2.0)
    land = chief_landing_mm(lens, plan.focus.film_distance_mm,
                            plan.focus.object_distance_from_film_mm, [r_mm], lam)[:, 0]
    w = spectral.colour_weights(lam)
    ok = np.isfinite(land)
    mean = [(w[ok, c] @ land[ok]) / w[ok, c].sum() for c in range(3)]
    predicted = (mean[2] - mean[0]) / pitch
    print(f"{ray_mesh}: lateral colour measured {measured:.3f} px, predicted {predicted:.3f} px")
    assert predicted > 1.5                               # a colour fringe worth measuring
    assert measured == pytest.approx(predicted, rel=0.3)


@pytest.mark.parametrize("ray_mesh", ["field", "pixel"])
def test_grey_card_stays_grey(files, ray_mesh):
    img, _ = render(files, "grey.pov", "lens.dat", "grey" + "-px" * (ray_mesh == "pixel"),
                    "--dispersion", "--samples", "16", "--ray-mesh", ray_mesh)
    lit = img[..., 1] > 0.05
    assert lit.mean() > 0.9
    for c in (0, 2):
        ratio = img[..., c][lit] / img[..., 1][lit]
        assert np.max(np.abs(ratio - 1.0)) < 0.01


def test_glass_without_dispersion_renders_as_without_the_option(files):
    with_opt, _ = render(files, "edge.pov", "flat.dat", "flat-d", "--dispersion",
                         "--samples", "16")
    without, _ = render(files, "edge.pov", "flat.dat", "flat", "--samples", "16")
    other_seed, _ = render(files, "edge.pov", "flat.dat", "flat-s1", "--dispersion",
                           "--samples", "16", "--seed", "1")
    assert read_plan(files / "flat-d").inputs.dispersion
    # the noise of the spectral estimate: the same render with other sample points
    noise = math.sqrt(np.mean((with_opt - other_seed) ** 2))
    diff = math.sqrt(np.mean((with_opt - without) ** 2))
    print(f"rmse with/without {diff:.4g}, seed 0/1 {noise:.4g}")
    assert 0 < diff < noise
    assert with_opt.mean() == pytest.approx(without.mean(), rel=0.01)


def test_dispersion_in_plan_and_notes(files):
    out = files / "cooke"
    r = povlens("convert", ROOT / "scenes" / "chart.pov", "--lens", "cooke.triplet.50mm",
                "--dispersion", *SIZE, "--samples", "4", "-o", out, "--json")
    assert r.returncode == 0, r.stderr
    plan = read_plan(out)
    d = plan.dispersion
    assert plan.inputs.dispersion and d["rendered"]
    assert len(d["lateral_colour_px"]) == len(d["field_fraction"]) == 6
    assert d["longitudinal_colour_mm"] is not None and d["model"]
    assert plan.field_mesh.pupil_disc_radius_mm >= d["pupil_disc_radius_d_line_mm"]
    # a lens without Abbe numbers: rendered as before, with a note
    r = povlens("convert", ROOT / "scenes" / "chart.pov", "--lens", "dgauss.50mm",
                "--dispersion", *SIZE, "--samples", "4", "-o", files / "dg")
    assert r.returncode == 0, r.stderr
    assert "povlens: note: --dispersion: the lens file" in r.stderr and "Abbe" in r.stderr
    plan = read_plan(files / "dg")
    assert plan.inputs.dispersion is None and plan.dispersion is None
    assert '"dispersion":' not in (files / "dg" / "plan.json").read_text()
    # a method that cannot render it: a note, the numbers still in the plan
    r = povlens("convert", ROOT / "scenes" / "chart.pov", "--lens", "tessar.50mm",
                "--dispersion", *SIZE[:-2], "--method", "focal-blur", "-o", files / "fb")
    assert r.returncode == 0, r.stderr
    assert "only the mesh method renders colour fringes" in r.stderr
    plan = read_plan(files / "fb")
    assert plan.inputs.dispersion is None and plan.dispersion["rendered"] is False
    # per-pixel meshes: the exit-pupil table grown to hold the band (a factor per knot)
    r = povlens("convert", ROOT / "scenes" / "chart.pov", "--lens", "cooke.triplet.50mm",
                "--dispersion", *SIZE, "--samples", "4", "--ray-mesh", "pixel",
                "-o", files / "px")
    assert r.returncode == 0, r.stderr
    plan = read_plan(files / "px")
    assert plan.inputs.dispersion and plan.field_mesh is None and plan.dispersion["rendered"]
    factors = plan.dispersion["pupil_dilation"]
    assert len(factors) > 1 and all(1.0 <= f < 1.1 for f in factors)


def test_composite_without_colour_science_exits_2(files, monkeypatch, capsys):
    if not (files / "grey" / "plan.json").exists():
        render(files, "grey.pov", "lens.dat", "grey", "--dispersion", "--samples", "16")
    spectral._tables.cache_clear()
    monkeypatch.setitem(sys.modules, "colour", None)
    monkeypatch.setenv("XDG_CACHE_HOME", str(files / "no-cache"))
    rc = main(["composite", str(files / "grey")])
    spectral._tables.cache_clear()
    err = capsys.readouterr().err
    assert rc == 2
    assert "colour-science" in err and "Traceback" not in err


def test_report_shows_the_colour(files):
    if not (files / "edge-field" / "plan.json").exists():
        render(files, "edge.pov", "lens.dat", "edge-field", "--dispersion", "--samples", "32")
    r = povlens("report", files / "edge-field", "-o", files / "report.html")
    assert r.returncode == 0, r.stderr
    page = (files / "report.html").read_text()
    d = read_plan(files / "edge-field").dispersion
    assert f"colour (--dispersion, rendered): lateral up to {d['max_lateral_colour_px']:.3g} px" \
        in page
    assert "lateral colour (px)" in page


def test_auto_picks_mesh_when_the_colour_is_visible(files):
    from povlens.plan.dispersion_plan import colour_decision
    from povlens.plan.options import ConvertOptions
    from povlens.plan.schema import Decision
    out = files / "auto"
    r = povlens("convert", files / "edge.pov", "--lens", files / "lens.dat", "--dispersion",
                *SIZE, "--samples", "4", "-o", out)
    assert r.returncode == 0, r.stderr
    plan = read_plan(out)
    lens = lens_for(plan)
    opts = ConvertOptions.of(scene=str(files / "edge.pov"), lens=str(files / "lens.dat"),
                          focus=4.0, outdir=str(out), method="auto", dispersion=True)
    view = Decision("focal-blur", 32, ["-> focal-blur: within the budget"])
    chosen = colour_decision(opts, lens, plan, view)
    assert (chosen.method, chosen.samples) == ("mesh", 16)
    assert chosen.reasons[-1].startswith("-> mesh: --dispersion")
    kept = colour_decision(opts.replace(tolerance_px=1e3), lens, plan, view)
    assert kept.method == "focal-blur" and "within the tolerance" in kept.reasons[-2]
    assert colour_decision(opts.replace(dispersion=False), lens, plan,
                           view) is view


def test_cached_colour_tables_equal_colour_sciences(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    spectral._tables.cache_clear()
    first = spectral._tables()                          # made with colour-science, cached
    assert list((tmp_path / "povlens").glob("cmf-srgb-*.npz"))
    spectral._tables.cache_clear()
    again = spectral._tables()                          # read from the cache
    spectral._tables.cache_clear()
    for a, b, c in zip(first, again, spectral.tables_from_colour_science()):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)
