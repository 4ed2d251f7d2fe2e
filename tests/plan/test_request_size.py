"""Requests far beyond the usual say what they cost and need --yes (issue 24 item 9);
a lens with thousands of clipped rows warns about a few of them and counts the rest."""

from __future__ import annotations

import subprocess
import sys
import warnings

import pytest

from conftest import ROOT
from povlens.lens.prescription import CLIP_WARNINGS_SHOWN, read_lens
from povlens.plan.convert import ConvertOptions, convert
from povlens.plan.request_size import (LIMITS, BigRequestError, BigRequestWarning,
                                       request_costs)

SCENE = str(ROOT / "scenes" / "paper.pov")


def _povlens(*args):
    return subprocess.run([sys.executable, "-m", "povlens", *map(str, args)],
                          capture_output=True, text=True, cwd=ROOT, timeout=300)


def _plates_lens(path, surfaces: int, meet: bool = True):
    """A 'lens' of ``surfaces`` surfaces: thin plates (whose faces meet inside their
    stated aperture, so that each row is clipped, when ``meet``), a stop and a
    singlet."""
    rows = ["# plates\n"]
    back = "-1000" if meet else "1000"
    for _ in range((surfaces - 3) // 2):
        rows += ["1000\t0.2\t1.5\t30\n", f"{back}\t0.2\t1\t30\n"]
    rows += ["0\t1\t0\t20\n", "50\t3\t1.6\t40\n", "-50\t50\t1\t40\n"]
    path.write_text("".join(rows))
    return path


def test_many_samples_stop_with_their_expected_time_and_go_on_with_yes(tmp_path):
    out = tmp_path / "o"
    r = _povlens("convert", SCENE, "--lens", "dgauss.50mm", "--method", "mesh",
                 "--samples", "100000", "-o", out)
    assert r.returncode == 2, r.stderr
    assert "100,000 lens samples at 640x480" in r.stderr and "take about 17.1 h" in r.stderr
    assert "--yes" in r.stderr and "Traceback" not in r.stderr
    assert not out.exists()                               # nothing written
    r = _povlens("convert", SCENE, "--lens", "dgauss.50mm", "--method", "mesh",
                 "--samples", "100000", "--width", 32, "--height", 24, "--yes", "-o", out)
    assert r.returncode == 0, r.stderr
    assert "povlens: warning: 100,000 lens samples at 32x24" in r.stderr
    assert "going on (--yes)" in r.stderr and (out / "plan.json").is_file()


def test_usual_requests_say_nothing(tmp_path):
    r = _povlens("convert", SCENE, "--lens", "dgauss.50mm", "--method", "mesh",
                 "--samples", "1024", "--width", 32, "--height", 24, "-o", tmp_path / "o")
    assert r.returncode == 0 and "warning" not in r.stderr, r.stderr
    assert request_costs(256, 1920, 1080, read_lens("dgauss.50mm")) == []


def test_a_huge_image_stops_with_its_memory(tmp_path):
    r = _povlens("convert", SCENE, "--lens", "dgauss.50mm", "--method", "pinhole",
                 "--width", 40000, "--height", 30000, "-o", tmp_path / "o")
    assert r.returncode == 2 and "40000x30000 (1200 Mpx)" in r.stderr, r.stderr
    assert "GiB of memory" in r.stderr


def test_a_lens_of_thousands_of_surfaces_is_timed_and_its_warnings_summarised(tmp_path):
    lens = _plates_lens(tmp_path / "plates.dat", 2001)
    r = _povlens("convert", SCENE, "--lens", lens, "--method", "pinhole",
                 "--width", 32, "--height", 24, "-o", tmp_path / "o")
    assert r.returncode == 2, r.stderr
    assert "has 2,001 surfaces (real lenses have up to about 40)" in r.stderr
    assert "focusing it alone takes about" in r.stderr
    clipped = [line for line in r.stderr.splitlines() if "clipped" in line]
    assert len(clipped) == CLIP_WARNINGS_SHOWN + 1, clipped
    assert "1,995 more rows' aperture diameters clipped the same way" in clipped[-1]


def test_the_api_refuses_or_warns_as_yes_says(tmp_path):
    lens = _plates_lens(tmp_path / "plates.dat", LIMITS.surfaces + 11, meet=False)
    opts = ConvertOptions.of(SCENE, str(lens), str(tmp_path / "o"), method="pinhole",
                             width=16, height=12, focus=5.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(BigRequestError, match="211 surfaces"):
            convert(opts)
    with pytest.warns(BigRequestWarning, match="211 surfaces"):
        convert(opts.replace(yes=True))
