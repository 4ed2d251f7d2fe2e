"""bench_auto: --method auto against the fixed methods at equal error."""

import csv
import math
import shutil

import numpy as np
import pytest

from povlens.bench.auto import shift_rmse, time_at_error
from povlens.cli import main


def test_shift_rmse_of_a_step_edge():
    # a vertical step 0 -> 1: moving it by s px changes one column by s
    img = np.zeros((10, 12, 3))
    img[:, 6:] = 1.0
    s = 0.5
    core = img[1:-1, 1:-1]
    # +x / -x: one of the 10 interior columns changes by s; +y / -y: nothing changes
    want = (2 * math.sqrt(s * s / core.shape[1]) + 0.0 + 0.0) / 4
    assert shift_rmse(img, s) == pytest.approx(want)
    assert shift_rmse(img, 0.25) < shift_rmse(img, 0.5)
    # 1.5 px: two columns change, by 0.5 and by 1; a 2 px border is left out
    want = (2 * math.sqrt((0.5 ** 2 + 1.0) / 8) + 0.0 + 0.0) / 4
    assert shift_rmse(img, 1.5) == pytest.approx(want)
    with pytest.raises(ValueError):
        shift_rmse(img, -1.0)


def test_time_at_error():
    pts = [(1.0, 0.08), (2.0, 0.04), (4.0, 0.02)]
    assert time_at_error(pts, 0.04) == pytest.approx(2.0)
    # halfway in log error between 0.04 and 0.02 -> halfway in log time
    assert time_at_error(pts, math.sqrt(0.04 * 0.02)) == pytest.approx(math.sqrt(8.0))
    assert time_at_error(pts, 0.5) == pytest.approx(1.0)    # even the cheapest is better
    assert math.isinf(time_at_error(pts, 0.01))             # never reached
    assert math.isinf(time_at_error([], 0.1))
    # a flat floor (focal_blur): the cheapest point below the target wins
    assert time_at_error([(1.0, 0.2), (1.1, 0.1), (1.2, 0.1)], 0.15) < 1.1


@pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")
def test_bench_auto_tiny(tmp_path, capsys):
    code = main(["bench", "--auto", "--quick", "--width", "24", "--height", "18",
                 "--reference-samples", "8", "--samples", "2,4", "--out", str(tmp_path)])
    assert code == 0
    with open(tmp_path / "auto_quick.csv") as f:
        rows = list(csv.DictReader(f))
    methods = [(r["method"], int(r["samples"])) for r in rows]
    assert methods[0] == ("reference", 8) and methods[1][0] == "auto"
    assert {("pinhole", 1), ("focal-blur", 2), ("focal-blur", 4), ("mesh", 2),
            ("mesh", 4)} <= set(methods)
    auto = rows[1]
    assert auto["chosen"] in ("pinhole", "focal-blur", "mesh")
    assert all(float(r["seconds"]) > 0 for r in rows)
    # one repeat (--quick): the median is that run
    assert all(float(r["median_seconds"]) == float(r["seconds"]) for r in rows[1:])
    assert all(float(r["rmse"]) > 0 for r in rows)   # reference row: its own noise
    text = (tmp_path / "auto_quick.txt").read_text()
    assert "auto/best" in text and "why auto chose" in text
    assert "(median runs)" in text
    assert "what the map cannot carry (cat's eye)" in text    # the probe's image criterion


def test_corrected_rmse_removes_reference_noise_in_quadrature():
    from povlens.bench.auto import corrected_rmse
    assert corrected_rmse(0.05, 0.03) == pytest.approx(0.04)
    assert corrected_rmse(0.05, 0.0) == pytest.approx(0.05)
    assert corrected_rmse(0.05, 0.06) == pytest.approx(0.005)   # floored, never NaN
