"""Point sets for the lens and the estimates built on a lens sampler."""

import math

import numpy as np
import pytest

from povlens.errors import OpticsError, UsageError
from povlens.lens.focus import thick_lens_film_distance_mm
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import read_lens
from povlens.pupil.build import build_pupil_table
from povlens.pupil.sampler_interface import LensSample
from povlens.pupil.baselines import NaiveRearElement, radical_inverse
from povlens.pupil.monte_carlo import (cranley_patterson, exposure_normalisation,
                                       halton_points, irradiance_factor, lens_points,
                                       pass_fraction, sobol_points, stratified_points)


@pytest.mark.parametrize("gen", [sobol_points, halton_points, stratified_points])
def test_point_sets_are_in_the_unit_square_and_reproducible(gen):
    a = gen(1000, 2, seed=3)
    assert a.shape == (1000, 2) and a.dtype == np.float64
    assert np.all(a >= 0) and np.all(a < 1)
    assert np.array_equal(a, gen(1000, 2, seed=3))
    assert not np.array_equal(a, gen(1000, 2, seed=4))
    assert gen(0, 2, seed=0).shape == (0, 2)


def test_sobol_points_are_stratified_in_each_dimension():
    for n in (256, 1024):
        p = sobol_points(n, 2, seed=11)
        for d in range(2):
            assert np.array_equal(np.sort(np.floor(p[:, d] * n).astype(int)), np.arange(n))
        # (0, m, 2)-net: every elementary box of area 1/n (here 16 x n/16) holds one point.
        cols = np.floor(p[:, 0] * 16).astype(int)
        rows = np.floor(p[:, 1] * (n // 16)).astype(int)
        assert len(set(zip(cols, rows))) == n


def test_stratified_points_put_one_point_in_each_cell():
    p = stratified_points(400, seed=1)
    cells = np.floor(p * 20).astype(int)
    assert len(set(map(tuple, cells))) == 400
    q = stratified_points(50, seed=2)  # not a square: distinct cells of an 8 x 8 grid
    assert len(set(map(tuple, np.floor(q * 8).astype(int)))) == 50
    with pytest.raises(ValueError):
        stratified_points(16, 3)


def test_lens_points_by_name_and_bad_name():
    assert np.array_equal(lens_points(64, method="halton", seed=5), halton_points(64, seed=5))
    with pytest.raises(UsageError, match="unknown"):
        lens_points(8, method="random-ish")
    with pytest.raises(UsageError):
        sobol_points(-1)


def test_cranley_patterson_shift_is_a_torus_translation():
    p = sobol_points(128, seed=0)
    q = cranley_patterson(p, np.array([0.75, 0.5]))
    assert np.all((q >= 0) & (q < 1))
    d = np.mod(q - p, 1.0)
    assert np.allclose(d[:, 0], 0.75) and np.allclose(d[:, 1], 0.5)
    # Still one point per 1/n stratum in each dimension.
    assert np.array_equal(np.sort(np.floor(q[:, 0] * 128).astype(int)), np.arange(128))


def test_radical_inverse():
    assert np.allclose(radical_inverse(np.arange(8), 2),
                       [0, 0.5, 0.25, 0.75, 0.125, 0.625, 0.375, 0.875])
    assert np.allclose(radical_inverse(np.arange(5), 3), [0, 1 / 3, 2 / 3, 1 / 9, 4 / 9])


@pytest.fixture(scope="module")
def cooke():
    lens = read_lens("cooke.triplet.50mm")
    fd = thick_lens_film_distance_mm(lens, 10_000.0)
    return lens, fd, build_pupil_table(lens, fd, 17.5)


def test_exposure_normalisation_makes_the_centre_as_bright_as_a_pinhole(cooke):
    lens, fd, table = cooke
    k = exposure_normalisation(table, lens, fd, n_samples=1 << 14)
    # The normalised centre irradiance of a unit-radiance scene is 1: the pinhole value.
    e0 = table.irradiance_factor([0.0], n_samples=1 << 14, seed=7)[0]
    assert k * e0 == pytest.approx(1.0, rel=2e-3)
    assert k == pytest.approx(table.exposure_normalisation(), rel=2e-3)
    n_f = paraxial_data(lens).f_number
    assert 1.0 / k == pytest.approx(math.pi / (4 * n_f ** 2), rel=0.03)
    # The same answer from naive sampling (also unbiased, just wasteful).
    naive = NaiveRearElement.build(lens, fd, 17.5)
    assert exposure_normalisation(naive, lens, fd, n_samples=1 << 15) == pytest.approx(k, rel=5e-3)


class _Blind:
    """A sampler that never proposes a ray."""

    def sample(self, film_xy, u):
        n = len(film_xy)
        z = np.zeros((n, 3))
        return LensSample(z, z, z + [0, 0, 1], np.zeros(n), np.zeros(n), np.zeros(n, bool))


def test_estimates_with_a_sampler_that_proposes_nothing(cooke):
    lens, fd, _ = cooke
    pf = pass_fraction(_Blind(), lens, fd, [0.0, 5.0], n_samples=16)
    assert pf.vignetted.all() and np.all(pf.fraction == 0) and np.all(pf.n_valid == 0)
    assert np.all(irradiance_factor(_Blind(), lens, fd, [0.0, 5.0], n_samples=16) == 0)
    with pytest.raises(OpticsError, match="film centre"):
        exposure_normalisation(_Blind(), lens, fd, n_samples=16)


def test_pass_fraction_counts_traced_rays(cooke):
    lens, fd, table = cooke
    pf = pass_fraction(table, lens, fd, np.array([0.0, 10.0]), n_samples=256, seed=1)
    assert pf.n_samples == 256 and np.all(pf.n_valid == 256)
    assert np.all((pf.fraction > 0.95) & (pf.fraction <= 1.0))
    naive = NaiveRearElement.build(lens, fd, 17.5)
    assert np.all(pass_fraction(naive, lens, fd, [0.0, 10.0], n_samples=256).fraction < 0.9)


def test_interrupts_are_deferred_not_lost(monkeypatch):
    # a Ctrl-C inside the guarded block arrives after it, as KeyboardInterrupt
    import signal
    from povlens.util.signals import interrupts_deferred
    ran_to_end = False
    with pytest.raises(KeyboardInterrupt):
        with interrupts_deferred():
            signal.raise_signal(signal.SIGINT)
            ran_to_end = True
    assert ran_to_end
