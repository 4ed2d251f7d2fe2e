"""The decision of --method auto as typed records: the checks it measures
(:class:`~povlens.plan.decision.DecisionChecks`), the reason text made from them
(:func:`~povlens.plan.decision.decision_reasons`), and the decisions of the release
before the records, reproduced string for string."""

import dataclasses
import json
import math
import pathlib

import pytest

from povlens.plan.decision import (Check, DecisionChecks, Verdict, decide, decision_reasons,
                                   measure_checks)
from povlens.thinlens.model import EquivalentThinLens
from povlens.thinlens.model_error import ModelError

DATA = pathlib.Path(__file__).resolve().parent / "data"
#: decide()'s inputs and the decision it returned (Decision.to_dict, as plan.json holds
#: it), written by the code of commit 3e3d89b (before the records): 12 cases covering
#: every conclusion (pinhole, focal-blur, the cat's-eye floor, the cat's eye, the
#: aperture shape, the real lens) and every way the cat's eye is judged (the probe's
#: image, the pupil cut in pixels, the relative illumination, not wanted), with a lens
#: shift.  The model errors are measured at 3 film heights (n_field=3) to keep it small.
CASES = json.loads((DATA / "decisions_v1.json").read_text())


def _inputs(case: dict) -> dict:
    kw = dict(case["decide"])
    kw["model"] = EquivalentThinLens(**case["model"])
    kw["model_error"] = ModelError.from_dict(case["model_error"])
    return kw


def test_the_cases_cover_every_verdict():
    """Every verdict of the release before the records (the anamorphic lens's came after:
    :func:`test_an_anamorphic_lens_rules_focal_blur_out`)."""
    conclusions = {c["decision"]["reasons"][-1].split(":")[0] for c in CASES}
    assert conclusions == {"-> pinhole", "-> focal-blur", "-> mesh"}
    assert len({c["decision"]["reasons"][-1][:40] for c in CASES}) == len(Verdict) - 1


def test_an_anamorphic_lens_rules_focal_blur_out():
    """A case whose thin lens would do (focal-blur) decides mesh with an anamorphic lens,
    saying why in a focal-blur line and the conclusion; a pinhole case stays pinhole (its
    view is framed per meridian)."""
    what = "EFL_x 31.49 mm, EFL_y 60.55 mm, squeeze 1.92"
    fb = next(c for c in CASES if c["decision"]["method"] == "focal-blur")
    d = decide(**_inputs(fb), anamorphic=what)
    assert d.method == "mesh" and d.focal_blur is None
    assert any(r.startswith("focal-blur: cannot draw an anamorphic lens (" + what)
               for r in d.reasons)
    assert d.reasons[-1].startswith("-> mesh: the lens is anamorphic")
    assert d.samples == decide(**_inputs(fb)).numbers["blur_rule_samples"]
    ph = next(c for c in CASES if c["decision"]["method"] == "pinhole")
    assert decide(**_inputs(ph), anamorphic=what).method == "pinhole"


@pytest.mark.parametrize("case", CASES, ids=[c["case"] for c in CASES])
def test_decide_gives_the_decision_of_the_release_before_the_records(case):
    d = decide(**_inputs(case))
    assert d.reasons == case["decision"]["reasons"]
    # plan.json's decision byte for byte: keys in order, the same floats
    assert json.dumps(d.to_dict()) == json.dumps(case["decision"])


@pytest.mark.parametrize("case", CASES, ids=[c["case"] for c in CASES])
def test_the_reason_text_function_alone_gives_the_old_strings(case):
    kw = _inputs(case)
    checks = measure_checks(kw.pop("near_z_mm"), kw.pop("far_z_mm"), kw.pop("model"),
                            kw.pop("model_error"), kw.pop("pixel_pitch_mm"),
                            kw.pop("tolerance_px", 0.5), kw.pop("vignetting", True),
                            kw.pop("image_error", None), kw.pop("catseye", None),
                            kw.pop("aperture_shape", None), kw.pop("shift_tilt_cos", 1.0))
    assert not kw
    assert isinstance(checks, DecisionChecks)
    same = [v for v in Verdict if decision_reasons(checks, v) == case["decision"]["reasons"]]
    assert len(same) == 1 and same[0].method == case["decision"]["method"]


def test_a_check_passes_under_its_limit_and_its_line_says_so():
    ok, bad = Check("pinhole: max distortion", 0.25, 0.5), Check("x", 0.5, 0.5)
    assert ok.passed and not bad.passed
    with pytest.raises(dataclasses.FrozenInstanceError):
        ok.value_px = 1.0
    case = next(c for c in CASES if c["case"] == "pinhole")
    kw = _inputs(case)
    checks = measure_checks(kw["near_z_mm"], kw["far_z_mm"], kw["model"], kw["model_error"],
                            kw["pixel_pitch_mm"], 0.5, True, None, None, None, 1.0)
    moved = dataclasses.replace(checks, pinhole=(ok, bad) + checks.pinhole[2:])
    lines = decision_reasons(moved, Verdict.MESH_LENS)
    assert "pinhole: max distortion 0.25 px < 0.5 px" in lines
    assert "x 0.5 px >= 0.5 px" in lines
    assert lines[-1].startswith("-> mesh: the real lens deviates")
    assert math.isinf(checks.far_z_mm) == math.isinf(kw["far_z_mm"])
