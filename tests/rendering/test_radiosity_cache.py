"""Radiosity computed once for all lens samples (issue 25, first step): a mesh plan of a
scene with radiosity shares one pretrace's samples (``radiosity.rca``, POV-Ray's
``+RFO`` then ``+RFI``); the image stays the uncached one within radiosity's noise."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from povlens.util.images import read_image

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")

RADIOSITY_SCENE = """#version 3.7;
global_settings { assumed_gamma 1 radiosity { pretrace_start 0.08 pretrace_end 0.02
  count 60 nearest_count 5 error_bound 0.8 recursion_limit 1 } }
camera { location <0, 1.2, -3.5> look_at <0, 0.8, 0> }
light_source { <1, 3, -2> rgb 1 }
box { <-2, 0, -4>, <2, 3, 2> inverse pigment { rgb 0.8 } }
box { <-2, 0, -4>, <-1.99, 3, 2> pigment { rgb <0.9, 0.1, 0.1> } }
sphere { <0.3, 0.5, 0.2>, 0.5 pigment { rgb <0.2, 0.8, 0.3> } }
"""
SIZE = ("--width", "48", "--height", "36", "--lens", "dgauss.50mm", "--method", "mesh",
        "--samples", "4", "-q")


#: One lens sample per POV-Ray run (``POVLENS_STACK``): a render of all its samples in
#: one run computes one pretrace and has no file to share (test_sample_stacks.py).
ONE_PER_RUN = {"POVLENS_STACK": "1"}


def assert_same_within_radiosity_noise(reference: Path, other: Path) -> None:
    """The images of two render folders of the radiosity scene agree within what
    POV-Ray's radiosity varies by: the same mean within 3 % (noise, not a bias), RMSE
    within 3 % of the brightest value."""
    a = read_image(Path(reference) / "image.exr")[..., :3]
    b = read_image(Path(other) / "image.exr")[..., :3]
    assert a.mean() > 0.05
    assert abs(b.mean() / a.mean() - 1.0) < 0.03
    assert np.sqrt(np.mean((a - b) ** 2)) < 0.03 * a.max()


def _povlens(*args, cwd=None, env=None):
    r = subprocess.run([sys.executable, "-m", "povlens", *map(str, args)], capture_output=True,
                       text=True, timeout=300, cwd=cwd, env={**os.environ, **(env or {})})
    assert r.returncode == 0, r.stderr
    return r


def test_a_radiosity_scene_shares_one_pretrace_and_keeps_its_image(tmp_path):
    scene = tmp_path / "rad.pov"
    scene.write_text(RADIOSITY_SCENE)
    _povlens("render", scene, *SIZE, "-o", tmp_path / "cached", env=ONE_PER_RUN)
    plan = json.loads((tmp_path / "cached" / "plan.json").read_text())
    assert plan["povray"]["radiosity_cache"] is True
    assert any(n.startswith("radiosity: its samples are computed once") for n in plan["notes"])
    assert (tmp_path / "cached" / "radiosity.rca").stat().st_size > 0
    # the user's own radiosity file option: every sample computes its own (the old way)
    _povlens("render", scene, *SIZE, "--povray-option", "Radiosity_File_Name=own.rca",
             "-o", tmp_path / "plain", env=ONE_PER_RUN)
    plain = json.loads((tmp_path / "plain" / "plan.json").read_text())
    assert "radiosity_cache" not in plain["povray"]
    assert not (tmp_path / "plain" / "radiosity.rca").exists()
    assert_same_within_radiosity_noise(tmp_path / "plain", tmp_path / "cached")


def test_make_renders_with_the_shared_radiosity(tmp_path):
    scene = tmp_path / "rad.pov"
    scene.write_text(RADIOSITY_SCENE)
    out = tmp_path / "o"
    _povlens("convert", scene, *SIZE[:-1], "--batch-size", "2", "-o", out)
    assert not (out / "radiosity.rca").exists()              # made by the first render
    r = subprocess.run(["make", "-C", str(out), "-j2"], capture_output=True, text=True,
                       timeout=300, env={**os.environ, **ONE_PER_RUN})
    assert r.returncode == 0, r.stderr
    assert (out / "radiosity.rca").stat().st_size > 0 and (out / "image.exr").is_file()
    assert not list(out.glob(".radiosity*")) and not list(out.glob(".*tmp*"))


def test_a_scene_without_radiosity_renders_as_before(tmp_path):
    scene = tmp_path / "plain.pov"
    start = RADIOSITY_SCENE.index(" radiosity {")
    scene.write_text(RADIOSITY_SCENE[:start] + " }\n" + RADIOSITY_SCENE.split("} }\n", 1)[1])
    _povlens("convert", scene, *SIZE[:-1], "-o", tmp_path / "o")
    plan = json.loads((tmp_path / "o" / "plan.json").read_text())
    assert "radiosity_cache" not in plan["povray"]
    assert not any(n.startswith("radiosity") for n in plan.get("notes", []))



def test_two_samples_measure_whether_sharing_pays(tmp_path):
    """Sample 0 renders with its own radiosity, sample 1 reading the shared samples, side
    by side; radiosity.json records both (wall clock; POV-Ray's phase times for a finished
    one) and the choice they make."""
    from povlens.rendering.radiosity_cache import choice_from
    scene = tmp_path / "rad.pov"
    scene.write_text(RADIOSITY_SCENE)
    out = tmp_path / "o"
    _povlens("render", scene, *SIZE, "-o", out, env=ONE_PER_RUN)
    rec = json.loads((out / "radiosity.json").read_text())
    assert rec["own"]["sample"] == 0 and rec["shared"]["sample"] == 1
    assert rec["own"]["wall_s"] > 0 and rec["shared"]["wall_s"] > 0
    assert rec["own"]["finished"] or rec["shared"]["finished"]
    done = rec["own"] if rec["own"]["finished"] else rec["shared"]
    assert done["radiosity_s"] >= 0 and done["trace_s"] >= 0
    assert isinstance(rec["share"], bool) and choice_from(rec) is rec["share"]
    assert (out / "radiosity.rca").is_file()        # made for the shared probe
    assert read_image(out / "image.exr")[..., :3].mean() > 0.05


@pytest.mark.parametrize("share", [True, False])
def test_a_recorded_choice_is_followed(tmp_path, share):
    """A folder whose record says 'own' renders every sample without the file (none is
    made); 'shared' makes it and every sample reads it; no probe runs again."""
    scene = tmp_path / "rad.pov"
    scene.write_text(RADIOSITY_SCENE)
    out = tmp_path / "o"
    _povlens("convert", scene, *SIZE[:-1], "-o", out)
    record = {"share": share, "own": {"sample": 9, "radiosity_s": 1.0, "trace_s": 1.0},
              "shared": {"sample": 8, "radiosity_s": 0.5, "trace_s": 1.0}}
    (out / "radiosity.json").write_text(json.dumps(record))
    _povlens("render", scene, *SIZE, "-o", out, env=ONE_PER_RUN)
    assert (out / "radiosity.rca").is_file() is share
    assert json.loads((out / "radiosity.json").read_text()) == record
    assert read_image(out / "image.exr")[..., :3].mean() > 0.05


def test_the_choice_from_the_probes_measurements(tmp_path):
    """Both finished: the faster decides; one finished and the other, still running,
    already slower: decided early; otherwise not yet. A finished measurement is never
    replaced by a running one, and a damaged record is measured again."""
    from povlens.rendering.radiosity_cache import (choice_from, probe_measurement,
                                                   probes_missing, record_probes,
                                                   sharing_chosen)
    stats = ("Render Time:\n  Photon Time:      No photons\n"
             "  Radiosity Time:   0 hours  0 minutes  1 seconds (1.392 seconds)\n"
             "  Trace Time:       0 hours  0 minutes  1 seconds (1.149 seconds)\n")
    own = probe_measurement(0, 3.24, stats)                    # cornell's sample, by hand
    assert own == {"sample": 0, "wall_s": 3.24, "finished": True, "radiosity_s": 1.392,
                   "trace_s": 1.149}
    assert choice_from({"own": own}) is None
    assert choice_from({"own": own, "shared": probe_measurement(1, 1.80, "")}) is True
    assert choice_from({"own": own, "shared": probe_measurement(1, 3.5, "")}) is False
    assert choice_from({"own": own, "shared": probe_measurement(1, 2.0)}) is None
    assert choice_from({"own": own, "shared": probe_measurement(1, 3.3)}) is False   # early
    assert choice_from({"own": probe_measurement(0, 2.5),
                        "shared": probe_measurement(1, 1.8, "")}) is True          # early
    assert sharing_chosen(tmp_path) is None and probes_missing(tmp_path) == ["own", "shared"]
    assert record_probes(tmp_path, {"own": own}) is None         # one measurement: no choice
    assert probes_missing(tmp_path) == ["shared"] and sharing_chosen(tmp_path) is None
    assert record_probes(tmp_path, {"own": probe_measurement(0, 9.0)}) is None
    assert json.loads((tmp_path / "radiosity.json").read_text())["own"] == own   # kept
    assert record_probes(tmp_path, {"shared": probe_measurement(1, 1.8, stats)}) is True
    assert sharing_chosen(tmp_path) is True and probes_missing(tmp_path) == []
    (tmp_path / "radiosity.json").write_text("{broken")
    assert sharing_chosen(tmp_path) is None and probes_missing(tmp_path) == ["own", "shared"]


def test_a_run_stopped_once_its_radiosity_file_is_closed_saved_all_of_it(tmp_path):
    """A run that hands on its radiosity samples is stopped once it has closed its image
    and the file, before its idle exit (mesh_samples._SampleRenders._saved and the
    chained runs' povray_finished): the file is the one a run left to exit saves, byte
    for byte (one thread: POV-Ray's radiosity is then deterministic)."""
    import time
    from povlens.pov.executable import find_povray
    from povlens.pov.process import povray_finished, start_povray
    (tmp_path / "rad.pov").write_text(RADIOSITY_SCENE)

    killed = []

    def run(name: str, stop_early: bool) -> bool:
        cmd = [find_povray(), "-D", "-V", "-GA", "+Irad.pov", f"+O{name}.exr", "+FE", "+W64",
               "+H48", "-A", "+WT1", f"Radiosity_File_Name={name}.rca", "+RFO"]
        with open(tmp_path / f"{name}.txt", "w") as err:
            proc = start_povray(cmd, tmp_path, err)
        t0 = time.perf_counter()
        if not stop_early:
            return proc.wait() == 0
        kill = proc.kill
        proc.kill = lambda: killed.append(name) or kill()
        while not povray_finished(proc, tmp_path / f"{name}.exr", time.perf_counter() - t0,
                                  [tmp_path / f"{name}.rca"]):
            time.sleep(0.005)
        return proc.returncode == 0

    assert run("exited", False) and run("stopped", True)
    assert killed == ["stopped"]        # it was stopped before its exit
    whole = (tmp_path / "exited.rca").read_bytes()
    assert len(whole) > 1000 and (tmp_path / "stopped.rca").read_bytes() == whole
