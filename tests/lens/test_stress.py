"""Stress tests with hypothesis: random valid lenses and awkward rays through
povlens.lens.tracer, paraxial agreement, focusing, and fuzzed lens files.

Camera frame of povlens.lens.coordinates (mm, film at z = 0, +z toward the scene).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, event, given, settings, strategies as st

from povlens.lens import focus as focus_mod
from povlens.errors import LensFileError, OpticsError, UsageError
from povlens.lens.coordinates import vertex_z_mm
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import (AIR, LensPrescription, format_lens, parse_lens_text,
                                  read_lens, sag_mm)
from povlens.lens.tracer import trace_from_film, trace_from_scene

SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                      HealthCheck.filter_too_much])
GRID = 257  # the crossing check of prescription.py samples this many radii

# ----- strategies -------------------------------------------------------------------


@st.composite
def radii(draw):
    """Signed radius in mm: flat (0), or 1e-1 .. 1e12 mm, log-uniform."""
    if draw(st.integers(0, 4)) == 0:
        return 0.0
    mag = 10.0 ** draw(st.floats(-1.0, 12.0))
    return mag if draw(st.booleans()) else -mag


def _min_thickness(c0: float, a0: float, c1: float, a1: float) -> float:
    """Smallest axial gap between vertex 0 and vertex 1 so they do not cross."""
    r = np.linspace(0.0, min(a0, a1), GRID)
    need = np.max(sag_mm(c0, r) - sag_mm(c1, r))
    return max(float(need), 0.0)


@st.composite
def lenses(draw, max_elements: int = 3):
    """(lens, film_distance_mm): a valid random lens, read back through parse_lens_text.

    Elements are glass between two spheres/planes, with an optional aperture row
    between them; radii span 0.1 mm .. 1e12 mm and flats; clear radii may equal |R|
    (hemispheres); neighbouring surfaces may touch (zero extra clearance).
    """
    n_el = draw(st.integers(1, max_elements))
    semi = draw(st.floats(0.5, 30.0))
    stop_before = draw(st.integers(-1, n_el))  # -1: no aperture row
    rows = []  # (radius, index_after, semi_aperture)

    def clear(R):
        if R == 0.0:
            return semi * draw(st.floats(0.2, 1.0))
        f = draw(st.one_of(st.just(1.0), st.floats(0.05, 1.0)))
        return min(semi * draw(st.floats(0.2, 1.0)), abs(R) * f)

    for e in range(n_el + 1):
        if e == stop_before:
            rows.append((0.0, AIR, semi * draw(st.floats(0.05, 1.0))))
        if e == n_el:
            break
        n_glass = draw(st.floats(1.3, 2.1))
        for k in range(2):
            R = draw(radii())
            rows.append((R, n_glass if k == 0 else AIR, clear(R)))
    lines = []
    for i, (R, n, a) in enumerate(rows):
        if i + 1 < len(rows):
            R1, _, a1 = rows[i + 1]
            c0 = 0.0 if R == 0 else 1.0 / R
            c1 = 0.0 if R1 == 0 else 1.0 / R1
            extra = draw(st.one_of(st.just(0.0), st.floats(1e-9, 1e-3), st.floats(0.01, 20.0)))
            t = _min_thickness(c0, a, c1, a1) + extra
        else:
            t = 0.0  # ignored; 0 so the file is never read as a Kolb axial-position table
        lines.append(f"{R:.17g} {t:.17g} {0.0 if n == AIR else n:.17g} {2 * a:.17g}")
    try:
        lens = parse_lens_text("\n".join(lines) + "\n", "<random>")
    except LensFileError:  # pragma: no cover - construction is meant to be safe
        assume(False)
    film = draw(st.one_of(st.floats(0.0, 200.0), st.just(1e-3)))
    return lens, film


@st.composite
def film_rays(draw, lens: LensPrescription, film: float, n: int = 24):
    """Rays from the film toward the lens: random, grazing, exactly at the rear
    surface's clear-aperture edge, along the axis."""
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 32 - 1)))
    spread = draw(st.sampled_from([0.0, 1e-6, 1.0, 20.0]))
    o = np.zeros((n, 3))
    o[:, :2] = rng.uniform(-spread, spread, (n, 2))
    theta = rng.uniform(0, 0.5 * math.pi, n)
    theta[: n // 6] = 0.5 * math.pi - 10.0 ** rng.uniform(-12, -1, n // 6)  # grazing
    theta[n // 6] = 0.5 * math.pi                                          # parallel to film
    phi = rng.uniform(0, 2 * math.pi, n)
    d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], 1)
    # Aim a third of the rays exactly at the rear surface's rim.
    zr = vertex_z_mm(lens.thickness_mm, film)[-1]
    a = lens.aperture_radius_mm[-1]
    c = lens.curvature_per_mm[-1]
    m = n // 3
    psi = rng.uniform(0, 2 * math.pi, m)
    rim = np.stack([a * np.cos(psi), a * np.sin(psi), np.full(m, zr - float(sag_mm(c, a)))], 1)
    d[-m:] = rim - o[-m:]
    d[-1] = [0.0, 0.0, 1.0]
    o[-1] = 0.0
    if draw(st.booleans()):
        o, d = o.astype(np.float32), d.astype(np.float32)
    return o, d


