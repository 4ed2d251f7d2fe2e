"""Lens shift (``--shift-mm X,Y``): the frame off the lens axis, verticals kept vertical.

Real POV-Ray renders of the bundled chart at 160 x 120 (dgauss.50mm, 28 x 21 mm film,
0.175 mm pixels).
"""

import json
import math
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from povlens.errors import ParameterError
from povlens.lens.film import Film, parse_shift
from povlens.lens.prescription import read_lens
from povlens.lens.reference_tracer import trace_rays_from_film
from povlens.plan.schema import Inputs, read_plan
from povlens.pupil.field import trace_field
from povlens.util.images import read_image

from conftest import ROOT

CHART = ROOT / "scenes" / "chart.pov"
needs_povray = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")
SIZE = ["--width", "160", "--height", "120"]
BASE = ["--lens", "dgauss.50mm", "--focus", "8"]
# 6.3 mm = 36 pixels of 0.175 mm: the shifted frame is rows 0..119 of a 192-row one
SHIFT = "0,6.3"


def povlens(*args):
    return subprocess.run([sys.executable, "-m", "povlens", *map(str, args)],
                          capture_output=True, text=True, cwd=ROOT, env=dict(os.environ),
                          timeout=600)


def render(out, *args):
    r = povlens("render", CHART, *BASE, "-q", "-o", out, *args)
    assert r.returncode == 0, r.stderr
    return read_image(out / "image.exr")[..., :3]


def test_film_points_move_by_the_shift_and_radii_follow():
    centred = Film(28.0, 21.0, 16, 12)
    shifted = Film(28.0, 21.0, 16, 12, 2.0, 6.0)
    # +y shifts the image up: the film (inverted image) moves down by the shift
    np.testing.assert_allclose(shifted.film_points_mm() - centred.film_points_mm(),
                               np.broadcast_to([-2.0, -6.0], (12, 16, 2)), atol=1e-12)
    assert shifted.max_field_radius_mm == pytest.approx(math.hypot(16.0, 16.5))
    assert centred.max_field_radius_mm == pytest.approx(centred.half_diagonal_mm)
    assert shifted.min_field_radius_mm == 0.0
    assert Film(28.0, 21.0, 16, 12, 0.0, 20.0).min_field_radius_mm == pytest.approx(9.5)
    assert shifted.resized(14.0, 10.5, 8, 6).shift_mm == (2.0, 6.0)
    assert parse_shift("1.5,-2") == (1.5, -2.0) and parse_shift((0, 3)) == (0.0, 3.0)
    for bad in ("6", "a,b", "1,2,3", "nan,0", "inf,1"):
        with pytest.raises(ParameterError) as e:
            parse_shift(bad)
        assert e.value.parameter == "shift_mm" and "shift_mm" in e.value.message


def test_shifted_field_rays_match_the_reference_tracer_past_the_image_circle():
    """The exact tracer's rays of a shifted frame (film points from the shift) agree
    with the reference tracer's, also where the shift leaves the image circle."""
    lens = read_lens("dgauss.50mm")
    fd, zp = 36.0, 40.0
    film = Film(28.0, 21.0, 24, 18, 3.0, 24.0)       # top rows beyond the 28 mm circle
    rows, cols = np.mgrid[0:18, 0:24].astype(float)
    rays = trace_field(lens, fd, film, zp, (1.0, -2.0), cols.ravel(), rows.ravel())
    # the shift mapping written out independently (lens.film's module doc)
    u = cols.ravel() / 24 * 28.0 - 14.0 + 3.0
    v = 10.5 - rows.ravel() / 18 * 21.0 + 24.0
    origin = np.column_stack([-u, -v, np.zeros_like(u)])
    direction = np.column_stack([1.0 + u, -2.0 + v, np.full_like(u, zp)])
    ref = trace_rays_from_film(lens, fd, origin, direction)
    assert 0 < ref.passed.sum() < ref.passed.size           # light and dark corners
    np.testing.assert_array_equal(rays.passed, ref.passed)
    ok = ref.passed
    np.testing.assert_allclose(rays.direction[ok], ref.direction[ok], atol=1e-9)
    np.testing.assert_allclose(rays.origin_mm[ok], ref.origin_mm[ok], atol=1e-7)


