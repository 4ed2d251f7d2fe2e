"""Exit-pupil tables: containment against brute-force tracing, tightness,
unbiasedness, smoothness over the film (no rings), vignetting, files."""

import json
import math
import zlib

import numpy as np
import pytest

from conftest import ROUND_LENSES
from povlens.errors import OpticsError, PovlensError, UsageError
from povlens.lens.focus import thick_lens_film_distance_mm
from povlens.lens.paraxial import paraxial_data, stopped_down
from povlens.lens.prescription import read_lens
from povlens.pupil.build import build_pupil_table, sampling_plane_z_mm
from povlens.pupil.prober import PupilProber
from povlens.pupil.sampler_interface import LensSample
from povlens.pupil.storage import load, load_if_current
from povlens.pupil.baselines import NaiveRearElement, PbrtBoxes
from povlens.pupil.monte_carlo import sobol_points
from povlens.lens.tracer import trace_from_film

HALF_DIAGONAL = 17.5  # 35 mm film diagonal


@pytest.fixture(scope="session")
def tables():
    """Every shipped lens focused at 10 m (thick lens), stop as in the file."""
    out = {}
    for name in ROUND_LENSES:
        lens = read_lens(name)
        fd = thick_lens_film_distance_mm(lens, 10_000.0)
        out[name] = build_pupil_table(lens, fd, HALF_DIAGONAL)
    return out


def brute_force(table, r, n=300):
    """Plane points (rotated frame) of a dense grid over a disc that holds every ray
    that can pass, the pass mask, the grid and its cell area."""
    pr = PupilProber(table.lens, table.film_distance_mm, table.plane_z_mm)
    dcx, dR = pr.domain(np.array([r]))
    g = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    X, Y = np.meshgrid(dcx[0] + dR[0] * g, dR[0] * g)
    ok = pr.passes(np.array(r), X, Y)
    return X, Y, ok, (2.0 * dR[0] / n) ** 2


def test_shipped_lenses_are_all_covered():
    assert len(ROUND_LENSES) >= 9


@pytest.mark.parametrize("name", ROUND_LENSES)
def test_table_contains_every_ray_that_passes(tables, name):
    """Dense brute-force tracing at many film radii (knots, between knots, random):
    no passing ray lies outside the table's region."""
    t = tables[name]
    knots = t.film_radius_mm
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    radii = np.concatenate([knots[::2], knots[:-1] + 0.3 * np.diff(knots),
                            rng.uniform(0.0, t.max_film_radius_mm, 6)])
    radii = np.unique(radii)[:24]
    total = 0
    for r in radii:
        X, Y, ok, _ = brute_force(t, r, n=220)
        pts = np.stack([X[ok], Y[ok]], axis=1)
        inside = t.contains(r, pts)
        total += ok.sum()
        assert inside.all(), (f"{name}: {int((~inside).sum())} passing rays outside the table "
                              f"at film radius {r:.4f} mm")
    assert total > 10_000  # the grids did find the pupil


@pytest.mark.parametrize("name", ROUND_LENSES)
def test_pass_fraction_at_least_95_percent_everywhere(tables, name):
    t = tables[name]
    radii = np.linspace(0.0, HALF_DIAGONAL, 25)
    pf = t.pass_fraction(radii, n_samples=512, seed=2)
    live = ~pf.vignetted
    assert live[0] and live.sum() >= 15
    assert pf.fraction[live].min() >= 0.95, dict(zip(radii[live].round(2),
                                                     pf.fraction[live].round(3)))


def test_table_is_much_tighter_than_pbrt_boxes_and_naive_sampling(tables):
    t = tables["dgauss.50mm.dat"]
    boxes = PbrtBoxes.build(t.lens, t.film_distance_mm, HALF_DIAGONAL, rays_per_interval=2048)
    naive = NaiveRearElement.build(t.lens, t.film_distance_mm, HALF_DIAGONAL)
    radii = np.array([1.0, 9.0, 17.0])
    ours = t.pass_fraction(radii, n_samples=1024).fraction
    assert np.all(ours > boxes.pass_fraction(radii, n_samples=1024).fraction + 0.2)
    assert np.all(ours > naive.pass_fraction(radii, n_samples=1024).fraction + 0.15)


