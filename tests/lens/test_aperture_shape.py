"""Shaped aperture stops (lens/aperture_shape.py): the iris and mask geometry, the stop test
in the fast and the reference tracer, and the spot of a far point light (its corners)."""

import math

import numpy as np
import pytest

from povlens.errors import ParameterError
from povlens.lens import reference_tracer
from povlens.lens.aperture_shape import ApertureShape, area_fraction, shaped_lens
from povlens.lens.focus import focus
from povlens.lens.paraxial import paraxial_data, stop_index
from povlens.lens.prescription import read_lens
from povlens.lens.tracer import (stop_hits_from_film, trace_from_film, trace_from_scene,
                                 trace_unclipped_from_film)


@pytest.fixture(scope="module")
def dgauss():
    lens = read_lens("dgauss.50mm")
    return lens, focus(lens, 3000.0).exact_film_distance_mm


def test_polygon_is_inscribed_and_has_its_area():
    for n in (3, 5, 6, 9):
        s = ApertureShape(blades=n, rotation_deg=11.0)
        corners = math.radians(90 + 11.0) + 2 * math.pi * np.arange(n) / n
        # corners on the circle, edge midpoints at the apothem
        assert np.allclose(s.boundary_radius_mm(corners, 2.0), 2.0)
        assert np.allclose(s.boundary_radius_mm(corners + math.pi / n, 2.0),
                           2.0 * math.cos(math.pi / n))
        exact = n / 2 * math.sin(2 * math.pi / n) / math.pi
        assert area_fraction(s) == pytest.approx(exact, abs=3e-3)
    # curvature 1 is the round stop; 0.5 lies between
    assert ApertureShape(blades=6, curvature=1.0).is_round
    half = area_fraction(ApertureShape(blades=6, curvature=0.5))
    assert area_fraction(ApertureShape(blades=6)) < half < 1.0


def test_margin_sign_is_the_inside_test_and_round_margin_is_the_tracers():
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-1.2, 1.2, (2, 20000))
    s = ApertureShape(blades=7, curvature=0.3, rotation_deg=-40)
    m = s.margin_mm2(x, y, 1.0)
    rho = s.boundary_radius_mm(np.arctan2(y, x), 1.0)
    assert np.array_equal(m > 0, np.hypot(x, y) < rho)
    assert np.allclose(ApertureShape().margin_mm2(x, y, 1.5), 2.25 - x * x - y * y)


def test_mask_transmission_is_bilinear_and_spans_the_stop():
    mask = np.array([[0.0, 1.0], [0.5, 0.25]])      # row 0 at +y, column 0 at -x
    s = ApertureShape(mask=mask)
    r = 4.0
    # pixel centres at +-R/2
    assert s.transmission(np.array([-2.0, 2.0, -2.0, 2.0]), np.array([2.0, 2.0, -2.0, -2.0]),
                          r) == pytest.approx([0.0, 1.0, 0.5, 0.25])
    assert s.transmission(np.array([0.0]), np.array([0.0]), r)[0] == pytest.approx(0.4375)
    assert s.transmission(np.array([4.1]), np.array([0.0]), r)[0] == 0.0
    # the margin is negative where the mask is black
    assert s.margin_mm2(np.array([-2.0]), np.array([2.0]), r)[0] < 0
    assert s.margin_mm2(np.array([2.0]), np.array([2.0]), r)[0] > 0


@pytest.mark.parametrize("kw, parameter", [
    ({"blades": 2}, "aperture_blades"), ({"blades": 4.5}, "aperture_blades"),
    ({"blades": 6, "curvature": 1.5}, "blade_curvature"),
    ({"blades": 6, "curvature": -0.1}, "blade_curvature"),
    ({"blades": 6, "rotation_deg": math.inf}, "blade_rotation_deg"),
    ({"mask": np.zeros((4, 4)), "mask_source": "black.png"}, "aperture_image"),
    ({"mask": np.ones(5)}, "aperture_image")])
def test_bad_shapes_are_refused(kw, parameter):
    with pytest.raises(ParameterError) as e:
        ApertureShape(**kw)
    assert e.value.parameter == parameter


def _rays_at_stop(lens, fd, n, rng):
    """Rays from film points aimed through the stop's disc (most reach it)."""
    f = np.zeros((n, 3))
    f[:, :2] = rng.uniform(-8, 8, (n, 2))
    p = paraxial_data(lens)
    zp = fd - p.exit_pupil_position
    target = rng.uniform(-1.1, 1.1, (n, 2)) * 0.5 * p.exit_pupil_diameter
    d = np.c_[target - f[:, :2], np.full(n, zp)]
    return f, d