def _check_result(res, lens, n):
    assert res.origin_mm.shape == (n, 3) and res.direction.shape == (n, 3)
    assert res.origin_mm.dtype == np.float64 and res.direction.dtype == np.float64
    assert np.all(np.isfinite(res.origin_mm)), "non-finite origin left the tracer"
    assert np.all(np.isfinite(res.direction)), "non-finite direction left the tracer"
    norm = np.linalg.norm(res.direction, axis=1)
    p = res.passed
    assert np.all(np.abs(norm[p] - 1.0) < 1e-12)
    assert np.all(res.blocked_at[p] == -1)
    assert np.all((res.blocked_at[~p] >= 0) & (res.blocked_at[~p] < lens.n_surfaces))


# ----- tracer properties ------------------------------------------------------------


@settings(max_examples=120, **SETTINGS)
@given(data=st.data(), lf=lenses())
def test_film_rays_stay_finite_and_round_trip(data, lf):
    lens, film = lf
    o, d = data.draw(film_rays(lens, film))
    fwd = trace_from_film(lens, film, o, d)
    _check_result(fwd, lens, len(o))
    p = np.nonzero(fwd.passed)[0]
    if p.size == 0:
        return
    assert np.all(fwd.direction[p, 2] > 0)
    back = trace_from_scene(lens, film, fwd.origin_mm[p], -fwd.direction[p])
    _check_result(back, lens, p.size)
    ok = back.passed
    bo, bd = back.origin_mm[ok], back.direction[ok]
    assert np.all(bd[:, 2] < 0)
    start = np.asarray(o, dtype=np.float64)[p[ok]]
    # The round trip is held to 1e-9 mm for well-conditioned rays.  Near grazing
    # incidence on any surface the problem itself is ill-conditioned: Snell's law
    # gives cos_t = sqrt(1 - mu^2 sin_i^2), so rounding eps in sin_i moves cos_t by
    # ~eps / cos_t, and the hit point L further on by ~L eps / cos_t^2 (a zero-
    # thickness flat plate crossed at d_z = 1e-4 comes back 1e-7 mm off).  So the
    # condition number K of the forward trace is measured by finite differences
    # (output origin, and direction times 100 mm, per mm / radian of input); rays
    # with K > 1e3 or that meet the film at |d_z| < 0.01 are only checked finite.
    # Known gap (HYPOTHESIS_PROFILE=explore finds it now and then): at grazing
    # incidence on a hemisphere's rim (aperture = 2|R|) the sensitivity is a square
    # root, which finite differences of 1e-7 do not see (K ~ 100 measured), and the
    # round trip can come back ~1e-9 mm off; the deterministic examples avoid it.
    kcond = _condition(lens, film, np.asarray(o, np.float64)[p[ok]],
                       np.asarray(d, np.float64)[p[ok]], fwd.origin_mm[p[ok]],
                       fwd.direction[p[ok]])
    strict = (kcond < 1e3) & (np.abs(bd[:, 2]) >= 0.01)
    w = start - bo
    perp = np.linalg.norm(w - np.sum(w * bd, axis=1)[:, None] * bd, axis=1)
    t = -bo[:, 2] / bd[:, 2]
    hit = bo[:, :2] + t[:, None] * bd[:, :2]
    err = np.abs(hit - start[:, :2]).max(axis=1)
    assert np.all(perp[strict] < 1e-9), (perp[strict].max(), lens.radius_mm, film)
    # Where the returning ray lands on the film: a miss of perp across the ray moves
    # the landing point by perp / |d_z| in the film plane, so rays meeting the film
    # more obliquely than |d_z| = 0.1 (84 deg) get that projection in the bound (a
    # ray with d_z = 0.0147 came back 3.3e-11 mm off its line, 1.3e-9 mm in the plane).
    bound = 1e-9 * np.maximum(1.0, 0.1 / np.abs(bd[:, 2]))
    assert np.all(err[strict] < bound[strict]), (err[strict].max(), lens.radius_mm, film)


