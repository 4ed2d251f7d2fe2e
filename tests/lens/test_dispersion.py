"""Dispersion from n_d and V_d (lens/dispersion.py): the Cauchy model, lenses at a
wavelength, chromatic aberration and the pass radius of every wavelength."""

import math

import numpy as np
import pytest

from povlens.errors import LensFileError
from povlens.lens.dispersion import (BAND_NM, LINE_C_NM, LINE_D_NM, LINE_F_NM, chief_landing_mm,
                                     chromatic_aberration, disperses, has_abbe_numbers,
                                     index_at, lens_at_wavelength, pass_radius_mm)
from povlens.lens.focus import focus
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import parse_lens_text, read_lens
from povlens.lens.tracer import trace_from_film


def test_cauchy_model_goes_through_nd_and_gives_the_abbe_number():
    n_d, v_d = np.array([1.62041, 1.78472, 1.5]), np.array([60.32, 25.68, 0.0])
    n_f, n_dd, n_c = (index_at(n_d, v_d, lam) for lam in (LINE_F_NM, LINE_D_NM, LINE_C_NM))
    np.testing.assert_allclose(n_dd, n_d, rtol=0, atol=1e-15)
    np.testing.assert_allclose((n_d[:2] - 1) / (n_f[:2] - n_c[:2]), v_d[:2], rtol=1e-12)
    assert n_f[2] == n_c[2] == 1.5                      # V_d 0: unknown, no dispersion
    assert index_at([1.7], [math.inf], 400.0)[0] == 1.7  # V_d inf: none either
    assert index_at([1.0], [30.0], 400.0)[0] == 1.0      # air never disperses
    assert index_at([1.6], [30.0], 400.0)[0] > index_at([1.6], [30.0], 700.0)[0]


def test_lens_files_take_an_infinite_abbe_number_and_refuse_nan():
    lens = parse_lens_text("20 4 1.6 10 inf\n-20 0 1 10\n", "t.dat")
    assert has_abbe_numbers(lens) and not disperses(lens)
    assert lens_at_wavelength(lens, 400.0) is lens
    with pytest.raises(LensFileError, match="Abbe number"):
        parse_lens_text("20 4 1.6 10 nan\n-20 0 1 10\n", "t.dat")
    with pytest.raises(LensFileError, match="thickness"):
        parse_lens_text("20 inf 1.6 10 30\n-20 0 1 10\n", "t.dat")


def test_bundled_converted_lenses_carry_abbe_numbers():
    for name in ("cooke.triplet.50mm", "tessar.50mm", "singlet.pcx.25mm"):
        assert disperses(read_lens(name)), name
    assert not has_abbe_numbers(read_lens("dgauss.50mm"))
    assert read_lens("singlet.pcx.25mm").abbe_vd[1] == 25.68


def test_lens_at_wavelength_changes_only_the_glass_indices():
    lens = read_lens("cooke.triplet.50mm")
    blue = lens_at_wavelength(lens, 450.0)
    for a in ("radius_mm", "thickness_mm", "aperture_diameter_mm", "abbe_vd"):
        np.testing.assert_array_equal(getattr(blue, a), getattr(lens, a))
    glass = lens.index_after != 1.0
    assert np.all(blue.index_after[glass] > lens.index_after[glass])
    np.testing.assert_array_equal(blue.index_after[~glass], 1.0)
    with pytest.raises(ValueError):
        lens_at_wavelength(lens, -1.0)


def test_singlet_longitudinal_colour_is_the_thin_lens_f_over_v():
    # a thin positive singlet: f_F - f_C = -f / V_d (blue focuses nearer the lens)
    lens = read_lens("singlet.pcx.25mm")
    fd = focus(lens, 1e9).exact_film_distance_mm
    ca = chromatic_aberration(lens, fd, math.inf, 21.6, 0.05)
    f = paraxial_data(lens).efl
    assert ca["longitudinal_colour_mm"] == pytest.approx(-f / 25.68, rel=0.15)
    # front stop, positive lens: blue's image is smaller, lands nearer the centre
    lat = [v for v in ca["lateral_colour_px"][1:] if v is not None]
    assert lat and all(v < 0 for v in lat)
    assert ca["max_lateral_colour_px"] == pytest.approx(max(abs(v) for v in lat))
    assert ca["lateral_colour_px"][0] == pytest.approx(0.0, abs=1e-9)


def test_chief_landing_agrees_with_a_direct_trace():
    # the landing at lambda of the object point the d chief ray sees, checked by
    # tracing the lambda chief ray from that landing back to the object plane
    lens = read_lens("singlet.pcx.25mm")
    fd = focus(lens, 2000.0).exact_film_distance_mm
    obj = 2000.0
    r_d = np.array([5.0, 10.0, 15.0])
    land = chief_landing_mm(lens, fd, obj, r_d, (LINE_D_NM, 420.0))
    np.testing.assert_allclose(land[0], r_d, atol=1e-3)
    from povlens.lens.chief_ray import chief_rays

    def height(lens_, r):
        t, _ = chief_rays(lens_, fd, r)
        return t.origin_mm[:, 0] + (obj - t.origin_mm[:, 2]) / t.direction[:, 2] * t.direction[:, 0]

    np.testing.assert_allclose(height(lens_at_wavelength(lens, 420.0), land[1]),
                               height(lens, r_d), rtol=1e-4)


def test_pass_radius_bounds_every_passing_ray():
    lens = read_lens("singlet.pcx.25mm")
    fd = focus(lens, 4000.0).exact_film_distance_mm
    plane_z = fd + 3.0
    rng = np.random.default_rng(1)
    for lam in (BAND_NM[0], LINE_D_NM, BAND_NM[1]):
        lam_lens = lens_at_wavelength(lens, lam)
        rad = pass_radius_mm(lam_lens, fd, 20.0, plane_z, 30.0)
        assert 0 < rad < 30.0
        n = 200_000
        fr = 20.0 * np.sqrt(rng.random(n))
        fa = 2 * np.pi * rng.random(n)
        rho = rad * (1.0 + rng.random(n))                # outside the radius found
        pa = 2 * np.pi * rng.random(n)
        o = np.column_stack([fr * np.cos(fa), fr * np.sin(fa), np.zeros(n)])
        d = np.column_stack([rho * np.cos(pa) - o[:, 0], rho * np.sin(pa) - o[:, 1],
                             np.full(n, plane_z)])
        assert not trace_from_film(lam_lens, fd, o, d).passed.any(), lam
    assert pass_radius_mm(lens_at_wavelength(lens, BAND_NM[0]), fd, 20.0, plane_z, 30.0) > \
        pass_radius_mm(lens_at_wavelength(lens, BAND_NM[1]), fd, 20.0, plane_z, 30.0)