def test_pbrt_boxes_reproduce_the_reference_bounds():
    """realistic-camera.md §8.3, dgauss.50mm bucket 0 with pbrt's 2^20 rays:
    x[-9.314, 9.443] y[-9.337, 9.335].  With fewer rays the box is grown more
    (2 |diag| / sqrt(n)) and found from fewer points: within that margin."""
    lens = read_lens("dgauss.50mm")
    fd = thick_lens_film_distance_mm(lens, 10_000.0)
    b = PbrtBoxes.build(lens, fd, HALF_DIAGONAL, n_intervals=64, rays_per_interval=4096)
    ref = np.array([-9.314, 9.443, -9.337, 9.335])
    grow = 2 * 3 * math.sqrt(2) * 10.0 / math.sqrt(4096) - 2 * 3 * math.sqrt(2) * 10.0 / 1024
    assert np.all(np.abs(np.abs(b.boxes[0]) - np.abs(ref)) < grow + 0.05)
    assert np.all(np.abs(b.boxes[0]) >= np.abs(ref) - 0.05)
    assert 0 < b.rays_traced <= 64 * 4096


def brute_irradiance(table, r, n=500):
    X, Y, ok, dA = brute_force(table, r, n)
    zp = table.plane_z_mm
    cos = zp / np.sqrt((X - r) ** 2 + Y ** 2 + zp ** 2)
    return float(np.sum(np.where(ok, cos ** 4, 0.0)) * dA / zp ** 2)


@pytest.mark.parametrize("name", ["dgauss.50mm.dat", "cooke.triplet.50mm.dat",
                                  "fisheye.10mm.dat"])
def test_mean_weight_is_the_brute_force_irradiance(tables, name):
    """E/L = mean of weight * passed is unbiased: equal to the brute-force
    integral of cos^4 / z^2 over the pass region within noise, for the table and
    for both baselines (all three divide by their pdf)."""
    t = tables[name]
    radii = np.array([0.0, 6.0, 11.0])
    bf = np.array([brute_irradiance(t, r) for r in radii])
    boxes = PbrtBoxes.build(t.lens, t.film_distance_mm, HALF_DIAGONAL, rays_per_interval=1024)
    naive = NaiveRearElement.build(t.lens, t.film_distance_mm, HALF_DIAGONAL)
    for sampler in (t, boxes, naive):
        est = sampler.irradiance_factor(radii, n_samples=1 << 13, seed=5)
        assert est == pytest.approx(bf, rel=4e-3), type(sampler).__name__


@pytest.mark.parametrize("name, reference", [("dgauss.50mm", 0.19251),
                                             ("cooke.triplet.50mm", 0.03047)])
def test_on_axis_irradiance_approaches_pi_over_4n2(name, reference):
    """realistic-camera.md §5.4: on axis the mean weight is E/L = 0.19251 for
    dgauss.50mm (N 2.030) and 0.03047 for the Cooke triplet (N 5.04), within 2 %
    of pi / (4 N^2).  (Those values are for the lens focused at infinity.)"""
    lens = read_lens(name)
    fd = thick_lens_film_distance_mm(lens, math.inf)
    t = build_pupil_table(lens, fd, HALF_DIAGONAL)
    n_f = paraxial_data(lens).f_number
    assert t.axial_irradiance_factor == pytest.approx(reference, rel=3e-4)
    est = t.irradiance_factor([0.0], n_samples=1 << 14, seed=1)[0]
    assert est == pytest.approx(reference, rel=2e-3)
    assert est == pytest.approx(math.pi / (4 * n_f ** 2), rel=0.02)
    assert t.exposure_normalisation() == pytest.approx(1 / reference, rel=3e-4)


