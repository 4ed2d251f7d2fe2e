"""The relative illumination map: against brute-force tracing, the on-axis exact value,
the mesh render's own weights, and as a map of a film's pixels."""

import math

import numpy as np
import pytest

from conftest import ROUND_LENSES
from povlens.lens.film import Film
from povlens.lens.focus import thick_lens_film_distance_mm
from povlens.lens.prescription import read_lens
from povlens.lens.tracer import trace_from_film
from povlens.pupil.build import build_pupil_table
from povlens.pupil.illumination import (IlluminationProfile, illumination_profile,
                                        irradiance_at, profile_from_record, profile_record,
                                        relative_illumination_map)
from povlens.pupil.prober import PupilProber
from povlens.pupil.rays import ScenePlacement, sample_points, sample_rays
from povlens.pupil.monte_carlo import exposure_normalisation, sobol_points

HALF_DIAGONAL = 17.5  # 35 mm film diagonal


@pytest.fixture(scope="module")
def tables():
    out = {}
    for name in ("dgauss.50mm", "wide.22mm", "fisheye.10mm", "cooke.triplet.50mm"):
        lens = read_lens(name)
        out[name] = build_pupil_table(lens, thick_lens_film_distance_mm(lens, 4000.0),
                                      HALF_DIAGONAL)
    return out


@pytest.fixture(scope="module")
def profiles(tables):
    return {name: illumination_profile(t) for name, t in tables.items()}


def brute_force_irradiance(table, r: float, n: int = 1 << 18) -> float:
    """E/L at film point (r, 0) without the table: scrambled Sobol' points uniform in
    a disc of the sampling plane that holds every ray that can pass
    (:meth:`PupilProber.domain`), traced with the exact tracer, weight
    cos^4 / z_p^2 x disc area."""
    pr = PupilProber(table.lens, table.film_distance_mm, table.plane_z_mm)
    cx, rad = (float(v[0]) for v in pr.domain(np.array([r])))
    u = sobol_points(n, 2, seed=99)
    rho = rad * np.sqrt(u[:, 0])
    phi = 2 * math.pi * u[:, 1]
    zp = table.plane_z_mm
    d = np.column_stack([cx + rho * np.cos(phi) - r, rho * np.sin(phi), np.full(n, zp)])
    d /= np.linalg.norm(d, axis=1)[:, None]
    o = np.zeros((n, 3))
    o[:, 0] = r
    passed = trace_from_film(table.lens, table.film_distance_mm, o, d).passed
    cos4 = d[:, 2] ** 4
    return float(np.mean(np.where(passed, cos4, 0.0)) * math.pi * rad * rad / zp ** 2)


@pytest.mark.parametrize("name, radii", [("dgauss.50mm", (0.0, 6.0, 12.3, 17.5)),
                                         ("wide.22mm", (0.0, 9.0, 17.5)),
                                         ("fisheye.10mm", (0.0, 7.0, 12.0, 13.2)),
                                         ("cooke.triplet.50mm", (0.0, 17.5))])
def test_profile_matches_brute_force_tracing(tables, profiles, name, radii):
    """E/L from the exact boundaries agrees with 2^18 traced rays over a disc that
    holds every ray that can pass (their own error is ~1e-3 there), at the corner of
    the frame, in the cat's eye, and near the fisheye's cut-off."""
    t, p = tables[name], profiles[name]
    e = np.interp(radii, p.film_radius_mm, p.irradiance_factor)
    ref = np.array([brute_force_irradiance(t, r) for r in radii])
    np.testing.assert_allclose(e, ref, rtol=3e-3)
    ri = p.at(np.array(radii))
    np.testing.assert_allclose(ri, ref / ref[0], rtol=4e-3)
    # a 1 % error would be caught
    assert not np.allclose(1.01 * e[1:], ref[1:], rtol=3e-3)


@pytest.mark.parametrize("name", ROUND_LENSES)
def test_profile_on_axis_is_the_tables_exact_value(name):
    lens = read_lens(name)
    t = build_pupil_table(lens, thick_lens_film_distance_mm(lens, 10_000.0), HALF_DIAGONAL)
    p = illumination_profile(t)
    assert p.irradiance_factor[0] == pytest.approx(t.axial_irradiance_factor, rel=1e-4)
    assert p.relative_illumination[0] == 1.0
    assert np.all(np.isfinite(p.relative_illumination)) and np.all(p.relative_illumination >= 0)
    assert np.all(np.diff(p.film_radius_mm) > 0)
    # to the frame's corner, or to the cut-off beyond which no ray gets through
    assert p.film_radius_mm[-1] >= min(HALF_DIAGONAL, t.vignetted_beyond_mm or math.inf)


def test_profile_between_its_radii_is_within_its_interpolation_tolerance(tables, profiles):
    """Linear interpolation between the profile's radii (refined where a rim starts
    to cut: a kink between grid points) against direct evaluation at random radii."""
    for name in ("dgauss.50mm", "wide.22mm", "fisheye.10mm"):
        t, p = tables[name], profiles[name]
        end = min(HALF_DIAGONAL, t.vignetted_beyond_mm or HALF_DIAGONAL) - 0.05
        r = np.sort(np.random.default_rng(5).uniform(0, end, 60))
        direct = irradiance_at(t, r) / p.irradiance_factor[0]
        assert np.max(np.abs(p.at(r) - direct)) < 2e-4, name
    # without the refinement (every 4th radius) it would not hold
    assert np.max(np.abs(np.interp(r, p.film_radius_mm[::4], p.relative_illumination[::4])
                         - direct)) > 2e-4


