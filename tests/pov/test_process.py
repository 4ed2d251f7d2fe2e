"""povlens.pov.process and povlens.pov.executable against the real POV-Ray (small images)."""

from __future__ import annotations

import re
import os
import shutil
import time

import numpy as np
import pytest

from povlens.pov import executable
from povlens.pov import process as povray
from povlens.errors import PovrayError, UsageError
from povlens.util.images import read_image

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray is not installed")

FLAT = """#version 3.7;
global_settings { assumed_gamma 1.0 }
camera { location <0, 0, -3> look_at 0 }
plane { -z, 0 pigment { rgb 0.5 } finish { ambient 1 diffuse 0 } }
"""


@pytest.fixture
def flat_scene(tmp_path):
    p = tmp_path / "flat.pov"
    p.write_text(FLAT)
    return p


def _leftovers(folder):
    return sorted(p.name for p in folder.iterdir() if ".tmp" in p.name or p.suffix == ".log")


def test_version_and_row_workaround():
    v = executable.povray_version()
    assert re.fullmatch(r"\d+(\.\d+)+", v)
    assert executable.povray_version() is v  # cached
    assert executable.needs_row_workaround("3.7.0.10")
    assert executable.needs_row_workaround("3.7.0")
    assert not executable.needs_row_workaround("3.7.1")
    assert not executable.needs_row_workaround("3.8.0")


def test_render_exr(flat_scene, tmp_path):
    out = tmp_path / "out" / "flat.exr"
    out.parent.mkdir()
    assert povray.render(flat_scene, out, 16, 12) == out
    img = read_image(out)
    assert img.shape == (12, 16, 3)
    np.testing.assert_allclose(img, 0.5, atol=1e-3)
    assert _leftovers(tmp_path) == [] and _leftovers(out.parent) == []


@pytest.mark.parametrize(
    "rows, cols",
    [((1, 3), (None, None)), ((0, 1), (2, 5)), ((11, 12), (15, 16)), ((None, None), (0, 1))],
)
def test_render_subrectangle(flat_scene, tmp_path, rows, cols):
    out = tmp_path / "sub.exr"
    povray.render(flat_scene, out, 16, 12, start_row=rows[0], end_row=rows[1],
                  start_col=cols[0], end_col=cols[1])  # fmt: skip
    img = read_image(out)[:, :, 0]
    expect = np.zeros((12, 16), bool)
    expect[slice(*rows), slice(*cols)] = True
    np.testing.assert_array_equal(img > 0.25, expect)


def test_bad_subrectangle(flat_scene, tmp_path):
    with pytest.raises(UsageError, match="row"):
        povray.render(flat_scene, tmp_path / "x.exr", 16, 12, start_row=5, end_row=5)
    with pytest.raises(UsageError, match="col"):
        povray.render(flat_scene, tmp_path / "x.exr", 16, 12, end_col=17)


def test_pixel_ranges_are_written_as_pixel_numbers_never_as_fractions_of_one():
    assert povray.pixel_range_args(None, None, 12) == []
    assert povray.pixel_range_args(0, 12, 12, "col") == []
    assert povray.pixel_range_args(1, 3, 12) == ["+SR2", "+ER3"]
    assert povray.pixel_range_args(0, 1, 12) == [f"+ER{1.5 / 12:.9f}"]  # "+ER1" = all rows
    assert povray.pixel_range_args(15, None, 16, "col") == ["+SC16"]
    with pytest.raises(UsageError, match="start_row < end_row"):
        povray.pixel_range_args(5, 5, 12)


def test_one_command_line_for_every_render():
    switches = povray.render_switches("out.png", 16, 12, threads=2, start_row=1,
                                      library_paths=["/scenes"], extra_args=["Declare=K=1"])
    assert switches == ["+FN", "+W16", "+H12", "-A", "+WT2", "+SR2", "+L/scenes", "Declare=K=1"]
    assert povray.povray_command("povray", "a.pov", "out.png", switches, error_log="e.log") == [
        "povray", "-D", "-V", "-GR", "-GS", "+GFe.log", "+Ia.pov", "+Oout.png", *switches]
    assert "+GF" not in " ".join(povray.povray_command("povray", "a.pov", "b.exr", []))
    with pytest.raises(UsageError, match="suffix"):
        povray.render_switches("out.jpg", 16, 12)
    with pytest.raises(UsageError, match="thread"):
        povray.render_switches("out.exr", 16, 12, threads=0)


