"""The depth probe: a light at the eye with and without fade, three renders at the same
time; distances on scenes of known geometry (the camera inside a solid plane, a solid sky
sphere, a solid CSG room), black and emissive surfaces without depth, background at
infinity; the auto path's probe of the plan's camera, and its errors."""

from __future__ import annotations

import json
import math
import os
import shutil
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from povlens.errors import PovlensError, PovrayError
from povlens.lens.film import Film
from povlens.plan.auto import measure_depth_map, probe_size, start_depth_probe
from povlens.plan.camera_setup import FRAMING_NOTE_START
from povlens.plan.convert import ConvertOptions, convert, make_plan
from povlens.plan.depth_probe import (FADE_POWER, ProbeView, axial_depth, depth_limits,
                                      distance_from_fade, probe_depth, ray_directions,
                                      start_probe)
from povlens.plan.schema import PovrayCamera, read_plan
from povlens.pov import process as povray

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray is not installed")

# A plane z = 5 facing the camera and a mirror ball of radius 0.3 at (0.5, 0, 2), camera
# at the origin looking along +z: every distance is known exactly.
SCENE = textwrap.dedent("""\
    #version 3.7;
    global_settings { assumed_gamma 1.0 }
    camera { location <0, 0, 0> look_at <0, 0, 1> }
    light_source { <0, 5, -5> rgb 1 }
    plane { -z, -5 pigment { checker rgb 0.9 rgb 0.1 } finish { reflection 0.5 } }
    sphere { <0.5, 0, 2>, 0.3 pigment { rgb <1, 0, 0> } finish { reflection { 0.8 metallic } } }
    """)
BALL, RADIUS, PLANE_Z = np.array([0.5, 0.0, 2.0]), 0.3, 5.0


def _opts(tmp_path: Path, scene: str = SCENE, **kw) -> ConvertOptions:
    (tmp_path / "s.pov").write_text(scene)
    args = dict(scene=str(tmp_path / "s.pov"), lens="dgauss.50mm", focus=2.0,
                outdir=str(tmp_path / "out"), width=80, height=60, method="mesh",
                location=(0, 0, 0), look_at=(0, 0, 1))
    args.update(kw)
    return ConvertOptions.of(**args)


def _ball_or_plane(dirs: np.ndarray) -> np.ndarray:
    """Ray distance from the origin to the ball or the plane, per unit direction."""
    b = dirs @ BALL
    disc = b * b - (BALL @ BALL - RADIUS ** 2)
    ball = np.where(disc > 0, b - np.sqrt(np.maximum(disc, 0.0)), np.inf)
    return np.minimum(ball, PLANE_Z / dirs[..., 2])


# ----- the method ---------------------------------------------------------------------


def test_distance_from_fade_inverts_the_fade_model():
    """r = (B1 - B0) / (B2 - B0) = 2 / (1 + (d/D)^p) whatever the surface's response and
    the scene's own light; no response is no depth, alpha 0 is background."""
    D = 3.0
    d = np.array([[0.1, 1.0, 3.0, 30.0], [7.0, 300.0, 1.0, 1.0]])
    rng = np.random.default_rng(1)
    response = rng.uniform(5, 500, d.shape + (3,))          # L x diffuse x colour x cos
    b0 = rng.uniform(0, 2, d.shape + (3,))                   # the scene's own light
    response[1, 2] = 0.0                                     # black or emissive
    b2 = b0 + response
    b1 = b0 + response * (2 / (1 + (d / D) ** FADE_POWER))[..., None]
    alpha = np.ones(d.shape + (1,))
    alpha[1, 3] = 0.0                                        # nothing hit
    b0[1, 3] = b1[1, 3] = b2[1, 3] = 0.0
    got = distance_from_fade(*(np.concatenate([b, alpha], axis=2) for b in (b0, b1, b2)), D)
    ok = np.ones(d.shape, bool)
    ok[1, 2:] = False
    np.testing.assert_allclose(got[ok], d[ok], rtol=1e-9)
    assert np.isnan(got[1, 2]) and got[1, 3] == math.inf
    # half-float images (as POV-Ray writes EXR): the distances to the rounding's precision,
    # relative far away, absolute (a fraction of D) close to the eye
    half = [np.concatenate([b, alpha], axis=2).astype(np.float16) for b in (b0, b1, b2)]
    np.testing.assert_allclose(distance_from_fade(*half, D)[ok], d[ok], rtol=3e-3, atol=1e-3 * D)


