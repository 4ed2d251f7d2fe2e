"""The exit-pupil table over the film's x and y (povlens.pupil.grid_table), for lenses that
are not rotationally symmetric: on a rotationally symmetric lens it agrees with the radial
table; on lentil's anamorphic 2x designs (2004: a cylindrical front attachment on a prime,
2003: a rear anamorph behind a prime) its regions hold every ray found by brute-force
tracing, and its irradiance along x and along y is naive rear-element sampling's within
Monte Carlo error, with far fewer rays lost.  Files, cache keys, selection, bad input."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from conftest import LENS_DIR, ROOT
from povlens.lens.focus import focus, thick_lens_film_distance_mm
from povlens.lens.import_lentil import import_lentil
from povlens.lens.prescription import read_lens
from povlens.lens.tracer import trace_from_film
from povlens.pupil.baselines import NaiveRearElement
from povlens.pupil.build import build_pupil_table
from povlens.pupil.grid_build import build_grid_pupil_table
from povlens.pupil.grid_prober import GridProber
from povlens.pupil.grid_table import GridPupilTable, frame_extent_mm
from povlens.pupil.storage import cached_pupil_table, load, load_if_current, needs_grid_table
from povlens.errors import ParameterError

LENTIL = ROOT / "tests" / "data" / "lentil-lenses.json"
#: (lentil entry, frame extent (X, Y) mm): 2004 on a 24 x 18 mm frame, 2003 on 36 x 24.
ANAMORPHIC = {"2004": (12.0, 9.0), "2003": (18.0, 12.0)}
_CACHE: dict = {}


def lentil_lens(entry: str):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # the importer's notes on clipped rims
        return import_lentil(LENTIL, entry).lens


def anamorphic(entry: str):
    """(lens, film distance focused at 5 m, grid table) of a lentil entry."""
    if entry not in _CACHE:
        lens = lentil_lens(entry)
        fd = focus(lens, 5000.0).exact_film_distance_mm
        _CACHE[entry] = (lens, fd, build_grid_pupil_table(lens, fd, ANAMORPHIC[entry]))
    return _CACHE[entry]


def dgauss():
    """(lens, film distance, radial table, grid table) of dgauss.50mm at 10 m, 28 x 21 mm."""
    if "dgauss" not in _CACHE:
        lens = read_lens(LENS_DIR / "dgauss.50mm.dat")
        fd = thick_lens_film_distance_mm(lens, 10_000.0)
        _CACHE["dgauss"] = (lens, fd, build_pupil_table(lens, fd, 17.5),
                            build_grid_pupil_table(lens, fd, (14.0, 10.5)))
    return _CACHE["dgauss"]


def brute_force_misses(table, lens, fd, film_xy, n=200) -> tuple[int, int]:
    """(passing rays on a dense grid over the disc that holds every ray that can pass,
    how many of them lie outside the table's region) at one film point."""
    pr = GridProber(lens, fd, table.plane_z_mm)
    cx, cy, R = pr.domain(film_xy[0], film_xy[1])
    g = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    X, Y = np.meshgrid(cx[0] + R[0] * g, cy[0] + R[0] * g)
    ok = pr.passes(film_xy[0], film_xy[1], X, Y)
    inside = table.contains_at(film_xy, np.stack([X[ok], Y[ok]], 1))
    return int(ok.sum()), int((~inside).sum())


def mc_sigma(sampler, lens, fd, film_xy, n):
    """Standard error of the sampler's E/L estimate at each film point (iid estimate of
    the weights' spread: an upper bound for the scrambled Sobol' points used)."""
    from povlens.pupil.monte_carlo import sobol_points
    u = sobol_points(n, 2, seed=0)
    out = []
    for f in np.asarray(film_xy, float):
        s = sampler.sample(np.repeat(f[None], n, 0), u)
        ok = trace_from_film(lens, fd, s.film_point, s.direction).passed & s.valid
        w = np.where(ok, s.weight, 0.0)
        out.append(w.std() / math.sqrt(n))
    return np.array(out)


# ----- rotationally symmetric lens: the grid table against the radial one ---------------

def test_on_a_round_lens_the_grid_table_agrees_with_the_radial_table():
    """dgauss.50mm: at film points on the axes, the diagonal and in between, E/L and the
    pass fraction of the grid table are the radial table's within Monte Carlo error, and
    the on-axis irradiance factors (each from its own exact boundary) agree."""
    lens, fd, radial, grid = dgauss()
    pts = np.array([[0, 0], [6, 0], [0, 6], [-9, 4], [10, -7], [13.9, 10.4], [3, -10.3]], float)
    n = 1 << 14
    e_r = radial.irradiance_factor_at(pts, n_samples=n)
    e_g = grid.irradiance_factor_at(pts, n_samples=n)
    sig = np.hypot(mc_sigma(radial, lens, fd, pts, 4096) * 2, mc_sigma(grid, lens, fd, pts, 4096) * 2)
    assert np.all(np.abs(e_g - e_r) < 4 * sig + 1e-9), (e_g, e_r, sig)
    assert abs(grid.axial_irradiance_factor / radial.axial_irradiance_factor - 1) < 1e-6
    pf_r = radial.pass_fraction_at(pts, n_samples=2048).fraction
    pf_g = grid.pass_fraction_at(pts, n_samples=2048).fraction
    # the grid's default tolerance is twice the radial table's: a few more rays lost
    assert np.all(pf_g > 0.95) and np.all(pf_g > pf_r - 0.05), (pf_g, pf_r)


def test_grid_table_areas_are_the_radial_regions_areas():
    """The dilated regions' areas at film points of equal radius and other azimuths are
    within the two tolerances of the radial table's area there."""
    _, _, radial, grid = dgauss()
    r = np.array([0.0, 4.0, 9.0, 10.4])
    phi = np.array([0.0, 0.4, 1.1, 1.5])
    pts = np.stack([r * np.cos(phi), r * np.sin(phi)], 1)
    ratio = grid.area_at(pts) / radial.area_mm2(r)
    assert np.all(np.abs(ratio - 1) < 0.04), ratio


# ----- anamorphic lenses: containment and irradiance against naive sampling -------------

@pytest.mark.parametrize("entry", sorted(ANAMORPHIC))
def test_anamorphic_regions_hold_every_ray_that_passes(entry):
    """Dense brute-force tracing at the frame's corners, on its axes and at random film
    points between the grid's checks: no passing ray lies outside the table's region."""
    lens, fd, table = anamorphic(entry)
    assert lens.is_anamorphic and needs_grid_table(lens)
    X, Y = ANAMORPHIC[entry]
    rng = np.random.default_rng(7)
    pts = np.concatenate([[[0, 0], [X, 0], [0, Y], [X, Y], [-X, -Y], [0.37 * X, -0.81 * Y]],
                          rng.uniform(-1, 1, (10, 2)) * (X, Y)])
    total = 0
    for f in pts:
        passed, outside = brute_force_misses(table, lens, fd, f, n=180)
        total += passed
        assert outside == 0, f"{entry}: {outside} of {passed} passing rays outside at {f}"
    assert total > 50_000


@pytest.mark.parametrize("entry", sorted(ANAMORPHIC))
def test_anamorphic_irradiance_along_x_and_y_matches_naive_rear_element_sampling(entry):
    """E/L at film points along x and along y (and off both axes): the table's estimate
    and naive rear-element sampling's (every ray toward the whole rear element) agree
    within 4 standard errors; the table wastes few rays, the naive sampler most."""
    lens, fd, table = anamorphic(entry)
    X, Y = ANAMORPHIC[entry]
    pts = np.array([[0, 0], [0.5 * X, 0], [X, 0], [0, 0.5 * Y], [0, Y], [0.7 * X, -0.6 * Y]])
    naive = NaiveRearElement.build(lens, fd, math.hypot(X, Y))
    e_t = table.irradiance_factor_at(pts, n_samples=1 << 14)
    e_n = naive.irradiance_factor_at(pts, n_samples=1 << 16)
    sig = np.hypot(mc_sigma(table, lens, fd, pts, 4096) / 2, mc_sigma(naive, lens, fd, pts, 4096) / 4)
    assert np.all(np.abs(e_t - e_n) < 4 * sig), (e_t, e_n, sig)
    # x and y differ on an anamorphic lens (what a radial table could not describe)
    assert abs(e_t[2] / e_t[4] - 1) > 0.02
    pf_t = table.pass_fraction_at(pts, n_samples=2048).fraction
    pf_n = naive.pass_fraction_at(pts, n_samples=2048).fraction
    print(f"{entry}: pass fraction table {np.round(pf_t, 3)}, naive {np.round(pf_n, 3)}")
    assert np.all(pf_t > 0.95) and np.all(pf_n < 0.75)


def test_samples_are_uniform_on_the_region_with_pdf_one_over_area():
    """At film points of lentil 2004, the samples' mean is the polygon's centroid (shoelace
    formula) and the pdf is 1 / the polygon's area; samples at mirrored film points are
    mirrored."""
    lens, fd, table = anamorphic("2004")
    from povlens.pupil.monte_carlo import sobol_points
    u = sobol_points(1 << 14, 2, seed=3)
    for f in ([0.0, 0.0], [7.5, 5.0], [11.0, 1.0], [2.0, 8.5]):
        poly = table.region_at(f)
        x, y = poly[:, 0], poly[:, 1]
        xn, yn = np.roll(x, -1), np.roll(y, -1)
        cross = x * yn - xn * y
        area = 0.5 * cross.sum()
        centroid = np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6 * area)
        s = table.sample(np.repeat([f], len(u), 0), u)
        assert s.valid.all()
        assert np.allclose(1.0 / s.pdf_per_mm2, abs(area), rtol=1e-9)
        size = math.sqrt(abs(area))
        assert np.all(np.abs(s.pupil_point[:, :2].mean(0) - centroid) < 2e-3 * size)
        pts = centroid + (s.pupil_point[:, :2] - centroid) * (1 - 1e-9)
        assert table.contains_at(f, pts).all()
        if f[0] == 0:
            continue
        m = table.sample(np.repeat([[-f[0], f[1]]], len(u), 0), u)
        assert np.allclose(m.pupil_point[:, 0], -s.pupil_point[:, 0])
        assert np.allclose(m.pupil_point[:, 1], s.pupil_point[:, 1])