@needs_povray
def test_pinhole_shift_is_a_crop_of_a_taller_centred_frame(tmp_path):
    """POV-Ray's off-axis frustum: the shifted 160 x 120 frame is the top 120 rows of
    the centred 160 x 192 frame of the same field radius (same thin lens), vignetting
    map included."""
    for extra in ([], ["--no-vignetting"]):
        name = "v" if not extra else "nv"
        shifted = render(tmp_path / f"s{name}", "--method", "pinhole", *SIZE,
                         "--shift-mm", SHIFT, *extra)
        tall = render(tmp_path / f"t{name}", "--method", "pinhole", "--width", "160",
                      "--height", "192", "--film-size", "28,33.6", *extra)
        assert np.abs(tall[:120] - shifted).max() < 1e-5
        assert np.abs(tall[36:156] - shifted).mean() > 0.01          # not any crop
    plan = json.loads((tmp_path / "sv" / "plan.json").read_text())
    assert plan["inputs"]["shift_mm"] == [0.0, 6.3]
    assert (plan["film"]["shift_x_mm"], plan["film"]["shift_y_mm"]) == (0.0, 6.3)
    assert read_plan(tmp_path / "sv").film.shift_mm == (0.0, 6.3)
    centred = json.loads((tmp_path / "tv" / "plan.json").read_text())
    assert "shift_mm" not in centred["inputs"] and "shift_x_mm" not in centred["film"]


def _line_columns(img, r0, r1, c0):
    """Sub-pixel columns of the chart wall's dark vertical lines in rows [r0, r1)."""
    lum = np.clip(img[r0:r1, c0:, :3], 0, 1).mean(axis=(0, 2))
    base = np.median(lum)
    out = []
    for c in range(2, lum.size - 2):
        if lum[c] < 0.75 * base and lum[c] == lum[c - 2:c + 3].min():
            w = np.clip(base - lum[c - 2:c + 3], 0, None)
            out.append(c0 + c + float((w * np.arange(-2, 3)).sum() / w.sum()))
    return np.array(out)


def _line_slopes(img):
    """Column change per row (px / px) of each wall line between rows 2-14 and 58-68
    (right of the checker chart)."""
    top, bottom = _line_columns(img, 2, 14, 90), _line_columns(img, 58, 68, 90)
    pairs = [(x, bottom[np.argmin(abs(bottom - x))]) for x in top
             if np.min(abs(bottom - x)) < 4]
    assert len(pairs) >= 3, (top, bottom)
    return np.array([(b - a) / 55.0 for a, b in pairs])


@needs_povray
def test_mesh_shift_keeps_the_chart_verticals_parallel(tmp_path):
    """Exact lens rays, camera level, frame shifted up: the wall's vertical lines stay
    vertical; tilting the camera up as far instead makes them converge."""
    shifted = render(tmp_path / "mesh", "--method", "mesh", "--samples", "8", *SIZE,
                     "--shift-mm", SHIFT)
    s = _line_slopes(shifted)
    # the lens's own distortion bends them a little: converged (64 per-pixel samples)
    # the slopes are 0.002-0.0121 px/px; tilting gives 0.012-0.035
    assert np.abs(s).max() < 0.015, s
    # the same view by tilting: look_at raised by atan(6.3 / 50.6 mm) = 7.1 degrees
    tilted = render(tmp_path / "tilt", "--method", "pinhole", *SIZE, "--location", "0,1.5,0",
                    "--look-at", "0,2.4949,8", "--povray-option", "+A0.05",
                    "--povray-option", "+R3")
    t = _line_slopes(tilted)
    assert t.max() > 0.025 and np.all(np.diff(t) > 0), t    # converging toward the top
    # and the mesh render of the shift is the crop of the taller centred frame's
    tall = render(tmp_path / "tall", "--method", "mesh", "--samples", "8", "--width", "160",
                  "--height", "192", "--film-size", "28,33.6")
    d = np.clip(tall[:120], 0, 1) - np.clip(shifted, 0, 1)
    assert math.sqrt(float(np.mean(d * d))) < 0.01


@needs_povray
def test_shift_past_the_image_circle_darkens_the_corners_without_nan(tmp_path):
    img = render(tmp_path / "far", "--method", "mesh", "--samples", "8", *SIZE,
                 "--shift-mm", "0,18")
    assert np.all(np.isfinite(img))
    assert img[:4, :8].max() == 0.0 and img[:4, -8:].max() == 0.0     # beyond 28.2 mm
    assert img[-20:, 60:100].mean() > 0.05


