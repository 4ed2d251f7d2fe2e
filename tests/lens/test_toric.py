"""Anamorphic (toric, cylindrical) surfaces: the fast tracer against the independent
reference tracer, a cylinder against Snell's law worked by hand, paraxial data per
meridian against a y-nu trace, the lens-file directive ``#!toric`` (round trip, errors),
clipping where a cylinder ends, and the focus of an anamorphic lens."""
import math
import warnings

import numpy as np
import pytest

from conftest import ROOT
from import_reference import trace as ynu_trace

from povlens.errors import LensClipWarning, LensFileError
from povlens.lens.focus import astigmatic_foci_mm, focus, rms_spot_mm
from povlens.lens.import_lentil import import_lentil
from povlens.lens.paraxial import anamorphic_data, paraxial_data
from povlens.lens.prescription import format_lens, parse_lens_text
from povlens.lens.reference_tracer import trace_rays_from_film, trace_rays_from_scene
from povlens.lens.tracer import trace_from_film, trace_from_scene, trace_unclipped_from_film

DATABASE = ROOT / "tests" / "data" / "lentil-lenses.json"
TOL_MM = 1e-9


def lentil(lens_id):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return import_lentil(DATABASE, lens_id).lens


def film_bundle(lens, film_distance_mm, n=13):
    """Rays from a 2-D set of film points (on and off both axes: skew rays) to a grid
    over (and past) the rear clear aperture."""
    r = float(lens.aperture_radius_mm[-1])
    g = np.linspace(-1.15, 1.15, n) * r
    px, py = (a.ravel() for a in np.meshgrid(g, g))
    s = 0.08 * float(lens.aperture_radius_mm.max())
    origins, dirs = [], []
    for fx, fy in ((0, 0), (1, 0), (0, 1), (0.8, -0.6), (-1.3, 0.9)):
        o = np.column_stack([np.full(px.size, fx * s), np.full(px.size, fy * s),
                             np.zeros(px.size)])
        origins.append(o)
        dirs.append(np.column_stack([px - o[:, 0], py - o[:, 1],
                                     np.full(px.size, film_distance_mm)]))
    return np.concatenate(origins), np.concatenate(dirs)


def scene_bundle(lens, film_distance_mm, n=13):
    """Parallel bundles from the scene (axial and oblique in x, y and both) over a grid
    wider than the front clear aperture."""
    r = float(lens.aperture_radius_mm[0])
    g = np.linspace(-1.1, 1.1, n) * r
    px, py = (a.ravel() for a in np.meshgrid(g, g))
    z = film_distance_mm + lens.total_track_mm + 1.0
    origins, dirs = [], []
    for ax, ay in ((0, 0), (0.08, 0), (0, 0.08), (0.06, -0.05)):
        origins.append(np.column_stack([px, py, np.full(px.size, z)]))
        dirs.append(np.tile([ax, ay, -1.0], (px.size, 1)))
    return np.concatenate(origins), np.concatenate(dirs)


def assert_tracers_agree(fast, ref):
    """Same verdict and blocking row for every ray, positions within 1e-9 mm, directions
    within 1e-9, nothing non-finite."""
    assert np.all(np.isfinite(fast.origin_mm)) and np.all(np.isfinite(fast.direction))
    assert np.array_equal(fast.passed, ref.passed)
    assert np.array_equal(fast.blocked_at, ref.blocked_at)
    p = fast.passed
    assert p.sum() >= 50                      # enough rays get through to compare
    assert np.max(np.abs(fast.origin_mm[p] - ref.origin_mm[p])) < TOL_MM
    assert np.max(np.abs(fast.direction[p] - ref.direction[p])) < TOL_MM