def test_tracers_agree_on_the_shaped_stop(dgauss):
    lens0, fd = dgauss
    rng = np.random.default_rng(7)
    f, d = _rays_at_stop(lens0, fd, 1500, rng)
    base = trace_from_film(lens0, fd, f, d).passed
    for shape in (ApertureShape(blades=6), ApertureShape(blades=5, curvature=0.6,
                                                         rotation_deg=33),
                  ApertureShape(mask=np.pad(np.ones((8, 8)), 4))):
        lens = shaped_lens(lens0, shape)
        assert lens.aperture_shape_row == stop_index(lens0)
        assert lens.sha256() == lens0.sha256()          # the file's hash, not the shape's
        fast = trace_from_film(lens, fd, f, d)
        unclipped = trace_unclipped_from_film(lens, fd, f, d)
        ref = reference_tracer.trace_rays_from_film(lens, fd, f, d)
        assert np.array_equal(fast.passed, ref.passed)
        assert np.array_equal(fast.blocked_at, ref.blocked_at)
        assert np.array_equal(fast.passed, unclipped.passed)
        # the shape only removes rays, and removes some where it cuts the disc
        assert not np.any(fast.passed & ~base)
        assert 0.3 < fast.passed.sum() / base.sum() < 0.99
        # the removed rays are blocked at the stop, and cross it outside the shape
        cut = base & ~fast.passed
        assert np.all(fast.blocked_at[cut] == lens.aperture_shape_row)
        hits = stop_hits_from_film(lens, fd, f[cut], d[cut])
        r = lens.aperture_radius_mm[lens.aperture_shape_row]
        assert np.all(shape.margin_mm2(hits[:, 0], hits[:, 1], r) < 0)


def _film_spot(lens, fd, distance_mm, n=500):
    """Film points (m, 2) of a far point light on the axis, through a dense grid over the
    front element (traced from the scene)."""
    c = (np.arange(n) + 0.5) / n * 2 - 1
    gx, gy = np.meshgrid(c, c)
    front = 0.5 * lens.aperture_diameter_mm[0]
    target = np.c_[gx.ravel(), gy.ravel()] * front
    zf = fd + lens.total_track_mm
    src = np.array([0.0, 0.0, zf + distance_mm])
    d = np.c_[target, np.full(len(target), zf)] - src
    o = np.tile(src, (len(d), 1))
    t = trace_from_scene(lens, fd, o, d)
    o, d = t.origin_mm[t.passed], t.direction[t.passed]
    s = -o[:, 2] / d[:, 2]                      # to the film plane z = 0
    return o[:, :2] + s[:, None] * d[:, :2]


def _outline_radius(points, bins=360):
    """(bins,) the spot's outline radius against angle about its centroid (mm), the
    largest radius in each 1-degree bin, smoothed over 9 bins."""
    v = points - points.mean(0)
    ang = np.degrees(np.arctan2(v[:, 1], v[:, 0])) % 360
    k = (ang / (360 / bins)).astype(int) % bins
    rad = np.zeros(bins)
    np.maximum.at(rad, k, np.hypot(v[:, 0], v[:, 1]))
    return np.convolve(np.r_[rad[-4:], rad, rad[:4]], np.ones(9) / 9, "valid")


def _corner_angles(points, bins=360):
    """Angles (deg) of the local maxima of the spot's outline radius against angle."""
    sm = _outline_radius(points, bins)
    peak = (sm > np.roll(sm, 1)) & (sm >= np.roll(sm, -1))
    peak &= sm > np.median(sm)
    return (np.nonzero(peak)[0] + 0.5) * 360 / bins


@pytest.mark.parametrize("blades, rotation", [(6, 0.0), (6, 20.0), (9, 7.0)])
def test_far_highlight_shows_the_polygon_at_its_rotation(dgauss, blades, rotation):
    lens0, _ = dgauss
    fd = focus(lens0, 250.0).exact_film_distance_mm       # focused near: 20 m is far out
    lens = shaped_lens(lens0, ApertureShape(blades=blades, rotation_deg=rotation))
    spot = _film_spot(lens, fd, 20000.0)
    corners = _corner_angles(spot)
    assert len(corners) == blades
    # beyond the focus the film spot is the stop turned 180 deg (the image turns it back)
    want = (90 + rotation + 180 + 360 * np.arange(blades) / blades) % 360
    err = np.abs((corners[:, None] - want[None, :] + 180) % 360 - 180).min(1)
    assert err.max() < 3.0
    # the outline's radius varies as the polygon's (corners / edge midpoints), the round
    # stop's not
    poly = _outline_radius(spot)
    assert poly.max() / poly.min() == pytest.approx(1 / math.cos(math.pi / blades), rel=0.02)
    disc = _outline_radius(_film_spot(lens0, fd, 20000.0))
    assert disc.max() / disc.min() < 1.01