def _view(tmp_path: Path, scene: str, location, direction, right, up, w=64, h=48,
          focus=5.0) -> ProbeView:
    (tmp_path / "scene.pov").write_text(textwrap.dedent(scene))
    cam = PovrayCamera(tuple(map(float, location)), tuple(map(float, direction)),
                       tuple(map(float, right)), tuple(map(float, up)), 0.0, focus, 60.0)
    return ProbeView(cam, Film(36.0, 27.0, w, h), 1000.0, str(tmp_path / "scene.pov"), focus)


def _probe(tmp_path: Path, view: ProbeView) -> np.ndarray:
    d = start_probe(view, tmp_path, keep_wrappers=False).result()
    assert not list(tmp_path.glob(".depth.*"))                # images removed
    return d


def _box_exit(o, dirs, lo, hi):
    """Ray distance (H, W) from ``o`` inside the box [lo, hi] to its walls."""
    t = np.full(dirs.shape[:2], np.inf)
    for k in range(3):
        with np.errstate(divide="ignore"):
            tk = np.where(dirs[..., k] > 0, (hi[k] - o[k]) / dirs[..., k],
                          np.where(dirs[..., k] < 0, (lo[k] - o[k]) / dirs[..., k], np.inf))
        t = np.minimum(t, tk)
    return t