def test_no_rings_relative_illumination_is_smooth(tables):
    """A flat white scene: E(r)/E(0) over 301 film radii with the same sample points
    at every radius.  The table's curve has no step above the noise of single
    samples flipping; pbrt's boxes with v3's simple weighting (box areas
    ignored) show the 64 rings to the same detector."""
    t = tables["dgauss.50mm.dat"]
    radii = np.linspace(0.0, HALF_DIAGONAL, 301)
    n = 2048

    def roughness(sampler):
        e = sampler.irradiance_factor(radii, n_samples=n, seed=1)
        e = e / e[0]
        return float(np.max(np.abs(np.diff(e, 2)))), e

    # One sample flipping changes E/E(0) by about its weight / (n E(0)) ~ 1 / n.
    noise = 1.0 / n
    rough, e = roughness(t)
    assert rough < 6 * noise, rough
    assert np.all(np.diff(e) < 4 * noise)  # falls off monotonically (cos^4, cat's eye)
    boxes = PbrtBoxes.build(t.lens, t.film_distance_mm, HALF_DIAGONAL, rays_per_interval=1024)
    ringy, _ = roughness(boxes.with_weighting("simple"))
    assert ringy > 30 * noise, ringy


def test_fisheye_corners_are_vignetted_without_nan(tables):
    t = tables["fisheye.10mm.dat"]
    assert t.vignetted_beyond_mm is not None and 12.0 < t.vignetted_beyond_mm < 15.0
    beyond = np.linspace(t.vignetted_beyond_mm + 0.01, HALF_DIAGONAL, 5)
    for r in beyond:  # brute force agrees: nothing gets through there
        assert not brute_force(t, r, n=200)[2].any()
    assert np.all(t.is_vignetted(beyond))
    # Film corners of a 4:3 frame and the whole diagonal: finite, zero weight outside.
    phi = np.linspace(0, 2 * np.pi, 7)
    r = np.repeat(np.linspace(0, HALF_DIAGONAL, 50), len(phi))
    ang = np.tile(phi, 50)
    film = np.stack([r * np.cos(ang), r * np.sin(ang)], axis=1)
    u = sobol_points(len(film), seed=3)
    s = t.sample(film, u)
    for a in (s.film_point, s.pupil_point, s.direction, s.pdf_per_mm2, s.weight):
        assert np.all(np.isfinite(a))
    out = r > t.vignetted_beyond_mm
    assert not s.valid[out].any() and np.all(s.weight[out] == 0) and np.all(s.pdf_per_mm2[out] == 0)
    assert s.valid[r < 13.0].all() and np.all(s.weight[r < 13.0] > 0)
    pf = t.pass_fraction([16.0, 17.5])
    assert pf.vignetted.all() and np.all(pf.fraction == 0)
    assert np.all(t.irradiance_factor([16.0, 17.5], n_samples=64) == 0)


