"""The depth probe of ``--method auto``: the main plan's camera at the probe size, its two
fogged renders running at the same time, and its errors."""

from __future__ import annotations

import dataclasses
import math
import os
import shutil
import stat
import textwrap
from pathlib import Path

import numpy as np
import pytest

from povlens.pov import process as povray
from povlens.plan.auto import measure_depth_map, probe_size, start_depth_probe
from povlens.plan.convert import ConvertOptions, _make_plan, convert, read_plan
from povlens.plan.depth_probe import axial_depth, probe_depth, ray_directions, start_probe
from povlens.errors import PovlensError, PovrayError

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray is not installed")

# A plane z = 5 facing the camera and a ball of radius 0.3 at (0.5, 0, 2), camera at the
# origin looking along +z: every distance is known exactly.
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
    return ConvertOptions(**args)


def _geometric_distance(dirs: np.ndarray) -> np.ndarray:
    """Ray distance from the origin to the ball or the plane, per unit direction."""
    b = dirs @ BALL
    disc = b * b - (BALL @ BALL - RADIUS ** 2)
    ball = np.where(disc > 0, b - np.sqrt(np.maximum(disc, 0.0)), np.inf)
    return np.minimum(ball, PLANE_Z / dirs[..., 2])


def test_auto_probe_uses_the_plans_camera_at_the_probe_size(tmp_path):
    opts = _opts(tmp_path)
    Path(opts.outdir).mkdir()
    plan, _, _, film = _make_plan(opts)
    probe = start_depth_probe(opts, film, plan)
    pw, ph = probe_size(film)
    assert (pw, ph) == (64, 48)
    assert probe.plan["film"]["width_px"] == pw and probe.plan["film"]["height_px"] == ph
    d = probe.result()                                   # scene units (m), ray distance
    assert d.shape == (ph, pw) and np.isfinite(d).all()
    expected = _geometric_distance(ray_directions(probe.plan))
    assert (expected < 2.0).sum() > 20                   # the ball is in view
    # Half-float EXR: f to ~5e-4; the mirrors' reflections must not leak in.
    assert np.max(np.abs(d / expected - 1)) < 5e-3
    z = axial_depth(probe.plan, d)
    assert np.allclose(z[expected > 4.0], PLANE_Z, rtol=5e-3)
    assert os.listdir(opts.outdir) == ["pupil.npz"]      # probe folder removed


def test_auto_probe_gives_the_depth_map_of_the_former_separate_pinhole_conversion(tmp_path):
    """Before, the probe converted the scene as 'pinhole' at the probe size (same film in
    mm) into a folder and probed that.  The plan's own camera must give the same map."""
    opts = _opts(tmp_path)
    Path(opts.outdir).mkdir()
    plan, _, _, film = _make_plan(opts)
    pw, ph = probe_size(film)
    old_dir = tmp_path / "old"
    old = convert(dataclasses.replace(opts, outdir=str(old_dir), method="pinhole", samples=1,
                                      width=pw, height=ph,
                                      film_size_mm=(film.width_mm, film.height_mm)))
    assert old["povray_camera"] == plan["povray_camera"]
    old_axial = axial_depth(read_plan(old_dir), probe_depth(old_dir)) * old["mm_per_unit"]
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


def test_the_two_fog_renders_run_at_the_same_time(tmp_path, monkeypatch):
    convert(_opts(tmp_path, method="pinhole", samples=1, width=32, height=24))
    out = tmp_path / "out"
    monkeypatch.setenv(povray.ENV_VAR, str(_fake_povray(tmp_path, "")))
    d = probe_depth(out)
    assert d.shape == (24, 32)
    t = _calls(tmp_path)
    black, white = t["+Idepth_fog_black.pov"], t["+Idepth_fog_white.pov"]
    assert white["start"] < black["end"] and black["start"] < white["end"]   # they overlap
    assert not list(out.glob(".depth.*"))


def test_a_failing_fog_render_raises_povrays_message_and_stops_the_other(tmp_path, monkeypatch):
    convert(_opts(tmp_path, method="pinhole", samples=1, width=32, height=24))
    out = tmp_path / "out"
    fail_white = textwrap.dedent("""\
        case "$name" in *white*)
            echo "Parse Error: fake failure of the white fog" >&2
            echo "end $name $(date +%s.%N)" >> "$log"; exit 1;;
        esac""")
    monkeypatch.setenv(povray.ENV_VAR, str(_fake_povray(tmp_path, fail_white)))
    with pytest.raises(PovrayError, match="fake failure of the white fog") as info:
        probe_depth(out)
    assert "depth_fog_white.pov" in str(info.value)
    assert not list(out.glob(".depth.*"))                 # images and logs removed
    assert not [p for p in out.rglob("*") if ".tmp" in p.name or p.suffix == ".log"]
    # the auto path: same error, and its probe folder is removed too
    monkeypatch.setenv(povray.ENV_VAR, str(_fake_povray(tmp_path, fail_white)))
    opts = _opts(tmp_path, method="auto", outdir=str(tmp_path / "auto"))
    with pytest.raises(PovrayError, match="fake failure of the white fog"):
        convert(opts)
    assert not list((tmp_path / "auto").glob(".probe.*"))


def test_camera_inside_a_solid_is_reported_by_the_auto_probe(tmp_path):
    inside = SCENE.replace("plane { -z, -5", "plane { z, 5")   # the inside is z < 5
    opts = _opts(tmp_path, inside, method="auto")
    with pytest.raises(PovlensError, match="inside a solid object") as info:
        convert(opts)
    assert "s.pov" in str(info.value)
    assert not list(Path(opts.outdir).glob(".probe.*"))
    assert not (Path(opts.outdir) / "plan.json").exists()


def test_start_probe_rejects_a_bad_fog_distance_before_rendering(tmp_path):
    convert(_opts(tmp_path, method="pinhole", samples=1, width=16, height=12))
    out = tmp_path / "out"
    for bad in (0.0, -1.0, math.inf, math.nan):
        with pytest.raises(PovlensError, match="fog distance"):
            start_probe(read_plan(out), out, fog_distance=bad)
    assert not list(out.glob(".depth.*"))
