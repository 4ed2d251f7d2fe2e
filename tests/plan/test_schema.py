"""plan.json as typed records: plans written before the schema module read unchanged, the
reader and writer round-trip, and plans povlens cannot read are refused clearly."""

import json
import math
import os
import pathlib

import pytest

from povlens.errors import PovlensError
from povlens.lens.film import Film
from povlens.plan.schema import (SCHEMA_VERSION, AdaptiveSampling, Decision, FocalBlurSettings,
                                 Plan, plan_json, read_plan, write_plan)
from povlens.thinlens.model import EquivalentThinLens

DATA = pathlib.Path(__file__).resolve().parent / "data"
#: plan.json files written by povlens before plan/schema.py (commit 1347934; scene and
#: lens paths replaced by /path/to/povlens/): a pinhole plan, an auto plan that chose
#: focal-blur, and an auto plan that chose an adaptive mesh render; and by the release
#: before the typed model error (commit 3e3d89b, ``plan_v1_release_*``): a pinhole plan
#: (its model error not measured: ``{}``) and an auto plan that chose focal-blur.
OLD_PLANS = sorted(p.name for p in DATA.glob("plan_v1_*.json"))


def test_the_old_plans_are_there():
    assert len(OLD_PLANS) == 5


@pytest.mark.parametrize("name", OLD_PLANS)
def test_a_plan_json_of_the_previous_code_reads_and_writes_back_byte_for_byte(name, tmp_path):
    text = (DATA / name).read_text()
    plan = read_plan(DATA / name)
    assert isinstance(plan, Plan) and isinstance(plan.film, Film)
    assert isinstance(plan.thin_lens, EquivalentThinLens)
    assert plan.inputs.scene == "/path/to/povlens/scenes/paper.pov"
    assert plan.film.width_px == 32 and plan.film.height_px == 24
    assert plan.batches and all(isinstance(k, int) for b in plan.batches for k in b)
    assert plan_json(plan) == text
    write_plan(plan, tmp_path)                                  # a folder: its plan.json
    assert (tmp_path / "plan.json").read_text() == text
    assert read_plan(tmp_path) == plan


def test_the_typed_parts_of_the_old_plans():
    pin = read_plan(DATA / "plan_v1_pinhole.json")
    assert pin.inputs.method == "pinhole" and pin.decision is None
    assert pin.sample_rows is None and pin.adaptive is None
    assert pin.rows_of_sample(0) == (0, 24)
    fb = read_plan(DATA / "plan_v1_auto_focal_blur.json")
    assert fb.inputs.requested_method == "auto" and fb.inputs.method == "focal-blur"
    assert isinstance(fb.decision, Decision) and fb.decision.method == "focal-blur"
    assert fb.decision.focal_blur == FocalBlurSettings(32, 256, 0.99, 1e-4)
    assert fb.decision.reasons[-1].startswith("-> focal-blur")
    assert fb.decision.numbers["depth_probe"]["probe_width"] == 32
    mesh = read_plan(DATA / "plan_v1_auto_adaptive_mesh.json")
    assert isinstance(mesh.adaptive, AdaptiveSampling)
    assert len(mesh.sample_rows) == mesh.inputs.samples == max(mesh.adaptive.band_samples)
    assert all(mesh.rows_of_sample(k) == (0, 24) for k in range(mesh.adaptive.n_min))


def test_a_plan_without_the_version_key_reads(tmp_path):
    d = json.loads((DATA / "plan_v1_pinhole.json").read_text())
    del d["povlens_plan"]
    (tmp_path / "plan.json").write_text(json.dumps(d))
    plan = read_plan(tmp_path)
    assert plan == read_plan(DATA / "plan_v1_pinhole.json")
    assert json.loads(plan_json(plan))["povlens_plan"] == SCHEMA_VERSION


@pytest.mark.parametrize("change, words", [
    (lambda d: d.update(povlens_plan=SCHEMA_VERSION + 1), "another version of povlens"),
    (lambda d: d.pop("film"), "not a plan this version of povlens can read"),
    (lambda d: d["inputs"].pop("lens"), "not a plan this version of povlens can read"),
    (lambda d: d.update(batches=7), "not a plan this version of povlens can read"),
])
def test_a_plan_povlens_cannot_read_is_refused_with_the_advice_to_convert_again(tmp_path,
                                                                                change, words):
    d = json.loads((DATA / "plan_v1_pinhole.json").read_text())
    change(d)
    (tmp_path / "plan.json").write_text(json.dumps(d))
    with pytest.raises(PovlensError, match=words) as info:
        read_plan(tmp_path)
    assert "povlens convert" in info.value.hint


def test_missing_and_broken_plan_files_are_refused(tmp_path):
    with pytest.raises(PovlensError, match="does not exist") as info:
        read_plan(tmp_path)
    assert "povlens convert" in info.value.hint
    (tmp_path / "plan.json").write_text("{not json")
    with pytest.raises(PovlensError, match="not valid JSON"):
        read_plan(tmp_path)
    (tmp_path / "plan.json").write_text("[1, 2]")
    with pytest.raises(PovlensError, match="not a povlens plan"):
        read_plan(tmp_path)


def test_write_plan_leaves_an_identical_file_alone(tmp_path):
    plan = read_plan(DATA / "plan_v1_auto_focal_blur.json")
    path = write_plan(plan, tmp_path)
    os.utime(path, ns=(1, 1))
    write_plan(plan, tmp_path)
    assert path.stat().st_mtime_ns == 1                         # make would rebuild otherwise
    plan.decision.add_remark("(a remark)")
    write_plan(plan, tmp_path)
    assert path.stat().st_mtime_ns != 1
    assert read_plan(tmp_path).decision.reasons[-2] == "(a remark)"
    assert not [p for p in tmp_path.iterdir() if p.name != "plan.json"]   # no temporary left