def test_samples_are_uniform_in_the_region_with_pdf_one_over_area(tables):
    t = tables["wide.22mm.dat"]
    r = 9.3
    n = 1 << 14
    film = np.tile([[r, 0.0]], (n, 1))
    s = t.sample(film, sobol_points(n, seed=4))
    assert s.valid.all()
    area = t.area_mm2(r)[0]
    assert np.allclose(s.pdf_per_mm2, 1.0 / area)
    assert np.allclose(s.pupil_point[:, 2], t.plane_z_mm)
    assert t.contains(r, s.pupil_point[:, :2]).all()
    # Uniform: the share of samples in a sub-box equals its share of the area
    # (area of the sub-box part measured with a fine grid).
    poly = t.region(r)
    x0, x1 = poly[:, 0].min(), poly[:, 0].max()
    y0, y1 = poly[:, 1].min(), poly[:, 1].max()
    g = 600
    X, Y = np.meshgrid(np.linspace(x0, x1, g), np.linspace(y0, y1, g))
    inside = t.contains(r, np.stack([X.ravel(), Y.ravel()], 1)).reshape(X.shape)
    assert inside.sum() * (x1 - x0) * (y1 - y0) / g ** 2 == pytest.approx(area, rel=0.01)
    for cx, cy in ((x0 + 0.3 * (x1 - x0), 0.0), (x0 + 0.8 * (x1 - x0), y0 + 0.2 * (y1 - y0))):
        box = (np.abs(X - cx) < 0.15 * (x1 - x0)) & (np.abs(Y - cy) < 0.15 * (y1 - y0))
        want = (inside & box).sum() / inside.sum()
        p = s.pupil_point
        got = np.mean((np.abs(p[:, 0] - cx) < 0.15 * (x1 - x0))
                      & (np.abs(p[:, 1] - cy) < 0.15 * (y1 - y0)))
        assert got == pytest.approx(want, abs=0.01)
    # Weight = cos^4 / z^2 / pdf.
    cos = s.direction[:, 2]
    assert np.allclose(s.weight, cos ** 4 / t.plane_z_mm ** 2 * area)
    assert np.allclose(np.linalg.norm(s.direction, axis=1), 1.0)


