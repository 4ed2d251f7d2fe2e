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
    """PIDs of POV-Ray processes whose command line, working folder or environment
    (the test's TMPDIR, inherited by every process the command starts) mention
    ``marker``."""
    found = []
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
            if "povray" not in cmd.split(" ")[0]:
                continue
            cwd = os.readlink(f"/proc/{pid}/cwd")
            env = Path(f"/proc/{pid}/environ").read_bytes().decode(errors="replace")
        except OSError:
            continue
        if marker in cmd or marker in cwd or marker in env:
            found.append(int(pid))
    return found


def _start(args: list[str], tmp_path: Path) -> subprocess.Popen:
    env = dict(os.environ, TMPDIR=str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir(exist_ok=True)
    return subprocess.Popen([sys.executable, "-m", "povlens", *args], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _run_and_signal(args: list[str], tmp_path: Path, signum: int, after_s: float = 0.2):
    """Run the command; ``after_s`` after its first POV-Ray started, send ``signum``."""
    p = _start(args, tmp_path)
    deadline = time.monotonic() + 60
    while not _povray_processes(str(tmp_path)) and p.poll() is None:
        assert time.monotonic() < deadline, "POV-Ray never started"
        time.sleep(0.02)
    assert p.poll() is None, f"finished before it could be interrupted: {p.stderr.read()}"
    time.sleep(after_s)
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


SIGNALS = [(signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted")]
# Commands whose interrupt takes seconds get one signal each, the two alternating (the
# same clean-up runs for both: cli.main); render, plan and convert get both.
TERM, INT = ([s] for s in SIGNALS)


def _convert(tmp_path: Path, outdir: Path, *more: str) -> None:
    r = subprocess.run([sys.executable, "-m", "povlens", "convert", str(SCENE), "--lens",
                        "dgauss.50mm", "--focus", "4", "-o", str(outdir), *more],
                       cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr


def _assert_stopped(code_: int, err: str, code: int, word: str) -> None:
    assert code_ == code, err
    assert "Traceback" not in err
    assert err.strip().splitlines()[-1].endswith(word), err


@pytest.mark.parametrize("signum, code, word", SIGNALS)
@pytest.mark.parametrize("command", ["plan", "convert"])
def test_plan_and_convert_stopped_during_the_depth_probe(tmp_path, command, signum, code, word):
    """The probe's renders are started from a thread: they must not outlive the command."""
    outdir = tmp_path / "out"
    args = [command, str(SCENE), "--lens", "dgauss.50mm", "--width", "640", "--height", "480"]
    args += ["-o", str(outdir)] if command == "convert" else []
    _assert_stopped(*_run_and_signal(args, tmp_path, signum), code, word)
    _assert_clean(tmp_path, outdir)
    assert not (outdir / "plan.json").exists()


DEBIAN_SCENE = Path("/usr/share/doc/povray/examples/advanced/isocacti.pov")


@pytest.mark.skipif(not DEBIAN_SCENE.is_file(), reason="needs Debian's povray-examples "
                    "(bash .ci/setup --test installs it)")
@pytest.mark.parametrize("after_s", [0.5, 1.0, 2.0])
def test_plan_of_an_unseen_scene_terminated_at_any_moment(tmp_path, after_s):
    """SIGTERM at a fixed time after the start (import, probe start, model error, probe
    collection), whether or not POV-Ray runs yet: nothing is left running."""
    p = _start(["plan", str(DEBIAN_SCENE), "--lens", "dgauss.50mm", "--width", "320",
                "--height", "240"], tmp_path)
    time.sleep(after_s)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    assert p.returncode in (143, -signal.SIGTERM, 0), err   # -15: before Python's handler
    assert "Traceback" not in err
    _assert_clean(tmp_path, tmp_path / "none")


@pytest.mark.parametrize("signum, code, word", TERM)
def test_render_batch_interrupted_leaves_nothing_running(tmp_path, signum, code, word):
    outdir = tmp_path / "out"
    _convert(tmp_path, outdir, "--method", "mesh", "--samples", "8", "--width", "320",
             "--height", "240")
    _assert_stopped(*_run_and_signal(["render-batch", str(outdir), "0"],
                                     tmp_path, signum), code, word)
    _assert_clean(tmp_path, outdir)


@pytest.mark.parametrize("signum, code, word", INT)
def test_render_view_interrupted_leaves_nothing_running(tmp_path, signum, code, word):
    outdir = tmp_path / "out"
    _convert(tmp_path, outdir, "--method", "focal-blur", "--width", "640", "--height", "480")
    _assert_stopped(*_run_and_signal(["render-view", str(outdir), "--view", "focal-blur"],
                                     tmp_path, signum), code, word)
    _assert_clean(tmp_path, outdir)


@pytest.mark.parametrize("signum, code, word", TERM)
def test_report_interrupted_while_it_renders_a_missing_view(tmp_path, signum, code, word):
    outdir = tmp_path / "out"
    _convert(tmp_path, outdir, "--method", "focal-blur", "--width", "640", "--height", "480")
    page = tmp_path / "report.html"
    _assert_stopped(*_run_and_signal(["report", str(outdir), "-o", str(page)], tmp_path,
                                     signum), code, word)
    _assert_clean(tmp_path, outdir)
    assert not page.exists()


@pytest.mark.parametrize("signum, code, word", INT)
def test_bench_interrupted_leaves_nothing_running(tmp_path, signum, code, word):
    _assert_stopped(*_run_and_signal(
        ["bench", "--quick", "--tracer-rays", "0", "--out", str(tmp_path / "bench")],
        tmp_path, signum, after_s=0.5), code, word)
    _assert_clean(tmp_path, tmp_path / "bench")


# A command whose clean-up after SIGTERM fails with another error, and that leaves a
# child process behind (a POV-Ray a thread started, say).
CLEANUP_FAILS = r"""
import os, signal, subprocess, sys, time
import povlens.cli, povlens.cli.focus_cmd as f
def run(args):
    child = subprocess.Popen(["sleep", "60"], stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    print(child.pid, flush=True)
    try:
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(30)
    except KeyboardInterrupt:
        raise RuntimeError("the clean-up failed")
f.run = run
sys.argv = ["povlens", "focus", "dgauss.50mm", "--distance", "4"]
povlens.cli.run()
"""

FAILS = CLEANUP_FAILS.replace("os.kill(os.getpid(), signal.SIGTERM)",
                              "raise povlens.errors.PovrayError('POV-Ray failed')").replace(
                              "import povlens.cli,", "import povlens.errors, povlens.cli,")


def _gone(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except OSError:
        return True


@pytest.mark.parametrize("script, code, word", [(CLEANUP_FAILS, 143, "terminated"),
                                                (FAILS, 3, "POV-Ray failed")])
def test_a_failed_or_terminated_command_leaves_no_child(script, code, word):
    """The signal received decides the exit code even when the clean-up then fails; a
    command that fails kills what is left below it."""
    r = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True,
                       text=True, timeout=60)
    pid = int(r.stdout.split()[0])
    try:
        assert r.returncode == code, r.stderr
        assert word in r.stderr and "internal error" not in r.stderr, r.stderr
        time.sleep(0.1)
        assert _gone(pid), "the child process outlived the command"
    finally:
        if not _gone(pid):
            os.kill(pid, signal.SIGKILL)


@pytest.mark.parametrize("command", ["plan", "render"])
def test_a_second_signal_during_the_clean_up_leaves_nothing(tmp_path, command):
    """SIGTERM, then SIGINT 30 ms later (a batch system, then an impatient user): the
    clean-up of the first is not cut short by the second."""
    outdir = tmp_path / "out"
    p = _start([command, str(SCENE), "--lens", "dgauss.50mm", "--focus", "4", "--width",
                "640", "--height", "480", "-o", str(outdir)], tmp_path)
    deadline = time.monotonic() + 60
    while not _povray_processes(str(tmp_path)) and p.poll() is None:
        assert time.monotonic() < deadline, "POV-Ray never started"
        time.sleep(0.02)
    time.sleep(0.2)
    p.send_signal(signal.SIGTERM)
    time.sleep(0.03)
    if p.poll() is None:
        p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode in (130, 143) and "Traceback" not in err, err
    _assert_clean(tmp_path, outdir)