@needs_povray
def test_shift_errors_name_the_option(tmp_path):
    r = povlens("convert", CHART, *BASE, "--method", "pinhole", "--shift-mm", "up",
                "-o", tmp_path / "a")
    assert r.returncode == 2 and "--shift-mm" in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) <= 2
    r = povlens("convert", CHART, *BASE, "--method", "mesh", "--shift-mm", "0,40",
                "-o", tmp_path / "b")
    assert r.returncode == 2 and "--shift-mm" in r.stderr and "image circle" in r.stderr
    r = povlens("convert", CHART, *BASE, "--method", "focal-blur", "--shift-mm", "0,12",
                "-o", tmp_path / "c")
    assert r.returncode == 0 and "focal_blur" in r.stderr and "narrower" in r.stderr


def test_older_inputs_read_and_write_back_without_a_shift():
    d = Inputs(scene="s.pov", lens="l", lens_sha256="0", focus=1.0, units="m", f_number=None,
               stop_diameter_mm=None, film_diagonal_mm=35.0, film_size_mm=None, width=4,
               height=3, method="pinhole", samples=1, batch_size=None, seed=0).to_dict()
    assert "shift_mm" not in d and Inputs.from_dict(d).shift_mm is None
    assert Inputs.from_dict({**d, "shift_mm": [1, 2]}).shift_mm == (1.0, 2.0)


@needs_povray
def test_autofocus_point_of_a_shifted_frame(tmp_path):
    """--focus-at X,Y names a pixel of the shifted frame: near its top, the chart's wall
    8 m away (axial distance along the lens axis, not along the tilted direction)."""
    r = povlens("convert", CHART, "--lens", "dgauss.50mm", "--method", "mesh", "--samples",
                "4", "--width", "64", "--height", "48", "--shift-mm", "3,6", "--focus-at",
                "50,10", "-o", tmp_path / "fa")
    assert r.returncode == 0, r.stderr
    inputs = json.loads((tmp_path / "fa" / "plan.json").read_text())["inputs"]
    assert inputs["focus"] == pytest.approx(8.0, abs=0.02)
    assert inputs["shift_mm"] == [3.0, 6.0]


def test_auto_counts_the_tilted_disc_of_focal_blur_against_the_budget(tmp_path):
    """focal_blur's disc is perpendicular to the shifted direction: the decision adds
    half the diameter it loses along the shift, blur x (1 - cos) / 2, to its checks."""
    import dataclasses
    from povlens.plan.decision import decide, shift_tilt_cos
    r = povlens("convert", CHART, *BASE, *SIZE, "--method", "focal-blur", "--shift-mm", "0,12",
                "-o", tmp_path / "fb")
    assert r.returncode == 0, r.stderr
    plan = read_plan(tmp_path / "fb")
    cos_t = shift_tilt_cos(plan.film.shift_mm, plan.thin_lens.image_distance_mm)
    d = np.asarray(plan.povray_camera.direction, dtype=float)
    assert cos_t == pytest.approx(1.0 / np.linalg.norm(d), rel=1e-12)   # the emitted tilt
    assert shift_tilt_cos((0.0, 0.0), 50.0) == 1.0
    # the decision's logic alone: a thin lens that matches the real one exactly (no
    # distortion, size or shape error), a scene from 0.6 m to 1 m, focused at 8 m
    err = dataclasses.replace(
        plan.model_error, max_distortion_px=0.0, max_blur_size_error_px=0.0,
        blur_real_px=np.zeros_like(np.asarray(plan.model_error.blur_real_px)),
        elongation=np.ones_like(np.asarray(plan.model_error.elongation)))
    c = plan.thin_lens.centre_z_mm
    kw = dict(near_z_mm=c + 600.0, far_z_mm=c + 1000.0, model=plan.thin_lens, model_error=err,
              pixel_pitch_mm=plan.film.pixel_pitch_mm, vignetting=False)
    blur = decide(tolerance_px=0.5, **kw).numbers["max_blur_px"]
    lost = blur * (1 - cos_t) / 2               # px the rim moves along the shift
    print(f"blur {blur:.3f} px, tilt {math.degrees(math.acos(cos_t)):.3f} deg, lost {lost:.3f} px")
    assert lost > 0.05
    for tol, method in ((0.9 * lost, "mesh"), (1.1 * lost, "focal-blur")):
        unshifted = decide(tolerance_px=tol, **kw)
        assert unshifted.method == "focal-blur", unshifted.reasons
        shifted = decide(tolerance_px=tol, shift_tilt_cos=cos_t, **kw)
        assert shifted.method == method, (lost, shifted.reasons)
        assert any("lens shift" in t and f"{lost:.3g} px" in t for t in shifted.reasons)
    assert shifted.numbers["shift_tilt_deg"] == pytest.approx(
        math.degrees(math.atan(12.0 / plan.thin_lens.image_distance_mm)), rel=1e-9)