def test_parse_error_carries_povray_message(tmp_path):
    bad = tmp_path / "bad.pov"
    bad.write_text(FLAT + "sphere { 0, 1 pigment { rgb 1 }\nlightsource { <1,1,1> rgb 1 }\n")
    out = tmp_path / "bad.exr"
    out.write_bytes(b"previous image")
    with pytest.raises(PovrayError) as info:
        povray.render(bad, out, 8, 6)
    msg = str(info.value)
    assert "bad.pov" in msg
    assert "Parse Error" in msg and "lightsource" in msg
    assert "Persistence of Vision" not in msg  # banner removed
    assert out.read_bytes() == b"previous image"  # never half-written
    assert _leftovers(tmp_path) == []


def test_missing_include_message(tmp_path):
    bad = tmp_path / "inc.pov"
    bad.write_text('#version 3.7;\n#include "no_such_file.inc"\n')
    with pytest.raises(PovrayError, match="no_such_file.inc"):
        povray.render(bad, tmp_path / "inc.exr", 8, 6)


def test_missing_povray(monkeypatch, flat_scene, tmp_path):
    monkeypatch.setenv(executable.ENV_VAR, str(tmp_path / "nowhere" / "povray"))
    with pytest.raises(PovrayError) as info:
        povray.render(flat_scene, tmp_path / "x.exr", 8, 6)
    assert executable.ENV_VAR in str(info.value)
    assert info.value.hint and "povray" in info.value.hint
    with pytest.raises(PovrayError, match=executable.ENV_VAR):
        executable.povray_version()


def test_missing_povray_on_path(monkeypatch, flat_scene, tmp_path):
    monkeypatch.delenv(executable.ENV_VAR, raising=False)
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(PovrayError, match="not found"):
        povray.render(flat_scene, tmp_path / "x.exr", 8, 6)


def test_usage_errors(flat_scene, tmp_path):
    with pytest.raises(UsageError, match="suffix"):
        povray.render(flat_scene, tmp_path / "x.jpg", 8, 6)
    with pytest.raises(UsageError, match="does not exist"):
        povray.render(tmp_path / "nope.pov", tmp_path / "x.exr", 8, 6)
    with pytest.raises(UsageError, match="folder"):
        povray.render(flat_scene, tmp_path / "no_dir" / "x.exr", 8, 6)


def test_library_paths_resolve_scene_includes(tmp_path):
    """POV-Ray resolves #include relative to its cwd/library paths only."""
    scene_dir = tmp_path / "scene"
    work = tmp_path / "work"
    scene_dir.mkdir()
    work.mkdir()
    (scene_dir / "colour.inc").write_text("#declare Col = rgb <0.25, 0.5, 0.75>;\n")
    (scene_dir / "s.pov").write_text(
        FLAT.replace("pigment { rgb 0.5 }", "pigment { Col }").replace(
            "camera", '#include "colour.inc"\ncamera'
        )
    )
    wrapper = work / "w.pov"
    wrapper.write_text(f'#version 3.7;\n#include "{scene_dir / "s.pov"}"\n')
    with pytest.raises(PovrayError, match="colour.inc"):
        povray.render(wrapper, work / "w.exr", 8, 6)
    povray.render(wrapper, work / "w.exr", 8, 6, library_paths=[scene_dir])
    np.testing.assert_allclose(read_image(work / "w.exr")[3, 4], [0.25, 0.5, 0.75], atol=1e-3)


