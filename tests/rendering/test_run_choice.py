"""One POV-Ray run for a stack of lens samples, or one run each, chosen on the first
sample's measurement (issue 25)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from povlens.pov.render_statistics import RenderStatistics
from povlens.rendering.run_choice import LOOKUP_S_PER_WORD, RADIOSITY_SHARED, choose_runs
from povlens.util.images import read_image
from tests.rendering.test_radiosity_cache import (ONE_PER_RUN, RADIOSITY_SCENE, SIZE, _povlens,
                                                   assert_same_within_radiosity_noise)

ROOT = Path(__file__).resolve().parents[2]
needs_povray = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")

#: What rad_def_test_37.pov's lead sample measured (320x240, tessar.50mm, 2 threads)
CHEAP = RenderStatistics(parse_s=0.015, radiosity_s=0.001, trace_s=0.105, trace_cpu_s=0.193,
                         rays=80227, radiosity_rays=3427, final_radiosity_rays=3427)
#: and cornell.pov's
HEAVY = RenderStatistics(parse_s=0.017, radiosity_s=0.309, radiosity_cpu_s=0.598,
                         trace_s=0.548, trace_cpu_s=1.077, rays=397950,
                         radiosity_rays=320700, final_radiosity_rays=114700)


def test_a_cheap_scene_runs_each_sample_and_a_radiosity_heavy_one_stacks():
    cheap = choose_runs(CHEAP, 0.52, 0.05, 7, 78000, 8 * 4928, 2)
    heavy = choose_runs(HEAVY, 1.27, 0.05, 7, 78000, 8 * 4928, 2)
    assert not cheap.stack and heavy.stack
    assert cheap.cost_s == pytest.approx(
        7 * 78000 * LOOKUP_S_PER_WORD * 8 * 4928 / 64 / 2 + 7 * 0.05 + (0.52 - CHEAP.phases_s))
    assert heavy.shared_s == pytest.approx(
        7 * (0.017 + RADIOSITY_SHARED * HEAVY.radiosity_work_cpu_s) / 2)
    # a stack costs more as its faces grow; a parse shared pays like radiosity
    assert choose_runs(HEAVY, 1.27, 0.05, 7, 78000, 200 * 4928, 2).cost_s > heavy.cost_s
    assert choose_runs(RenderStatistics(parse_s=2.0, trace_s=0.1, trace_cpu_s=0.1), 2.5, 0.05,
                       7, 78000, 8 * 4928, 2).stack
    d = heavy.as_dict()
    assert d["stack"] is True and "rule" in d


@needs_povray
def test_the_lead_sample_chooses_and_hands_on_its_radiosity(tmp_path):
    """A render whose samples stack: its first renders alone with POV-Ray's statistics,
    and the choice and measurement go to the timing file; every run reads the
    radiosity samples one pinhole pretrace of the frame saved (radiosity.rca, kept with
    the folder; no probes), and the file the lead hands on is gone afterwards; the image
    is the one of one run per sample within radiosity's noise."""
    scene = tmp_path / "rad.pov"
    scene.write_text(RADIOSITY_SCENE)
    _povlens("render", scene, *SIZE, "-o", tmp_path / "led")
    timing = json.loads((tmp_path / "led" / "samples" / "render.timing.json").read_text())
    assert timing["samples"] == 4 and timing["lead"]["samples"] == 1
    stats = timing["lead"]["statistics"]["0"]
    assert stats["trace_s"] > 0 and stats["radiosity_rays"] > 0 and stats["wall_s"] > 0
    choice = timing["choice"]
    assert choice["stack"] == (choice["shared_s"] > choice["cost_s"])
    assert timing["runs_together"] == choice["stack"]
    assert [p.name for p in (tmp_path / "led").rglob("*.rca")] == ["radiosity.rca"]
    assert not (tmp_path / "led" / "radiosity.json").exists()       # nothing measured
    _povlens("render", scene, *SIZE, "--povray-option", "Radiosity_File_Name=own.rca",
             "-o", tmp_path / "own", env=ONE_PER_RUN)
    assert_same_within_radiosity_noise(tmp_path / "own", tmp_path / "led")


