"""A full disk, a read-only folder and a file size limit, for real: every error names
its cause and the path, exits 4 (an output could not be written), keeps POV-Ray's own
words, leaves nothing half-written at a final name, and a later run with room resumes.

The full disk is a small tmpfs mounted for the test (root only: skipped, saying why,
elsewhere); the file size limit is RLIMIT_FSIZE set in the command's process.
"""
from __future__ import annotations

import os
import resource
import shutil
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

from conftest import ROOT
from povlens.errors import PovrayWriteError, WriteError
from povlens.pov.process import render
from povlens.util.files import write_bytes, write_text

SCENE = ROOT / "scenes" / "paper.pov"
SMALL = ["--width", "96", "--height", "72"]


@pytest.fixture
def tmpfs(tmp_path):
    """Mount a tmpfs of a given size (``mount("40k")``, ``mount("1m", ro=True)``); every
    one is unmounted at the end."""
    mounted: list[Path] = []
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs (a real full disk) needs root")

    def mount(size: str, ro: bool = False) -> Path:
        point = tmp_path / f"fs-{uuid.uuid4().hex[:8]}"
        point.mkdir()
        opts = f"size={size}" + (",ro" if ro else "")
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(point)],
                           capture_output=True, text=True)
        if r.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here (a container without CAP_SYS_ADMIN?): "
                        f"{r.stderr.strip()}")
        mounted.append(point)
        return point

    try:
        yield mount
    finally:
        for point in reversed(mounted):
            if subprocess.run(["umount", str(point)], capture_output=True).returncode != 0:
                subprocess.run(["umount", "-l", str(point)], capture_output=True)


def _povlens(args, cwd, **kw):
    return subprocess.run([sys.executable, "-m", "povlens", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=120, **kw)


def _half_written(folder: Path) -> list[str]:
    return [p.name for p in folder.rglob("*")
            if ".tmp" in p.name or p.suffix == ".pov-state" or p.name.startswith(".povlens-")]


def test_povray_output_on_a_full_disk_names_the_cause_and_a_rerun_resumes(tmpfs, tmp_path):
    # 40 KiB: room for the render folder's small files, none for POV-Ray's state file
    disk = tmpfs("40k")
    out = disk / "out"
    r = _povlens(["render", str(SCENE), "--lens", "dgauss.50mm", "--focus", "4",
                  "--method", "pinhole", *SMALL, "-o", str(out)], tmp_path)
    assert (out / "plan.json").is_file(), f"Python's writes failed first:\n{r.stderr}"
    assert r.returncode == WriteError.exit_code == 4, r.stderr
    err = r.stderr
    assert "no space left on device" in err and str(out / "view-pinhole.exr") in err, err
    assert "POV-Ray said: Cannot access data in file." in err, err   # POV-Ray's own words
    assert "unclosed block" not in err and "fix the scene" not in err
    assert "Traceback" not in err
    assert not (out / "image.exr").exists() and _half_written(out) == []
    subprocess.run(["mount", "-o", "remount,size=4m", str(disk)], check=True)
    r = _povlens(["render", str(SCENE), "--lens", "dgauss.50mm", "--focus", "4",
                  "--method", "pinhole", *SMALL, "-o", str(out)], tmp_path)
    assert r.returncode == 0, r.stderr
    assert (out / "image.exr").is_file() and _half_written(out) == []


def test_a_lens_sample_on_a_full_disk_names_the_cause(tmpfs, tmp_path):
    disk = tmpfs("100k")               # the folder fits, POV-Ray's state file does not
    out = disk / "out"
    r = _povlens(["render", str(SCENE), "--lens", "dgauss.50mm", "--focus", "4",
                  "--method", "mesh", "--samples", "2", *SMALL, "-o", str(out)], tmp_path)
    assert (out / "plan.json").is_file(), f"Python's writes failed first:\n{r.stderr}"
    assert r.returncode == 4, r.stderr
    assert "no space left on device" in r.stderr and str(out / "samples") in r.stderr
    assert "POV-Ray said: Cannot access data in file." in r.stderr
    assert "fix the scene" not in r.stderr and _half_written(out) == []


@pytest.mark.parametrize("method", ["pinhole", "mesh"])     # mesh: pupil.npz first
def test_python_writes_on_a_full_disk_name_the_path(tmpfs, tmp_path, method):
    disk = tmpfs("8k")
    out = disk / "out"
    r = _povlens(["convert", str(SCENE), "--lens", "dgauss.50mm", "--focus", "4",
                  "--method", method, *SMALL, "-o", str(out)], tmp_path)
    assert r.returncode == 4, r.stderr
    line = next(ln for ln in r.stderr.splitlines() if "error:" in ln)
    assert f"cannot write {out}/" in line and "no space left on device" in line, line
    assert "[Errno 28]" not in r.stderr and "Traceback" not in r.stderr
    assert _half_written(out) == [] and not (out / "plan.json").exists()


def test_the_atomic_writers_name_the_final_path(tmpfs):
    disk = tmpfs("16k")
    with pytest.raises(WriteError) as e:
        write_bytes(disk / "big.bin", b"x" * 100_000)
    assert e.value.path == str(disk / "big.bin") and e.value.exit_code == 4
    assert "no space left on device (0 bytes free" in str(e.value)
    assert list(disk.iterdir()) == []                     # no temporary left either
    write_text(disk / "small.txt", "fits\n")             # a small file still fits
    assert (disk / "small.txt").read_text() == "fits\n"


def test_povray_in_a_read_only_folder(tmpfs, tmp_path):
    ro = tmpfs("1m", ro=True)
    scene = shutil.copy(SCENE, tmp_path / "paper.pov")
    with pytest.raises(PovrayWriteError) as e:
        render(scene, ro / "img.exr", 32, 24)
    text = str(e.value)
    assert e.value.exit_code == 4 and "read-only file system" in text
    assert str(ro / "img.exr") in text and "POV-Ray said: Cannot" in text, text
    assert "free some space" not in text


def test_povray_past_the_file_size_limit(tmp_path):
    """RLIMIT_FSIZE: POV-Ray is killed by SIGXFSZ with nothing printed (Python's own
    small files fit under the limit)."""
    out = tmp_path / "out"

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (16384, 16384))
    r = _povlens(["render", str(SCENE), "--lens", "dgauss.50mm", "--focus", "4",
                  "--method", "pinhole", *SMALL, "-o", str(out)], tmp_path, preexec_fn=limit)
    assert r.returncode == 4, r.stderr
    assert "killed by signal SIGXFSZ" in r.stderr and "file size limit" in r.stderr
    assert str(out / "view-pinhole.exr") in r.stderr and "ulimit -f" in r.stderr
    assert "fix the scene" not in r.stderr and "Traceback" not in r.stderr
    assert _half_written(out) == []