def _condition(lens, film, o, d, out_o, out_d, delta=1e-7):
    """Finite-difference condition number of trace_from_film per ray (inf when a
    perturbed ray is blocked)."""
    k = np.zeros(len(o))
    d = d / np.linalg.norm(d, axis=1)[:, None]
    for axis in range(4):
        oo, dd = o.copy(), d.copy()
        if axis < 2:
            oo[:, axis] += delta
        else:
            dd[:, axis - 2] += delta
        r = trace_from_film(lens, film, oo, dd)
        change = np.maximum(np.linalg.norm(r.origin_mm - out_o, axis=1),
                            100.0 * np.linalg.norm(r.direction - out_d, axis=1)) / delta
        k = np.maximum(k, np.where(r.passed, change, np.inf))
    return k


@settings(max_examples=80, **SETTINGS)
@given(data=st.data(), lf=lenses())
def test_scene_rays_stay_finite(data, lf):
    lens, film = lf
    rng = np.random.default_rng(data.draw(st.integers(0, 2 ** 32 - 1)))
    n = 24
    front = vertex_z_mm(lens.thickness_mm, film)[0]
    a = lens.aperture_radius_mm[0]
    o = np.column_stack([rng.uniform(-2 * a, 2 * a, (n, 2)),
                         front + rng.choice([1e-9, 1.0, 1e3], n)])
    theta = rng.uniform(0, 0.5 * math.pi, n)
    theta[:4] = 0.5 * math.pi - 10.0 ** rng.uniform(-12, -2, 4)
    phi = rng.uniform(0, 2 * math.pi, n)
    d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), -np.cos(theta)], 1)
    d[:3] *= 10.0 ** rng.uniform(-30, 30, (3, 1))  # unnormalised inputs
    if data.draw(st.booleans()):
        o, d = o.astype(np.float32), d.astype(np.float32)
    res = trace_from_scene(lens, film, o, d)
    _check_result(res, lens, n)
    assert np.all(res.direction[res.passed, 2] < 0)


def test_invalid_and_degenerate_inputs_are_blocked_not_propagated():
    lens = parse_lens_text("50 5 1.5 20\n-50 40 0 20\n")
    o = np.array([[0, 0, 0], [np.nan, 0, 0], [0, 0, 0], [0, 0, 0], [np.inf, 0, 0], [0, 0, 0]],
                 float)
    d = np.array([[0, 0, 1], [0, 0, 1], [0, 0, 0], [np.nan, 0, 1], [0, 0, 1], [1, 0, 0]], float)
    for fn in (trace_from_film, trace_from_scene):
        res = fn(lens, 40.0, o, d if fn is trace_from_film else -d)
        _check_result(res, lens, len(o))
        assert list(res.passed) == ([True] if fn is trace_from_film else [False]) + [False] * 5


def test_total_internal_reflection_is_blocked():
    """A glass hemisphere seen from inside: steep rays leave the flat face fine but
    hit the front sphere beyond the critical angle (n = 2: 30 degrees)."""
    lens = parse_lens_text("10 10 2.0 20\n0 5 0 20\n")
    x = np.linspace(-9.99, 9.99, 41)
    o = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    d = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    # Parallel rays entering the flat rear face go straight on; at the sphere the
    # angle of incidence is asin(|x|/R): TIR beyond |x| = R sin(30 deg) = 5 mm.
    res = trace_from_film(lens, 5.0, o, d)
    _check_result(res, lens, len(x))
    assert np.array_equal(res.passed, np.abs(x) < 5.0 - 1e-9)
    assert np.all(res.blocked_at[~res.passed] == 0)


# ----- paraxial limit ---------------------------------------------------------------


