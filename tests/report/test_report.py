"""The depth probe of a render folder (a light at the eye, with and without fade) and
``povlens report``."""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import textwrap
from pathlib import Path

import numpy as np
import pytest

from povlens.plan.convert import ConvertOptions, convert
from povlens.plan.schema import read_plan
from povlens.plan.depth_probe import FADE_POWER, axial_depth, distance_from_fade, probe_depth
from povlens.plan.depth_probe import ray_directions

ROOT = Path(__file__).resolve().parents[2]

PLANE_SCENE = textwrap.dedent("""\
    #version 3.7;
    global_settings { assumed_gamma 1.0 }
    camera { location <0, 0, 0> look_at <0, 0, 1> }
    light_source { <0, 5, -5> rgb 1 }
    // Normal -z: the inside is z > 5, so the camera is outside.
    plane { -z, -5 pigment { checker rgb 0.9 rgb 0.1 } finish { reflection 0.5 } }
    sphere { <0.5, 0, 2>, 0.3 pigment { rgb <1, 0, 0> } finish { reflection { 0.8 metallic } } }
    """)


def _plane_folder(tmp_path: Path, scene: str = PLANE_SCENE) -> Path:
    (tmp_path / "plane.pov").write_text(scene)
    out = tmp_path / "pl"
    convert(ConvertOptions.of(scene=str(tmp_path / "plane.pov"), lens="dgauss.50mm", focus=5,
                           outdir=str(out), width=32, height=24, samples=1, method="pinhole",
                           location=(0, 0, 0), look_at=(0, 0, 1)))
    return out


def test_distance_from_fade_inverts_the_fade_model():
    D = 3.0
    d = np.array([[0.1, 1.0, 3.0], [7.0, 15.0, 150.0]])
    colour = np.random.default_rng(1).uniform(0.1, 2, d.shape + (3,))
    b0 = 0.5 * colour
    b2 = b0 + 100 * colour
    b1 = b0 + 100 * colour * (2 / (1 + (d / D) ** FADE_POWER))[..., None]
    got = distance_from_fade(b0, b1, b2, D)
    assert np.allclose(got, d, rtol=1e-9)


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
    assert all((out / f"depth_fade_{k}.pov").is_file() for k in ("b0", "b1", "b2"))
    assert not list(out.glob(".depth.*"))


def test_probe_depth_background_is_inf_and_camera_inside_a_solid_is_measured(tmp_path):
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
    d = probe_depth(out)                        # POV-Ray's fog would do nothing here
    z = axial_depth(read_plan(out), d)
    assert np.isfinite(d).all() and np.median(np.abs(z[z > 4.0] / 5.0 - 1)) < 2e-3


# ----- povlens report --------------------------------------------------------------------

from povlens.cli import main as cli_main  # noqa: E402
from povlens.lens.coordinates import vertex_z_mm  # noqa: E402
from povlens.lens.prescription import read_lens, sag_mm  # noqa: E402
from povlens.report.html import depth_of_field, make_report, surface_hits  # noqa: E402
from povlens.thinlens.model import EquivalentThinLens  # noqa: E402

CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--virtual-time-budget=5000"]


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> Path:
    """A tiny mesh render of the paper scene (32x24, 2 lens samples)."""
    from povlens.rendering.driver import render_outdir
    out = tmp_path_factory.mktemp("report") / "paper"
    convert(ConvertOptions.of(scene=str(ROOT / "scenes" / "paper.pov"), lens="dgauss.50mm",
                           focus=4, outdir=str(out), width=32, height=24, samples=2, method="mesh"))
    render_outdir(out, jobs=2, quiet=True)
    return out


def _img_srcs(text: str) -> list[str]:
    return re.findall(r'<img[^>]*\ssrc="([^"]*)"', text)


def _chromium() -> str:
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        pytest.skip("chromium is not installed (.ci/setup installs it: apt-get install chromium)")
    return exe


