"""povlens.compare and ``povlens compare``: metrics, mask, agreement with OIIO, CLI."""

import json
import math

import numpy as np
import OpenImageIO as oiio
import pytest

from povlens.cli import main
from povlens.report.compare import (CompareError, compare_arrays, difference_magnitude, false_colour,
                             numpy_metrics, oiio_metrics)
from povlens.util.images import read_image, write_exr


def _buf(x):
    buf = oiio.ImageBuf(oiio.ImageSpec(x.shape[1], x.shape[0], x.shape[2], oiio.FLOAT))
    buf.set_pixels(oiio.ROI(), np.ascontiguousarray(x, dtype=np.float32))
    return buf


def _rng_image(seed, h=16, w=24, c=3):
    return np.random.default_rng(seed).random((h, w, c)).astype(np.float32)


def test_identical_images_give_zero_error_and_infinite_psnr():
    a = _rng_image(0)
    for r in (compare_arrays(a, a), numpy_metrics(a, a)):
        assert r["rmse"] == 0.0 and r["mean_abs_error"] == 0.0 and r["max_abs_error"] == 0.0
        assert math.isinf(r["psnr_db"])


def test_known_offset_gives_known_rmse_psnr_and_max():
    a = _rng_image(1) * 0.5
    b = a + np.float32(0.25)  # exact in float32 for these values up to rounding of a + 0.25
    b[3, 7, 2] = a[3, 7, 2] + np.float32(0.75)
    d = np.abs(b.astype(np.float64) - a)
    expect_rms = math.sqrt(np.mean(d ** 2))
    r = compare_arrays(a, b)
    assert r["rmse"] == pytest.approx(expect_rms, rel=1e-6)
    assert r["psnr_db"] == pytest.approx(20 * math.log10(1.0 / expect_rms), rel=1e-6)
    assert r["max_abs_error"] == pytest.approx(0.75, abs=1e-6)
    assert (r["max_at"]["x"], r["max_at"]["y"], r["max_at"]["channel"]) == (7, 3, 2)
    # A pure constant offset: RMSE = mean = max = offset, PSNR = -20 log10(offset).
    r = compare_arrays(np.zeros((4, 4, 3)), np.full((4, 4, 3), 0.1))
    assert r["rmse"] == pytest.approx(0.1, rel=1e-6)
    assert r["mean_abs_error"] == pytest.approx(0.1, rel=1e-6)
    assert r["psnr_db"] == pytest.approx(20.0, rel=1e-6)
    assert r["psnr_peak"] == 1.0


def test_alpha_is_ignored_and_grey_images_work():
    a = _rng_image(2, c=4)
    b = a.copy()
    b[..., 3] = 0.0
    assert compare_arrays(a, b)["rmse"] == 0.0
    g = _rng_image(3, c=1)
    r = compare_arrays(g, g + 0.5)
    assert r["channels"] == 1 and r["rmse"] == pytest.approx(0.5, rel=1e-6)
    with pytest.raises(CompareError, match="grey"):
        compare_arrays(g, _rng_image(3))


def test_mask_restricts_the_metrics():
    a = np.zeros((8, 10, 3), np.float32)
    b = a.copy()
    b[:, :5] = 0.2
    b[:, 5:] = 0.6
    mask = np.zeros((8, 10), np.float32)
    mask[:, :5] = 1.0
    r = compare_arrays(a, b, mask)
    assert r["masked"] and r["pixels"] == 40
    assert r["rmse"] == pytest.approx(0.2) and r["max_abs_error"] == pytest.approx(0.2)
    # Any non-zero value counts, in any channel.
    m3 = np.zeros((8, 10, 3), np.float32)
    m3[:, 5:, 1] = -3.0
    r = compare_arrays(a, b, m3)
    assert r["pixels"] == 40 and r["mean_abs_error"] == pytest.approx(0.6)
    err = difference_magnitude(a, b, mask)
    assert np.all(err[:, 5:] == 0) and np.allclose(err[:, :5], 0.2)
    with pytest.raises(CompareError, match="mask .* 3x3 pixels"):
        compare_arrays(a, b, np.ones((3, 3)))
    with pytest.raises(CompareError, match="no non-zero"):
        compare_arrays(a, b, np.zeros((8, 10)))


