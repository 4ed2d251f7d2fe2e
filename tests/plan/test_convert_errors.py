"""The error paths of every --method through 'povlens convert' and 'povlens render': exit
code 2 for bad input, one message, no traceback, nothing half-written; and the automatic
path stops what it started when it fails."""

import os
import shutil
import subprocess
import sys

import pytest

from povlens.cli import main
from povlens.plan.options import METHODS

from conftest import ROOT

PAPER = str(ROOT / "scenes" / "paper.pov")

#: (what is wrong, arguments, words of the message)
BAD_INPUTS = [
    ("missing scene", [str(ROOT / "scenes" / "no-such-scene.pov"), "--lens", "dgauss.50mm"],
     "does not exist"),
    ("refused f-number", [PAPER, "--lens", "dgauss.50mm", "--f-number", "1"], "opens only to"),
    ("missing lens file", [PAPER, "--lens", str(ROOT / "lenses" / "no-such-lens.dat")],
     "no such lens file"),
]


def _left_behind(out):
    """Files of the conversion left in OUTDIR (plan, images, temporaries)."""
    return sorted(p.name for p in out.rglob("*")) if out.exists() else []


@pytest.mark.parametrize("command", ["convert", "render"])
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("what, args, words", BAD_INPUTS, ids=[b[0] for b in BAD_INPUTS])
def test_bad_input_exits_2_with_one_message(tmp_path, capsys, command, method, what, args,
                                             words):
    out = tmp_path / "out"
    code = main([command, *args, "--focus", "4", "--method", method, "--width", "16",
                 "--height", "12", "-o", str(out)] + (["-q"] if command == "render" else []))
    err = capsys.readouterr().err
    assert code == 2, err
    assert words in err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert lines[0].startswith(f"povlens {command}: error: ")
    assert sum("error" in ln for ln in lines) == 1, err           # one message (and its hint)
    assert "Traceback" not in err and "internal error" not in err
    assert _left_behind(out) == []                                 # no plan.json, no image


def test_the_issue_reproduction_has_no_traceback(tmp_path):
    """issue 12: a refused f-number with --method mesh ended as an UnboundLocalError."""
    r = subprocess.run([sys.executable, "-m", "povlens", "render", PAPER, "--lens",
                        "dgauss.50mm", "--focus", "4", "--f-number", "1", "--method", "mesh",
                        "-o", str(tmp_path / "x")], capture_output=True, text=True, cwd=ROOT,
                       timeout=120)
    assert r.returncode == 2, r.stderr
    assert "opens only to" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "x" / "plan.json").exists()


@pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")
@pytest.mark.parametrize("lens, started", [("telephoto.250mm", ".speculative-focal-blur.pov"),
                                           ("fisheye.10mm", "plan.json")])
def test_a_failing_decision_stops_what_auto_started(tmp_path, monkeypatch, lens, started):
    """The decision fails after the depth probe and the speculative work started (the
    focal_blur view for telephoto.250mm, the early lens samples for the fisheye, whose
    distortion rules out the views; dgauss.50mm's vignetting no longer does): the
    error comes through, and no POV-Ray process, probe folder or wrapper is left."""
    import povlens.plan.convert as conv
    from povlens.errors import PovlensError
    from povlens.plan.convert import ConvertOptions
    from povlens.rendering.driver import convert_and_render

    seen = []

    def failing_choice(opts, *args, probe=None, **kw):
        seen.append(sorted(p.name for p in out.iterdir()))
        probe.result()                                       # the probe ran to the end
        raise PovlensError("decision failed")

    monkeypatch.setattr(conv, "choose_method", failing_choice)
    out = tmp_path / "auto"
    with pytest.raises(PovlensError, match="decision failed"):
        convert_and_render(ConvertOptions.of(scene=PAPER, lens=lens, focus=4.0, outdir=str(out),
                                          width=48, height=36, method="auto"), quiet=True)
    assert started in seen[0]                                # it had started
    assert not list(out.glob(".probe.*")) and not list(out.glob(".speculative*"))
    assert not list(out.rglob("*.inc")) and not list(out.rglob(".sample_*"))
    assert not list(out.rglob("*.tmp*")) and not (out / "image.exr").exists()
    assert _processes_in(out) == []                          # no POV-Ray still running


def _processes_in(folder) -> list[int]:
    """PIDs of processes working in ``folder`` or below (POV-Ray runs there)."""
    pids = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                if os.readlink(f"/proc/{d}/cwd").startswith(str(folder)):
                    pids.append(int(d))
            except OSError:
                pass
    return pids