def test_report_is_self_contained_and_every_image_loads_in_chromium(rendered, tmp_path):
    page = tmp_path / "report.html"
    assert cli_main(["report", str(rendered), "-o", str(page)]) == 0
    text = page.read_text()
    srcs = _img_srcs(text)
    # lens, pupil, depth of field, depth map, 3 renders, 2 differences, model error
    assert len(srcs) == 10
    assert all(s.startswith("data:image/png;base64,") for s in srcs)
    assert not re.search(r'(src|href)="(?!data:|#)', text)      # nothing external
    for needle in ("Paraxial data", "effective focal length", "film distance", "Exit pupil",
                   "Depth of field", "Errors against the mesh render", "RMSE", "Times",
                   "mesh: POV-Ray", "depth probe", "thin-lens model gets wrong"):
        assert needle in text, needle
    assert "not rendered" not in text
    from povlens.plan.schema import read_plan
    fm = read_plan(rendered).field_mesh
    assert fm is not None and f"rays within {fm.max_ray_error_px:.3f} px" in text
    assert not list(tmp_path.glob(".*"))                       # no temporary left behind
    exe = _chromium()
    proc = subprocess.run([exe, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'chromium'}",
                           "--dump-dom", page.as_uri()], capture_output=True, text=True,
                          timeout=120, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stderr[-2000:]
    dom = proc.stdout
    assert f"<title>images-ok {len(srcs)}</title>" in dom, re.findall(r"<title>.*?</title>", dom)
    assert "Paraxial data" in dom


def test_report_shows_missing_pieces_and_several_folders(rendered, tmp_path):
    bare = tmp_path / "bare"                 # converted, never rendered
    convert(ConvertOptions.of(scene=str(ROOT / "scenes" / "paper.pov"), lens="dgauss.50mm",
                           focus=4, outdir=str(bare), width=32, height=24, samples=2, method="mesh"))
    page = tmp_path / "r.html"
    make_report([bare, rendered], page, render_missing=False)
    text = page.read_text()
    assert text.count("<section") == 2
    assert "pinhole: not rendered" in text and "mesh (exact lens rays): not rendered" in text
    assert "differences against the mesh render" in text
    assert all(s.startswith("data:image/png;base64,") for s in _img_srcs(text))
    assert not (bare / "view-pinhole.exr").exists()            # --no-render ran no POV-Ray


def test_report_bad_outdir_exits_2_without_traceback(tmp_path, capsys):
    assert cli_main(["report", str(tmp_path / "nope"), "-o", str(tmp_path / "r.html")]) == 2
    assert cli_main(["report", str(tmp_path), "-o", str(tmp_path / "r.html")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "is not a folder" in err and "plan.json" in err
    assert not (tmp_path / "r.html").exists()


def test_surface_hits_lie_on_the_surfaces():
    lens = read_lens("dgauss.50mm")
    fd = 37.0
    aims = np.linspace(-10, 10, 9)
    o = np.tile([5.0, 0.0, 0.0], (len(aims), 1))
    d = np.column_stack([aims - 5.0, np.zeros_like(aims), np.full_like(aims, fd)])
    hits, full = surface_hits(lens, fd, o, d)
    zv = vertex_z_mm(lens.thickness_mm, fd)
    assert full.passed.any() and not full.passed.all()
    for k in range(len(aims)):
        last = -1 if full.passed[k] else full.blocked_at[k] + 1
        for i in range(lens.n_surfaces):
            h = hits[k, i]
            if full.passed[k] or i >= last:
                assert np.all(np.isfinite(h)), (k, i)
                r = math.hypot(h[0], h[1])
                assert r <= lens.aperture_radius_mm[i] + 1e-9
                assert abs(h[2] - (zv[i] - sag_mm(lens.curvature_per_mm[i], r))) < 1e-9
            else:
                assert np.all(np.isnan(h)), (k, i)
        if full.passed[k]:
            assert np.allclose(hits[k, 0], full.origin_mm[k], atol=1e-12)


def test_depth_of_field_limits_have_the_chosen_blur(rendered):
    plan = read_plan(rendered)
    tl = plan.thin_lens
    m = EquivalentThinLens(tl.centre_z_mm, tl.image_distance_mm, tl.pupil_diameter_mm,
                           tl.focus_z_mm)
    mpu, pitch = plan.mm_per_unit, plan.film.pixel_pitch_mm
    near, far = depth_of_field(plan, coc_px=0.2)
    assert near < plan.inputs.focus < far < math.inf
    blur = m.blur_diameter_mm(np.array([near, far]) * mpu + tl.centre_z_mm)
    assert np.allclose(blur, 0.2 * pitch, rtol=1e-9)
    # 1.5 px of 0.875 mm: beyond the hyperfocal distance, far is infinite.
    near, far = depth_of_field(plan, coc_px=1.5)
    assert far == math.inf
    assert np.isclose(m.blur_diameter_mm(np.array([near * mpu + tl.centre_z_mm]))[0],
                      1.5 * pitch, rtol=1e-9)
    assert tl.pupil_diameter_mm * tl.image_distance_mm / tl.focus_distance_mm <= 1.5 * pitch