def test_image_is_taken_when_written_not_at_process_exit(tmp_path):
    """POV-Ray idles ~0.3 s after closing its image; output_written sees the
    closed file while the process still runs, and the image is complete."""
    import subprocess
    scene = tmp_path / "s.pov"
    scene.write_text(FLAT + "sphere { 0, 1 pigment { checker rgb 1 rgb 0 scale 0.2 } "
                            "finish { ambient 1 diffuse 0 } }\n")
    out = tmp_path / "a.exr"
    proc = subprocess.Popen([executable.find_povray(), "-D", "-V", "-GR", "-GS", f"+I{scene}",
                             f"+O{out}", "+FE", "+W64", "+H48", "-A", "+WT1"],
                            cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    seen_while_running = False
    while proc.poll() is None:
        if povray.output_written(proc.pid, out):
            seen_while_running = proc.poll() is None
            shutil.copy(out, tmp_path / "early.exr")   # what a caller takes at once
            break
        time.sleep(0.002)
    proc.wait()
    assert seen_while_running
    early = read_image(tmp_path / "early.exr")
    full = povray.render(scene, tmp_path / "b.exr", 64, 48)
    np.testing.assert_array_equal(early, read_image(full))
    assert not povray.output_written(proc.pid, tmp_path / "missing.exr")


def test_a_wrapper_script_is_never_judged_done_before_it_exits(tmp_path):
    """A POVLENS_POVRAY wrapper may work on after its POV-Ray child exits (the
    window between the child's exit and its own): never picked up early then."""
    import subprocess
    scene = tmp_path / "s.pov"
    scene.write_text(FLAT + "sphere { 0, 1 pigment { rgb 1 } }\n")
    out = tmp_path / "a.exr"
    wrapper = tmp_path / "wrap"
    wrapper.write_text(f'#!/bin/sh\n"{executable.find_povray()}" "$@"\n'
                       # shell builtins only: no child process while it works on
                       'i=0; while [ $i -lt 100000 ]; do i=$((i+1)); done\n'
                       f'echo done > "{tmp_path}/marker"\n')
    wrapper.chmod(0o755)
    proc = subprocess.Popen([str(wrapper), "-D", "-V", "-GR", "-GS", f"+I{scene}", f"+O{out}",
                             "+FE", "+W16", "+H12", "-A"], cwd=tmp_path,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    judged_early = False
    while proc.poll() is None:
        if out.exists() and povray.output_written(proc.pid, out):
            judged_early = proc.poll() is None
            break
        time.sleep(0.005)
    proc.wait()
    assert not judged_early
    assert (tmp_path / "marker").exists()


def _povray_stat(pid: int) -> list[str]:
    """/proc/PID/stat fields after the name, once PID runs POV-Ray (a ``chrt`` or
    ``nice`` prefix execs it in the same process)."""
    deadline = time.monotonic() + 5
    while "povray" not in os.path.basename(os.readlink(f"/proc/{pid}/exe")):
        assert time.monotonic() < deadline, "POV-Ray did not start"
        time.sleep(0.001)
    return open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()


@pytest.fixture(params=["prefix", "preexec_fn"])
def priority_by(request, monkeypatch):
    """Both ways start_render lowers priorities: a chrt / nice prefix, and the
    preexec_fn fallback where those programs are missing."""
    if request.param == "preexec_fn":
        monkeypatch.setattr(povray, "priority_tools", lambda: (None, None))
    else:
        assert all(povray.priority_tools()), "chrt and nice are on every Debian"
    return request.param


def test_start_render_can_lower_the_priority(tmp_path, priority_by):
    scene = tmp_path / "s.pov"
    scene.write_text(FLAT + "sphere { 0, 1 pigment { rgb 1 } }\n")
    job = povray.start_render(scene, tmp_path / "a.exr", 16, 12, nice=7)
    try:
        fields = _povray_stat(job.proc.pid)
        own = int(open("/proc/self/stat").read().rsplit(")", 1)[1].split()[16])
        assert int(fields[16]) == min(19, own + 7)     # field 19 of stat: nice
    finally:
        job.wait()
    assert (tmp_path / "a.exr").exists()


def test_start_render_can_run_at_idle_priority(tmp_path, priority_by):
    """idle=True: Linux's SCHED_IDLE policy (5), field 41 of /proc/PID/stat."""
    scene = tmp_path / "s.pov"
    scene.write_text(FLAT + "sphere { 0, 1 pigment { rgb 1 } }\n")
    job = povray.start_render(scene, tmp_path / "a.exr", 16, 12, idle=True)
    try:
        fields = _povray_stat(job.proc.pid)
        assert int(fields[38]) == os.SCHED_IDLE
    finally:
        job.wait()
    assert (tmp_path / "a.exr").exists()


def test_version_is_remembered_across_runs_and_asked_again_after_an_upgrade(tmp_path,
                                                                           monkeypatch):
    """The version cache: a second process (lru_cache cleared) does not run POV-Ray;
    a binary that changes (another mtime: an upgrade) is asked again; a script is
    never cached (its POV-Ray may change behind it)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    real = shutil.which("povray")
    binary = tmp_path / "povray"
    shutil.copy(real, binary)                          # an ELF binary we can touch
    calls = []
    ask = executable.ask_povray_version
    monkeypatch.setattr(executable, "ask_povray_version", lambda exe: calls.append(exe) or ask(exe))
    executable.cached_povray_version.cache_clear()
    v = executable.povray_version(str(binary))
    executable.cached_povray_version.cache_clear()
    assert executable.povray_version(str(binary)) == v and len(calls) == 1
    os.utime(binary, ns=(0, 10**18))                   # "upgraded"
    executable.cached_povray_version.cache_clear()
    assert executable.povray_version(str(binary)) == v and len(calls) == 2
    script = tmp_path / "wrap"
    script.write_text(f'#!/bin/sh\nexec "{real}" "$@"\n')
    script.chmod(0o755)
    for _ in range(2):
        executable.cached_povray_version.cache_clear()
        assert executable.povray_version(str(script)) == v
    assert len(calls) == 4
    executable.cached_povray_version.cache_clear()


def test_a_chrt_that_cannot_set_the_policy_is_not_used(tmp_path, monkeypatch):
    """A sandbox may forbid SCHED_IDLE: chrt then exits 1 instead of running POV-Ray.
    The first use tries 'chrt --idle 0 true'; on failure the preexec_fn fallback
    starts POV-Ray (here with SCHED_IDLE, which this machine permits)."""
    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "chrt").write_text("#!/bin/sh\necho 'chrt: failed to set pid 0 policy' >&2\nexit 1\n")
    (fake / "chrt").chmod(0o755)
    monkeypatch.setenv("PATH", f"{fake}:{os.environ['PATH']}")
    povray.priority_tools.cache_clear()
    try:
        assert povray.priority_tools()[0] is None
        scene = tmp_path / "s.pov"
        scene.write_text(FLAT + "sphere { 0, 1 pigment { rgb 1 } }\n")
        job = povray.start_render(scene, tmp_path / "a.exr", 16, 12, idle=True)
        try:
            assert int(_povray_stat(job.proc.pid)[38]) == os.SCHED_IDLE
        finally:
            job.wait()
        assert (tmp_path / "a.exr").exists()
    finally:
        povray.priority_tools.cache_clear()


def test_a_cancelled_render_leaves_no_render_state_file(tmp_path):
    # POV-Ray writes IMAGE.pov-state while it renders; killed, it would stay behind
    scene = tmp_path / "slow.pov"
    scene.write_text("camera { location <0,0,-3> look_at 0 }\n"
                     "light_source { <2,4,-3> color rgb 1 }\n"
                     "sphere { 0, 1 pigment { granite } finish { reflection 0.3 } }\n")
    job = povray.start_render(scene, tmp_path / "out.png", 2000, 1500,
                              extra_args=["+A0.01", "+R5"])
    deadline = time.monotonic() + 20
    while not list(tmp_path.glob("*.pov-state")) and time.monotonic() < deadline:
        time.sleep(0.05)
    job.cancel()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["slow.pov"]


def test_an_interrupt_inside_popen_stops_the_child_it_started(monkeypatch, tmp_path):
    """A Ctrl-C that lands inside Popen after the fork (Popen then has no handle to
    return) used to leave POV-Ray running: it is held until the process is known,
    then the process is killed and the interrupt raised."""
    import signal
    import subprocess
    from povlens.pov import process
    started = []
    real_popen = subprocess.Popen

    def popen_then_interrupted(*args, **kwargs):
        proc = real_popen(["sleep", "30"], stdin=subprocess.DEVNULL)
        started.append(proc)
        signal.raise_signal(signal.SIGINT)      # arrives while Popen has not returned
        return proc

    monkeypatch.setattr(process.subprocess, "Popen", popen_then_interrupted)
    with open(tmp_path / "err.txt", "w") as err, pytest.raises(KeyboardInterrupt):
        process.start_povray(["povray"], tmp_path, err)
    assert len(started) == 1 and started[0].poll() == -signal.SIGKILL


def test_kill_descendants_reaches_grandchildren(tmp_path):
    """The last step of an interrupted command: nothing started below it survives."""
    import subprocess
    import sys
    code = ("import subprocess, time\n"
            "from povlens.util.signals import descendants, kill_descendants\n"
            "subprocess.Popen(['sh', '-c', 'sleep 60 & sleep 60 & wait'])\n"
            "time.sleep(0.5)\n"
            "found = descendants()\n"
            "kill_descendants()\n"
            "print(' '.join(map(str, found)))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=30, check=True).stdout.split()
    assert len(out) == 3                       # sh and its two sleeps
    time.sleep(0.3)
    for pid in map(int, out):
        try:
            with open(f"/proc/{pid}/stat") as f:
                assert f.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")
        except FileNotFoundError:
            pass                               # gone and reaped


def test_the_poll_interval_grows_with_the_oldest_runs_age_within_its_bounds():
    from povlens.pov.process import POLL_MAX_S, POLL_MIN_S, POLL_SHARE, poll_interval_s
    assert poll_interval_s(0.0) == POLL_MIN_S          # a young run: noticed at once
    assert poll_interval_s(1.0) == POLL_SHARE * 1.0    # 2 % of a second's run
    assert poll_interval_s(600.0) == POLL_MAX_S        # a long run: never slower than this
    ages = [0.0, 0.1, 0.5, 1.0, 2.0, 5.0, 60.0]
    steps = [poll_interval_s(a) for a in ages]
    assert steps == sorted(steps)