def test_map_is_the_mean_weight_of_the_mesh_render(tables, profiles):
    """What the mesh composite multiplies a pixel by (its mean radiometric weight
    times the exposure) converges to the map: 64 jittered samples per pixel of a
    40 x 30 image through dgauss.50mm, averaged over rings of film radius."""
    t, p = tables["dgauss.50mm"], profiles["dgauss.50mm"]
    film = Film.from_diagonal(2 * HALF_DIAGONAL, 40, 30)
    placement = ScenePlacement(np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]),
                               np.array([0, 0, 1.0]), 1.0)
    n = 64
    pts = sample_points(n, film.height_px, film.width_px, seed=3)
    w = np.zeros((film.height_px, film.width_px))
    for k in range(n):
        w += sample_rays(t.lens, t.film_distance_mm, film, t, placement, pts(k)).weight
    mesh = w / n * exposure_normalisation(t, t.lens, t.film_distance_mm)
    ri = relative_illumination_map(p, film.width_mm, film.height_mm, film.width_px,
                                   film.height_px)
    r = np.hypot(*np.meshgrid((np.arange(40) + 0.5) / 40 - 0.5, (np.arange(30) + 0.5) / 30 - 0.5))
    ring = np.minimum((r / r.max() * 8).astype(int), 7)
    for k in range(8):
        sel = ring == k
        assert mesh[sel].mean() == pytest.approx(ri[sel].mean(), rel=5e-3), k
    # per pixel: the samples' own noise only
    assert np.sqrt(np.mean((mesh - ri) ** 2)) < 0.02
    assert ri.min() < 0.4 < ri.max()                      # the lens vignettes strongly


def test_map_of_a_film(profiles):
    p = profiles["dgauss.50mm"]
    film = Film.from_diagonal(2 * HALF_DIAGONAL, 64, 48)
    m = relative_illumination_map(p, film.width_mm, film.height_mm, 64, 48)
    assert m.shape == (48, 64) and m.dtype == np.float64
    np.testing.assert_allclose(m, m[::-1, :], rtol=1e-14)    # radially symmetric
    np.testing.assert_allclose(m, m[:, ::-1], rtol=1e-14)
    corner = p.at(np.hypot(film.width_mm, film.height_mm) / 2 * (1 - 1 / 64))
    assert m[0, 0] == pytest.approx(corner, abs=2e-3)
    assert m[0, 0] < 0.4 and m[23, 31] > 0.99
    centres = relative_illumination_map(p, film.width_mm, film.height_mm, 64, 48,
                                        pixel_average=False)
    # the mean over the pixel differs from its centre only where the profile bends
    assert np.max(np.abs(m - centres)) < 5e-3
    # the same table gives the same map
    np.testing.assert_array_equal(m, relative_illumination_map(p, film.width_mm,
                                                               film.height_mm, 64, 48))
    big = relative_illumination_map(p, 36.0, 24.0, 1920, 1080)
    assert big.shape == (1080, 1920) and np.all(np.isfinite(big))
    with pytest.raises(ValueError, match="pixels"):
        relative_illumination_map(p, 36.0, 24.0, 0, 10)
    with pytest.raises(ValueError, match="positive"):
        relative_illumination_map(p, -36.0, 24.0, 10, 10)


def test_fisheye_map_is_black_beyond_its_image_circle(tables, profiles):
    t, p = tables["fisheye.10mm"], profiles["fisheye.10mm"]
    cut = t.vignetted_beyond_mm
    assert cut is not None and cut < HALF_DIAGONAL
    assert p.at(cut + 0.01) == 0.0 and p.at(np.inf) == 0.0 and p.at(cut - 0.5) > 0
    m = relative_illumination_map(p, 28.0, 21.0, 160, 120)
    assert m[0, 0] == 0.0 and m[60, 80] > 0.99
    # the pixels the circle crosses take the mean over their area: between 0 and inside
    r = np.hypot(*np.meshgrid(((np.arange(160) + 0.5) / 160 - 0.5) * 28,
                              ((np.arange(120) + 0.5) / 120 - 0.5) * 21))
    edge = np.abs(r - cut) < 0.05
    assert edge.any() and np.all(m[edge] < p.at(r[edge] - 0.1))


def test_profile_record_round_trip(tables, profiles):
    t, p = tables["dgauss.50mm"], profiles["dgauss.50mm"]
    rec = profile_record(p, t)
    back = profile_from_record(rec, t)
    assert isinstance(back, IlluminationProfile)
    np.testing.assert_allclose(back.relative_illumination, p.relative_illumination, atol=1e-7)
    assert profile_from_record(rec, tables["wide.22mm"]) is None          # another lens
    assert profile_from_record({**rec, "film_distance_mm": 1.0}, t) is None
    assert profile_from_record({**rec, "relative_illumination": [1.0]}, t) is None
    assert profile_from_record(None, t) is None