def test_infinities_are_written_as_null_and_read_back_as_infinity(tmp_path):
    plan = read_plan(DATA / "plan_v1_pinhole.json")
    plan.thin_lens = EquivalentThinLens(plan.thin_lens.centre_z_mm,
                                        plan.thin_lens.image_distance_mm,
                                        plan.thin_lens.pupil_diameter_mm, math.inf)
    write_plan(plan, tmp_path)
    d = json.loads((tmp_path / "plan.json").read_text())
    assert d["thin_lens"]["focus_z_mm"] is None and d["thin_lens"]["focus_distance_mm"] is None
    assert math.isinf(read_plan(tmp_path).thin_lens.focus_z_mm)


def test_a_new_plan_round_trips(tmp_path):
    """A plan as convert makes it equals the plan read back from its plan.json."""
    from povlens.plan.convert import ConvertOptions, convert
    root = pathlib.Path(__file__).resolve().parents[2]
    for method, kw in (("pinhole", {}), ("mesh", {"samples": 3, "batch_size": 2,
                                                  "film_size_mm": (24.0, 18.0)})):
        out = tmp_path / method
        plan = convert(ConvertOptions.of(scene=str(root / "scenes" / "paper.pov"),
                                      lens="tessar.50mm", focus=3, outdir=str(out), width=16,
                                      height=12, method=method, **kw))
        assert read_plan(out) == plan
        assert plan_json(read_plan(out)) == (out / "plan.json").read_text()


def test_the_focus_source_and_the_depth_probe_record_round_trip(tmp_path):
    """Issue 13's fields: written when set, read back equal; absent in the old plans."""
    import dataclasses
    from povlens.plan.schema import DepthProbeRecord
    old = read_plan(DATA / "plan_v1_pinhole.json")
    assert old.inputs.focus_from is None and old.depth_probe is None
    rec = DepthProbeRecord("light fade", "background inf",
                           {"probe_pixels": 12, "no_depth_pixels": 3},
                           {"point_px": [3.5, 12.5], "rounds": 1})
    plan = dataclasses.replace(old, inputs=dataclasses.replace(
        old.inputs, focus_from="depth probe at 3,12", focus_at=(3, 12)), depth_probe=rec)
    d = json.loads(plan_json(plan))
    assert d["inputs"]["focus_from"] == "depth probe at 3,12" and d["inputs"]["focus_at"] == [3, 12]
    assert d["depth_probe"]["depth_range"]["no_depth_pixels"] == 3
    write_plan(plan, tmp_path)
    assert read_plan(tmp_path) == plan
    bare = dataclasses.replace(rec, focus=None)
    assert set(bare.to_dict()) == {"method", "treatment", "depth_range"}


def test_the_povray_options_and_notes_round_trip_and_old_plans_have_none(tmp_path):
    """Issue 13's POV-Ray options (inputs) and notes: written when set, read back equal."""
    import dataclasses
    old = read_plan(DATA / "plan_v1_pinhole.json")
    assert (old.inputs.library_paths, old.inputs.clock, old.inputs.povray_options) == ((), None, ())
    assert old.notes == []
    plan = dataclasses.replace(
        old, inputs=dataclasses.replace(old.inputs, library_paths=("/scenes/inc",), clock=0.5,
                                        povray_options=("+A0.3", "Jitter=off")),
        notes=["the scene's focal blur is replaced"])
    d = json.loads(plan_json(plan))
    assert d["inputs"]["library_paths"] == ["/scenes/inc"] and d["inputs"]["clock"] == 0.5
    assert d["inputs"]["povray_options"] == ["+A0.3", "Jitter=off"]
    assert d["notes"] == ["the scene's focal blur is replaced"]
    write_plan(plan, tmp_path)
    back = read_plan(tmp_path)
    assert back == plan and isinstance(back.inputs.library_paths, tuple)
    plan.add_note("the scene's focal blur is replaced")          # once only
    plan.add_note(None)
    assert plan.notes == ["the scene's focal blur is replaced"]


def test_the_fog_note_of_a_plan_written_before_notes_moves_to_the_notes(tmp_path):
    d = json.loads((DATA / "plan_v1_pinhole.json").read_text())
    d["depth_probe"] = {"method": "light fade", "treatment": "background inf",
                        "scene_atmosphere": "the scene has fog: the depth probe does not see it"}
    (tmp_path / "plan.json").write_text(json.dumps(d))
    plan = read_plan(tmp_path)
    assert plan.notes == ["the scene has fog: the depth probe does not see it"]
    assert "scene_atmosphere" not in plan.to_dict()["depth_probe"]


def test_the_model_error_is_a_record_or_none_written_as_an_empty_object(tmp_path):
    """A measured model error reads as a ModelError and writes back key for key; a
    pinhole plan's, not measured, is ``{}`` in plan.json and None in the plan."""
    from povlens.thinlens.model_error import ModelError
    for name in OLD_PLANS:
        stored = json.loads((DATA / name).read_text())["model_error"]
        plan = read_plan(DATA / name)
        if not stored:
            assert plan.model_error is None
            assert json.loads(plan_json(plan))["model_error"] == {}
        else:
            assert isinstance(plan.model_error, ModelError)
            assert json.dumps(plan.model_error.to_dict()) == json.dumps(stored)
    assert read_plan(DATA / "plan_v1_release_pinhole.json").model_error is None
