"""One writer per render folder (povlens.plan.folder_lock): two 'povlens render', or
'make -j2' beside 'povlens render', on one folder wait for each other instead of
deleting each other's ray meshes, and end with the image of a single run.  With the
real POV-Ray, small images."""

import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from povlens.plan.folder_lock import folder_lock, lock_holders
from povlens.plan.render_folder import RenderFolder
from povlens.util.images import read_image

from conftest import ROOT

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")

OPTIONS = [str(ROOT / "scenes" / "paper.pov"), "--lens", "dgauss.50mm", "--focus", "4",
           "--method", "mesh", "--width", "48", "--height", "36", "--samples", "8",
           "--batch-size", "2"]


def povlens(*args) -> list[str]:
    return [sys.executable, "-m", "povlens", *map(str, args)]


def run(cmd):
    return subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=600)


def start(cmd):
    return subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The image of one 'povlens render' alone."""
    out = tmp_path_factory.mktemp("lock") / "ref"
    r = run(povlens("render", *OPTIONS, "-o", out, "-q"))
    assert r.returncode == 0, r.stderr
    return read_image(out / "image.exr")


def test_two_renders_of_one_folder_wait_and_give_the_single_image(tmp_path, reference):
    out = tmp_path / "out"
    procs = [start(povlens("render", *OPTIONS, "-o", out, "-q")) for _ in range(2)]
    results = [(p.wait(timeout=600), p.communicate()[1]) for p in procs]
    for code, err in results:
        assert code == 0, err               # without the lock: exit 3, an unclosed block
        assert "Traceback" not in err
    waited = [err for _, err in results if "is in use by PID" in err]
    assert waited, [err for _, err in results]
    assert str(out) in waited[0] and "povlens render" in waited[0]
    assert np.array_equal(read_image(out / "image.exr"), reference)


def test_make_j2_beside_povlens_render_gives_the_single_image(tmp_path, reference):
    out = tmp_path / "out"
    r = run(povlens("convert", *OPTIONS, "-o", out))
    assert r.returncode == 0, r.stderr
    make = start(["make", "-j2", "-C", str(out)])
    time.sleep(0.5)                          # make's recipes hold the folder
    render = start(povlens("render", *OPTIONS, "-o", out, "-q"))
    for p in (make, render):
        code = p.wait(timeout=600)
        assert code == 0, p.communicate()
    assert np.array_equal(read_image(out / "image.exr"), reference)
    assert not list((out / "samples").glob("*.inc"))


def test_two_makes_in_one_folder_give_the_single_image(tmp_path, reference):
    out = tmp_path / "out"
    assert run(povlens("convert", *OPTIONS, "-o", out)).returncode == 0
    makes = [start(["make", "-j2", "-C", str(out)]) for _ in range(2)]
    for p in makes:
        assert p.wait(timeout=600) == 0, p.communicate()
    assert np.array_equal(read_image(out / "image.exr"), reference)


def test_a_killed_holder_leaves_no_stale_lock(tmp_path):
    out = tmp_path / "out"
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time\nfrom povlens.plan.folder_lock import "
         "folder_lock\nwith folder_lock(sys.argv[1]):\n    print('held', flush=True)\n"
         "    time.sleep(60)\n", str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        holders = lock_holders(RenderFolder(out).lock_file)
        assert holders and f"PID {holder.pid}" in holders[0]
    finally:
        os.kill(holder.pid, signal.SIGKILL)
        holder.wait()
    t0 = time.perf_counter()
    with folder_lock(out):                  # the kernel dropped it with the process
        pass
    assert time.perf_counter() - t0 < 1.0


def test_a_refused_conversion_leaves_no_folder_behind(tmp_path):
    out = tmp_path / "new"
    r = run(povlens("render", *OPTIONS, "--povray-option", "+W320", "-o", out, "-q"))
    assert r.returncode == 2, r.stderr
    assert not out.exists()
