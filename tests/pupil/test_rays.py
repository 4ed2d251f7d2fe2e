"""lens_camera: per-pixel lens samples traced through the real lens and placed in the world."""

import numpy as np
import pytest

from povlens.lens.film import Film
from povlens.lens.focus import thick_lens_film_distance_mm
from povlens.pupil.rays import ScenePlacement, sample_points, sample_rays
from povlens.lens.prescription import read_lens
from povlens.pupil.build import build_pupil_table
from povlens.lens.reference_tracer import trace_ray_from_film


@pytest.fixture(scope="module")
def setup():
    lens = read_lens("dgauss.50mm")
    fd = thick_lens_film_distance_mm(lens, 4000.0)
    film = Film.from_diagonal(35.0, 24, 18)
    table = build_pupil_table(lens, fd, film.half_diagonal_mm)
    placement = ScenePlacement(np.array([0.0, 1.0, -3.0]), np.array([1.0, 0, 0]),
                               np.array([0, 1.0, 0]), np.array([0, 0, 1.0]), 1000.0)
    points = sample_points(4, film.height_px, film.width_px, seed=3)(1)
    return lens, fd, film, table, placement, points


def test_rows_trace_only_those_rows_and_match_the_whole_frame(setup):
    lens, fd, film, table, placement, points = setup
    full = sample_rays(lens, fd, film, table, placement, points)
    part = sample_rays(lens, fd, film, table, placement, points, rows=(5, 11))
    assert full.valid.mean() > 0.5
    sl = slice(5, 11)
    np.testing.assert_array_equal(part.valid[sl], full.valid[sl])
    np.testing.assert_array_equal(part.weight[sl], full.weight[sl])
    np.testing.assert_array_equal(part.origin[sl][part.valid[sl]], full.origin[sl][full.valid[sl]])
    np.testing.assert_array_equal(part.direction[sl], full.direction[sl])
    outside = np.ones(film.height_px, bool)
    outside[sl] = False
    assert not part.valid[outside].any() and not part.weight[outside].any()
    assert np.isfinite(part.origin).all() and np.isfinite(part.direction).all()
    with pytest.raises(ValueError):
        sample_rays(lens, fd, film, table, placement, points, rows=(3, 40))


def test_sample_rays_agree_with_the_reference_tracer(setup):
    """The fast path (table sampling + vectorized tracer + placement) against one
    ray at a time through the reference tracer, for the same film point and direction."""
    lens, fd, film, table, placement, points = setup
    rays = sample_rays(lens, fd, film, table, placement, points)
    xy = film.film_points_mm(points[..., :2])
    s = table.sample(xy.reshape(-1, 2), points[..., 2:].reshape(-1, 2))
    checked = 0
    for i in np.flatnonzero(rays.valid.ravel())[::7]:
        r = trace_ray_from_film(lens, fd, s.film_point[i], s.direction[i])
        assert r.passed
        o, d = np.array(r.origin_mm), np.array(r.direction)
        np.testing.assert_allclose(placement.points_to_world(o), rays.origin.reshape(-1, 3)[i],
                                   atol=1e-9)
        np.testing.assert_allclose(placement.directions_to_world(d),
                                   rays.direction.reshape(-1, 3)[i], atol=1e-9)
        checked += 1
    assert checked > 20