@pytest.mark.parametrize("lens_id", ["2001", "2002", "2003", "2004", "9991"])
def test_fast_and_reference_tracers_agree_on_lentil_anamorphic_lenses(lens_id):
    lens = lentil(lens_id)
    assert lens.is_anamorphic
    a = anamorphic_data(lens)
    fd = next(f for f in (a.focus_y_mm, a.focus_x_mm, 50.0) if math.isfinite(f) and f > 0)
    o, d = film_bundle(lens, fd)
    assert_tracers_agree(trace_from_film(lens, fd, o, d), trace_rays_from_film(lens, fd, o, d))
    o, d = scene_bundle(lens, fd)
    assert_tracers_agree(trace_from_scene(lens, fd, o, d),
                         trace_rays_from_scene(lens, fd, o, d))


TOROIDS = [
    # a toroidal doublet with an aspheric y profile (conic, y^4, y^6) on its front face
    "60 6 1.62 30 50 #!toric rx=-45 #!asphere k=-0.6 a4=-2e-6 a6=1e-9\n"
    "-200 3 1.0 30 #!toric rx=80\n0 40 0 16\n30 5 1.5 24\n-90 0 1 24\n",
    # saddle faces (opposite curvatures in x and y) and a y cylinder with a conic
    "-80 5 1.7 26 #!toric rx=35\n120 2 1.0 26 #!toric rx=-150\n0 10 0 14\n"
    "45 6 1.55 24 #!toric rx=0 #!asphere k=-1.2\n0 0 1 24\n",
]


