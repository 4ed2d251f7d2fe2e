"""Even aspheres (issue 26 item 1): the sag and its slope against hand values, the
conic's implicit equation and mpmath; the fast tracer (Newton) against the reference
tracer (bracketing and bisection) to 1e-9 mm; zero terms trace as the sphere; the
lens-file comment round trip and its errors; paraxial data from the base curvature."""

import math
import warnings

import mpmath
import numpy as np
import pytest

from povlens.errors import LensFileError
from povlens.lens import asphere, tracer
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import format_lens, parse_lens_text, read_lens
from povlens.lens.reference_tracer import trace_rays_from_film, trace_rays_from_scene
from povlens.lens.tracer import trace_from_film, trace_from_scene

from conftest import ROOT

DGAUSS = (ROOT / "lenses" / "dgauss.50mm.dat").read_text()
#: dgauss.50mm with its front face a prolate asphere and its rear face an oblate one
#: with an r^2 term (which changes the paraxial power).
ASPHERIC_DGAUSS = (DGAUSS.replace("29.475\t3.76\t1.67\t25.2",
                                  "29.475\t3.76\t1.67\t25.2\t#!asphere k=-0.3 a4=-2e-6 a6=1e-9")
                   .replace("-39.73\t0\t1\t20", "-39.73\t0\t1\t20\t#!asphere k=5 a2=1e-4 a4=3e-6 "
                            "a8=-1e-11"))
#: A strongly aspheric singlet: a paraboloid with r^4 and r^6 terms, then a hyperboloid.
SINGLET = """# aspheric singlet
20  6  1.6  16  #!asphere k=-1 a4=-4e-5 a6=2e-7
-60 40 1 16     #!asphere k=-3 a4=1e-5
"""


def _lens(text, name="test.dat"):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return parse_lens_text(text, name)


# ----- sag and slope ------------------------------------------------------------------

def test_sag_hand_values():
    row = np.zeros(9)
    # sphere R = 10 at r = 6: 10 - sqrt(100 - 36) = 2
    assert asphere.sag_mm(0.1, row, 36.0) == pytest.approx(2.0, abs=1e-15)
    # paraboloid c = 1/20, k = -1: c r^2 / 2 = 0.625 at r = 5; + a4 r^4 = 1e-4 * 625
    row[0], row[2] = -1.0, 1e-4
    assert asphere.sag_mm(0.05, row, 25.0) == pytest.approx(0.625 + 0.0625, abs=1e-15)
    # a plane with every term: sum a_2i r^2i at r = 1.1, term by term
    row = np.array([0.0, 1e-2, -2e-3, 3e-4, -4e-5, 5e-6, -6e-7, 7e-8, -8e-9])
    want = sum(row[i] * 1.21 ** i for i in range(1, 9))
    assert asphere.sag_mm(0.0, row, 1.21) == pytest.approx(want, rel=1e-14)


@pytest.mark.parametrize("k", [-3.0, -1.0, -0.4, 0.0, 0.7])
def test_conic_sag_solves_the_conic_equation(k):
    """c (r^2 + (1 + k) z^2) - 2 z = 0 on the vertex branch (an implicit form the code
    does not use)."""
    c, row = 1 / 15.0, np.array([k] + [0.0] * 8)
    r = np.linspace(0, 0.95 * math.sqrt(min(asphere.domain_r2_mm2(c, k), 400.0)), 50)
    z = asphere.sag_mm(c, row, r * r)
    assert np.all(np.abs(c * (r * r + (1 + k) * z * z) - 2 * z) < 1e-14)
    assert np.all(np.abs(z) < 1 / (c * max(1 + k, 1e-9)) + 1e-12)      # not the far branch


def test_slope_is_the_derivative_of_the_sag():
    """(dz/dr) / r against mpmath's numerical derivative of the sag, in 30 digits."""
    c, row = -1 / 23.0, np.array([0.6, 2e-4, -3e-6, 4e-8, -1e-10, 0, 0, 0, 1e-19])
    mpmath.mp.dps = 30

    def sag(r):
        q = 1 - (1 + mpmath.mpf(row[0])) * c * c * r * r
        return c * r * r / (1 + mpmath.sqrt(q)) + sum(mpmath.mpf(row[i]) * r ** (2 * i)
                                                      for i in range(1, 9))
    for r in (0.5, 3.0, 7.5, 11.0):
        want = float(mpmath.diff(sag, mpmath.mpf(r)) / r)
        assert asphere.slope_over_r(c, row, r * r) == pytest.approx(want, rel=1e-12)
    assert asphere.paraxial_curvature_per_mm(_lens(ASPHERIC_DGAUSS))[-1] == pytest.approx(
        -1 / 39.73 + 2e-4, rel=1e-15)


# ----- the two tracers ---------------------------------------------------------------