def _box_entry(o, dirs, lo, hi):
    """Ray distance (H, W) from ``o`` outside the box [lo, hi] to it (inf: missed)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (np.asarray(lo) - o) / dirs
        t2 = (np.asarray(hi) - o) / dirs
    near = np.nanmax(np.minimum(t1, t2), axis=2)
    far = np.nanmin(np.maximum(t1, t2), axis=2)
    return np.where((far >= near) & (near > 0), near, np.inf)


def _assert_region(d, truth, mask, what, rtol=0.01):
    assert mask.sum() >= 20, what
    rel = d[mask] / truth[mask] - 1
    assert np.isfinite(rel).all(), what
    assert abs(np.median(rel)) < 2e-3 and np.percentile(np.abs(rel), 99) < rtol, \
        (what, np.median(rel), np.abs(rel).max())


# ----- scenes of known geometry ------------------------------------------------------------


def test_camera_inside_a_solid_plane_backdrop_with_columns(tmp_path):
    """plane { z, 14 }: the camera is in its solid half-space (POV-Ray's fog does nothing
    there); the backdrop is 14 along the axis, the columns 4 (radius 0.3), the floor 1
    below the eye; a black emissive ball has no depth."""
    scene = """\
        #version 3.7;
        global_settings { assumed_gamma 1 }
        camera { location <0, 1, 0> look_at <0, 1, 4> }
        light_source { <5, 10, -3> color rgb 1 }
        plane { z, 14 pigment { checker rgb 1 rgb 0.3 scale 2 } }
        plane { y, 0 pigment { rgb <0.5, 0.7, 0.5> } }
        cylinder { <-1, 0, 4>, <-1, 3, 4>, 0.3 pigment { rgb <1, 0.2, 0.2> } finish { phong 0.8 } }
        cylinder { <1.2, 0, 4>, <1.2, 3, 4>, 0.3 pigment { rgb <0.2, 0.2, 1> } finish { reflection 0.5 } }
        sphere { <0, 0.5, 2>, 0.3 pigment { rgb 0 } finish { ambient 1 diffuse 0 } }
        """
    eye = np.array([0.0, 1.0, 0.0])
    view = _view(tmp_path, scene, eye, (0, 0, 1), (1.2, 0, 0), (0, 0.9, 0), 80, 60, focus=4.0)
    d = _probe(tmp_path, view)
    dirs = ray_directions(view)
    backdrop = 14.0 / dirs[..., 2]
    floor = np.where(dirs[..., 1] < 0, -1.0 / np.minimum(dirs[..., 1], -1e-300), np.inf)
    columns = np.full(d.shape, np.inf)
    for cx in (-1.0, 1.2):
        ox, oz = eye[0] - cx, eye[2] - 4.0
        a = dirs[..., 0] ** 2 + dirs[..., 2] ** 2
        b = 2 * (ox * dirs[..., 0] + oz * dirs[..., 2])
        disc = b * b - 4 * a * (ox * ox + oz * oz - 0.09)
        t = np.where(disc > 0, (-b - np.sqrt(np.maximum(disc, 0))) / (2 * a), np.inf)
        columns = np.minimum(columns, np.where(t * dirs[..., 1] + 1 < 3, t, np.inf))
    oc = eye - np.array([0, 0.5, 2])
    bb = dirs @ oc
    ball = (bb * bb - (oc @ oc - 0.09)) > 0
    truth = np.minimum(np.minimum(backdrop, floor), columns)
    _assert_region(d, truth, (truth == backdrop) & ~ball, "backdrop")
    _assert_region(d, truth, (truth == columns) & ~ball, "columns")
    _assert_region(d, truth, (truth == floor) & ~ball, "floor")
    assert 13.9 < np.nanmin(d[truth == backdrop]) and np.nanmax(d[truth == backdrop]) < 17.5
    # the black emissive ball: no depth (not a wrong one); its rim may show the floor
    assert np.isnan(d[ball]).mean() > 0.9
    assert not np.isinf(d).any()                             # nothing is background


def test_camera_inside_a_solid_sky_sphere(tmp_path):
    """A lit (non-hollow) sky sphere of radius 60 around the camera and a box 3 ahead:
    every pixel is 60 away but for the box's face."""
    scene = """\
        #version 3.7;
        global_settings { assumed_gamma 1 }
        camera { location 0 direction z }
        light_source { <1, 2, -1> color rgb 1 }
        sphere { 0, 60 pigment { granite color_map { [0 rgb 0.3] [1 rgb 0.9] } } }
        box { <-0.5, -0.5, 3>, <0.5, 0.5, 3.5> pigment { rgb 0.6 } }
        """
    view = _view(tmp_path, scene, (0, 0, 0), (0, 0, 1), (1.6, 0, 0), (0, 1.2, 0), focus=5.0)
    d = _probe(tmp_path, view)
    dirs = ray_directions(view)
    face = (np.abs(3 * dirs[..., 0] / dirs[..., 2]) < 0.5) & (np.abs(3 * dirs[..., 1]
                                                                      / dirs[..., 2]) < 0.5)
    _assert_region(d, np.full(d.shape, 60.0), ~face, "sky sphere")
    _assert_region(d, 3.0 / dirs[..., 2], face, "box")
    z = axial_depth(view, d)
    assert np.allclose(z[face], 3.0, rtol=3e-3)


def test_camera_inside_a_solid_csg_room(tmp_path):
    """difference { room box, table box }, not hollow: the camera is inside the CSG
    object (fog does nothing there); it sees the room's walls and the carved table."""
    scene = """\
        #version 3.7;
        global_settings { assumed_gamma 1 }
        camera { location 0 direction z }
        light_source { <2, 2, 1> color rgb 1 }
        difference {
          box { <-4, -2.5, -1>, <4, 2.5, 8> }
          box { <-1.13, -2.6, 3.1>, <0.87, -1.07, 4.2> }
          pigment { checker rgb 0.8 rgb 0.4 }
        }
        """
    view = _view(tmp_path, scene, (0, 0, 0), (0, 0, 1), (1.6, 0, 0), (0, 1.2, 0), focus=5.0)
    d = _probe(tmp_path, view)
    o = np.zeros(3)
    dirs = ray_directions(view)
    walls = _box_exit(o, dirs, (-4, -2.5, -1), (4, 2.5, 8))
    table = _box_entry(o, dirs, (-1.13, -2.6, 3.1), (0.87, -1.07, 4.2))
    truth = np.minimum(walls, table)
    _assert_region(d, truth, table < walls, "table")
    back = (truth == walls) & (walls == 8.0 / dirs[..., 2])
    _assert_region(d, truth, back, "back wall")
    _assert_region(d, truth, (truth == walls) & ~back, "floor, ceiling and side walls")