@pytest.mark.parametrize("text", TOROIDS)
def test_fast_and_reference_tracers_agree_on_toroids(text):
    """General toroids (the fast tracer's Newton path, not the cylinders' closed form)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LensClipWarning)
        lens = parse_lens_text(text, "toroids.dat")
    fd = 45.0
    o, d = film_bundle(lens, fd, n=11)
    assert_tracers_agree(trace_from_film(lens, fd, o, d), trace_rays_from_film(lens, fd, o, d))
    o, d = scene_bundle(lens, fd, n=11)
    assert_tracers_agree(trace_from_scene(lens, fd, o, d),
                         trace_rays_from_scene(lens, fd, o, d))


def snell_by_hand(n1, n2, d, N, T):
    """Snell's law worked in the surface's own basis: N (unit normal), T (unit tangent in
    the plane of curvature) and Y = N x T (along the cylinder's axis).  The tangential
    components of n d are kept; the normal one follows from |d'| = 1."""
    Y = np.cross(N, T)
    dt, dy = n1 / n2 * (d @ T), n1 / n2 * (d @ Y)
    dn = math.copysign(math.sqrt(1.0 - dt * dt - dy * dy), d @ N)
    return dn * N + dt * T + dy * Y


@pytest.mark.parametrize("curved_in", ["x", "y"])
@pytest.mark.parametrize("u0,v0,slope_v,slope_u", [(6.0, 0.0, 0.0, 0.0), (-9.0, 4.0, 0.0, 0.0),
                                                   (4.0, -3.0, 0.12, 0.0),
                                                   (-2.5, 7.0, -0.2, 0.05)])
def test_a_cylinder_refracts_by_snells_law(curved_in, u0, v0, slope_v, slope_u):
    """A plano-convex cylinder lens, radius 25 curving in ``curved_in`` (u: that axis, v:
    the cylinder's axis), glass n = 1.6, 4 mm thick, its flat back face at the rear
    vertex.  A ray from the scene at (u0, v0) with slopes (slope_u, slope_v) is followed
    by hand: to the circle z = z_c + sqrt(R^2 - u^2) (u found by a 1-D solve), refracted
    in the basis of its normal (at the angle asin(u/R) from the axis), carried to the flat
    face and refracted there."""
    R, n2, t, fd = 25.0, 1.6, 4.0, 100.0
    row = f"0 {t} {n2} 26 #!toric rx={R}" if curved_in == "x" else f"{R} {t} {n2} 26 #!toric rx=0"
    lens = parse_lens_text(row + "\n0 0 1 26\n")
    z0 = fd + t                               # front vertex; the centre at z0 - R
    zs = z0 + 2.0
    d = np.array([slope_u, slope_v, -1.0]) / math.sqrt(1.0 + slope_u ** 2 + slope_v ** 2)
    # by hand, in (u, v, z): the hit where u(s)^2 + (z(s) - (z0 - R))^2 = R^2, near side
    lo, hi = 0.0, 10.0                        # bisection on the path length s
    g = lambda s: (zs + s * d[2]) - (z0 - R) - math.sqrt(R * R - (u0 + s * d[0]) ** 2)  # noqa
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if g(mid) > 0 else (lo, mid)
    s_hit = 0.5 * (lo + hi)
    hit = np.array([u0, v0, zs]) + s_hit * d
    a = math.asin(hit[0] / R)
    N = np.array([math.sin(a), 0.0, math.cos(a)])      # toward the scene
    T = np.array([math.cos(a), 0.0, -math.sin(a)])
    inside = snell_by_hand(1.0, n2, d, N, T)
    back = hit + (fd - hit[2]) / inside[2] * inside     # the flat face at z = fd
    out = snell_by_hand(n2, 1.0, inside, np.array([0.0, 0.0, 1.0]),
                        np.array([1.0, 0.0, 0.0]))
    swap = [0, 1, 2] if curved_in == "x" else [1, 0, 2]   # (u, v, z) -> camera (x, y, z)
    r = trace_from_scene(lens, fd, [np.array([u0, v0, zs])[swap]], [d[swap]])
    assert r.passed[0]
    assert r.origin_mm[0] == pytest.approx(back[swap], abs=1e-12)
    assert r.direction[0] == pytest.approx(out[swap], abs=1e-12)
    ref = trace_rays_from_scene(lens, fd, [np.array([u0, v0, zs])[swap]], [d[swap]])
    assert ref.origin_mm[0] == pytest.approx(back[swap], abs=1e-11)
    assert ref.direction[0] == pytest.approx(out[swap], abs=1e-12)


@pytest.mark.parametrize("text", TOROIDS)
def test_paraxial_data_per_meridian_match_a_y_nu_trace(text):
    """Each meridian traced with the curvatures of its own plane: 1/radius (+ 2 a2, none
    here) in y, 1/rx in x; the row numbers read from the text, not from povlens."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LensClipWarning)
        lens = parse_lens_text(text)
    rows = [line.split("#")[0].split() for line in text.splitlines()]
    rx = [float(line.split("rx=")[1].split()[0]) if "rx=" in line else float(r[0])
          for line, r in zip(text.splitlines(), rows)]
    n = [float(r[2]) or 1.0 for r in rows]
    for meridian, radii in (("y", [float(r[0]) for r in rows]), ("x", rx)):
        surfaces = [(1.0 / R if R else 0.0, float(r[1]), ni) for R, r, ni in zip(radii, rows, n)]
        heights, y_k, nu_k = ynu_trace(surfaces, 1.0, 0.0)
        p = paraxial_data(lens, meridian)
        assert p.efl == pytest.approx(-1.0 / nu_k, rel=1e-12)
        assert p.bfl == pytest.approx(-y_k / nu_k, rel=1e-12)
    a = anamorphic_data(lens)
    assert a.squeeze == pytest.approx(paraxial_data(lens, "y").efl / paraxial_data(lens, "x").efl)


ROUND_TRIP = """# a toric test lens
60 6 1.62041 30 60.32 #!asphere k=-0.5 a4=-2e-6 #!toric rx=-45 #!glass N-SK16
-200 3 0 30 #!toric rx=80
0 40 0 16
0 5 1.5168 24 64.17 #!glass N-BK7 #!toric rx=33
-90 0 1 24
"""


def test_lens_file_round_trip_keeps_toric_rows_exactly(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lens = parse_lens_text(ROUND_TRIP, "rt.dat")
        text = format_lens(lens)
        back = parse_lens_text(text, "back.dat")
    assert back == lens and back.sha256() == lens.sha256()
    assert back.radius_x_mm.tolist() == [-45.0, 80.0, 0.0, 33.0, -90.0]
    assert lens.is_anamorphic and lens.is_aperture.tolist() == [False, False, True, False, False]
    assert text.count("#!toric") == 3 and "#!toric rx=-45\t#!asphere k=-0.5 a4=" in text
    assert "#!glass SCHOTT:N-SK16" in text and "#!glass SCHOTT:N-BK7" in text
    assert back.glass == lens.glass == ("SCHOTT:N-SK16", "", "", "SCHOTT:N-BK7", "")
    # the radius column is the y-z section: a Kolb reader ignoring comments sees it
    assert [float(line.split()[0]) for line in text.splitlines() if line[:1] != "#"] == \
        [60.0, -200.0, 0.0, 0.0, -90.0]
    # x radii count in equality and in the hash; sub-lenses keep them
    other = lens.replace(radius_x_mm=lens.radius_x_mm * 1.01)
    assert other != lens and other.sha256() != lens.sha256()
    assert lens.sub_lens(1).radius_x_mm.tolist() == [80.0, 0.0, 33.0, -90.0]
    # rotationally symmetric files gain nothing
    plain = parse_lens_text("50 5 1.5 20\n-50 40 1 20\n")
    assert plain.radius_x_mm is None and "#!toric" not in format_lens(plain)
    same = parse_lens_text("50 5 1.5 20 #!toric rx=50\n-50 40 1 20\n")
    assert same.radius_x_mm is None and same == plain and not same.is_anamorphic


def test_a_cylinder_flat_in_y_is_not_an_aperture():
    lens = parse_lens_text("0 5 1.5 20 #!toric rx=30\n0 2 1 20\n0 30 0 10\n")
    assert lens.is_aperture.tolist() == [False, False, True]
    assert paraxial_data(lens, "x").efl == pytest.approx(60.0)    # 30 / (1.5 - 1)


@pytest.mark.parametrize("text,match", [
    ("# #!toric rx=5\n50 5 1.5 20\n-50 0 1 20\n", r"t.dat:1: '#!toric' stands on a line "
                                                     r"without a row"),
    ("50 5 1.5 20 #!toric\n-50 0 1 20\n", r"t.dat:1: #!toric: nothing given; write "
                                            r"'#!toric rx=R'"),
    ("50 5 1.5 20 #!toric ry=5\n-50 0 1 20\n", r"t.dat:1: #!toric: 'ry=5' is not rx=<radius>"),
    ("50 5 1.5 20\n-50 0 1 20 #!toric rx=abc\n", r"t.dat:2: #!toric: rx: 'abc' is not a number"),
    ("50 5 1.5 20 #!toric rx=inf\n-50 0 1 20\n", r"t.dat:1: #!toric: rx: 'inf' is not a finite"),
    ("50 5 1.5 20 #!toric rx=5 rx=6\n-50 0 1 20\n", r"t.dat:1: #!toric: 'rx=5 rx=6' given"),
    ("50 5 1.5 20 #!toric rx=5 #!toric rx=6\n-50 0 1 20\n", r"t.dat:1: '#!toric' is given "
                                                               r"twice on one row"),
    ("50 5 1.5 20 #!toric rx=1e-9\n-50 0 1 20\n", r"t.dat:1: #!toric: rx 1e-09 mm is "
                                                   r"outside the supported range"),
    ("50 5 1.5 20\n-50 5 1 20\n0 5 0 10 #!toric rx=40\n50 0 1 20\n",
     r"t.dat:3: row 2: '#!toric rx=40': it is a plane in air on both sides \(an aperture "
     r"row\)"),
    ("50 5 1.5 20 #!toric rx=50 #!asphere k=-1\n-50 0 1 20\n",
     r"t.dat:1: row 0: '#!toric rx=50': its x-z radius equals its y-z radius"),
])
def test_bad_toric_directives_name_the_file_and_line(text, match):
    with pytest.raises(LensFileError, match=match):
        parse_lens_text(text, "t.dat")


def test_a_cylinder_is_clipped_where_the_element_edge_closes_in_its_curved_meridian():
    """Plano-convex cylinder R = 25 curving in x, 4 mm thick: its faces meet where the sag
    is 4 mm, at x = sqrt(25^2 - 21^2) (along y they never meet)."""
    with pytest.warns(LensClipWarning, match="where the faces of the element"):
        lens = parse_lens_text("0 4 1.6 40 #!toric rx=25\n0 0 1 40\n")
    assert lens.aperture_diameter_mm[0] == pytest.approx(2 * math.sqrt(25 ** 2 - 21 ** 2),
                                                          rel=1e-9)
    with pytest.warns(LensClipWarning, match=r"the cylinder \(x-z radius 8 mm, flat in y\) "
                                             r"ends"):
        lens = parse_lens_text("0 9 1.6 30 #!toric rx=8\n0 0 1 30\n")
    assert lens.aperture_diameter_mm[0] == pytest.approx(16.0)
    # crossed cylinders (front curving in x, back in y): the faces meet first on the
    # meridians, where one sag alone reaches the 1 mm centre thickness: r^2 = 20^2 - 19^2
    with pytest.warns(LensClipWarning, match="where the faces of the element"):
        lens = parse_lens_text("0 1 1.6 20 #!toric rx=20\n-20 0 1 20 #!toric rx=0\n")
    assert lens.aperture_diameter_mm[0] == pytest.approx(2 * math.sqrt(39.0), rel=1e-9)


def test_unclipped_trace_of_a_toric_lens_is_finite_and_blocks_beyond_the_domain():
    lens = lentil("2004")
    o, d = film_bundle(lens, 43.3, n=9)
    d[:, :2] *= 8.0                           # steep rays that miss the cylinders too
    u = trace_unclipped_from_film(lens, 43.3, o, d)
    assert np.all(np.isfinite(u.origin_mm)) and np.all(np.isfinite(u.direction))
    assert not u.exists.all() and u.exists.any()
    assert np.array_equal(u.passed, trace_from_film(lens, 43.3, o, d).passed)


def test_an_anamorphic_lens_focuses_on_the_smallest_2d_spot():
    """Schneider's 2x anamorphic (lentil 2004): the astigmatic foci are each meridian's
    back focal distance (an independent trace, via anamorphic_data's equality to the
    y-nu test in test_lentil_database); the real-ray focus minimises the RMS spot of the
    2-D bundle: no film distance nearby, nor either meridian's focus, does better."""
    lens = lentil("2004")
    a = anamorphic_data(lens)
    foci = astigmatic_foci_mm(lens, math.inf)
    assert foci == {"y": pytest.approx(a.focus_y_mm), "x": pytest.approx(a.focus_x_mm)}
    r = focus(lens, math.inf)
    assert r.astigmatic_foci_mm == foci
    assert r.thick_lens_film_distance_mm == pytest.approx(0.5 * (foci["x"] + foci["y"]))
    spot = r.exact_rms_spot_mm
    for fd in (foci["x"], foci["y"], r.exact_film_distance_mm - 0.05,
               r.exact_film_distance_mm + 0.05):
        assert rms_spot_mm(lens, fd, math.inf)[0] > spot
    d = r.to_dict()
    assert d["astigmatic_foci_mm"] == {"y": foci["y"], "x": foci["x"]}
    # a lens with no power in y focuses its x meridian; y stays infinite, not NaN
    r = focus(lentil("9991"), 5000.0)
    assert r.astigmatic_foci_mm["y"] == math.inf and r.to_dict()["astigmatic_foci_mm"]["y"] is None
    assert math.isfinite(r.exact_film_distance_mm) and r.exact_film_distance_mm > 0
