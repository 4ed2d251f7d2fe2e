"""The shared radiosity samples are made while the first lens samples' meshes are
written (issue 25): :func:`start_radiosity_cache` returns at once, runs that read the
file wait for it without holding up the meshes after theirs, and a render that fails
or is stopped leaves no half-made file."""

from __future__ import annotations

import shutil
import threading
import time
from pathlib import Path

import pytest

from povlens.plan.convert import convert
from povlens.plan.render_folder import RenderFolder
from povlens.rendering import mesh_samples
from povlens.rendering.folder_inputs import lens_for, pupil_table_for
from povlens.rendering.radiosity_cache import (cancel_radiosity_cache, radiosity_cache_for,
                                               radiosity_cache_ready, start_radiosity_cache)
from povlens.rendering.sample_stacks import StackPlan
from tests.conftest import paper_options
from tests.rendering.test_radiosity_cache import RADIOSITY_SCENE

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")


@pytest.fixture
def folder(tmp_path):
    scene = tmp_path / "rad.pov"
    scene.write_text(RADIOSITY_SCENE)
    out = tmp_path / "out"
    plan = convert(paper_options(tmp_path, scene=str(scene), focus=None))
    assert plan.povray.radiosity_cache
    return out, plan


def _leftovers(out: Path) -> list[str]:
    """Temporary files of a pinhole render left in the folder."""
    return sorted(p.name for p in out.iterdir() if ".tmp" in p.name or p.name.startswith("."))