def test_sample_map_is_continuous_over_the_quadrant():
    """Small film steps inside the quadrant move the pupil points of fixed u a little
    (no seams at cell edges)."""
    _, _, table = anamorphic("2004")
    u = np.random.default_rng(0).random((500, 2))
    for x in np.linspace(0.05, 11.9, 25):
        a = table.sample(np.tile([x, 3.0], (500, 1)), u).pupil_point
        b = table.sample(np.tile([x + 1e-4, 3.0], (500, 1)), u).pupil_point
        assert np.abs(a - b).max() < 0.05


def test_outside_points_and_nan_are_invalid_without_nan():
    _, _, table = anamorphic("2004")
    f = np.array([[13.0, 0.0], [0.0, 9.5], [np.nan, 1.0], [np.inf, 0.0], [1.0, 1.0]])
    s = table.sample(f, np.full((5, 2), 0.3))
    assert s.valid.tolist() == [False, False, False, False, True]
    for a in (s.pupil_point, s.direction, s.weight, s.pdf_per_mm2):
        assert np.all(np.isfinite(a))
    assert table.region_at([20.0, 0.0]).shape == (0, 2)


# ----- files, cache keys and selection --------------------------------------------------

def test_save_load_and_cache_keys(tmp_path):
    lens, fd, table = anamorphic("2004")
    path = tmp_path / "pupil.npz"
    table.save(path)
    back = load(path)
    assert isinstance(back, GridPupilTable) and back.lens.sha256() == lens.sha256()
    assert back.lens.is_anamorphic
    u = np.random.default_rng(1).random((100, 2))
    f = np.random.default_rng(2).uniform(-9, 9, (100, 2))
    assert np.array_equal(back.sample(f, u).pupil_point, table.sample(f, u).pupil_point)
    got = load_if_current(path, lens, fd, 15.0, film_extent_mm=(12.0, 9.0))
    assert got is not None
    assert load_if_current(path, lens, fd, 15.0, film_extent_mm=(12.0, 9.5)) is None
    assert load_if_current(path, lens, fd + 0.01, 15.0, film_extent_mm=(12.0, 9.0)) is None
    # a round lens asking for this file gets None (it needs the radial table)
    assert load_if_current(path, read_lens(LENS_DIR / "dgauss.50mm.dat"), fd, 15.0) is None
    again, reused = cached_pupil_table(path, lens, fd, 15.0, film_extent_mm=(12.0, 9.0))
    assert reused and isinstance(again, GridPupilTable)