@pytest.mark.parametrize("seed", range(4))
def test_numpy_metrics_agree_with_oiio_compare(seed):
    rng = np.random.default_rng(seed)
    a = (rng.random((31, 17, 4)) * 3).astype(np.float32)
    b = (a + rng.normal(0, 0.05 * (seed + 1), a.shape)).astype(np.float32)
    mine, theirs = numpy_metrics(a, b), oiio_metrics(a, b)
    for k in ("rmse", "psnr_db", "mean_abs_error", "max_abs_error"):
        assert mine[k] == pytest.approx(theirs[k], rel=1e-6), k
    assert mine["max_at"] == theirs["max_at"]
    # and directly against OIIO on the RGB channels of the full buffers
    bufs = []
    for x in (a, b):
        buf = oiio.ImageBuf(oiio.ImageSpec(17, 31, 4, oiio.FLOAT))
        buf.set_pixels(oiio.ROI(), x)
        bufs.append(buf)
    r = oiio.ImageBufAlgo.compare(bufs[0], bufs[1], 1e9, 1e9, roi=oiio.ROI(0, 17, 0, 31, 0, 1, 0, 3))
    assert mine["rmse"] == pytest.approx(r.rms_error, rel=1e-6)
    # OIIO's own PSNR takes the peak as max(1, largest value of the images); ours is
    # always 1.0 (linear white), so they differ by exactly that factor for HDR images.
    peak = max(1.0, float(a.max()), float(b.max()))
    assert mine["psnr_db"] == pytest.approx(r.PSNR - 20 * math.log10(peak), rel=1e-6, abs=1e-9)
    small = oiio.ImageBufAlgo.compare(*[_buf(x.clip(0, 1)) for x in (a, b)], 1e9, 1e9,
                                      roi=oiio.ROI(0, 17, 0, 31, 0, 1, 0, 3))
    assert compare_arrays(a.clip(0, 1), b.clip(0, 1))["psnr_db"] == pytest.approx(small.PSNR, rel=1e-6)
    # an all-ones mask is the unmasked comparison
    assert numpy_metrics(a, b, np.ones((31, 17)))["rmse"] == pytest.approx(theirs["rmse"], rel=1e-6)


def test_size_mismatch_is_a_clear_error():
    with pytest.raises(CompareError, match="B is 5x4 pixels but A is 6x4"):
        compare_arrays(np.zeros((4, 6, 3)), np.zeros((4, 5, 3)))


def test_false_colour_scaling():
    err = np.array([[0.0, 0.5], [1.0, 2.0]])
    rgb, scale = false_colour(err)
    assert scale == 2.0 and rgb.shape == (2, 2, 3) and rgb.dtype == np.float32
    assert np.all((rgb >= 0) & (rgb <= 1))
    rgb2, scale2 = false_colour(err, scale=1.0)
    assert scale2 == 1.0 and np.allclose(rgb2[1, 0], rgb2[1, 1])  # saturated
    rgb0, _ = false_colour(np.zeros((2, 2)))
    assert np.allclose(rgb0, rgb0[0, 0])


# ----- command line (in-process: fast) -------------------------------------------------

@pytest.fixture
def pair(tmp_path):
    a = np.zeros((6, 8, 3), np.float32)
    b = a.copy()
    b[2, 3, 1] = 0.5
    pa, pb = tmp_path / "a.exr", tmp_path / "b.exr"
    write_exr(pa, a)
    write_exr(pb, b)
    return pa, pb


def test_cli_json(pair, tmp_path, capsys):
    pa, pb = pair
    diff = tmp_path / "diff.png"
    assert main(["compare", str(pa), str(pb), "--json", "-o", str(diff)]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["max_abs_error"] == pytest.approx(0.5)
    assert d["rmse"] == pytest.approx(math.sqrt(0.25 / (6 * 8 * 3)), rel=1e-6)
    assert d["psnr_peak"] == 1.0 and d["max_at"] == {"x": 3, "y": 2, "channel": 1}
    assert d["diff_image"]["scale"] == pytest.approx(0.5)
    img = read_image(diff)
    assert img.shape == (6, 8, 3)
    assert not np.allclose(img[2, 3], img[0, 0])  # the differing pixel stands out
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temp left


def test_cli_identical_psnr_null_in_json_and_inf_in_text(pair, capsys):
    pa, _ = pair
    assert main(["compare", str(pa), str(pa), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["psnr_db"] is None and d["rmse"] == 0.0
    assert main(["compare", str(pa), str(pa)]) == 0
    out = capsys.readouterr().out
    assert "PSNR          inf dB (peak 1)" in out


def test_cli_mask(pair, tmp_path, capsys):
    pa, pb = pair
    m = np.zeros((6, 8), np.float32)
    m[0, 0] = 1
    write_exr(tmp_path / "m.exr", m)
    assert main(["compare", str(pa), str(pb), "--mask", str(tmp_path / "m.exr"), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["pixels"] == 1 and d["rmse"] == 0.0 and d["masked"]


def test_cli_errors_name_the_file_and_exit_2(pair, tmp_path, capsys):
    pa, pb = pair
    small = tmp_path / "small.exr"
    write_exr(small, np.zeros((3, 3, 3)))
    junk = tmp_path / "junk.exr"
    junk.write_text("not an image")
    cases = [([str(pa), str(small)], "small.exr is 3x3"),
             ([str(pa), str(tmp_path / "missing.exr")], "missing.exr does not exist"),
             ([str(junk), str(pb)], "cannot read image .*junk.exr"),
             ([str(pa), str(pb), "--mask", str(small)], "mask .*small.exr is 3x3")]
    for args, msg in cases:
        assert main(["compare", *args]) == 2
        err = capsys.readouterr().err
        assert "Traceback" not in err
        assert __import__("re").search(msg, err), err
    assert not (tmp_path / "diff.png").exists()