def test_the_file_is_made_in_the_background_and_waited_for_once(folder):
    out, plan = folder
    start_radiosity_cache(plan, out)
    assert not radiosity_cache_ready(plan, out)      # POV-Ray takes >0.2 s to start
    start_radiosity_cache(plan, out)                 # a second call starts nothing more
    got = []
    threads = [threading.Thread(target=lambda: got.append(radiosity_cache_for(plan, out)))
               for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    cache = RenderFolder(out).radiosity_cache
    assert got == [cache] * 3
    assert cache.stat().st_size > 0 and cache.read_bytes().endswith(b"\n")
    assert radiosity_cache_ready(plan, out)
    assert _leftovers(out) == []


def test_a_cancelled_render_leaves_nothing(folder):
    out, plan = folder
    start_radiosity_cache(plan, out)
    time.sleep(0.05)
    cancel_radiosity_cache(out)
    assert not RenderFolder(out).radiosity_cache.exists()
    assert _leftovers(out) == []
    assert radiosity_cache_ready(plan, out)          # nothing is being made any more
    # made again when asked for
    assert radiosity_cache_for(plan, out).stat().st_size > 0


def test_meshes_are_written_while_the_file_is_made_and_no_run_starts_before_it(folder,
                                                                             monkeypatch):
    out, plan = folder
    cache = RenderFolder(out).radiosity_cache
    events = []
    write_mesh, start_povray = mesh_samples._write_mesh, mesh_samples.start_povray

    def writing(plan_, lens, table, outdir, k, **kw):
        drawn = write_mesh(plan_, lens, table, outdir, k, **kw)
        events.append(("mesh", k, cache.is_file()))
        return drawn

    def starting(cmd, cwd, err, **kw):
        events.append(("run", cmd, cache.is_file()))
        return start_povray(cmd, cwd, err, **kw)

    monkeypatch.setattr(mesh_samples, "_write_mesh", writing)
    monkeypatch.setattr(mesh_samples, "start_povray", starting)
    lens = lens_for(plan)
    table = pupil_table_for(out, plan, lens)
    start_radiosity_cache(plan, out)
    mesh_samples.render_samples(plan, lens, table, out, 0, [0, 1, 2, 3], in_flight=4,
                                stacking=StackPlan(1, 4, 1, False), read_shared=True)
    runs = [e for e in events if e[0] == "run"]
    meshes = [e for e in events if e[0] == "mesh"]
    assert len(meshes) == 4 and len(runs) == 4
    assert all(made for _, _, made in runs)          # every run read the whole file
    assert not meshes[1][2]                          # the second mesh came before it
    assert events.index(meshes[1]) < events.index(runs[0])
    assert all(RenderFolder(out).sample_done(k) for k in range(4))
    assert _leftovers(out) == []


def _hook(calls, out_texts):
    def start_radiosity(opts, start, outdir):
        out_texts.append(RenderFolder(outdir).wrapper("pinhole").read_text())
        calls.append(start)
        return lambda: calls.append("cancelled")
    return start_radiosity


def test_convert_starts_the_radiosity_render_before_the_plan_is_finished(tmp_path):
    scene = tmp_path / "rad.pov"
    scene.write_text(RADIOSITY_SCENE)
    calls, texts = [], []
    plan = convert(paper_options(tmp_path, scene=str(scene), focus=None),
                   start_shared=_hook(calls, texts))
    assert len(calls) == 1 and calls[0].povray_camera == plan.povray_camera
    # the text written early is the folder's: write_folder left it as it was
    assert texts == [RenderFolder(tmp_path / "out").wrapper("pinhole").read_text()]
    # no radiosity, or not a mesh plan: nothing starts
    for opts in (paper_options(tmp_path / "plain"),
                 paper_options(tmp_path / "blur", scene=str(scene), focus=None,
                               method="focal-blur")):
        convert(opts, start_shared=_hook(calls, texts))
    assert len(calls) == 1


def test_a_failed_conversion_stops_what_it_started(tmp_path, monkeypatch):
    import povlens.plan.plan_finish as plan_finish
    scene = tmp_path / "rad.pov"
    scene.write_text(RADIOSITY_SCENE)

    def failing(*a, **kw):
        raise RuntimeError("the plan failed")

    monkeypatch.setattr(plan_finish, "finish_plan", failing)
    calls = []
    with pytest.raises(RuntimeError, match="the plan failed"):
        convert(paper_options(tmp_path, scene=str(scene), focus=None),
                start_shared=_hook(calls, []))
    assert calls[-1] == "cancelled"


def test_povlens_render_leaves_only_the_whole_file(tmp_path):
    from tests.rendering.test_radiosity_cache import SIZE, _povlens
    scene = tmp_path / "rad.pov"
    scene.write_text(RADIOSITY_SCENE)
    _povlens("render", scene, *SIZE, "-o", tmp_path / "out")
    out = tmp_path / "out"
    assert RenderFolder(out).radiosity_cache.read_bytes().endswith(b"\n")
    assert _leftovers(out) == [".povlens.lock"]
    assert (out / "image.exr").is_file()


def test_the_photon_map_starts_early_too_and_the_samples_wait_for_it(tmp_path):
    from tests.rendering.test_photon_map import PHOTON_SCENE
    from povlens.rendering.driver import start_shared_early
    from povlens.rendering.photon_map import photon_map_for, photon_map_ready
    scene = tmp_path / "p.pov"
    scene.write_text(PHOTON_SCENE)
    calls, texts = [], []
    hook = _hook(calls, texts)
    plan = convert(paper_options(tmp_path, scene=str(scene), focus=None),
                   start_shared=lambda o, s, d: (hook(o, s, d), start_shared_early(o, s, d))[1])
    out = tmp_path / "out"
    assert len(calls) == 1 and plan.povray.photon_settings
    assert "save_file" in texts[0] and texts[0] == RenderFolder(out).wrapper("pinhole").read_text()
    # started by convert and not waited for (a 32x24 render may already have finished
    # when convert returns on a loaded machine, so its state is not asserted)
    from povlens.rendering.pinhole_products import product_started
    assert product_started(RenderFolder(out).photon_map)
    assert photon_map_for(plan, out) == RenderFolder(out).photon_map
    assert RenderFolder(out).photon_map.stat().st_size > 0
    assert photon_map_ready(plan, out)
    assert _leftovers(out) == []


def test_a_scene_without_a_pretrace_makes_no_pinhole_render(tmp_path):
    """pretrace_end 1: one pinhole render's samples would be those its final trace
    computed (stackernight.pov's lead shot as many radiosity rays reading them as
    without), so none is made; the lead computes its own and hands them on, and the
    image is the one of one run per sample within radiosity's noise."""
    import json
    from povlens.plan.plan_finish import no_pretrace
    from tests.rendering.test_radiosity_cache import (ONE_PER_RUN, SIZE, _povlens,
                                                      assert_same_within_radiosity_noise)
    assert no_pretrace((1.0, 1.0)) and not no_pretrace((0.08, 0.04)) and not no_pretrace(None)
    scene = tmp_path / "rad.pov"
    scene.write_text(RADIOSITY_SCENE.replace("pretrace_start 0.08 pretrace_end 0.02",
                                             "pretrace_start 1 pretrace_end 1"))
    _povlens("render", scene, *SIZE, "-o", tmp_path / "led")
    led = tmp_path / "led"
    plan = json.loads((led / "plan.json").read_text())
    assert plan["povray"]["radiosity_cache"] is True
    assert plan["povray"]["radiosity_pretrace"] == [1.0, 1.0]
    assert any(n.startswith("radiosity: the scene has no pretrace") for n in plan["notes"])
    assert not RenderFolder(led).radiosity_cache.exists()
    timing = json.loads((led / "samples" / "render.timing.json").read_text())
    assert timing["lead"]["samples"] == 1 and timing["samples"] == 4
    assert _leftovers(led) == [".povlens.lock"]
    _povlens("render", scene, *SIZE, "--povray-option", "Radiosity_File_Name=own.rca",
             "-o", tmp_path / "own", env=ONE_PER_RUN)
    assert_same_within_radiosity_noise(tmp_path / "own", led)
