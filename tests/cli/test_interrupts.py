"""Ctrl-C and SIGTERM while POV-Ray runs: exit code, one message, no POV-Ray process
left running, no temporary folder left, nothing half-written at a final name.

The signal goes to the povlens process alone (as ``kill PID`` or a batch system sends
it), not to its process group, so POV-Ray stops only if povlens stops it.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import ROOT

SCENE = ROOT / "scenes" / "paper.pov"


def _povray_processes(marker: str) -> list[int]:
    """PIDs of POV-Ray processes whose command line or working folder mention ``marker``."""
    found = []
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
            cwd = os.readlink(f"/proc/{pid}/cwd")
        except OSError:
            continue
        if "povray" in cmd.split(" ")[0] and (marker in cmd or marker in cwd):
            found.append(int(pid))
    return found


def _run_and_signal(args: list[str], tmp_path: Path, signum: int):
    env = dict(os.environ, TMPDIR=str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    p = subprocess.Popen([sys.executable, "-m", "povlens", *args], cwd=tmp_path, env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not _povray_processes(str(tmp_path)) and p.poll() is None:
        assert time.monotonic() < deadline, "POV-Ray never started"
        time.sleep(0.02)
    assert p.poll() is None, f"finished before it could be interrupted: {p.stderr.read()}"
    time.sleep(0.2)
    p.send_signal(signum)
    out, err = p.communicate(timeout=60)
    return p.returncode, err


def _assert_clean(tmp_path: Path, outdir: Path):
    deadline = time.monotonic() + 5
    while _povray_processes(str(tmp_path)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _povray_processes(str(tmp_path)) == [], "a POV-Ray process is still running"
    assert list((tmp_path / "tmp").iterdir()) == [], "a temporary folder was left"
    if outdir.exists():
        left = [p.name for p in outdir.rglob("*") if ".tmp" in p.name or
                (p.is_dir() and p.name.startswith(".")) and p.name != ".make"]
        assert left == [], f"temporaries left in the output folder: {left}"
        assert not (outdir / "image.exr").exists()


@pytest.mark.parametrize("signum, code, word", [(signal.SIGTERM, 143, "terminated"),
                                                (signal.SIGINT, 130, "interrupted")])
@pytest.mark.parametrize("method", ["mesh", "focal-blur", "auto"])
def test_render_interrupted_leaves_nothing_running(tmp_path, method, signum, code, word):
    outdir = tmp_path / "out"
    code_, err = _run_and_signal(
        ["render", str(SCENE), "--lens", "dgauss.50mm", "--focus", "4", "--method", method,
         "--samples", "64", "--width", "320", "--height", "240", "-o", str(outdir)],
        tmp_path, signum)
    assert code_ == code, err
    assert "Traceback" not in err
    assert err.strip().splitlines()[-1].endswith(word)
    _assert_clean(tmp_path, outdir)


def test_plan_terminated_during_the_depth_probe(tmp_path):
    code, err = _run_and_signal(
        ["plan", str(SCENE), "--lens", "dgauss.50mm", "--focus", "4", "--width", "640",
         "--height", "480"], tmp_path, signal.SIGTERM)
    assert code == 143 and "Traceback" not in err
    _assert_clean(tmp_path, tmp_path / "none")