def test_emissive_surfaces_have_no_depth_and_background_is_infinitely_far(tmp_path):
    """A floor under an open sky (a sky_sphere: POV-Ray would show it) and two emissive
    balls, one black and one white: sky pixels are inf, the balls nan, the floor its
    distance; depth_limits leaves the balls out of the range and counts them."""
    scene = """\
        #version 3.7;
        global_settings { assumed_gamma 1 }
        camera { location <0, 1, 0> look_at <0, 1, 1> }
        light_source { <3, 10, -2> color rgb 1 }
        sky_sphere { pigment { gradient y color_map { [0 rgb 1] [1 rgb <0.2, 0.3, 1>] } } }
        plane { y, 0 pigment { rgb 0.5 } }
        sphere { <-0.6, 1, 4>, 0.5 pigment { rgb 0 } finish { ambient 1 diffuse 0 } }
        sphere { <0.6, 1, 4>, 0.5 pigment { rgb 1 } finish { ambient 1 diffuse 0 emission 1 } }
        """
    eye = np.array([0.0, 1.0, 0.0])
    view = _view(tmp_path, scene, eye, (0, 0, 1), (1.6, 0, 0), (0, 1.2, 0), focus=4.0)
    d = _probe(tmp_path, view)
    dirs = ray_directions(view)
    balls = np.zeros(d.shape, bool)
    for c in ((-0.6, 1, 4), (0.6, 1, 4)):
        oc = eye - np.asarray(c)
        b = dirs @ oc
        balls |= (b * b - (oc @ oc - 0.25)) > 1e-3
    floor = (dirs[..., 1] < 0) & ~balls
    sky = (dirs[..., 1] > 0) & ~balls
    assert np.isinf(d[sky]).all() and (d[sky] > 0).all()
    assert np.isnan(d[balls]).all()
    _assert_region(d, -1.0 / np.minimum(dirs[..., 1], -1e-300), floor, "floor")
    near, far, info = depth_limits(axial_depth(view, d) * 1000.0)
    assert far == math.inf and info["no_depth_pixels"] == balls.sum()
    assert info["background_fraction"] == pytest.approx(sky.mean())
    assert near > 1000.0 / 0.6                     # no floor point is nearer along the axis


def test_plan_auto_succeeds_on_a_backdrop_scene(tmp_path):
    """The issue's everyday case: with a backdrop plane the camera is inside, 'povlens
    plan' (--method auto) succeeds and puts the backdrop at 14, the columns at about 4."""
    (tmp_path / "backdrop.pov").write_text(textwrap.dedent("""\
        #version 3.7;
        global_settings { assumed_gamma 1 }
        camera { location <0, 1, 0> look_at <0, 1, 4> angle 60 }
        light_source { <5, 10, -3> color rgb 1 }
        plane { z, 14 pigment { checker rgb 1 rgb 0.3 scale 2 } }
        plane { y, 0 pigment { rgb <0.5, 0.7, 0.5> } }
        cylinder { <-0.5, 0, 4>, <-0.5, 3, 4>, 0.3 pigment { rgb <1, 0.2, 0.2> } }
        cylinder { <0.6, 0, 4>, <0.6, 3, 4>, 0.3 pigment { rgb <0.2, 0.2, 1> } }
        """))
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "povlens", "plan", str(tmp_path / "backdrop.pov"),
                        "--lens", "dgauss.50mm", "--width", "32", "--height", "24", "-o",
                        str(out), "--json"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    plan = json.loads((out / "plan.json").read_text())
    n = plan["decision"]["numbers"]
    assert plan["inputs"]["focus"] == 4.0 and plan["inputs"]["focus_from"] == "look_at"
    assert 3600 < n["near_distance_mm"] < 3800                # the columns' fronts (3.7 m)
    assert 13900 < n["far_distance_mm"] < 14100               # the backdrop (14 m)
    rec = plan["depth_probe"]
    assert rec["depth_range"]["no_depth_pixels"] == 0 and "light fade" in rec["method"]
    assert all(n.startswith(FRAMING_NOTE_START) for n in plan.get("notes", []))  # no fog
    assert not list(out.glob(".probe.*"))