def test_sample_map_is_continuous_and_rotates_with_the_film_point(tables):
    t = tables["dgauss.50mm.dat"]
    u = sobol_points(256, seed=9)
    r = 12.0
    base = t.sample(np.tile([[r, 0.0]], (256, 1)), u).pupil_point
    for phi in (0.7, 2.5, -1.9):
        film = np.tile([[r * math.cos(phi), r * math.sin(phi)]], (256, 1))
        p = t.sample(film, u).pupil_point
        c, s = math.cos(phi), math.sin(phi)
        rot = np.stack([c * base[:, 0] - s * base[:, 1], s * base[:, 0] + c * base[:, 1]], 1)
        assert np.allclose(p[:, :2], rot, atol=1e-9)
    # Small steps in u or in film radius give small steps on the plane (no seams).
    eps = 1e-6
    p0 = t.sample(np.tile([[r, 0.0]], (256, 1)), u).pupil_point
    p1 = t.sample(np.tile([[r, 0.0]], (256, 1)), np.clip(u + eps, 0, 0.999999)).pupil_point
    assert np.max(np.linalg.norm(p1 - p0, axis=1)) < 1e-3
    p2 = t.sample(np.tile([[r + eps, 0.0]], (256, 1)), u).pupil_point
    assert np.max(np.linalg.norm(p2 - p0, axis=1)) < 1e-4
    # Across a knot, the area is continuous.
    k = t.film_radius_mm[len(t.film_radius_mm) // 2]
    a = t.area_mm2([k - 1e-9, k, k + 1e-9])
    assert np.ptp(a) < 1e-6 * a[1]


def test_tolerance_sets_the_number_of_knots():
    lens = read_lens("dgauss.50mm")
    fd = thick_lens_film_distance_mm(lens, 10_000.0)
    loose = build_pupil_table(lens, fd, HALF_DIAGONAL, tolerance=0.05)
    tight = build_pupil_table(lens, fd, HALF_DIAGONAL, tolerance=0.001)
    assert tight.n_knots > loose.n_knots
    assert tight.n_angles >= loose.n_angles
    assert tight.stats["max_check_area_error"] <= 0.001
    radii = np.linspace(0.5, 17, 8)
    assert (tight.pass_fraction(radii, n_samples=512).fraction.mean()
            > loose.pass_fraction(radii, n_samples=512).fraction.mean())


def test_build_is_fast_for_dgauss_at_f2(tables):
    """The speed claim itself is measured in benchmarks/bench_pupil.py; here only
    the work: a few hundred thousand traced rays, not pbrt's 64 x 2^20."""
    t = tables["dgauss.50mm.dat"]
    assert t.stats["rays_traced"] < 600_000
    assert t.n_knots < 40


def test_stopped_down_lens_gets_a_smaller_pupil():
    lens = read_lens("dgauss.50mm")
    fd = thick_lens_film_distance_mm(lens, 10_000.0)
    wide = build_pupil_table(lens, fd, HALF_DIAGONAL)
    f8 = build_pupil_table(stopped_down(lens, f_number=8.0), fd, HALF_DIAGONAL)
    assert f8.area_mm2(0.0)[0] < 0.1 * wide.area_mm2(0.0)[0]
    n_f = paraxial_data(f8.lens).f_number
    assert f8.axial_irradiance_factor == pytest.approx(math.pi / (4 * n_f ** 2), rel=0.03)


def test_sampling_plane_choice():
    lens = read_lens("dgauss.50mm")
    fd = thick_lens_film_distance_mm(lens, 10_000.0)
    z, name = sampling_plane_z_mm(lens, fd)
    assert name == "exit-pupil" and z == pytest.approx(fd + 17.7714, abs=1e-3)
    assert sampling_plane_z_mm(lens, fd, "rear-vertex") == (fd, "rear-vertex")
    with pytest.raises(UsageError, match="plane='front'"):
        sampling_plane_z_mm(lens, fd, "front")
    rear = build_pupil_table(lens, fd, HALF_DIAGONAL, plane="rear-vertex")
    assert rear.plane_z_mm == fd
    X, Y, ok, _ = brute_force(rear, 15.0, n=200)
    assert rear.contains(15.0, np.stack([X[ok], Y[ok]], 1)).all()


def test_bad_arguments_raise_usage_errors():
    lens = read_lens("dgauss.50mm")
    with pytest.raises(UsageError, match="film_distance_mm"):
        build_pupil_table(lens, -1.0, 17.5)
    with pytest.raises(UsageError, match="film_half_diagonal_mm"):
        build_pupil_table(lens, 36.0, float("nan"))
    with pytest.raises(UsageError, match="tolerance=0.0"):
        build_pupil_table(lens, 36.0, 17.5, tolerance=0.0)
    t = build_pupil_table(lens, 36.3, 5.0, tolerance=0.05)
    with pytest.raises(ValueError):
        t.sample(np.zeros((3, 2)), np.zeros((4, 2)))


def test_a_stop_too_small_to_resolve_is_a_clear_optics_error():
    lens = read_lens("dgauss.50mm")
    closed = lens.with_aperture_diameter(5, 1e-9)  # the stop closed to a nanometre
    with pytest.raises(OpticsError, match="stop diameter"):
        build_pupil_table(closed, 36.36, 17.5)
    # 5 um (1e-4 of the focal length) still works
    t = build_pupil_table(lens.with_aperture_diameter(5, 0.006), 36.36, 17.5)
    assert np.isfinite(t.area_mm2(np.array([0.0]))).all()


def test_save_load_and_cache_check(tables, tmp_path):
    t = tables["tessar.50mm.dat"]
    path = tmp_path / "table.npz"
    t.save(path)
    assert [p.name for p in tmp_path.iterdir()] == ["table.npz"]  # no temporary left
    back = load(path)
    for a in ("film_radius_mm", "centre_x_mm", "scale_x_mm", "scale_y_mm", "rho"):
        assert np.array_equal(getattr(back, a), getattr(t, a))
    assert back.lens == t.lens and back.plane_z_mm == t.plane_z_mm
    u = sobol_points(64, seed=1)
    film = np.tile([[7.0, 2.0]], (64, 1))
    assert np.array_equal(back.sample(film, u).pupil_point, t.sample(film, u).pupil_point)
    with np.load(path) as z:
        meta = json.loads(str(z["metadata"]))
    assert meta["lens"]["sha256"] == t.lens.sha256()
    assert meta["film_distance_mm"] == t.film_distance_mm
    assert meta["film"]["half_diagonal_mm"] == HALF_DIAGONAL
    assert meta["lens"]["f_number"] == pytest.approx(paraxial_data(t.lens).f_number)

    lens = read_lens("tessar.50mm")
    fd = t.film_distance_mm
    assert load_if_current(path, lens, fd, HALF_DIAGONAL) is not None
    assert load_if_current(path, lens, fd + 0.01, HALF_DIAGONAL) is None  # focus changed
    assert load_if_current(path, lens, fd, 21.6) is None                  # film changed
    assert load_if_current(path, stopped_down(lens, f_number=8), fd, HALF_DIAGONAL) is None
    assert load_if_current(path, lens, fd, HALF_DIAGONAL, tolerance=0.01) is None
    assert load_if_current(tmp_path / "missing.npz", lens, fd, HALF_DIAGONAL) is None
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a table")
    assert load_if_current(bad, lens, fd, HALF_DIAGONAL) is None
    with pytest.raises(PovlensError, match="bad.npz"):
        load(bad)
    with pytest.raises(UsageError, match="missing"):
        load(tmp_path / "missing.npz")


def test_lens_sample_has_the_documented_fields(tables):
    t = tables["singlet.pcx.25mm.dat"]
    s = t.sample(np.array([[1.0, 2.0], [0.0, 0.0]]), np.array([[0.2, 0.3], [0.9, 0.99]]))
    assert isinstance(s, LensSample) and len(s) == 2
    assert s.film_point.shape == (2, 3) and s.pupil_point.shape == (2, 3)
    assert s.direction.shape == (2, 3) and s.weight.shape == (2,) and s.valid.dtype == bool
    assert np.all(s.film_point[:, 2] == 0)
    # Traced, the samples get through (the on-axis region of a singlet is all pass).
    tr = trace_from_film(t.lens, t.film_distance_mm, s.film_point, s.direction)
    assert tr.passed.all()


def test_a_pupil_that_is_not_star_shaped_is_flagged(tables):
    """The F/1 singlet stopped to F/2 grows horns off axis (a strongly aberrated image
    of the stop); the build reports it.  The shipped lenses as shipped are all
    star-shaped at every probed radius."""
    lens = stopped_down(read_lens("singlet.pcx.25mm"), f_number=2.0)
    fd = thick_lens_film_distance_mm(lens, 2000.0)
    t = build_pupil_table(lens, fd, 21.65, tolerance=0.1, n_angles=32)
    assert t.stats["non_star_shaped_radii"] > 0 and t.stats["non_star_shaped_from_mm"] > 5
    for name, table in tables.items():
        assert table.stats["non_star_shaped_radii"] == 0, name


@pytest.mark.parametrize("name, stop_mm", [("dgauss.50mm", 0.3), ("telephoto.250mm", 2.0),
                                           ("wide.22mm", 0.5)])
def test_tiny_stops_are_found_and_contained(name, stop_mm):
    """A pinhole-like stop makes a pass region far smaller than the coarse search grid;
    the chief ray seeds it.  The table must still contain every passing ray."""
    lens = stopped_down(read_lens(name), stop_diameter_mm=stop_mm)
    fd = thick_lens_film_distance_mm(lens, 8_000.0)
    t = build_pupil_table(lens, fd, HALF_DIAGONAL)
    assert t.pass_fraction(np.array([0.0, 8.0, 16.0]), n_samples=512).fraction.min() > 0.95
    for r in (0.0, 9.0):
        pr = PupilProber(t.lens, t.film_distance_mm, t.plane_z_mm)
        # a dense grid over the table's own region grown 3x: passing rays must be inside
        pts = t.region(r)
        c = pts.mean(axis=0)
        half = 3.0 * np.abs(pts - c).max()
        g = np.linspace(-half, half, 121)
        X, Y = np.meshgrid(c[0] + g, c[1] + g)
        ok = pr.passes(np.array(r), X, Y)
        assert ok.sum() > 100
        assert t.contains(r, np.stack([X[ok], Y[ok]], axis=1)).all()