def _film_rays(lens, film_mm, n, seed):
    rng = np.random.default_rng(seed)
    a = float(lens.aperture_radius_mm[-1])
    o = np.column_stack([rng.uniform(-12, 12, n), rng.uniform(-12, 12, n), np.zeros(n)])
    tgt = np.column_stack([rng.uniform(-a, a, n), rng.uniform(-a, a, n), np.full(n, film_mm)])
    return o, tgt - o


def _scene_rays(passed, n, seed):
    """Rays from the scene: the film rays that passed, reversed from 5 mm in front of
    where they left, each direction shaken by up to 0.02 (most still pass)."""
    rng = np.random.default_rng(seed)
    k = rng.integers(0, len(passed.origin_mm), n)
    d = -passed.direction[k] + rng.uniform(-0.02, 0.02, (n, 3))
    return passed.origin_mm[k] + 5 * passed.direction[k], d


def _assert_agree(fast, ref, at_least):
    assert np.array_equal(fast.blocked_at, ref.blocked_at)
    ok = fast.passed
    assert ok.sum() >= at_least
    assert np.abs(fast.origin_mm[ok] - ref.origin_mm[ok]).max() < 1e-9
    assert np.abs(fast.direction[ok] - ref.direction[ok]).max() < 1e-9
    assert np.all(np.isfinite(fast.origin_mm)) and np.all(np.isfinite(fast.direction))


@pytest.mark.parametrize("name", ["dgauss", "singlet", "lentil-0014"])
def test_fast_and_reference_tracers_agree_on_aspheric_lenses(name):
    if name == "lentil-0014":
        from povlens.lens.import_lentil import read_lentil
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            lens = read_lentil(ROOT / "tests" / "data" / "lentil-lenses.json", "0014")
    else:
        lens = _lens(ASPHERIC_DGAUSS if name == "dgauss" else SINGLET)
    assert asphere.aspheric_rows(lens).sum() >= 2
    film = paraxial_data(lens).bfl
    o, d = _film_rays(lens, film, 1500, 1)
    fast = trace_from_film(lens, film, o, d)
    _assert_agree(fast, trace_rays_from_film(lens, film, o, d), 40)
    passed = tracer.TraceResult(fast.origin_mm[fast.passed], fast.direction[fast.passed],
                                fast.passed[fast.passed], fast.blocked_at[fast.passed])
    o, d = _scene_rays(passed, 1500, 2)
    _assert_agree(trace_from_scene(lens, film, o, d), trace_rays_from_scene(lens, film, o, d),
                  40)


def test_the_unclipped_trace_takes_aspheres():
    lens = _lens(ASPHERIC_DGAUSS)
    film = paraxial_data(lens).bfl
    o, d = _film_rays(lens, film, 300, 3)
    u, f = tracer.trace_unclipped_from_film(lens, film, o, d), trace_from_film(lens, film, o, d)
    assert np.array_equal(u.passed, f.passed)
    assert np.array_equal(u.origin_mm[f.passed], f.origin_mm[f.passed])


def test_zero_terms_trace_as_the_sphere():
    """A lens whose asphere data are all zero traces bit for bit as the spherical one, and
    the Newton intersection with zero terms meets the analytic sphere to 1e-12 mm."""
    sph = _lens(DGAUSS)
    zero = sph.replace(asphere=np.zeros((sph.n_surfaces, 9)))
    film = paraxial_data(sph).bfl
    o, d = _film_rays(sph, film, 400, 4)
    a, b = trace_from_film(sph, film, o, d), trace_from_film(zero, film, o, d)
    assert np.array_equal(a.origin_mm, b.origin_mm) and np.array_equal(a.direction, b.direction)
    assert _lens(DGAUSS.replace("0.12\t1\t25.2", "0.12\t1\t25.2\t#!asphere k=0")) == sph
    rng = np.random.default_rng(5)
    x, y = rng.uniform(-8, 8, 200), rng.uniform(-8, 8, 200)
    dx, dy = rng.uniform(-0.3, 0.3, 200), rng.uniform(-0.3, 0.3, 200)
    dz = -np.sqrt(1 - dx * dx - dy * dy)
    z = np.full(200, 20.0)
    for c in (1 / 29.475, -1 / 14.495):
        hx, hy, hs, bad = tracer._intersect(c, 10.0, x, y, z, dx, dy, dz, 1.0)
        ax, ay, ash, abad, _ = tracer._intersect_asphere(c, np.zeros(9), 10.0, x, y, z,
                                                          dx, dy, dz, 1.0)
        assert np.array_equal(bad, abad)
        assert np.abs(np.stack([hx - ax, hy - ay, hs - ash])[:, ~bad]).max() < 1e-12


