"""A pinhole plan skips what only the lens's blur needs (issue 14): no exit-pupil table
(no pupil.npz), no thin-lens model error (plan.json's model_error is empty, and a note
says so); every other number is the one the focal-blur plan of the same options has.
A pinhole that --method auto chose keeps what auto measured."""

import json
import shutil

import pytest

import povlens.plan.plan_finish as plan_finish
from povlens.plan.camera_setup import FRAMING_NOTE_START
from povlens.plan.convert import ConvertOptions, convert
from povlens.plan.plan_finish import PINHOLE_NOTE
from povlens.plan.schema import read_plan

from conftest import ROOT

PAPER = str(ROOT / "scenes" / "paper.pov")
pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")


def _opts(tmp_path, name, **kw):
    base = dict(method="mesh", scene=PAPER, lens="dgauss.50mm", focus=4.0, outdir=str(tmp_path / name),
                width=40, height=30)
    return ConvertOptions.of(**(base | kw))


def test_a_pinhole_plan_builds_no_pupil_table_and_measures_no_model_error(tmp_path,
                                                                          monkeypatch):
    def not_wanted(*args, **kw):
        raise AssertionError("a pinhole plan needs no pupil table or model error")
    with monkeypatch.context() as m:
        m.setattr(plan_finish, "cached_pupil_table", not_wanted)
        m.setattr(plan_finish, "measure_model_error", not_wanted)
        pin = convert(_opts(tmp_path, "pin", method="pinhole"))
    out = tmp_path / "pin"
    assert not (out / "pupil.npz").exists()
    notes = [n for n in pin.notes if not n.startswith(FRAMING_NOTE_START)]
    assert pin.model_error is None and notes == [PINHOLE_NOTE]
    saved = json.loads((out / "plan.json").read_text())
    assert saved["model_error"] == {} and saved["notes"] == pin.notes
    assert read_plan(out) == pin                                  # still a valid plan

    blur = convert(_opts(tmp_path, "blur", method="focal-blur"))
    assert (tmp_path / "blur" / "pupil.npz").is_file()
    assert blur.model_error.max_distortion_px >= 0 and PINHOLE_NOTE not in blur.notes
    a, b = pin.to_dict(), blur.to_dict()
    for key in ("lens", "focus", "film", "mm_per_unit", "placement", "thin_lens",
                "povray_camera", "povray", "sink_centre"):
        assert a[key] == b[key], key
    assert {k for k in a["inputs"] if a["inputs"][k] != b["inputs"][k]} == {"method"}


def test_the_pinhole_wrapper_is_the_same_as_before_the_skip(tmp_path):
    """The view a pinhole plan renders is the pinhole view of the focal-blur folder."""
    convert(_opts(tmp_path, "pin", method="pinhole"))
    convert(_opts(tmp_path, "blur", method="focal-blur"))
    assert (tmp_path / "pin" / "pinhole.pov").read_text() == \
        (tmp_path / "blur" / "pinhole.pov").read_text()


def test_a_pinhole_chosen_by_auto_keeps_its_measured_model_error(tmp_path):
    plan = convert(_opts(tmp_path, "auto", method="auto", f_number=22.0))
    assert plan.inputs.method == "pinhole", plan.decision.reasons
    assert plan.model_error.max_distortion_px >= 0
    assert PINHOLE_NOTE not in plan.notes
    assert (tmp_path / "auto" / "pupil.npz").is_file()