def test_a_parse_warning_in_the_wrapper_is_no_parse_error():
    """The wrapper's 'More than one camera' warning names its line: a failed write must
    not be read as a scene ending inside an unclosed block."""
    from povlens.pov.povray_output import error_in_wrapper
    text = ("File 'pinhole.pov' line 18: Parse Warning: More than one camera in scene.\n"
            "Cannot access data in file.\nRender failed")
    assert error_in_wrapper(Path("pinhole.pov"), ROOT, text) is None


def _fill(folder: Path) -> None:
    """Write into ``folder`` until its file system is full."""
    fd = os.open(folder / "filler", os.O_WRONLY | os.O_CREAT)
    try:
        while os.write(fd, b"\0" * 4096):
            pass
    except OSError:
        pass
    finally:
        os.close(fd)


def test_an_optional_cache_on_a_full_disk_is_left_alone(tmpfs, tmp_path):
    """The POV-Ray version cache ($XDG_CACHE_HOME) cannot be written: the render goes
    on (a WriteError is an OSError, which the cache's writer lets pass)."""
    cache = tmpfs("16k")
    (cache / "povlens").mkdir()
    _fill(cache)
    out = tmp_path / "out"
    r = _povlens(["render", str(SCENE), "--lens", "dgauss.50mm", "--focus", "4",
                  "--method", "pinhole", *SMALL, "-o", str(out)], tmp_path,
                 env=dict(os.environ, XDG_CACHE_HOME=str(cache)))
    assert r.returncode == 0, r.stderr
    assert (out / "image.exr").is_file()
    assert sorted(p.name for p in (cache / "povlens").iterdir()) == []


def test_a_missing_include_is_the_scenes_error_not_a_write_failure(tmp_path):
    scene = tmp_path / "s.pov"
    scene.write_text('#version 3.7;\n#include "not_there.inc"\n'
                     "camera { location <0, 0, -5> look_at 0 }\n")
    with pytest.raises(Exception) as e:
        render(scene, tmp_path / "img.exr", 32, 24)
    assert not isinstance(e.value, WriteError) and e.value.exit_code == 3
    assert "not_there.inc" in str(e.value)


def test_images_on_a_full_disk_are_refused_not_cut_short(tmpfs):
    """OpenImageIO's EXR writer fails ('Failed to write pixel data'); its PNG writer
    reports nothing and leaves a file cut at the last free byte: neither may appear."""
    import numpy as np
    from povlens.util.images import write_exr, write_png_srgb
    disk = tmpfs("16k")
    pixels = np.random.default_rng(1).random((200, 200, 3)).astype(np.float32)
    for write, name in ((write_exr, "image.exr"), (write_png_srgb, "image.png")):
        with pytest.raises(WriteError, match="no space left on device") as e:
            write(disk / name, pixels)
        assert e.value.path == str(disk / name)
        assert list(disk.iterdir()) == [], name


def test_a_file_system_without_a_size_is_not_taken_as_full(tmpfs):
    """An unlimited tmpfs (size=0) reports 0 blocks and 0 free: writes still go."""
    disk = tmpfs("0")
    assert os.statvfs(disk).f_blocks == 0
    write_text(disk / "plan.txt", "x" * 100_000)
    assert (disk / "plan.txt").stat().st_size == 100_000