def _led_render(monkeypatch, out: Path, stack: bool, *extra) -> dict:
    """``povlens render`` of the radiosity scene in this process, the lead's choice
    forced; returns the timing record."""
    import povlens.rendering.lead_render as lead_render
    from povlens.cli import main
    from povlens.rendering.run_choice import RunChoice
    monkeypatch.setattr(lead_render, "choose_runs", lambda *a: RunChoice(stack, 0, 0))
    monkeypatch.delenv("POVLENS_STACK", raising=False)
    scene = out.parent / "rad.pov"
    scene.write_text(RADIOSITY_SCENE)
    assert main(["render", str(scene), *SIZE, *extra, "-o", str(out)]) == 0
    return json.loads((out / "samples" / "render.timing.json").read_text())


@needs_povray
@pytest.mark.parametrize("runs", ["stack", "own"])
def test_after_the_lead_both_ways_render_the_samples_a_stack_renders(tmp_path, monkeypatch,
                                                                    runs):
    """Whichever way the lead chooses, the samples are those a stacked render gives,
    within radiosity's noise (each way computes its radiosity samples its own way)."""
    timing = _led_render(monkeypatch, tmp_path / "led", runs == "stack")
    assert timing["runs_together"] == (runs == "stack") and timing["samples"] == 4
    _povlens("render", tmp_path / "rad.pov", *SIZE, "-o", tmp_path / "stack",
             env={"POVLENS_STACK": "8"})
    assert_same_within_radiosity_noise(tmp_path / "stack", tmp_path / "led")


@needs_povray
def test_one_run_each_is_recorded_and_a_resume_renders_the_same_bits(tmp_path, monkeypatch):
    """The lead chose one run each: the folder records one pass per run, and a lost
    sample rendered again alone is the same bits (its layout is the record's)."""
    out = tmp_path / "o"
    timing = _led_render(monkeypatch, out, False)
    assert json.loads((out / "samples" / "layout.json").read_text())["bands"] == 1
    assert timing["bands"] == 1 and not timing["runs_together"]
    first = read_image(out / "samples" / "sample_0002.exr")
    for f in (out / "samples").glob("sample_0002.*"):
        f.unlink()
    again = _led_render(monkeypatch, out, True)     # recorded: no lead, no choice
    assert again["samples"] == 1 and "choice" not in again
    assert np.array_equal(read_image(out / "samples" / "sample_0002.exr"), first)
    # more samples of the same plan keep the record (they are laid out alike); a new
    # focus drops every sample, and the record with them
    _povlens("convert", tmp_path / "rad.pov", *SIZE[:-3], "--samples", "8", "-o", out)
    assert (out / "samples" / "layout.json").exists()
    _povlens("convert", tmp_path / "rad.pov", *SIZE[:-1], "--focus", "2.5", "-o", out)
    assert not (out / "samples" / "layout.json").exists()


@needs_povray
def test_a_scene_without_radiosity_stacks_without_a_lead(tmp_path, monkeypatch):
    monkeypatch.delenv("POVLENS_STACK", raising=False)
    args = ("--width", "80", "--height", "60", "--lens", "dgauss.50mm", "--method", "mesh",
            "--samples", "4", "--focus", "1.5", "-q")
    _povlens("render", ROOT / "scenes" / "paper.pov", *args, "-o", tmp_path / "o")
    timing = json.loads((tmp_path / "o" / "samples" / "render.timing.json").read_text())
    assert timing["runs_together"] and "lead" not in timing
    assert not (tmp_path / "o" / "samples" / "layout.json").exists()


@needs_povray
def test_a_folder_holding_samples_keeps_their_layout_without_a_lead(tmp_path, monkeypatch):
    """Samples rendered before (here stacked, no record) keep the layout: the samples
    left stack with them, no lead."""
    monkeypatch.delenv("POVLENS_STACK", raising=False)
    scene = tmp_path / "rad.pov"
    scene.write_text(RADIOSITY_SCENE)
    out = tmp_path / "o"
    _povlens("render", scene, *SIZE, "-o", out, env={"POVLENS_STACK": "8"})
    for k in (2, 3):
        for f in (out / "samples").glob(f"sample_{k:04d}.*"):
            f.unlink()
    _povlens("render", scene, *SIZE, "-o", out)
    timing = json.loads((out / "samples" / "render.timing.json").read_text())
    assert timing["samples"] == 2 and "lead" not in timing and timing["runs_together"]
    assert not (out / "samples" / "layout.json").exists()
