"""povlens.util.images and povlens.rendering.composite."""

from __future__ import annotations

import numpy as np
import pytest

from povlens.rendering.composite import composite
from povlens.errors import PovlensError
from povlens.util.images import ImageError, read_image, write_exr, write_png_srgb


def _srgb(x):
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def _no_temp_files(folder):
    return [p.name for p in folder.iterdir() if ".tmp" in p.name] == []


def test_exr_roundtrip_float32(tmp_path):
    rng = np.random.default_rng(0)
    a = (rng.random((5, 7, 3)) * 3).astype(np.float32)
    p = write_exr(tmp_path / "a.exr", a)
    b = read_image(p)
    assert b.dtype == np.float32 and b.shape == (5, 7, 3)
    np.testing.assert_array_equal(a, b)
    assert _no_temp_files(tmp_path)


def test_exr_half_and_shapes(tmp_path):
    a = np.full((4, 6), 1.0 / 3.0)
    b = read_image(write_exr(tmp_path / "g.exr", a, half=True))
    assert b.shape == (4, 6, 1) and b.dtype == np.float32
    np.testing.assert_allclose(b[..., 0], a, rtol=1e-3)
    rgba = np.random.default_rng(1).random((3, 2, 4))
    assert read_image(write_exr(tmp_path / "rgba.exr", rgba)).shape == (3, 2, 4)
    with pytest.raises(ImageError, match="shape"):
        write_exr(tmp_path / "bad.exr", np.zeros((2, 2, 7)))


def test_png_srgb(tmp_path):
    lin = np.linspace(0.0, 1.5, 4 * 6 * 3).reshape(4, 6, 3).astype(np.float32)
    lin[0, 0, 0] = np.nan
    p = write_png_srgb(tmp_path / "p.png", lin)
    enc = read_image(p)  # 8-bit values in [0, 1], still sRGB-encoded
    expect = _srgb(np.nan_to_num(lin, nan=0.0))
    assert np.abs(enc - expect).max() <= 0.51 / 255
    rgba = np.concatenate([lin, np.full((4, 6, 1), 0.5, np.float32)], axis=2)
    enc4 = read_image(write_png_srgb(tmp_path / "p4.png", rgba))
    assert enc4.shape == (4, 6, 4)
    assert np.abs(enc4[..., 3] - 0.5).max() <= 0.51 / 255  # alpha is not converted
    assert _no_temp_files(tmp_path)


def test_read_errors(tmp_path):
    with pytest.raises(ImageError, match="does not exist"):
        read_image(tmp_path / "missing.exr")
    junk = tmp_path / "junk.exr"
    junk.write_text("not an image")
    with pytest.raises(ImageError) as info:
        read_image(junk)
    assert "junk.exr" in str(info.value) and info.value.hint


def test_write_into_missing_folder(tmp_path):
    with pytest.raises(PovlensError, match="does not exist"):
        write_exr(tmp_path / "nope" / "a.exr", np.zeros((2, 2, 3)))


def _samples(tmp_path, k=3, shape=(5, 4, 3), half=True):
    rng = np.random.default_rng(2)
    imgs = [rng.random(shape).astype(np.float32) * 2 for _ in range(k)]
    paths = [write_exr(tmp_path / f"s{i}.exr", im, half=half) for i, im in enumerate(imgs)]
    return [read_image(p) for p in paths], paths


def test_composite_mean_reads_half_as_float(tmp_path):
    imgs, paths = _samples(tmp_path, k=4)
    out = composite(paths)
    assert out.dtype == np.float32 and out.shape == (5, 4, 3)
    np.testing.assert_allclose(out, np.mean(np.array(imgs, np.float64), axis=0), atol=1e-6)


def test_composite_weighted_and_drop(tmp_path):
    imgs, paths = _samples(tmp_path, k=3, shape=(6, 4, 3))
    w = [np.ones((5, 4)), np.full((5, 4), 2.0), np.zeros((5, 4))]
    w[0][0, 0] = w[1][0, 0] = 0.0  # a pixel with zero total weight
    out = composite(paths, w, drop_top_rows=1)
    assert out.shape == (5, 4, 3)
    num = sum(wk[..., None] * im[1:] for wk, im in zip(w, imgs))
    den = sum(w)[..., None]
    expect = np.divide(num, den, out=np.zeros_like(num), where=den > 0)
    np.testing.assert_allclose(out, expect, atol=1e-6)
    assert np.all(np.isfinite(out)) and np.all(out[0, 0] == 0)


def test_composite_errors(tmp_path):
    imgs, paths = _samples(tmp_path, k=2)
    with pytest.raises(PovlensError, match="no sample"):
        composite([])
    with pytest.raises(PovlensError, match="weight"):
        composite(paths, [np.ones((5, 4))])
    with pytest.raises(PovlensError, match="shape"):
        composite(paths, [np.ones((5, 4)), np.ones((4, 4))])
    with pytest.raises(PovlensError, match="negative"):
        composite(paths, [np.ones((5, 4)), -np.ones((5, 4))])
    other = write_exr(tmp_path / "other.exr", np.zeros((3, 4, 3)))
    with pytest.raises(PovlensError, match="same size"):
        composite([paths[0], other])
    with pytest.raises(PovlensError, match="does not exist"):
        composite([paths[0], tmp_path / "gone.exr"])
