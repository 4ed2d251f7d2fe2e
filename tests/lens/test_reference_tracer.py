"""The reference tracer (one ray at a time, Newton on the sag) against the fast tracer.

Film distances: the "film @ inf" column of realistic-camera.md §8.2 (the paraxial
back focal length).  The old 100 mm-scale files are the same designs as
dgauss.50mm (scale 0.5) and wide.22mm (scale 0.22), so their film distances are
those values times 2 and 100/22.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from povlens.lens import check
from povlens.lens import reference_tracer as rt
from povlens.lens import tracer
from povlens.lens.check import check_lens, check_rays
from povlens.lens.prescription import parse_lens_text, read_lens

LENS_DIR = Path(__file__).resolve().parents[2] / "lenses"

FILM_AT_INFINITY_MM = {
    "dgauss.50mm.dat": 36.1059,
    "wide.22mm.dat": 14.3182,
    "fisheye.10mm.dat": 23.1600,
    "telephoto.250mm.dat": 105.0705,
    "singlet.pcx.25mm.dat": 21.4757,
    "cooke.triplet.50mm.dat": 42.4363,
    "tessar.50mm.dat": 42.7235,
    # paraxial back focal distances by the independent y-nu trace of the file's numbers
    # (tests/lens/import_reference.trace)
    "angenieux.100mm.dat": 55.9771,
    "aspheric.31mm.dat": 21.4472,
    "anamorphic.60mm.dat": 43.3545,     # its y-z meridian's
    "dgauss.dat": 36.1059 * 2.0,
    "wide.dat": 14.3182 * 100.0 / 22.0,
}

SHIPPED = sorted(p.name for p in LENS_DIR.glob("*.dat"))

# Lenses outside the shipped set that stress the intersection: a ball lens whose
# clear radius equals |R| (hemispheres, infinite sag slope at the rim), a strongly
# curved doublet, and a glass block with flat refracting faces.
SYNTHETIC = {
    "ball": "10 20 1.5 20\n-10 0 1 20\n",
    "strong": "6 11 1.8 11.9\n-6 0.5 1 11.9\n5 5 1.5 9.9\n50 0 1 9\n",
    "flat-faces": "0 3 1.5 20\n-30 1 1 20\n0 2 1.6 20\n0 0 1 20\n",
}


def test_every_shipped_lens_has_a_film_distance():
    assert SHIPPED, "no lens files found"
    assert set(SHIPPED) == set(FILM_AT_INFINITY_MM)


@pytest.mark.parametrize("name", SHIPPED)
def test_reference_and_fast_tracer_agree_on_shipped_lens(name):
    lens = read_lens(LENS_DIR / name)
    report = check_lens(lens, FILM_AT_INFINITY_MM[name])
    assert report.n_rays >= 10_000
    # The comparison must not be vacuous, and the overfilled pupil must block some rays.
    assert report.n_compared >= 200
    assert report.n_passed_fast < report.n_rays
    assert report.max_position_diff_mm <= 1e-9, report.format_text()
    assert report.max_direction_diff <= 1e-12, report.format_text()
    assert report.n_disagreements_away_from_edge == 0, report.format_text()
    assert report.ok


def _steep_rays(z_start, z_target, target_diameter, seed, n=3000, half_width=25.0):
    """Random start points on the plane z_start (|x|, |y| <= half_width) and directions up
    to 89 deg off the axis toward z_target; half are aimed at random points of the
    plane z_target within 0.7 x target_diameter."""
    rng = np.random.default_rng(seed)
    sense = 1.0 if z_target > z_start else -1.0
    o = np.column_stack([rng.uniform(-half_width, half_width, (n, 2)), np.full(n, z_start)])
    th = np.arccos(rng.uniform(math.cos(math.radians(89)), 1.0, n))
    ph = rng.uniform(0, 2 * math.pi, n)
    d = np.column_stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), sense * np.cos(th)])
    m = n // 2
    tgt = np.column_stack([rng.uniform(-0.7, 0.7, (m, 2)) * target_diameter, np.full(m, z_target)])
    d[:m] = tgt - o[:m]
    return o, d


def _assert_agree(fast, ref):
    both = fast.passed & ref.passed
    assert both.sum() >= 20
    pos = np.linalg.norm(fast.origin_mm[both] - ref.origin_mm[both], axis=1)
    dirn = np.linalg.norm(fast.direction[both] - ref.direction[both], axis=1)
    assert pos.max() <= 1e-9
    assert dirn.max() <= 1e-12
    near_edge = (ref.edge_margin <= check.EDGE_RTOL) | (ref.borderline != "")
    disagree = (fast.passed != ref.passed) | (fast.blocked_at != ref.blocked_at)
    assert not np.any(disagree & ~near_edge), np.nonzero(disagree & ~near_edge)[0][:5]


@pytest.mark.parametrize("name", SHIPPED + sorted(SYNTHETIC))
def test_agree_on_steep_rays_both_directions(name):
    if name in SYNTHETIC:
        lens, film = parse_lens_text(SYNTHETIC[name], name), 10.0
    else:
        lens, film = read_lens(LENS_DIR / name), FILM_AT_INFINITY_MM[name]
    o, d = _steep_rays(0.0, film, lens.aperture_diameter_mm[-1], seed=len(name))
    _assert_agree(tracer.trace_from_film(lens, film, o, d),
                  rt.trace_rays_from_film(lens, film, o, d))
    # From the scene: random steep rays at the front element, plus the reversed
    # (and slightly tilted) output rays of a film -> scene trace, which reach the film.
    z_front = film + lens.total_track_mm
    o1, d1 = _steep_rays(z_front + 20.0, z_front, lens.aperture_diameter_mm[0], seed=len(name) + 1,
                         n=1500, half_width=0.5 * lens.aperture_diameter_mm[0])
    fo, fd = check_rays(lens, film, n_film=10, n_pupil=150)
    out = tracer.trace_from_film(lens, film, fo, fd)
    rng = np.random.default_rng(len(name) + 2)
    d2 = -out.direction[out.passed] + rng.normal(0.0, 0.02, (int(out.passed.sum()), 3))
    o2 = out.origin_mm[out.passed] + 5.0 * out.direction[out.passed]
    o, d = np.concatenate([o1, o2]), np.concatenate([d1, d2])
    _assert_agree(tracer.trace_from_scene(lens, film, o, d),
                  rt.trace_rays_from_scene(lens, film, o, d))


def test_reference_slab_matches_snell_analytically():
    # A 5 mm plane-parallel plate (n = 1.5): the ray leaves parallel to itself,
    # shifted sideways by t sin(a - b) / cos(b), sin(a) = n sin(b).
    lens = parse_lens_text("0 5 1.5 40\n0 0 1 40\n", "slab")
    film = 10.0
    a = math.radians(30.0)
    origin = (0.0, 0.0, 30.0)
    direction = (math.sin(a), 0.0, -math.cos(a))
    ray = rt.trace_ray_from_scene(lens, film, origin, direction)
    assert ray.passed and ray.blocked_at == -1 and ray.reason == ""
    assert np.allclose(ray.direction, direction, rtol=0, atol=1e-15)
    b = math.asin(math.sin(a) / 1.5)
    x_front = (30.0 - 15.0) * math.tan(a)
    x_rear = x_front + 5.0 * math.tan(b)
    assert ray.origin_mm == pytest.approx((x_rear, 0.0, 10.0), abs=1e-13)


def test_reference_axial_ray_is_undeviated():
    lens = read_lens(LENS_DIR / "dgauss.50mm.dat")
    ray = rt.trace_ray_from_film(lens, 36.1059, (0.0, 0.0, 0.0), (0.0, 0.0, 2.0))
    assert ray.passed
    assert ray.direction == pytest.approx((0.0, 0.0, 1.0), abs=1e-15)
    assert ray.origin_mm == pytest.approx((0.0, 0.0, 36.1059 + lens.total_track_mm), abs=1e-12)


def test_reference_blocking_reasons():
    lens = read_lens(LENS_DIR / "singlet.pcx.25mm.dat")
    film = 21.4757
    tir = rt.trace_ray_from_film(lens, film, (-40.0, 0.0, 0.0), (32.0, 0.0, film))
    assert (tir.passed, tir.blocked_at, tir.reason) == (False, 1, "tir")
    # Blocked rays keep the state before the blocking surface: here on the rear face.
    assert tir.origin_mm[2] == pytest.approx(film, abs=1e-3)
    clipped = rt.trace_ray_from_film(lens, film, (0.0, 0.0, 0.0), (20.0, 0.0, film))
    assert (clipped.blocked_at, clipped.reason) == (2, "aperture")
    back = rt.trace_ray_from_film(lens, film, (0.0, 0.0, 0.0), (0.0, 0.1, -1.0))
    assert (back.blocked_at, back.reason) == (2, "turned-back")
    for bad in ((0.0, 0.0, 0.0), (math.nan, 0.0, 1.0), (0.0, math.inf, 1.0)):
        r = rt.trace_ray_from_film(lens, film, (0.0, 0.0, 0.0), bad)
        assert (r.passed, r.blocked_at, r.reason) == (False, 2, "invalid-ray")
        assert all(map(math.isfinite, r.origin_mm + r.direction))
    r = rt.trace_ray_from_scene(lens, film, (math.nan, 0.0, 50.0), (0.0, 0.0, -1.0))
    assert (r.blocked_at, r.reason) == (0, "invalid-ray")


def test_trace_rays_from_film_shapes():
    lens = read_lens(LENS_DIR / "tessar.50mm.dat")
    o, d = check_rays(lens, 42.7235, n_film=3, n_pupil=5)
    res = rt.trace_rays_from_film(lens, 42.7235, o, d)
    assert len(res) == 15
    assert res.origin_mm.shape == res.direction.shape == (15, 3)
    assert res.passed.dtype == bool and res.blocked_at.dtype == np.int64
    assert np.all(res.blocked_at[res.passed] == -1) and np.all(res.blocked_at[~res.passed] >= 0)
    assert np.all(np.isfinite(res.origin_mm)) and np.all(np.isfinite(res.direction))
    with pytest.raises(ValueError):
        rt.trace_rays_from_film(lens, 42.7235, o, d[:3])


def test_check_report_serializes_and_formats():
    lens = read_lens(LENS_DIR / "cooke.triplet.50mm.dat")
    report = check_lens(lens, 42.4363, n_film=4, n_pupil=50)
    assert report.n_rays == 200 and report.ok
    d = report.to_dict()
    text = json.dumps(d, allow_nan=False)
    assert json.loads(text)["ok"] is True
    assert d["n_rays"] == 200 and d["max_position_diff_mm"] <= 1e-9
    assert "result: OK" in report.format_text()


def test_check_detects_a_perturbed_fast_tracer(monkeypatch):
    real = tracer.trace_from_film

    def perturbed(lens, film, o, d):
        res = real(lens, film, o, d)
        direction = res.direction.copy()
        direction[:, 0] += 1e-10
        direction /= np.linalg.norm(direction, axis=1)[:, None]
        return tracer.TraceResult(res.origin_mm, direction, res.passed, res.blocked_at)

    monkeypatch.setattr(tracer, "trace_from_film", perturbed)
    report = check_lens(read_lens(LENS_DIR / "dgauss.50mm.dat"), 36.1059, n_film=4, n_pupil=64)
    assert not report.ok
    assert report.max_direction_diff > 1e-12
    assert "FAILED" in report.format_text()


def test_check_detects_pass_block_disagreement(monkeypatch):
    real = tracer.trace_from_film

    def lets_everything_pass(lens, film, o, d):
        res = real(lens, film, o, d)
        return tracer.TraceResult(res.origin_mm, res.direction, np.ones_like(res.passed),
                                  np.full_like(res.blocked_at, -1))

    monkeypatch.setattr(tracer, "trace_from_film", lets_everything_pass)
    report = check_lens(read_lens(LENS_DIR / "dgauss.50mm.dat"), 36.1059, n_film=4, n_pupil=64)
    assert report.n_disagreements_away_from_edge > 0
    assert not report.ok
    assert report.disagreements and not report.disagreements[0].near_edge
    json.dumps(report.to_dict(), allow_nan=False)


def test_check_rejects_bad_parameters():
    from povlens.errors import UsageError
    lens = read_lens(LENS_DIR / "tessar.50mm.dat")
    for kwargs in ({"film_distance_mm": -1.0}, {"film_distance_mm": math.nan},
                   {"film_distance_mm": 40.0, "n_film": 0},
                   {"film_distance_mm": 40.0, "n_pupil": 2.5}):
        with pytest.raises(UsageError):
            check_lens(lens, **kwargs)
