"""Shaped apertures end to end: options, plan.json, the planner, the field samples' pupil
domain and weights, real POV-Ray renders of a far highlight, and the CLI's errors."""

import json
import math

import numpy as np
import pytest

from povlens.cli import main
from povlens.lens import reference_tracer
from povlens.lens.aperture_shape import ApertureShape, shaped_lens
from povlens.lens.film import Film
from povlens.lens.focus import focus
from povlens.lens.prescription import read_lens
from povlens.lens.tracer import trace_from_film
from povlens.plan.aperture import describe
from povlens.plan.decision import decide
from povlens.plan.schema import read_plan
from povlens.pupil.aperture_domain import iris_domain, iris_point_mm, iris_scale
from povlens.pupil.build import build_pupil_table
from povlens.pupil.field import bounding_disc_radius_mm, concentric_disc_mm
from povlens.pupil.field_mask import field_transmission
from povlens.rendering.folder_inputs import lens_for
from povlens.util.images import read_image, write_png_srgb

from conftest import ROOT

BOKEH = """#version 3.7;
global_settings { assumed_gamma 1.0 }
camera { perspective location <0, 0, 0> look_at <0, 0, 1> right x up y }
background { rgb 0 }
sphere { <0, 0, 10>, 0.12 pigment { rgb 1 } finish { emission 1 diffuse 0 ambient 0 } }
"""


def _ring_mask(path, n=64, inner=0.55):
    c = (np.arange(n) + 0.5) / n * 2 - 1
    x, y = np.meshgrid(c, c)
    r = np.hypot(x, y)
    m = ((r > inner) & (r < 1.0)).astype(np.float32)
    # write_png_srgb encodes linear light; the mask is read as stored (0 and 1 stay)
    write_png_srgb(path, np.repeat(m[..., None], 3, axis=2))
    return path


def _render(tmp_path, name, *extra, samples=32):
    scene = tmp_path / "bokeh.pov"
    scene.write_text(BOKEH)
    out = tmp_path / name
    rc = main(["render", str(scene), "--lens", "dgauss.50mm", "--focus", "0.25",
               "--method", "mesh", "--samples", str(samples), "--width", "64", "--height", "64",
               "-q", "-o", str(out), *extra])
    assert rc == 0
    return read_image(out / "image.exr")[..., 0].astype(float), out


def _radial_energy(img):
    """Energy-weighted radii of the highlight about its centroid (pixels) and weights."""
    y, x = np.nonzero(img > 0)
    w = img[y, x]
    cx, cy = np.average(x, weights=w), np.average(y, weights=w)
    return np.hypot(x - cx, y - cy), w