@settings(max_examples=100, **SETTINGS)
@given(lf=lenses())
def test_paraxial_limit_matches_paraxial_bfl(lf):
    lens, film = lf
    try:
        p = paraxial_data(lens)
    except OpticsError:
        return  # afocal
    assume(math.isfinite(p.efl) and abs(p.efl) < 1e5 and abs(p.bfl) < 1e5)
    h = 1e-6 * float(np.min(lens.aperture_radius_mm))
    front = vertex_z_mm(lens.thickness_mm, film)[0]
    o = np.array([[h, 0.0, front + 10.0], [0.0, -h, front + 10.0]])
    d = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])
    res = trace_from_scene(lens, film, o, d)
    _check_result(res, lens, 2)
    assert res.passed.all()
    oo, dd = res.origin_mm, res.direction
    # Where the outgoing ray (or its backward extension) meets the axis.
    z0 = oo[0, 2] - oo[0, 0] * dd[0, 2] / dd[0, 0]
    z1 = oo[1, 2] - oo[1, 1] * dd[1, 2] / dd[1, 1]
    for z in (z0, z1):
        bfl_real = film - z  # rear vertex to focus, + toward the film
        assert bfl_real == pytest.approx(p.bfl, rel=1e-6, abs=1e-6 * abs(p.efl))


# ----- focusing ---------------------------------------------------------------------

distances = st.one_of(st.just(math.inf), st.floats(1e-3, 1e7), st.floats(-1e3, 0.0),
                      st.just(0.0), st.just(math.nan))


@settings(max_examples=150, **SETTINGS)
@given(lf=lenses(), dist=distances)
def test_thick_lens_focus_is_finite_or_a_povlens_error(lf, dist):
    lens, _ = lf
    try:
        v = focus_mod.thick_lens_film_distance_mm(lens, dist)
    except (OpticsError, UsageError):
        return
    assert math.isfinite(v)


@settings(max_examples=20, **SETTINGS)
@given(lf=lenses(max_elements=2),
       dist=st.one_of(st.just(math.inf), st.floats(10.0, 1e6), st.floats(-1.0, 1.0)))
def test_exact_focus_is_finite_or_a_povlens_error(lf, dist):
    lens, _ = lf
    try:
        r = focus_mod.focus(lens, dist)
    except (OpticsError, UsageError) as e:
        event(f"refused: {type(e).__name__}")
        return
    event("focused")
    assert math.isfinite(r.exact_film_distance_mm) and math.isfinite(r.thick_lens_film_distance_mm)


SHIPPED = ["dgauss.50mm", "cooke.triplet.50mm", "singlet.pcx.25mm", "tessar.50mm",
           "telephoto.250mm", "fisheye.10mm", "wide.22mm"]


@settings(max_examples=10, **SETTINGS)
@given(name=st.sampled_from(SHIPPED), f_number=st.one_of(st.none(), st.floats(0.5, 64.0)),
       dist=st.one_of(st.just(math.inf), st.floats(1.0, 1e7)))
def test_focus_of_shipped_lenses_converges_or_refuses(name, f_number, dist):
    from povlens.lens.paraxial import stopped_down
    lens = read_lens(name)
    try:
        lens = stopped_down(lens, f_number=f_number)
        r = focus_mod.focus(lens, dist)
    except (OpticsError, UsageError) as e:
        event(f"refused: {type(e).__name__}")
        return
    event("focused")
    assert math.isfinite(r.exact_film_distance_mm) and r.exact_film_distance_mm > 0
    assert math.isfinite(r.exact_rms_spot_mm)


def test_focus_of_a_diverging_lens_is_an_optics_error():
    """Regression: a negative thick-lens film distance reached scipy's bounded
    minimiser with lower bound > upper bound (ValueError)."""
    lens = parse_lens_text("-1 0.1 2 2\n0 50 0 2\n0 0 0 2\n")
    with pytest.raises(OpticsError, match="not behind the lens"):
        focus_mod.focus(lens, math.inf)
    with pytest.raises(OpticsError):
        focus_mod.exact_film_distance_mm(lens, 1000.0)


# ----- fuzzed lens files ------------------------------------------------------------

VALID = (read_lens("dgauss.50mm").source and
         open(read_lens("dgauss.50mm").source, encoding="utf-8").read())


def _check_parsed(text):
    try:
        lens = parse_lens_text(text, "<fuzz>")
    except LensFileError as e:
        assert "<fuzz>" in str(e)
        return
    assert lens.n_surfaces >= 1
    for a in (lens.radius_mm, lens.thickness_mm, lens.index_after,
              lens.aperture_diameter_mm, lens.abbe_vd):
        assert a.shape == (lens.n_surfaces,) and np.all(np.isfinite(a))
    assert np.all(lens.aperture_diameter_mm > 0) and np.all(lens.index_after >= 1.0)
    assert lens.index_after[-1] == AIR


