"""``povlens bench`` on a tiny image: the CSV has every row and (c)'s error falls with N."""

import csv
import shutil

import pytest

from povlens.bench.time_error import Row, time_to_error
from povlens.cli import main

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")


def test_bench_quick_tiny(tmp_path, capsys):
    code = main(["bench", "--quick", "--width", "24", "--height", "18", "--lenses",
                 "dgauss.50mm", "--samples", "2,8", "--reference-samples", "16",
                 "--pbrt-rays", "4096", "--tracer-rays", "0", "--out", str(tmp_path)])
    assert code == 0
    with open(tmp_path / "time_error_quick.csv") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["method", "lens", "samples", "seconds", "rmse"]
    got = sorted((r["method"], r["lens"], int(r["samples"])) for r in rows)
    want = sorted((m, "dgauss.50mm", n) for m in ("naive-random", "pbrt-random",
                                                   "povlens-sobol", "focal-blur",
                                                   "povlens-field")
                  for n in (2, 8))
    assert got == want
    assert all(float(r["seconds"]) > 0 and float(r["rmse"]) > 0 for r in rows)
    c = {int(r["samples"]): float(r["rmse"]) for r in rows if r["method"] == "povlens-sobol"}
    assert c[8] < c[2]
    assert (tmp_path / "time_error_quick.png").stat().st_size > 0
    assert "time to equal rmse" in (tmp_path / "time_error_quick.txt").read_text()
    assert "focal_blur error floor" in capsys.readouterr().out


def test_time_to_error_interpolates_in_log_log():
    rows = [Row("m", "l", 4, 1.0, 0.1), Row("m", "l", 16, 4.0, 0.05)]
    t, extrapolated = time_to_error(rows, 0.1 / 2 ** 0.5)
    assert t == pytest.approx(2.0) and not extrapolated
    t, extrapolated = time_to_error(rows, 0.025)
    assert t == pytest.approx(16.0) and extrapolated
