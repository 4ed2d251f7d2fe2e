"""Every failure a user meets × every command × every method: one clear message, the
right exit code, no traceback, nothing half-written, no temporary folder left.

(Interrupts, Ctrl-C and SIGTERM while POV-Ray runs, are in test_interrupts.py.)
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

from conftest import ROOT
from povlens.cli import main

METHODS = ["auto", "pinhole", "focal-blur", "mesh"]
COMMANDS = ["plan", "convert", "render"]
SCENE = ROOT / "scenes" / "paper.pov"


def _scene_with(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _failure(kind: str, tmp_path: Path, monkeypatch) -> tuple[list[str], set[int], str]:
    """Arguments, the exit codes allowed, and a word the message must contain."""
    if kind == "missing scene":
        return [str(tmp_path / "nope.pov"), "--lens", "dgauss.50mm", "--focus", "4"], {2}, \
            "does not exist"
    if kind == "unreadable camera":
        scene = _scene_with(tmp_path, "fn.pov", "#version 3.7;\n"
                            "#declare F = function(x) { 2 * x }\n"
                            "camera { location <F(1), 1, -5> look_at 0 }\n"
                            "sphere { 0, 1 pigment { rgb 1 } }\n")
        return [str(scene), "--lens", "dgauss.50mm", "--focus", "4"], {2}, "--location"
    if kind == "bad lens":
        lens = _scene_with(tmp_path, "bad.dat", "# radius thickness index aperture\n"
                           "20\t5\tglass\t10\n")
        return [str(SCENE), "--lens", str(lens), "--focus", "4"], {2}, "bad.dat"
    if kind == "refused f-number":
        return [str(SCENE), "--lens", "dgauss.50mm", "--focus", "4", "--f-number", "1"], {2}, \
            "--f-number"
    if kind == "POV-Ray missing":
        monkeypatch.setenv("POVLENS_POVRAY", str(tmp_path / "no-povray"))
        return [str(SCENE), "--lens", "dgauss.50mm", "--focus", "4"], {3}, "POV-Ray"
    if kind == "POV-Ray parse error":
        scene = _scene_with(tmp_path, "broken.pov", "#version 3.7;\n"
                            "camera { location <0, 1, -5> look_at 0 }\n"
                            "sphere { 0, 1 pigment { rgb 1 } \n")   # unclosed
        return [str(scene), "--lens", "dgauss.50mm", "--focus", "4"], {3}, "broken.pov"
    raise AssertionError(kind)


FAILURES = ["missing scene", "unreadable camera", "bad lens", "refused f-number",
            "POV-Ray missing", "POV-Ray parse error"]


def _needs_povray(kind: str, command: str, method: str) -> bool:
    """Failures only POV-Ray finds: a command that runs no POV-Ray may succeed."""
    runs_povray = command == "render" or method == "auto"
    return kind in ("POV-Ray missing", "POV-Ray parse error") and not runs_povray


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize("kind", FAILURES)
def test_failure_gives_one_clear_message(kind, command, method, tmp_path, monkeypatch,
                                         capsys):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    args, codes, word = _failure(kind, tmp_path, monkeypatch)
    outdir = tmp_path / "out"
    argv = [command, *args, "--method", method, "--samples", "2", "--width", "32",
            "--height", "24", "-o", str(outdir)]
    if command == "render":
        argv.append("--quiet")
    code = main(argv)
    err = capsys.readouterr().err
    assert "Traceback" not in err
    if _needs_povray(kind, command, method) and code == 0:
        return                          # nothing ran that could see it; render will say
    assert code in codes, err
    errors = [ln for ln in err.splitlines() if ": error: " in ln]
    assert len(errors) == 1, err
    assert word in err, err
    assert list(tmp.iterdir()) == [], "a temporary folder was left"
    if outdir.exists():
        names = [p.name for p in outdir.rglob("*")]
        assert not [n for n in names if ".tmp" in n or n.endswith(".pov-state")], names
        assert "image.exr" not in names