def test_rays_that_miss_an_asphere_are_blocked_never_nan():
    lens = _lens(SINGLET)
    o = np.array([[0, 0, 0], [0, 0, 0], [30, 0, 0], [0, 0, 0]], dtype=float)
    d = np.array([[0, 0, 1], [1, 0, 0.01], [-1, 0, 0.02], [np.nan, 0, 1]], dtype=float)
    r = trace_from_film(lens, 40.0, o, d)
    assert r.passed.tolist() == [True, False, False, False]
    assert np.all(np.isfinite(r.origin_mm)) and np.all(np.isfinite(r.direction))


# ----- the lens file and paraxial data -------------------------------------------------

def test_lens_file_round_trip_and_pbrt_view(tmp_path):
    lens = _lens(ASPHERIC_DGAUSS)
    assert lens.asphere[0].tolist() == [-0.3, 0, -2e-6, 1e-9, 0, 0, 0, 0, 0]
    assert lens.asphere[-1][:5].tolist() == [5, 1e-4, 3e-6, 0, -1e-11]
    back = _lens(format_lens(lens))
    assert back == lens and back.sha256() == lens.sha256()
    assert lens.sha256() != _lens(DGAUSS).sha256()                  # tables are not shared
    # what a Kolb reader that drops comments sees: the base spheres
    plain = "\n".join(line.split("#")[0] for line in format_lens(lens).splitlines())
    assert _lens(plain) == _lens(DGAUSS)
    sub = lens.sub_lens(6)
    assert np.array_equal(sub.asphere, lens.asphere[6:])


def test_paraxial_data_from_the_base_curvature():
    """EFL by an independent y-nu trace with c + 2 a2 (a4.. and k change nothing)."""
    lens = _lens(ASPHERIC_DGAUSS)
    rows = [line.split("#")[0].split() for line in ASPHERIC_DGAUSS.splitlines()]
    rows = [[float(v) for v in r] for r in rows if r]
    thick = [r[1] for r in rows]
    y, nu, n = 1.0, 0.0, 1.0
    for i, (radius, _, index, _) in enumerate(rows):
        c = (1 / radius if radius else 0.0) + (2e-4 if i == len(rows) - 1 else 0.0)
        n_after = index or 1.0
        nu -= y * (n_after - n) * c
        n = n_after
        y += thick[i] * nu / n
    assert paraxial_data(lens).efl == pytest.approx(-1 / nu, rel=1e-12)
    spherical_efl = paraxial_data(_lens(DGAUSS)).efl
    assert abs(paraxial_data(lens).efl - spherical_efl) > 0.05


@pytest.mark.parametrize("text,match", [
    ("29.475\t3.76\t1.67\t25.2\t#!asphere k=-0.3 b4=1", r"test.dat:6: #!asphere: 'b4=1' is not"),
    ("29.475\t3.76\t1.67\t25.2\t#!asphere a4=x", r"test.dat:6: #!asphere: a4: 'x' is not a num"),
    ("29.475\t3.76\t1.67\t25.2\t#!asphere a4=1 a4=2", r"test.dat:6: .*'a4' is given twice"),
    ("#!asphere a4=1\n29.475\t3.76\t1.67\t25.2", r"test.dat:6: '#!asphere' stands on a line"),
    ("0\t4.5\t0\t17.1\t#!asphere a4=1e-5", r"row 0 is an aperture .* with asphere terms"),
])
def test_bad_asphere_comments_name_the_line(text, match):
    lines = DGAUSS.splitlines()
    lines[5] = text
    with pytest.raises(LensFileError, match=match):
        parse_lens_text("\n".join(lines), "test.dat")


def test_an_asphere_beyond_its_conic_is_clipped_where_it_ends():
    with pytest.warns(Warning, match=r"row 0: aperture diameter 16 mm clipped to 14\.14.*"
                                     r"asphere's conic"):
        lens = parse_lens_text("10 6 1.6 16 #!asphere k=1\n-60 40 1 16\n", "c.dat")
    assert lens.aperture_diameter_mm[0] == pytest.approx(2 * 10 / math.sqrt(2), rel=1e-12)


def test_bundled_lenses_unchanged():
    lens = read_lens("dgauss.50mm")
    assert lens.asphere is None


def test_asphere_and_glass_comments_share_a_row():
    for row in ("20 6 1.5168 16 64.17 #!asphere k=-1 a4=-4e-5 #!glass N-BK7",
                "20 6 1.5168 16 64.17 #!glass N-BK7 #!asphere k=-1 a4=-4e-5"):
        lens = _lens(row + "\n-60 40 1 16\n")
        assert lens.asphere[0, :3].tolist() == [-1, 0, -4e-5] and lens.glass[0].endswith("N-BK7")
        back = _lens(format_lens(lens))
        assert back == lens and back.glass == lens.glass
