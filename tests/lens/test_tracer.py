"""Properties of the vectorized tracer (povlens.lens.tracer), camera frame, mm."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from povlens.lens import reference_tracer as rt
from povlens.lens import tracer
from povlens.lens.check import check_rays
from povlens.lens.prescription import parse_lens_text, read_lens

LENS_DIR = Path(__file__).resolve().parents[2] / "lenses"
SHIPPED = sorted(p.name for p in LENS_DIR.glob("*.dat"))
# Film-to-rear-vertex distance for focus at infinity (realistic-camera.md §8.2; the
# old 100 mm-scale files are dgauss.50mm x 2 and wide.22mm x 100/22).
FILM_MM = {
    "dgauss.50mm.dat": 36.1059, "wide.22mm.dat": 14.3182, "fisheye.10mm.dat": 23.1600,
    "telephoto.250mm.dat": 105.0705, "singlet.pcx.25mm.dat": 21.4757,
    "cooke.triplet.50mm.dat": 42.4363, "tessar.50mm.dat": 42.7235,
    "dgauss.dat": 2.0 * 36.1059, "wide.dat": 14.3182 * 100.0 / 22.0,
    # paraxial back focal distances, y-nu trace (tests/lens/import_reference.trace)
    "angenieux.100mm.dat": 55.9771, "aspheric.31mm.dat": 21.4472,
    "anamorphic.60mm.dat": 43.3545,     # its y-z meridian's
}


def _shipped(name):
    return read_lens(LENS_DIR / name), FILM_MM[name]


@pytest.mark.parametrize("name", SHIPPED)
def test_round_trip_film_scene_film(name):
    lens, film = _shipped(name)
    o, d = check_rays(lens, film, n_film=20, n_pupil=256)
    fwd = tracer.trace_from_film(lens, film, o, d)
    p = fwd.passed
    assert p.sum() >= 100
    back = tracer.trace_from_scene(lens, film, fwd.origin_mm[p], -fwd.direction[p])
    assert back.passed.all()
    t = -back.origin_mm[:, 2] / back.direction[:, 2]       # intersect the film z = 0
    on_film = back.origin_mm + t[:, None] * back.direction
    assert np.abs(on_film[:, 2]).max() <= 1e-12
    assert np.linalg.norm(on_film - o[p], axis=1).max() <= 1e-9
    assert np.linalg.norm(back.direction + d[p], axis=1).max() <= 1e-12


@pytest.mark.parametrize("name", SHIPPED)
def test_output_directions_are_unit(name):
    lens, film = _shipped(name)
    o, d = check_rays(lens, film, n_film=20, n_pupil=256)
    d = d * np.linspace(0.1, 10.0, len(d))[:, None]       # inputs need not be unit
    fwd = tracer.trace_from_film(lens, film, o, d)
    assert np.abs(np.linalg.norm(fwd.direction, axis=1) - 1.0).max() <= 2e-15
    p = fwd.passed
    back = tracer.trace_from_scene(lens, film, fwd.origin_mm[p] + 3.0 * fwd.direction[p],
                                   -fwd.direction[p])
    assert np.abs(np.linalg.norm(back.direction, axis=1) - 1.0).max() <= 2e-15


# ---- flat refracting faces and huge radii -----------------------------------------

def _plano(front, rear):
    return parse_lens_text(f"{front} 4 1.5168 20\n{rear} 0 1 20\n", f"{front}/{rear}")


def _diff(a, b):
    assert np.array_equal(a.passed, b.passed)
    assert np.array_equal(a.blocked_at, b.blocked_at)
    p = a.passed
    return (np.linalg.norm(a.origin_mm[p] - b.origin_mm[p], axis=1).max(),
            np.linalg.norm(a.direction[p] - b.direction[p], axis=1).max())


@pytest.mark.parametrize("flat_first", [False, True])
@pytest.mark.parametrize("huge", ["1e15", "-1e15", "1e18"])
def test_huge_radius_behaves_like_flat_face(flat_first, huge):
    # At |R| >= 1e15 the sag over a 10 mm clear radius is < 1e-13 mm and the normal
    # tilts by < 1e-14: the face must trace like the flat face to rounding.  A root
    # formula that cancels catastrophically for tiny curvature would be far off.
    flat = _plano("0", "-60") if flat_first else _plano("60", "0")
    curved = _plano(huge, "-60") if flat_first else _plano("60", huge)
    assert not flat.is_aperture.any()              # R = 0 touching glass refracts
    film = 50.0
    o, d = check_rays(flat, film, n_film=10, n_pupil=64)
    pos, dirn = _diff(tracer.trace_from_film(flat, film, o, d),
                      tracer.trace_from_film(curved, film, o, d))
    assert pos <= 1e-9 and dirn <= 1e-12
    zs = film + 4.0 + 10.0
    o2 = np.column_stack([o[:, :2] * 0.5, np.full(len(o), zs)])
    pos, dirn = _diff(tracer.trace_from_scene(flat, film, o2, -d),
                      tracer.trace_from_scene(curved, film, o2, -d))
    assert pos <= 1e-9 and dirn <= 1e-12


def test_radius_1e9_differs_from_flat_only_by_its_geometry():
    # R = 1e9 mm is *not* flat to 1e-9 mm: at r = 10 mm its sag is 5e-8 mm and its
    # normal tilts by 1e-8 rad.  So it must agree with the flat face to within those
    # geometric effects (bounds below), and with the reference tracer to rounding.
    flat, curved = _plano("60", "0"), _plano("60", "1e9")
    film = 50.0
    o, d = check_rays(flat, film, n_film=10, n_pupil=64)
    a = tracer.trace_from_film(flat, film, o, d)
    b = tracer.trace_from_film(curved, film, o, d)
    pos, dirn = _diff(a, b)
    r_max, radius = 10.0, 1e9
    sag_max, tilt_max = r_max ** 2 / (2 * radius), r_max / radius
    assert 0.0 < dirn <= 2.0 * tilt_max                      # (n - 1) tilt, n < 3
    assert pos <= 2.0 * sag_max + 4.0 * 2.0 * tilt_max      # sag + tilt x 4 mm of glass
    ref = rt.trace_rays_from_film(curved, film, o, d)
    pos, dirn = _diff(b, ref)
    assert pos <= 1e-9 and dirn <= 1e-12


def test_flat_faces_refract_like_a_plane_parallel_plate():
    lens = parse_lens_text("0 5 1.5 40\n0 0 1 40\n", "slab")
    assert not lens.is_aperture.any()
    film, a = 10.0, math.radians(30.0)
    res = tracer.trace_from_scene(lens, film, [[0.0, 0.0, 30.0]], [[math.sin(a), 0.0, -math.cos(a)]])
    assert res.passed[0]
    b = math.asin(math.sin(a) / 1.5)
    x_rear = 15.0 * math.tan(a) + 5.0 * math.tan(b)           # not 20 tan(a): it refracted
    np.testing.assert_allclose(res.origin_mm[0], [x_rear, 0.0, 10.0], rtol=0, atol=1e-13)
    np.testing.assert_allclose(res.direction[0], [math.sin(a), 0.0, -math.cos(a)], rtol=0, atol=1e-15)


# ---- blocked rays -----------------------------------------------------------------

def test_blocked_rays_carry_blocked_at_and_finite_values():
    lens, film = _shipped("singlet.pcx.25mm.dat")     # rows: stop, R 19.93 (glass), R 1e6
    rays = [  # (origin, direction, expected blocked_at)
        ((10.0, 0.0, 0.0), (-18.0, 0.0, film), -1),          # passes
        ((-40.0, 0.0, 0.0), (32.0, 0.0, film), 1),           # TIR inside the glass
        ((0.0, 0.0, 0.0), (20.0, 0.0, film), 2),             # outside the rear clear aperture
        ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 2),               # zero direction
        ((0.0, 0.0, 0.0), (0.0, 0.1, -1.0), 2),              # pointing away from the lens
        ((0.0, 0.0, 0.0), (math.nan, 0.0, 1.0), 2),          # NaN direction
        ((math.inf, 0.0, 0.0), (0.0, 0.0, 1.0), 2),          # infinite origin
    ]
    o = np.array([r[0] for r in rays])
    d = np.array([r[1] for r in rays])
    res = tracer.trace_from_film(lens, film, o, d)
    expected = np.array([r[2] for r in rays])
    assert res.blocked_at.tolist() == expected.tolist()
    assert res.passed.tolist() == (expected < 0).tolist()
    assert np.all(np.isfinite(res.origin_mm)) and np.all(np.isfinite(res.direction))
    assert np.abs(np.linalg.norm(res.direction, axis=1) - 1.0).max() <= 2e-15
    # The TIR ray really is totally internally reflected (independent tracer).
    assert rt.trace_ray_from_film(lens, film, rays[1][0], rays[1][1]).reason == "tir"


def test_ray_missing_the_stop_is_blocked_at_the_stop():
    lens = parse_lens_text("0 2 0 4\n50 4 1.5 20\n-50 0 1 20\n", "front-stop")
    assert lens.is_aperture.tolist() == [True, False, False]
    film = 40.0
    o = np.zeros((3, 3))
    d = np.array([[0.0, 0.0, 1.0], [6.0, 0.0, film], [np.nan, np.nan, np.nan]])
    res = tracer.trace_from_film(lens, film, o, d)
    assert res.blocked_at.tolist() == [-1, 0, 2]
    assert np.all(np.isfinite(res.origin_mm)) and np.all(np.isfinite(res.direction))
    ref = rt.trace_ray_from_film(lens, film, o[1], d[1])
    assert (ref.blocked_at, ref.reason) == (0, "aperture")


@pytest.mark.parametrize("past_mm, blocked", [
    (-1.0, False), (0.0, False), (1e-12, False), (5e-10, False), (2e-9, True), (1e-6, True)])
def test_backward_tolerance(past_mm, blocked):
    # The ray starts past_mm beyond the front face of a glass block (already through
    # it): a surface more than 1e-9 mm behind the ray blocks it.
    lens = parse_lens_text("0 5 1.5 20\n0 0 1 20\n", "block")
    film = 10.0
    o = [[1.0, 0.0, 15.0 - past_mm]]
    d = [[0.1, 0.0, -1.0]]
    res = tracer.trace_from_scene(lens, film, o, d)
    assert bool(res.passed[0]) is (not blocked)
    assert res.blocked_at[0] == (0 if blocked else -1)
    ref = rt.trace_ray_from_scene(lens, film, o[0], d[0])
    assert ref.blocked_at == res.blocked_at[0]


# ---- first-order optics ------------------------------------------------------------

def _thick_lens(r1, r2, d, n):
    """EFL and BFL (mm) of a thick singlet in air (lensmaker's equation)."""
    power = (n - 1.0) * (1.0 / r1 - 1.0 / r2 + (n - 1.0) * d / (n * r1 * r2))
    f = 1.0 / power
    return f, f * (1.0 - (n - 1.0) * d / (n * r1))


def test_biconvex_singlet_focuses_paraxial_rays_at_thick_lens_bfl():
    r1, r2, t, n = 80.0, -80.0, 5.0, 1.5168
    efl, bfl = _thick_lens(r1, r2, t, n)
    assert efl == pytest.approx(78.23235, abs=1e-5)
    lens = parse_lens_text(f"{r1} {t} {n} 20\n{r2} 0 1 20\n", "biconvex")
    film = 100.0
    h = np.array([1e-3, -1e-3, 2e-3])
    z0 = film + t + 10.0
    for axis in (0, 1):                                    # x and y meridians
        o = np.zeros((3, 3))
        o[:, axis], o[:, 2] = h, z0
        res = tracer.trace_from_scene(lens, film, o, np.tile([0.0, 0.0, -1.0], (3, 1)))
        assert res.passed.all()
        oa, da = res.origin_mm[:, axis], res.direction[:, axis]
        assert np.all(np.sign(da) == -np.sign(h))          # converging
        z_cross = res.origin_mm[:, 2] - oa * res.direction[:, 2] / da
        np.testing.assert_allclose(film - z_cross, bfl, rtol=0, atol=1e-6)
        np.testing.assert_allclose(h * res.direction[:, 2] / da, efl, rtol=0, atol=1e-6)
    # Marginal rays focus shorter (undercorrected spherical aberration of a singlet).
    res = tracer.trace_from_scene(lens, film, [[8.0, 0.0, z0]], [[0.0, 0.0, -1.0]])
    z_cross = res.origin_mm[0, 2] - res.origin_mm[0, 0] * res.direction[0, 2] / res.direction[0, 0]
    assert film - z_cross < bfl - 0.1


# --- the unclipped trace (distribution-3 ray meshes) -------------------------------

@pytest.mark.parametrize("name", ["dgauss.50mm", "wide.22mm", "fisheye.10mm", "telephoto.250mm"])
def test_unclipped_trace_gives_the_clipped_verdict_and_rays(name):
    """Its margins reproduce trace_from_film's verdict exactly, and where a ray
    passes, its origin and direction are the same numbers."""
    from povlens.lens.focus import focus
    lens = read_lens(name)
    fd = focus(lens, 4000.0).exact_film_distance_mm
    rng = np.random.default_rng(3)
    n = 20000
    o = np.zeros((n, 3))
    o[:, :2] = rng.uniform(-22, 22, (n, 2))
    d = np.c_[rng.uniform(-1.2, 1.2, (n, 2)), np.ones(n)]
    clipped = tracer.trace_from_film(lens, fd, o, d)
    free = tracer.trace_unclipped_from_film(lens, fd, o, d)
    assert np.array_equal(free.passed, clipped.passed)
    assert 0 < clipped.passed.sum() < n
    p = clipped.passed
    assert np.array_equal(free.origin_mm[p], clipped.origin_mm[p])
    assert np.array_equal(free.direction[p], clipped.direction[p])
    # rays the apertures alone block still exist, with a finite state
    blocked_by_rim = ~p & free.exists
    assert blocked_by_rim.any()
    assert np.all(np.isfinite(free.origin_mm)) and np.all(np.isfinite(free.direction))
    assert not np.any(np.isnan(free.margin_mm2))
