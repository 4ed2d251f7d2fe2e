"""``povlens compare`` on an image with NaN or infinite pixels: it names the file, how
many pixels and where the first is, and exits 2 instead of printing nan."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from povlens.report.compare import CompareError, non_finite_pixels, require_finite
from povlens.util.images import write_exr


@pytest.fixture
def images(tmp_path):
    a = np.full((24, 32, 3), 0.5, np.float32)
    b = a.copy()
    b[3, 5, 1] = np.nan
    b[4, 6, :] = np.inf
    b[10, 20, 0] = np.nan
    pa, pb = tmp_path / "good.exr", tmp_path / "broken.exr"
    write_exr(pa, a)
    write_exr(pb, b)
    mask = np.ones((24, 32, 3), np.float32)
    mask[:12] = 0                                  # the top half: every bad pixel
    write_exr(tmp_path / "mask.exr", mask)
    return tmp_path, pa, pb


def _compare(*args, cwd):
    return subprocess.run([sys.executable, "-m", "povlens", "compare", *map(str, args)],
                          cwd=cwd, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("order", ["broken second", "broken first"])
def test_the_file_with_non_finite_pixels_is_named(images, order):
    tmp, pa, pb = images
    r = _compare(*((pa, pb) if order == "broken second" else (pb, pa)), cwd=tmp)
    assert r.returncode == 2, r.stdout + r.stderr
    assert f"{pb} holds 3 non-finite pixel(s) of 768 (2 NaN, 1 infinite; the first at " \
           "x=5 y=3)" in r.stderr, r.stderr
    assert str(pa) + " holds" not in r.stderr
    assert "nan" not in r.stdout.lower() and "Traceback" not in r.stderr


def test_json_too_and_a_mask_that_leaves_them_out_compares(images):
    tmp, pa, pb = images
    r = _compare(pa, pb, "--json", cwd=tmp)
    assert r.returncode == 2 and r.stdout == "" and "broken.exr holds 3" in r.stderr
    r = _compare(pa, pb, "--mask", tmp / "mask.exr", cwd=tmp)
    assert r.returncode == 0, r.stderr
    assert "RMSE          0\n" in r.stdout


def test_the_count_is_over_colour_channels_and_the_mask():
    x = np.zeros((4, 4, 4), np.float32)
    x[0, 0, 3] = np.nan                            # alpha: not a colour channel
    x[1, 1, 0] = -np.inf
    assert non_finite_pixels(x) == {"pixels": 1, "nan": 0, "inf": 1, "of": 16,
                                    "first": (1, 1)}
    m = np.ones((4, 4))
    m[1, 1] = 0
    assert non_finite_pixels(x, m)["pixels"] == 0
    with pytest.raises(CompareError, match=r"^b holds 1 non-finite pixel\(s\) of 16"):
        require_finite({"a": np.zeros((4, 4, 3)), "b": x})