def test_the_scenes_own_fog_and_media_are_noted_once(tmp_path):
    """The probe renders at +Q6 (no fog, no media): the distances are the surfaces' with
    or without the scene's fog, and plan.json says once that the probe does not see it."""
    base = SCENE + "fog { distance 3 color rgb 0.7 }\n"
    plans = {}
    for name, text in (("plain", SCENE), ("fog", base)):
        (tmp_path / name).mkdir()
        opts = _opts(tmp_path / name, text, method="auto", width=32, height=24)
        plans[name] = convert(opts)
    a, b = (p.decision.numbers for p in plans.values())
    assert a["near_distance_mm"] == b["near_distance_mm"]
    assert a["far_distance_mm"] == b["far_distance_mm"]
    scene_notes = {k: [n for n in p.notes if not n.startswith(FRAMING_NOTE_START)]
                   for k, p in plans.items()}
    assert scene_notes["plain"] == []
    (note,) = scene_notes["fog"]
    assert "fog" in note and "does not see" in note
    text = (tmp_path / "fog" / "out" / "plan.json").read_text()
    assert text.count("does not see") == 1


# ----- the auto path ---------------------------------------------------------------------


def test_auto_probe_uses_the_plans_camera_at_the_probe_size(tmp_path):
    opts = _opts(tmp_path)
    Path(opts.outdir).mkdir()
    plan = make_plan(opts)
    film = plan.film
    probe = start_depth_probe(opts, film, plan)
    pw, ph = probe_size(film)
    assert (pw, ph) == (64, 48)
    assert probe.view.film.width_px == pw and probe.view.film.height_px == ph
    d = probe.result()                                   # scene units (m), ray distance
    assert d.shape == (ph, pw) and np.isfinite(d).all()
    expected = _ball_or_plane(ray_directions(probe.view))
    assert (expected < 2.0).sum() > 20                   # the ball is in view
    # half-float EXR; the mirrors' reflections must not leak in (+Q6: none traced)
    assert np.max(np.abs(d / expected - 1)) < 5e-3
    z = axial_depth(probe.view, d)
    assert np.allclose(z[expected > 4.0], PLANE_Z, rtol=5e-3)
    assert os.listdir(opts.outdir) == ["pupil.npz"]      # probe folder removed


def test_auto_probe_gives_the_depth_map_of_the_former_separate_pinhole_conversion(tmp_path):
    """Before, the probe converted the scene as 'pinhole' at the probe size (same film in
    mm) into a folder and probed that.  The plan's own camera must give the same map."""
    opts = _opts(tmp_path)
    Path(opts.outdir).mkdir()
    plan = make_plan(opts)
    film = plan.film
    pw, ph = probe_size(film)
    old_dir = tmp_path / "old"
    old = convert(opts.replace(outdir=str(old_dir), method="pinhole", samples=1,
                                      width=pw, height=ph,
                                      film_size_mm=(film.width_mm, film.height_mm)))
    assert old.povray_camera == plan.povray_camera
    old_axial = axial_depth(read_plan(old_dir), probe_depth(old_dir)) * old.mm_per_unit
    new_axial = measure_depth_map(opts, film, plan=plan)
    np.testing.assert_array_equal(new_axial, old_axial)
    # without a plan, the camera is derived the same way
    np.testing.assert_array_equal(measure_depth_map(opts, film), old_axial)