def test_round_lenses_keep_the_radial_table_bit_for_bit(tmp_path):
    lens, fd, radial, _ = dgauss()
    assert not needs_grid_table(lens)
    table, reused = cached_pupil_table(tmp_path / "p.npz", lens, fd, 17.5,
                                       film_extent_mm=(14.0, 10.5))
    assert not reused and not isinstance(table, GridPupilTable)
    for name in ("film_radius_mm", "centre_x_mm", "scale_x_mm", "scale_y_mm", "rho"):
        assert np.array_equal(getattr(table, name), getattr(radial, name))


def test_frame_extent_and_bad_arguments():
    from povlens.lens.film import Film
    film = Film(24.0, 18.0, 96, 72, 1.5, -2.0)
    assert frame_extent_mm(film) == (13.5, 11.0)
    lens, fd, _ = anamorphic("2004")
    for bad in ((0.0, 9.0), (12.0, math.nan), "12"):
        with pytest.raises(ParameterError):
            build_grid_pupil_table(lens, fd, bad)
    with pytest.raises(ParameterError):
        build_grid_pupil_table(lens, fd, (12.0, 9.0), n_angles=30)


def test_plot_and_the_pupil_command_take_a_grid_table(tmp_path, capsys):
    """`povlens pupil` on an anamorphic lens file builds the grid table, compares it and
    draws its regions at film points along the frame's diagonal (no traceback)."""
    from povlens.cli import main
    from povlens.lens.prescription import write_lens
    from povlens.pupil.plot import plot_pupil_shapes
    lens, fd, table = anamorphic("2004")
    png = plot_pupil_shapes(table, tmp_path / "p.png", film_radii=[0.0, 7.0, 14.0], n_grid=48)
    assert png.stat().st_size > 1000
    path = tmp_path / "a.dat"
    write_lens(lens, path)
    rc = main(["pupil", str(path), "--focus", "5000", "--film-diagonal", "10", "--no-compare",
               "--tolerance", "0.02", "--samples", "256"])
    out = capsys.readouterr().out
    assert rc == 0 and "grid of film points over x and y (anamorphic lens)" in out
