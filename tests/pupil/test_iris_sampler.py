"""The per-pixel sampler for an iris: the tighter of the table's region and the iris
domain per film point, unbiased against a brute-force average over the plane."""

import math

import numpy as np
import pytest

from povlens.lens.aperture_shape import ApertureShape, shaped_lens
from povlens.lens.focus import focus
from povlens.lens.prescription import read_lens
from povlens.lens.tracer import trace_from_film
from povlens.pupil.aperture_domain import iris_domain
from povlens.pupil.build import build_pupil_table
from povlens.pupil.field import bounding_disc_radius_mm
from povlens.pupil.iris_sampler import IrisPixelSampler
from povlens.pupil.monte_carlo import irradiance_factor, pass_fraction


@pytest.fixture(scope="module")
def iris():
    lens0 = read_lens("dgauss.50mm")
    fd = focus(lens0, 2000.0).exact_film_distance_mm
    table = build_pupil_table(lens0, fd, 21.6)
    lens = shaped_lens(lens0, ApertureShape(blades=6, rotation_deg=10))
    rd, flip, _ = iris_domain(lens, fd, table)
    sampler = IrisPixelSampler(table, lens.aperture_shape, flip, rd,
                               bounding_disc_radius_mm(table))
    return lens, fd, table, sampler


def test_the_domain_is_used_near_the_axis_and_passes_more(iris):
    lens, fd, table, sampler = iris
    radii = np.array([0.0, 5.0, 10.0, 15.0, 20.0])
    use = sampler.uses_domain(radii)
    assert use[0] and not use[-1]           # the polygon on the axis, the cat's eye far off
    ours = pass_fraction(sampler, lens, fd, radii, n_samples=4096).fraction
    round_table = pass_fraction(table, lens, fd, radii, n_samples=4096).fraction
    print(f"pass fraction at {radii} mm: iris sampler {np.round(ours, 3)}, round table "
          f"{np.round(round_table, 3)}")
    assert ours[0] >= 0.95 and round_table[0] < 0.85       # on the axis: the polygon
    assert np.all(ours >= round_table - 0.01)               # never worse


def test_iris_sampler_is_unbiased_against_a_brute_force_average(iris):
    lens, fd, table, sampler = iris
    zp = table.plane_z_mm
    rb = bounding_disc_radius_mm(table)
    rng = np.random.default_rng(4)
    n = 400_000
    for r in (0.0, 6.0, 12.0, 18.0):
        phi = rng.uniform(0, 2 * math.pi)
        f = np.array([r * math.cos(phi), r * math.sin(phi)])
        rad, ang = rb * np.sqrt(rng.random(n)), 2 * math.pi * rng.random(n)
        o = np.zeros((n, 3))
        o[:, :2] = f
        d = np.column_stack([rad * np.cos(ang) - f[0], rad * np.sin(ang) - f[1],
                             np.full(n, zp)])
        passed = trace_from_film(lens, fd, o, d).passed
        cos4 = (zp / np.linalg.norm(d, axis=1)) ** 4
        brute = math.pi * rb ** 2 / zp ** 2 * np.mean(cos4 * passed)
        noise = brute * math.sqrt((1 - passed.mean()) / max(passed.sum(), 1))
        # irradiance_factor samples film points (r, 0): the lens is symmetric, the iris
        # is not, so sample the film point itself through the sampler
        from povlens.pupil.monte_carlo import sobol_points
        u = np.asarray(sobol_points(1 << 14, 2, seed=3))
        s = sampler.sample(np.tile(f, (len(u), 1)), u)
        t = trace_from_film(lens, fd, s.film_point, s.direction)
        got = float(np.mean(np.where(t.passed, s.weight, 0.0)))
        assert got == pytest.approx(brute, abs=5 * noise + 2e-3 * brute), r
    assert irradiance_factor(sampler, lens, fd, [0.0], n_samples=1 << 12)[0] > 0