def _fake_povray(tmp_path: Path, body: str) -> Path:
    """A POV-Ray stand-in: logs its start and end, runs ``body``, then the real POV-Ray."""
    real = shutil.which("povray")
    script = tmp_path / "fake-povray"
    script.write_text("\n".join([
        "#!/bin/sh",
        f"log={tmp_path}/calls.log",
        'name=$(for a in "$@"; do case "$a" in +I*) echo "$a";; esac; done)',
        'echo "start $name $(date +%s.%N)" >> "$log"',
        body,
        f'"{real}" "$@"',
        "status=$?",
        'echo "end $name $(date +%s.%N)" >> "$log"',
        "exit $status", ""]))
    script.chmod(script.stat().st_mode | stat.S_IXUSR)
    return script


def _calls(tmp_path: Path) -> dict:
    times: dict = {}
    for line in (tmp_path / "calls.log").read_text().splitlines():
        what, name, t = line.split()
        times.setdefault(name, {})[what] = float(t)
    return times


def test_the_three_renders_run_at_the_same_time_and_differ_only_by_the_light(tmp_path,
                                                                             monkeypatch):
    convert(_opts(tmp_path, method="pinhole", samples=1, width=32, height=24))
    out = tmp_path / "out"
    monkeypatch.setenv(povray.ENV_VAR, str(_fake_povray(tmp_path, "")))
    d = probe_depth(out)
    assert d.shape == (24, 32)
    t = _calls(tmp_path)
    runs = [t[f"+Idepth_fade_{k}.pov"] for k in ("b0", "b1", "b2")]
    assert max(r["start"] for r in runs) < min(r["end"] for r in runs)   # they overlap
    assert not list(out.glob(".depth.*"))
    b0, b1, b2 = ((out / f"depth_fade_{k}.pov").read_text().splitlines() for k in
                  ("b0", "b1", "b2"))
    assert b1[:len(b0)] == b0 and b2[:len(b0)] == b0          # the same but for the light
    light = "\n".join(b1[len(b0):])
    assert "light_source" in light and "fade_distance 2 fade_power 1" in light
    assert "media_interaction off" in light and "media_attenuation off" in light
    assert "\n".join(b2[len(b0):]) == light.replace("\n  fade_distance 2 fade_power 1", "")
    include = next(i for i, ln in enumerate(b0) if ln.startswith("#include"))
    assert b0.index("global_settings { assumed_gamma 1 }") < include   # POV-Ray keeps the first


def test_a_failing_render_raises_povrays_message_and_stops_the_others(tmp_path, monkeypatch):
    convert(_opts(tmp_path, method="pinhole", samples=1, width=32, height=24))
    out = tmp_path / "out"
    fail_b1 = textwrap.dedent("""\
        case "$name" in *b1*)
            echo "Parse Error: fake failure of the fading light" >&2
            echo "end $name $(date +%s.%N)" >> "$log"; exit 1;;
        esac""")
    monkeypatch.setenv(povray.ENV_VAR, str(_fake_povray(tmp_path, fail_b1)))
    with pytest.raises(PovrayError, match="fake failure of the fading light") as info:
        probe_depth(out)
    assert "depth_fade_b1.pov" in str(info.value)
    assert not list(out.glob(".depth.*"))                 # images and logs removed
    assert not [p for p in out.rglob("*") if ".tmp" in p.name or p.suffix == ".log"]
    # the auto path: same error, and its probe folder is removed too
    monkeypatch.setenv(povray.ENV_VAR, str(_fake_povray(tmp_path, fail_b1)))
    opts = _opts(tmp_path, method="auto", outdir=str(tmp_path / "auto"))
    with pytest.raises(PovrayError, match="fake failure of the fading light"):
        convert(opts)
    assert not list((tmp_path / "auto").glob(".probe.*"))


def test_start_probe_rejects_a_bad_fade_distance_before_rendering(tmp_path):
    convert(_opts(tmp_path, method="pinhole", samples=1, width=16, height=12))
    out = tmp_path / "out"
    for bad in (0.0, -1.0, math.inf, math.nan):
        with pytest.raises(PovlensError, match="fade distance"):
            start_probe(ProbeView.of_plan(read_plan(out)), out, fade_distance=bad)
    assert not list(out.glob(".depth.*"))
