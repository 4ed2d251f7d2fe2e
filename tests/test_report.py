"""The depth probe (POV-Ray fog inverted to distances) and ``povlens report``."""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import textwrap
from pathlib import Path

import numpy as np
import pytest

from povlens.convert import ConvertOptions, convert, read_plan
from povlens.depth_probe import axial_depth, distance_from_fog, probe_depth, ray_directions
from povlens.errors import PovlensError

ROOT = Path(__file__).resolve().parent.parent

PLANE_SCENE = textwrap.dedent("""\
    #version 3.7;
    global_settings { assumed_gamma 1.0 }
    camera { location <0, 0, 0> look_at <0, 0, 1> }
    light_source { <0, 5, -5> rgb 1 }
    // Normal -z: the inside is z > 5, so the camera is outside (fog applies).
    plane { -z, -5 pigment { checker rgb 0.9 rgb 0.1 } finish { reflection 0.5 } }
    sphere { <0.5, 0, 2>, 0.3 pigment { rgb <1, 0, 0> } finish { reflection { 0.8 metallic } } }
    """)


def _plane_folder(tmp_path: Path, scene: str = PLANE_SCENE) -> Path:
    (tmp_path / "plane.pov").write_text(scene)
    out = tmp_path / "pl"
    convert(ConvertOptions(scene=str(tmp_path / "plane.pov"), lens="dgauss.50mm", focus=5,
                           outdir=str(out), width=32, height=24, samples=1, method="pinhole",
                           location=(0, 0, 0), look_at=(0, 0, 1)))
    return out


def test_distance_from_fog_inverts_the_fog_model():
    D = 3.0
    d = np.array([[0.1, 1.0, 3.0], [7.0, 15.0, math.inf]])
    f = np.exp(-d / D)
    colour = np.random.default_rng(1).uniform(0, 2, d.shape + (3,))
    black = f[..., None] * colour
    white = black + (1 - f)[..., None]
    got = distance_from_fog(white, black, D)
    assert np.allclose(got[np.isfinite(d)], d[np.isfinite(d)], rtol=1e-9)
    assert np.isinf(got[1, 2])


def test_probe_depth_of_a_plane_and_a_mirror_ball(tmp_path):
    out = _plane_folder(tmp_path)
    d = probe_depth(out)
    plan = read_plan(out)
    dirs = ray_directions(plan)
    assert d.shape == (24, 32) and d.dtype == np.float64
    expected = 5.0 / dirs[..., 2]                       # the plane z = 5
    centre = np.array([0.5, 0.0, 2.0])                  # the mirror ball (radius 0.3)
    b = dirs @ centre
    disc = b * b - (centre @ centre - 0.09)
    t = np.where(disc > 0, b - np.sqrt(np.maximum(disc, 0.0)), np.inf)
    assert (disc > 0).sum() > 50
    expected = np.minimum(expected, t)
    # Half-float EXR: f to ~5e-4; the mirror's reflections must not leak in.
    assert np.max(np.abs(d / expected - 1)) < 5e-3
    z = axial_depth(plan, d)
    assert np.allclose(z[disc <= 0], 5.0, rtol=5e-3)
    assert (out / "depth_fog_white.pov").is_file() and (out / "depth_fog_black.pov").is_file()
    assert not list(out.glob(".depth.*"))


def test_probe_depth_background_is_inf_and_camera_inside_a_solid_is_reported(tmp_path):
    sky = PLANE_SCENE.replace("plane { -z, -5", "plane { y, -1")   # floor; sky above
    (tmp_path / "a").mkdir()
    out = _plane_folder(tmp_path / "a", sky)
    d = probe_depth(out)
    assert np.isinf(d[0]).all()                     # top row: nothing hit
    assert np.isfinite(d[-1]).all()                 # bottom row: the floor
    plan = read_plan(out)
    dirs = ray_directions(plan)
    floor = -1.0 / dirs[-1, :, 1]
    ball = np.isfinite(d[-1]) & (d[-1] < 2.5)
    assert np.allclose(d[-1][~ball], floor[~ball], rtol=5e-3)
    inside = PLANE_SCENE.replace("plane { -z, -5", "plane { z, 5")   # camera inside
    (tmp_path / "b").mkdir()
    out = _plane_folder(tmp_path / "b", inside)
    with pytest.raises(PovlensError, match="inside"):
        probe_depth(out)
