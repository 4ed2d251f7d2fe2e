"""Several lens samples per POV-Ray run (issue 25): field passes stacked as bands of one
render give the images each pass rendered alone gives, and a render of all its samples
in one run shares that run's radiosity pretrace instead of making a file."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from povlens.plan.schema import read_plan
from povlens.pov.field_mesh import pass_models, pass_size
from povlens.rendering.sample_stacks import (MAX_STACK, STACK_FACE_BUDGET, stack_bands,
                                             stack_plan, stack_position, stack_runs)
from povlens.util.images import read_image
from tests.rendering.test_radiosity_cache import (ONE_PER_RUN, RADIOSITY_SCENE, SIZE, _povlens,
                                                   assert_same_within_radiosity_noise)

ROOT = Path(__file__).resolve().parents[2]
#: Stacks of 8 whatever the lead sample measures (:mod:`povlens.rendering.run_choice`).
STACKED = {"POVLENS_STACK": "8"}
needs_povray = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")


@pytest.mark.parametrize("stride", [1, 3])
def test_a_band_samples_the_image_positions_the_pass_alone_samples(stride):
    """Band b of a stack: the same image positions as the pass rendered alone, its UV
    rectangles stacked without overlap inside [0, 1]."""
    W, H, bands = 50, 37, 3
    jit = np.random.default_rng(1).uniform(0, 1, (stride * stride, 2))
    alone = pass_models(W, H, stride, jit)
    assert pass_size(W, H, stride, bands)[1] == bands * (-(-H // stride)) + 1
    rects = []
    for b in range(bands):
        models = pass_models(W, H, stride, jit, band=b, bands=bands)
        for m, a in zip(models, alone):
            xa, ya = a.uv_to_image(*a.pixel_uv())
            xb, yb = m.uv_to_image(*m.pixel_uv())
            np.testing.assert_allclose(xb, xa, atol=1e-9)
            np.testing.assert_allclose(yb, ya, atol=1e-9)
            assert np.array_equal(m.rows(), a.rows()) and np.array_equal(m.columns(), a.columns())
            rects.append(m.uv_rect())
    r = np.array(rects)
    assert r[:, 2].min() >= 0 and r[:, 3].max() <= 1
    assert int(r[:, 0].min() * 10) == 0           # in POV-Ray's first bin (truncated)
    for i in range(len(r)):             # no two tiles' rectangles overlap
        for j in range(i + 1, len(r)):
            du = min(r[i, 1], r[j, 1]) - max(r[i, 0], r[j, 0])
            dv = min(r[i, 3], r[j, 3]) - max(r[i, 2], r[j, 2])
            assert du <= 1e-12 or dv <= 1e-12
    with pytest.raises(ValueError):
        pass_models(W, H, stride, jit, band=3, bands=3)


@needs_povray
def test_how_many_samples_a_run_renders(tmp_path, monkeypatch):
    """The bands of a stack follow from the plan's field mesh (the face budget); one run
    per stack the samples touch, threads for the cores the runs leave; one sample per
    run for per-pixel meshes."""
    monkeypatch.delenv("POVLENS_STACK", raising=False)
    out = tmp_path / "o"
    _povlens("convert", ROOT / "scenes" / "paper.pov", *SIZE[:-1], "-o", out)
    plan = read_plan(out)
    fm = plan.field_mesh
    faces = 2 * fm.grid[0] * fm.grid[1] * fm.interleave ** 2
    p = stack_bands(plan)
    assert p == min(MAX_STACK, STACK_FACE_BUDGET // faces) and p >= 4
    sp = stack_plan(plan, range(4), 2)
    assert (sp.bands, sp.runs, sp.threads, sp.together) == (p, 1, 2, True)
    assert [stack_position(plan, k) for k in (0, p - 1, p)] == [(0, 0), (0, p - 1), (1, 0)]
    assert list(stack_runs([0, 1, p, p + 1, 2], p)) == [[0, 1], [p, p + 1], [2]]
    assert list(stack_runs([0, 1], p, together=False)) == [[0], [1]]
    monkeypatch.setenv("POVLENS_STACK", "2")
    sp = stack_plan(plan, range(4), 2)
    assert (sp.bands, sp.runs, sp.threads) == (2, 2, 1)
    monkeypatch.delenv("POVLENS_STACK")
    _povlens("convert", ROOT / "scenes" / "paper.pov", *SIZE[:-1], "--ray-mesh", "pixel",
             "-o", tmp_path / "px")
    assert stack_bands(read_plan(tmp_path / "px")) == 1


@needs_povray
def test_a_stacked_run_renders_what_one_run_per_sample_renders(tmp_path):
    scene = ROOT / "scenes" / "paper.pov"
    args = ("--width", "80", "--height", "60", "--lens", "dgauss.50mm", "--method", "mesh",
            "--samples", "4", "--focus", "1.5", "-q")
    _povlens("render", scene, *args, "-o", tmp_path / "one", env=ONE_PER_RUN)
    _povlens("render", scene, *args, "-o", tmp_path / "stack", env=STACKED)
    timing = json.loads((tmp_path / "stack" / "samples" / "render.timing.json").read_text())
    assert timing["bands"] >= 4 and timing["runs_together"] and timing["threads"] >= 1
    assert json.loads((tmp_path / "one" / "samples" / "render.timing.json").read_text()
                      )["bands"] == 1
    for k in range(4):
        a = read_image(tmp_path / "one" / "samples" / f"sample_{k:04d}.exr")
        b = read_image(tmp_path / "stack" / "samples" / f"sample_{k:04d}.exr")
        assert a.shape == b.shape
        assert a[1:, :-1].mean() > 0.05
        # the same rays but for float rounding: a few silhouette pixels differ
        assert np.mean(np.abs(a - b).max(-1) > 2e-3) < 0.005
    assert not list((tmp_path / "stack" / "samples").glob("*.inc"))
    a = read_image(tmp_path / "one" / "image.exr")[..., :3]
    b = read_image(tmp_path / "stack" / "image.exr")[..., :3]
    assert np.sqrt(np.mean((a - b) ** 2)) < 2e-3


@needs_povray
def test_one_run_reads_the_frames_radiosity_without_probes(tmp_path):
    """Every sample in one run: it reads the samples one pinhole pretrace of the frame
    saved (its own pretrace, scaled to its bands and tiles, would trace bands x m^2 times
    the frame's; pov.mesh.pretrace_block), without probes; the image is the one whose
    samples each compute their own radiosity, within radiosity's noise."""
    scene = tmp_path / "rad.pov"
    scene.write_text(RADIOSITY_SCENE)
    _povlens("render", scene, *SIZE, "-o", tmp_path / "one")
    assert (tmp_path / "one" / "radiosity.rca").stat().st_size > 0
    assert not (tmp_path / "one" / "radiosity.json").exists()
    _povlens("render", scene, *SIZE, "--povray-option", "Radiosity_File_Name=own.rca",
             "-o", tmp_path / "own", env=ONE_PER_RUN)
    assert_same_within_radiosity_noise(tmp_path / "own", tmp_path / "one")


@needs_povray
def test_a_sample_rendered_alone_is_the_same_bits_as_in_its_stack(tmp_path):
    """Resume renders one lost sample alone, in its band: its image is the one the
    stacked run gave, bit for bit (the layout and the meshes' origin are the plan's)."""
    scene = ROOT / "scenes" / "paper.pov"
    out = tmp_path / "o"
    _povlens("render", scene, *SIZE, "-o", out, env=STACKED)
    timing = json.loads((out / "samples" / "render.timing.json").read_text())
    assert timing["bands"] >= 4 and timing["runs_together"]
    first = read_image(out / "samples" / "sample_0002.exr")
    for f in (out / "samples").glob("sample_0002.*"):
        f.unlink()
    _povlens("render", scene, *SIZE, "-o", out)
    again = json.loads((out / "samples" / "render.timing.json").read_text())
    assert again["samples"] == 1
    assert np.array_equal(read_image(out / "samples" / "sample_0002.exr"), first)


def test_image_size_words_outside_a_camera_are_found(tmp_path):
    from povlens.pov.sdl.scene_camera import image_size_uses
    inc = tmp_path / "size.inc"
    inc.write_text('// image_width in a comment\n#declare S = "image_height";\n'
                   "#declare Stripe = image_height * 2;\n")
    scene = tmp_path / "s.pov"
    scene.write_text('#include "size.inc"\n'
                     "camera { location <0, 1, -3> right x*image_width/image_height\n"
                     "  look_at <0, 0, 0> }\n/* image_width */ sphere { 0, 1 }\n")
    assert image_size_uses([scene]) == ()          # in the camera, a comment: not used
    assert image_size_uses([scene, inc]) == (f"{inc}:3",)


@needs_povray
def test_a_scene_reading_the_image_size_renders_passes_at_the_film_size(tmp_path):
    """image_height outside the camera: the passes render at the film's size (no tiles,
    no stack), with a note naming where."""
    scene = tmp_path / "s.pov"
    scene.write_text((ROOT / "scenes" / "paper.pov").read_text()
                     + "#declare Rows = image_height;\n"
                       "box { <-9, -1, 20>, <9, 0.001 * Rows, 21> pigment { rgb 0.5 } }\n")
    args = ("--width", "160", "--height", "120", "--lens", "dgauss.50mm", "--method", "mesh",
            "--samples", "2", "--focus", "4", "-q")
    _povlens("render", scene, *args, "-o", tmp_path / "o")
    plan = read_plan(tmp_path / "o")
    assert plan.povray.image_size_read and plan.field_mesh.interleave == 1
    assert (plan.povray.render_width, plan.povray.render_height) == (161, 121)
    assert stack_bands(plan) == 1
    assert any("image_width/image_height" in n and f"{scene}:" in n for n in plan.notes)
    assert read_image(tmp_path / "o" / "image.exr").shape[:2] == (120, 160)
    _povlens("convert", ROOT / "scenes" / "paper.pov", *args[:-1], "-o", tmp_path / "plain")
    assert read_plan(tmp_path / "plain").field_mesh.interleave > 1     # what it changes


@needs_povray
def test_stacked_runs_hand_on_their_radiosity_samples(tmp_path):
    """More samples than a stack holds: the runs follow one another on every core, each
    reading the radiosity samples of those before it (POV-Ray's +RFI +RFO on one file
    appends: measured on cornell.pov, the second run computed 1,043 samples against
    5,165), the first starting from the samples one pinhole pretrace of the frame saved
    (radiosity.rca); the chain's file is gone afterwards and the image is the per-sample
    one within radiosity's noise."""
    scene = tmp_path / "rad.pov"
    scene.write_text(RADIOSITY_SCENE)
    _povlens("render", scene, *SIZE, "-o", tmp_path / "chain", env={"POVLENS_STACK": "2"})
    timing = json.loads((tmp_path / "chain" / "samples" / "render.timing.json").read_text())
    assert timing["chained"] and timing["bands"] == 2 and timing["samples"] == 4
    assert [p.name for p in (tmp_path / "chain").rglob("*.rca")] == ["radiosity.rca"]
    assert not (tmp_path / "chain" / "radiosity.json").exists()     # nothing to choose
    _povlens("render", scene, *SIZE, "--povray-option", "Radiosity_File_Name=own.rca",
             "-o", tmp_path / "own", env=ONE_PER_RUN)
    assert_same_within_radiosity_noise(tmp_path / "own", tmp_path / "chain")