@settings(max_examples=200, **SETTINGS)
@given(raw=st.binary(max_size=400))
def test_fuzz_random_bytes(raw):
    _check_parsed(raw.decode("latin-1"))


@settings(max_examples=200, **SETTINGS)
@given(text=st.text(alphabet=st.sampled_from(list("0123456789.-+eE \t\n\r#naifNI_x")) |
                    st.characters(), max_size=300))
def test_fuzz_random_text(text):
    _check_parsed(text)


@st.composite
def mutated_lens_text(draw):
    lines = VALID.splitlines()
    for _ in range(draw(st.integers(1, 4))):
        i = draw(st.integers(0, len(lines) - 1))
        toks = lines[i].split()
        op = draw(st.sampled_from(["truncate", "swap", "drop", "dup", "replace", "delete"]))
        if op == "truncate":
            lines[i] = lines[i][: draw(st.integers(0, len(lines[i])))]
        elif op == "swap" and len(toks) >= 2:
            j, k = draw(st.integers(0, len(toks) - 1)), draw(st.integers(0, len(toks) - 1))
            toks[j], toks[k] = toks[k], toks[j]
            lines[i] = " ".join(toks)
        elif op == "drop" and toks:
            toks.pop(draw(st.integers(0, len(toks) - 1)))
            lines[i] = "\t".join(toks)
        elif op == "dup":
            lines.insert(i, lines[i])
        elif op == "replace" and toks:
            toks[draw(st.integers(0, len(toks) - 1))] = draw(st.sampled_from(
                ["nan", "inf", "-0", "0", "1e308", "1e-320", "-1e-320", "5e-324", "1e400",
                 "0x10", "1_0", "", "1e", ".", "-", "1e-300", "1e300", "2.5", "-7"]))
            lines[i] = " ".join(toks)
        elif op == "delete":
            del lines[i]
        if not lines:
            lines = [""]
    return "\n".join(lines)


@settings(max_examples=300, **SETTINGS)
@given(text=mutated_lens_text())
def test_fuzz_mutated_lens_files(text):
    _check_parsed(text)


@settings(max_examples=150, **SETTINGS)
@given(vals=st.lists(st.tuples(
    st.one_of(st.just(0.0), st.floats(allow_nan=False, allow_infinity=False)),
    st.floats(0, 1e300), st.one_of(st.just(0.0), st.floats(1.0, 5.0)),
    st.floats(min_value=0.0, max_value=1e300, exclude_min=True)), min_size=1, max_size=5),
    film=st.floats(0.0, 1e3))
def test_numerically_extreme_valid_rows_trace_finite(vals, film):
    """Rows of extreme but finite numbers: the parser accepts or refuses them; an
    accepted lens traces without NaN or inf."""
    text = "\n".join(" ".join(f"{v:.17g}" for v in row) for row in vals) + "\n"
    try:
        lens = parse_lens_text(text, "<fuzz>")
    except LensFileError:
        return
    _check_parsed(format_lens(lens))
    rng = np.random.default_rng(0)
    o = np.column_stack([rng.normal(0, 1, (8, 2)), np.zeros(8)])
    d = np.column_stack([rng.normal(0, 0.1, (8, 2)), np.ones(8)])
    _check_result(trace_from_film(lens, film, o, d), lens, 8)
    _check_result(trace_from_scene(lens, film, o + [0, 0, 1e3], -d), lens, 8)
    for dist in (math.inf, 1e4):
        try:
            v = focus_mod.thick_lens_film_distance_mm(lens, dist)
        except (OpticsError, UsageError):
            continue
        assert math.isfinite(v)


@pytest.mark.parametrize("text", [
    "1e-320 1 1.5 2e-320\n-1e-320 1 0 2e-320\n",   # 1/R overflows: infinite curvature
    "5e-324 1 1.5 1e-323\n0 1 0 1e-323\n",
    "10 1e308 1.5 5\n-10 1e308 0 5\n0 0 0 5\n",    # the total track overflows
    "1e308 1 1.5 1e308\n-1e308 1 0 1e308\n",        # focus bounds overflow
    "10 1 1e300 5\n-10 1 0 5\n",                  # absurd index
])
def test_lengths_that_overflow_are_refused_by_the_parser(text):
    """Regression: these parsed, and paraxial_data / focus then raised
    ZeroDivisionError or scipy's ValueError instead of a povlens error."""
    with pytest.raises(LensFileError, match="supported|no optical medium"):
        parse_lens_text(text)