@pytest.fixture(scope="module")
def renders(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("aperture")
    round_img, _ = _render(tmp, "round")
    hex_img, hex_out = _render(tmp, "hex", "--aperture-blades", "6", "--blade-rotation", "10")
    ring_img, ring_out = _render(tmp, "ring", "--aperture-image",
                                 str(_ring_mask(tmp / "ring.png")))
    return {"round": round_img, "hex": (hex_img, hex_out), "ring": (ring_img, ring_out),
            "tmp": tmp}


def test_renders_keep_the_light_and_the_mask_makes_a_ring(renders):
    round_img = renders["round"]
    hex_img, _ = renders["hex"]
    ring_img, _ = renders["ring"]
    # the highlight's light is the same through any stop once the exposure puts the frame
    # centre at the pinhole's brightness (within the noise of 32 samples, about 5 % each;
    # test_iris_domain_weights_are_unbiased checks the weights to 0.3 %)
    e = round_img.sum()
    assert hex_img.sum() == pytest.approx(e, rel=0.15)
    assert ring_img.sum() == pytest.approx(e, rel=0.15)
    # the ring mask leaves a hole: no light near the highlight's centre
    r, w = _radial_energy(round_img)
    r_edge = np.percentile(r, 97)
    inner_round = w[r < 0.35 * r_edge].sum() / w.sum()
    r2, w2 = _radial_energy(ring_img)
    inner_ring = w2[r2 < 0.35 * r_edge].sum() / w2.sum()
    assert inner_round > 0.05
    assert inner_ring < 0.2 * inner_round
    # the hexagon's highlight is smaller than the round one by the polygon's area
    n_hex = (hex_img > 0).sum()
    assert n_hex < (round_img > 0).sum()


def test_plan_records_the_shape_and_lens_for_rebuilds_it(renders):
    _, hex_out = renders["hex"]
    plan = read_plan(hex_out / "plan.json")
    inp = json.loads((hex_out / "plan.json").read_text())["inputs"]
    assert inp["aperture_blades"] == 6 and inp["blade_rotation_deg"] == 10.0
    assert "aperture_image" not in inp
    lens = lens_for(plan)
    assert lens.aperture_shape.blades == 6 and lens.aperture_shape.rotation_deg == 10.0
    # field meshes draw from the round stop's ellipses, which hold the iris's regions
    assert plan.field_mesh.domain is not None and plan.pixel_iris is None
    _, ring_out = renders["ring"]
    ring_plan = read_plan(ring_out / "plan.json")
    assert ring_plan.inputs.aperture_image_sha256
    assert lens_for(ring_plan).aperture_shape.mask is not None
    # a changed mask is refused (the samples' transmissions belong to the old one)
    mask = ring_plan.inputs.aperture_image
    old = open(mask, "rb").read()
    try:
        _ring_mask(mask, inner=0.3)
        with pytest.raises(Exception, match="aperture mask .* changed"):
            lens_for(ring_plan)
    finally:
        open(mask, "wb").write(old)


def test_iris_domain_contains_every_passing_ray_and_is_tight():
    lens0 = read_lens("dgauss.50mm")
    fd = focus(lens0, 2000.0).exact_film_distance_mm
    table = build_pupil_table(lens0, fd, 21.6)
    RB = bounding_disc_radius_mm(table)
    shape = ApertureShape(blades=6, rotation_deg=10)
    lens = shaped_lens(lens0, shape)
    RD, flip, _ = iris_domain(lens, fd, table)
    rng = np.random.default_rng(5)
    fractions = []
    for r in (0.0, 5.1, 10.3, 16.9, 21.0):
        phi = rng.uniform(0, 2 * math.pi)
        f = np.array([r * math.cos(phi), r * math.sin(phi)])
        P = concentric_disc_mm(rng.random((30000, 2)), RB)
        o = np.zeros((len(P), 3))
        o[:, :2] = f
        ok = trace_from_film(lens, fd, o, np.c_[P - f, np.full(len(P), table.plane_z_mm)]).passed
        gauge = np.hypot(P[ok, 0], P[ok, 1]) / iris_scale(shape, np.arctan2(P[ok, 1], P[ok, 0]),
                                                          flip)
        assert gauge.max() <= RD                       # conservative
        if r == 21.0:
            # the cat's eye still shows at the frame's edge: rims cut rays the iris passes
            t = trace_from_film(lens, fd, o, np.c_[P - f, np.full(len(P), table.plane_z_mm)])
            stop = lens.aperture_shape_row
            inside = (np.hypot(P[:, 0], P[:, 1])
                      < 0.9 * RD * iris_scale(shape, np.arctan2(P[:, 1], P[:, 0]), flip))
            rims = inside & ~t.passed & (t.blocked_at != stop)
            assert rims.sum() > 0.2 * inside.sum()
        if r == 0.0:
            Q = np.array([iris_point_mm(shape, flip, RD, RB, p)[0]
                          for p in concentric_disc_mm(rng.random((4000, 2)), 1.0)])
            o2 = np.zeros((len(Q), 3))
            fractions = [trace_from_film(lens, fd, o2, np.c_[Q, np.full(len(Q),
                                                                          table.plane_z_mm)]
                                         ).passed.mean(), ok.mean()]
    # on the axis the polygon domain passes >= 95 %, the disc only about the area ratio
    assert fractions[0] >= 0.95
    assert fractions[1] < 0.85


def test_iris_domain_with_dispersion_holds_every_wavelength(tmp_path):
    """--dispersion with an iris: the polygon domain holds the rays that pass at the
    band's ends and between (not only the d line's), and on the axis still passes
    more than the disc."""
    from povlens.lens.dispersion import BAND_NM, lens_at_wavelength
    from povlens.plan.aperture import band_iris_domain
    lens0 = read_lens("tessar.50mm")
    fd = focus(lens0, 2000.0).exact_film_distance_mm
    table = build_pupil_table(lens0, fd, 21.6)
    shape = ApertureShape(blades=6, rotation_deg=10)
    lens = shaped_lens(lens0, shape)
    rd_d, flip, _ = iris_domain(lens, fd, table)
    rd, flip_band = band_iris_domain(lens, fd, table)
    assert rd > rd_d and flip_band == flip
    rb = 1.2 * bounding_disc_radius_mm(table)
    rng = np.random.default_rng(2)
    worst_d = worst = 0.0
    for lam in (BAND_NM[0], 486.1, 656.3, BAND_NM[1]):
        lam_lens = lens_at_wavelength(lens, lam)
        for r in (0.0, 7.3, 14.1, 21.0):
            phi = rng.uniform(0, 2 * math.pi)
            f = np.array([r * math.cos(phi), r * math.sin(phi)])
            P = concentric_disc_mm(rng.random((30000, 2)), rb)
            o = np.zeros((len(P), 3))
            o[:, :2] = f
            ok = trace_from_film(lam_lens, fd, o,
                                 np.c_[P - f, np.full(len(P), table.plane_z_mm)]).passed
            gauge = np.hypot(P[ok, 0], P[ok, 1]) / iris_scale(
                shape, np.arctan2(P[ok, 1], P[ok, 0]), flip)
            worst, worst_d = max(worst, gauge.max() / rd), max(worst_d, gauge.max() / rd_d)
    print(f"largest gauge of a passing ray / R_D: band {worst:.4f}, d line {worst_d:.4f}")
    assert worst <= 1.0
    # the planner uses it: per-pixel meshes sample the polygon inside the band's disc
    out = tmp_path / "p"
    assert main(["convert", str(ROOT / "scenes" / "chart.pov"), "--lens", "tessar.50mm",
                 "--method", "mesh", "--samples", "4", "--width", "64", "--height", "48",
                 "--focus", "2", "--aperture-blades", "6", "--blade-rotation", "10",
                 "--dispersion", "--ray-mesh", "pixel", "-o", str(out)]) == 0
    plan = read_plan(out)
    pi = plan.pixel_iris
    assert plan.inputs.dispersion and pi is not None
    assert pi["domain_radius_mm"] > 0 and pi["flip"] == flip
    u = concentric_disc_mm(rng.random((4000, 2)), 1.0)
    polygon = np.array([iris_point_mm(shape, pi["flip"], pi["domain_radius_mm"],
                                      pi["disc_radius_mm"], p)[0] for p in u])
    disc = u * pi["disc_radius_mm"]
    axis = np.zeros((len(u), 3))
    passes = [trace_from_film(lens, fd, axis, np.c_[q, np.full(len(q), table.plane_z_mm)]
                              ).passed.mean() for q in (polygon, disc)]
    print(f"on the axis: polygon domain passes {passes[0]:.3f}, the disc {passes[1]:.3f}")
    assert passes[0] > 1.1 * passes[1]


def test_iris_domain_weights_are_unbiased():
    """E/L at the film centre from the polygon domain's points and weights (pi rho^2
    cos^4 / z^2) against a dense grid over the plane."""
    lens0 = read_lens("dgauss.50mm")
    fd = focus(lens0, 2000.0).exact_film_distance_mm
    table = build_pupil_table(lens0, fd, 21.6)
    RB = bounding_disc_radius_mm(table)
    shape = ApertureShape(blades=5, curvature=0.3)
    lens = shaped_lens(lens0, shape)
    RD, flip, _ = iris_domain(lens, fd, table)
    zp = table.plane_z_mm

    def passes(P):
        o = np.zeros((len(P), 3))
        d = np.c_[P, np.full(len(P), zp)]
        c = zp / np.sqrt((d * d).sum(1))
        return trace_from_film(lens, fd, o, d).passed, c ** 4 / zp ** 2

    n = 1200
    g = (np.arange(n) + 0.5) / n * 2 - 1
    X, Y = np.meshgrid(g * RB, g * RB)
    ok, f = passes(np.c_[X.ravel(), Y.ravel()])
    exact = (ok * f).sum() * (2 * RB / n) ** 2
    from povlens.pupil.monte_carlo import sobol_points
    u = np.asarray(sobol_points(1 << 14, 2, seed=1))
    pts = [iris_point_mm(shape, flip, RD, RB, p) for p in concentric_disc_mm(u, 1.0)]
    Q = np.array([p for p, _ in pts])
    rho = np.array([r for _, r in pts])
    ok2, f2 = passes(Q)
    est = np.mean(ok2 * f2 * math.pi * rho ** 2)
    assert est == pytest.approx(exact, rel=3e-3)


def test_mask_transmission_per_pixel_matches_the_reference_trace(tmp_path):
    lens0 = read_lens("dgauss.50mm")
    fd = focus(lens0, 2000.0).exact_film_distance_mm
    mask = np.clip(np.random.default_rng(2).random((16, 16)), 0, 1)
    lens = shaped_lens(lens0, ApertureShape(mask=mask))
    film = Film.from_diagonal(35.0, 24, 18)
    zp = fd + 30.0
    passed = np.ones((18, 24), bool)
    x, y = np.arange(24) + 0.3, np.arange(18) + 0.6
    t = field_transmission(lens, fd, film, zp, np.array([3.0, -2.0]), x, y, passed)
    # the reference tracer's hit on the stop (sub-lens traced one ray at a time)
    from povlens.pupil.field import image_to_film_mm
    X, Y = np.meshgrid(x, y)
    f = image_to_film_mm(film, X.ravel(), Y.ravel())
    o = np.c_[f, np.zeros(len(f))]
    d = np.c_[3.0 - f[:, 0], -2.0 - f[:, 1], np.full(len(f), zp)]
    row = lens.aperture_shape_row
    ref = reference_tracer.trace_rays_from_film(lens0.sub_lens(row), fd, o, d)
    r = lens.aperture_radius_mm[row]
    want = lens.aperture_shape.transmission(ref.origin_mm[:, 0], ref.origin_mm[:, 1], r)
    assert np.allclose(t.ravel(), want, atol=1e-6)
    assert 0.05 < t.mean() < 0.95


def test_auto_renders_mesh_with_a_shape_and_focal_blur_says_it_is_round(tmp_path):
    scene = tmp_path / "b.pov"
    scene.write_text(BOKEH)
    rc = main(["convert", str(scene), "--lens", "dgauss.50mm", "--focus", "4",
               "--method", "focal-blur", "--width", "32", "--height", "24",
               "--aperture-blades", "7", "-o", str(tmp_path / "fb")])
    assert rc == 0
    plan = read_plan(tmp_path / "fb" / "plan.json")
    assert any("focal_blur renders a round aperture" in n for n in plan.notes)
    # the decision: a blur the thin lens draws within the budget -> focal-blur, unless
    # the stop is shaped
    c = plan.thin_lens.centre_z_mm
    kw = dict(near_z_mm=c + 3000.0, far_z_mm=c + 6000.0, model=plan.thin_lens,
              model_error=plan.model_error, pixel_pitch_mm=plan.film.pixel_pitch_mm,
              tolerance_px=0.2, vignetting=False)
    free = decide(**kw)
    assert free.method == "focal-blur", free.reasons
    shaped = decide(aperture_shape=describe(ApertureShape(blades=7)), **kw)
    assert shaped.method == "mesh"
    assert "cannot draw the aperture shape (7 blades)" in shaped.reasons[-1]
    # far out of focus everywhere below the budget: pinhole, shape or not
    sharp = decide(aperture_shape="7 blades", **dict(kw, tolerance_px=50.0))
    assert sharp.method == "pinhole"


@pytest.mark.parametrize("args, says", [
    (["--aperture-blades", "2"], "--aperture-blades 2"),
    (["--aperture-blades", "6", "--blade-curvature", "1.5"], "--blade-curvature 1.5"),
    (["--blade-rotation", "15"], "--blade-rotation 15"),
    (["--aperture-image", "missing.png"], "no such file"),
    (["--aperture-image", "NOTPNG"], "not a readable image"),
    (["--aperture-image", "BLACK"], "transmits no light")])
def test_cli_errors_are_one_line(tmp_path, capsys, args, says):
    scene = tmp_path / "b.pov"
    scene.write_text(BOKEH)
    if args[-1] == "NOTPNG":
        (tmp_path / "x.png").write_text("not an image\n")
        args = ["--aperture-image", str(tmp_path / "x.png")]
    if args[-1] == "BLACK":
        write_png_srgb(tmp_path / "k.png", np.zeros((8, 8, 3), np.float32))
        args = ["--aperture-image", str(tmp_path / "k.png")]
    rc = main(["convert", str(scene), "--lens", "dgauss.50mm", "--focus", "1",
               "--method", "pinhole", "--width", "16", "--height", "16",
               "-o", str(tmp_path / "o"), *args])
    err = capsys.readouterr().err
    assert rc == 2
    first = err.strip().splitlines()[0]
    assert first.startswith("povlens convert: error:") and says in first
    assert "Traceback" not in err


HIGHLIGHT = """#version 3.7;
global_settings { assumed_gamma 1.0 }
camera { perspective location <0, 0, 0> look_at <0, 0, 1> right x*image_width/image_height
         angle 8 }
background { rgb 0 }
sphere { <0, 0, 15>, 0.06 pigment { rgb 1 } finish { emission 12 diffuse 0 ambient 0 } }
"""


def _outline_radius(img, n_angles, sigma):
    """The highlight's outline radius (px) at ``n_angles`` angles counter-clockwise from
    image right (y up): the half-level contour of the image smoothed by ``sigma`` px,
    walked along rays from the highlight's centre."""
    from scipy import ndimage
    im = ndimage.gaussian_filter(img, sigma)
    h, w = im.shape
    level = 0.5 * np.median(im[h // 2 - 4:h // 2 + 4, w // 2 - 4:w // 2 + 4])
    labels, _ = ndimage.label(im > level)
    cy, cx = ndimage.center_of_mass(labels == labels[h // 2, w // 2])
    theta = np.radians(np.arange(n_angles) * 360.0 / n_angles)
    r = np.arange(0.0, min(h, w) / 2, 0.25)
    profile = ndimage.map_coordinates(im, [cy - np.outer(np.sin(theta), r),
                                           cx + np.outer(np.cos(theta), r)], order=1)
    return r[np.argmax(profile <= level, axis=1)]


def _outline_corner_angles(img, n_angles=180):
    """Angles (deg) of the maxima of the highlight's outline radius (smoothed over
    +-8 angles)."""
    edge = _outline_radius(img, n_angles, 1.5)
    k = np.exp(-0.5 * (np.arange(-8, 9) / 2.5) ** 2)
    smooth = np.convolve(np.concatenate([edge[-8:], edge, edge[:8]]), k / k.sum(), "same")[8:-8]
    peak = ((smooth > np.roll(smooth, 1)) & (smooth >= np.roll(smooth, -1))
            & (smooth > np.median(smooth)))
    return np.nonzero(peak)[0] * 360.0 / n_angles


def _far_highlight(tmp_path, blades: int, rotation_deg: float, samples: int,
                   ray_mesh: str = "field") -> np.ndarray:
    """The grey (96, 96) mesh render of HIGHLIGHT far out of focus through an iris."""
    scene = tmp_path / "highlight.pov"
    scene.write_text(HIGHLIGHT)
    out = tmp_path / f"iris{blades}"
    assert main(["render", str(scene), "--lens", "dgauss.50mm", "--focus", "0.5",
                 "--film-diagonal", "6", "--method", "mesh", "--samples", str(samples),
                 "--ray-mesh", ray_mesh, "--width", "96", "--height", "96",
                 "--aperture-blades", str(blades), "--blade-rotation", str(rotation_deg),
                 "-q", "-o", str(out)]) == 0
    return read_image(out / "image.exr")[..., :3].mean(axis=2).astype(float)


def test_rendered_far_highlight_has_six_corners_at_the_rotation(tmp_path):
    # the test on a real render: 128 field samples resolve a hexagon's corners
    # (9 blades: below, with per-pixel meshes)
    img = _far_highlight(tmp_path, blades=6, rotation_deg=10, samples=128)
    corners = _outline_corner_angles(img)
    assert len(corners) == 6
    want = (100.0 + 60.0 * np.arange(6)) % 360
    err = np.abs((corners[:, None] - want[None, :] + 180) % 360 - 180).min(axis=1)
    assert err.max() < 8.0, corners


def _outline_harmonics(img, n_angles=360, keep=12):
    """The angles (deg) of the maxima of the outline radius's Fourier series cut after
    harmonic ``keep``, and the amplitudes of harmonics 0..keep."""
    f = np.fft.rfft(_outline_radius(img, n_angles, 1.0))
    f[keep + 1:] = 0
    smooth = np.fft.irfft(f, n_angles)
    peak = (smooth > np.roll(smooth, 1)) & (smooth >= np.roll(smooth, -1))
    return np.nonzero(peak)[0] * 360.0 / n_angles, np.abs(f[:keep + 1]) / n_angles


def test_rendered_far_highlight_has_nine_corners_with_per_pixel_meshes(tmp_path):
    # a 9-blade outline is 6 % from round: per-pixel meshes (a pupil point per pixel and
    # sample) resolve it in 128 samples (harmonic 9: 0.27, the next 0.11; corners within
    # 4 deg) where field meshes would need ~1000
    img = _far_highlight(tmp_path, blades=9, rotation_deg=7, samples=128, ray_mesh="pixel")
    corners, amplitude = _outline_harmonics(img)
    assert np.argmax(amplitude[1:]) + 1 == 9                  # nine-fold above all else
    assert len(corners) == 9
    want = (97.0 + 40.0 * np.arange(9)) % 360                 # corners at 90 + rotation
    err = np.abs((corners[:, None] - want[None, :] + 180) % 360 - 180).min(axis=1)
    assert err.max() < 12.0, corners


@pytest.mark.parametrize("extra", [[], ["--dispersion"]])
def test_per_pixel_plans_of_an_iris_record_its_domain(tmp_path, extra):
    from povlens.rendering.pixel_sampler import pixel_sampler
    from povlens.rendering.folder_inputs import pupil_table_for
    out = tmp_path / "px"
    assert main(["convert", str(ROOT / "scenes" / "chart.pov"), "--lens", "tessar.50mm",
                 "--method", "mesh", "--ray-mesh", "pixel", "--samples", "4", "--width", "32",
                 "--height", "24", "--aperture-blades", "6", *extra, "-o", str(out)]) == 0
    plan = read_plan(out)
    assert plan.field_mesh is None and bool(plan.inputs.dispersion) == bool(extra)
    iris = plan.pixel_iris
    assert iris["domain_radius_mm"] > 0 and iris["disc_radius_mm"] > 0
    assert json.loads((out / "plan.json").read_text())["pixel_iris"] == iris
    lens = lens_for(plan)
    sampler = pixel_sampler(plan, lens, pupil_table_for(out, plan, lens))
    assert sampler.uses_domain(np.array([0.0]))[0]
    if extra:                                          # the band table underneath
        assert sampler.table.metadata["band_dilation_max"] >= 1.0
    # no iris: no domain, and the plan.json has no such entry
    assert main(["convert", str(ROOT / "scenes" / "chart.pov"), "--lens", "tessar.50mm",
                 "--method", "mesh", "--ray-mesh", "pixel", "--samples", "4", "--width", "32",
                 "--height", "24", "-o", str(tmp_path / "round")]) == 0
    assert "pixel_iris" not in json.loads((tmp_path / "round" / "plan.json").read_text())
