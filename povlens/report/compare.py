"""Comparing two renders: error metrics in linear light and a false-colour difference.

Pure functions: arrays in, dicts and arrays out (the ``povlens compare`` command
does the reading and writing).  Images are ``(H, W, C)`` arrays as returned by
:func:`povlens.util.images.read_image`, in *linear* light (EXR).

Metrics are over the colour channels only: R, G, B (the first three channels;
a single grey channel for 1- or 2-channel images; alpha is ignored), every
channel of every counted pixel weighted equally:

* ``rmse`` = sqrt(mean((A - B)^2)),
* ``psnr`` = 20 log10(peak / rmse) in dB with **peak = 1.0** (linear white;
  HDR values above 1 are not clipped, so the PSNR of bright renders is only a
  relative figure; OpenImageIO's own PSNR instead takes max(1, brightest value)
  as the peak, so the two differ for HDR images); identical images give ``inf``,
* ``mean_abs_error`` = mean(|A - B|), ``max_abs_error`` = max(|A - B|), with the
  pixel (x, y; x right, y down from the top-left corner) and channel of the max.

Without a mask these come from OpenImageIO's own ``ImageBufAlgo.compare``;
with a mask (pixels where any channel of the mask is non-zero count) they are
computed with numpy in float64 (the tests check both ways agree).

What the eye sees of a difference: :func:`flip_error`, NVIDIA's FLIP (Andersson et al.
2020, the ``flip-evaluator`` package), LDR-FLIP of the sRGB previews (linear light
clipped to [0, 1] and sRGB-encoded, as ``image.png`` shows it) at its default 67 pixels
per degree: a per-pixel error in [0, 1] and its mean.  It ranks structured errors --
steps, ghost copies, rings -- above noise of the same RMSE, which RMSE alone does not.
"""

from __future__ import annotations

import math

import numpy as np
import OpenImageIO as oiio

from povlens.errors import PovlensError

__all__ = ["CompareError", "PSNR_PEAK", "colour_channels", "compare_arrays", "numpy_metrics",
           "oiio_metrics", "difference_magnitude", "false_colour", "flip_error", "srgb_preview",
           "FLIP_PPD", "non_finite_pixels", "require_finite"]

#: FLIP's viewing condition: pixels per degree of visual angle (its default, a 0.7 m
#: distant 24" 4K monitor).
FLIP_PPD = 67.0

#: Peak signal of the PSNR: linear white.
PSNR_PEAK = 1.0


class CompareError(PovlensError):
    """Images that cannot be compared (different sizes or channels, a bad mask)."""


def _hwc(a: np.ndarray, name: str) -> np.ndarray:
    a = np.asarray(a)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[0] < 1 or a.shape[1] < 1 or a.shape[2] < 1:
        raise CompareError(f"{name}: expected an (H, W) or (H, W, C) image, got shape {a.shape}")
    return a


def colour_channels(n_channels: int) -> int:
    """How many leading channels are colour: 3 for RGB(A) and more, 1 for Y / YA."""
    return 3 if n_channels >= 3 else 1


def _check_pair(a, b, name_a: str, name_b: str) -> tuple[np.ndarray, np.ndarray, int]:
    a, b = _hwc(a, name_a), _hwc(b, name_b)
    if a.shape[:2] != b.shape[:2]:
        raise CompareError(
            f"{name_b} is {b.shape[1]}x{b.shape[0]} pixels but {name_a} is "
            f"{a.shape[1]}x{a.shape[0]}; images of different sizes cannot be compared",
            "render both images at the same resolution")
    ca, cb = colour_channels(a.shape[2]), colour_channels(b.shape[2])
    if ca != cb:
        raise CompareError(
            f"{name_a} has {ca} colour channel(s) but {name_b} has {cb}; cannot compare "
            f"grey with colour")
    return a, b, ca


def _mask_pixels(mask, shape: tuple[int, int], name: str) -> np.ndarray:
    m = _hwc(mask, name)
    if m.shape[:2] != shape:
        raise CompareError(
            f"mask {name} is {m.shape[1]}x{m.shape[0]} pixels but the images are "
            f"{shape[1]}x{shape[0]}", "the mask must have the size of the images")
    return np.any(m != 0, axis=2)


def non_finite_pixels(image: np.ndarray, mask: np.ndarray | None = None,
                      name_mask: str = "mask") -> dict:
    """Pixels of ``image`` with a NaN or infinite colour channel (alpha is not looked
    at), among those where ``mask`` is non-zero (all without a mask).

    Returns
    -------
    dict
        ``pixels`` (non-finite ones), ``nan`` (with a NaN), ``inf`` (with an infinity
        and no NaN), ``of`` (pixels looked at), ``first`` ((x, y) of the first in
        reading order, or None).
    """
    a = _hwc(image, "image")
    colour = a[:, :, :colour_channels(a.shape[2])]
    sel = (np.ones(a.shape[:2], bool) if mask is None
           else _mask_pixels(mask, a.shape[:2], name_mask))
    nan = np.isnan(colour).any(axis=2) & sel
    bad = ~np.isfinite(colour).all(axis=2) & sel
    ys, xs = np.nonzero(bad)
    return {"pixels": int(bad.sum()), "nan": int(nan.sum()), "inf": int((bad & ~nan).sum()),
            "of": int(sel.sum()), "first": (int(xs[0]), int(ys[0])) if xs.size else None}


def require_finite(images: dict, mask: np.ndarray | None = None,
                   name_mask: str = "mask") -> None:
    """Refuse images that hold NaN or infinite pixels: every metric of them would be NaN
    or infinite, and say nothing about the rest.

    Parameters
    ----------
    images : {name: (H, W[, C]) array}, the name as the user gave it (a file path).
    mask, name_mask : only pixels where the mask is non-zero are looked at.

    Raises
    ------
    CompareError
        Naming each image with non-finite pixels, how many (NaN, infinite) and where
        the first is.
    """
    bad = []
    for name, image in images.items():
        n = non_finite_pixels(image, mask, name_mask)
        if n["pixels"]:
            x, y = n["first"]
            bad.append(f"{name} holds {n['pixels']} non-finite pixel(s) of {n['of']}"
                       f"{' in the mask' if mask is not None else ''} ({n['nan']} NaN, "
                       f"{n['inf']} infinite; the first at x={x} y={y})")
    if bad:
        raise CompareError("; ".join(bad) + ": the differences there are undefined",
                           "render the image again (a NaN pixel is a broken render), or "
                           "leave those pixels out with a mask (--mask)")


def _result(mean, rms, mx, where, n_pixels, nc, masked) -> dict:
    rms, mean, mx = float(rms), float(mean), float(mx)
    psnr = math.inf if rms == 0.0 else 20.0 * math.log10(PSNR_PEAK / rms)
    return {"rmse": rms, "psnr_db": psnr, "psnr_peak": PSNR_PEAK,
            "mean_abs_error": mean, "max_abs_error": mx,
            "max_at": where, "pixels": int(n_pixels), "channels": nc, "masked": masked}


def oiio_metrics(a: np.ndarray, b: np.ndarray, name_a: str = "A", name_b: str = "B") -> dict:
    """Metrics over all pixels, computed by ``OpenImageIO.ImageBufAlgo.compare``."""
    a, b, nc = _check_pair(a, b, name_a, name_b)
    h, w = a.shape[:2]
    bufs = []
    for x in (a, b):
        spec = oiio.ImageSpec(w, h, nc, oiio.FLOAT)
        buf = oiio.ImageBuf(spec)
        buf.set_pixels(oiio.ROI(), np.ascontiguousarray(x[:, :, :nc], dtype=np.float32))
        bufs.append(buf)
    r = oiio.ImageBufAlgo.compare(bufs[0], bufs[1], math.inf, math.inf,
                                  roi=oiio.ROI(0, w, 0, h, 0, 1, 0, nc))
    if r.error:
        raise CompareError(f"OpenImageIO could not compare {name_a} and {name_b}")
    where = {"x": int(r.maxx), "y": int(r.maxy), "channel": int(r.maxc)}
    out = _result(r.meanerror, r.rms_error, r.maxerror, where, h * w, nc, False)
    if not all(math.isfinite(v) for v in (r.meanerror, r.rms_error, r.maxerror)):
        out = numpy_metrics(a, b, None, name_a, name_b)  # NaN/inf pixels: report them plainly
    return out


def numpy_metrics(a: np.ndarray, b: np.ndarray, mask: np.ndarray | None = None,
                  name_a: str = "A", name_b: str = "B", name_mask: str = "mask") -> dict:
    """Metrics in float64 with numpy, over the pixels where ``mask`` is non-zero
    (all pixels when ``mask`` is None)."""
    a, b, nc = _check_pair(a, b, name_a, name_b)
    h, w = a.shape[:2]
    sel = np.ones((h, w), bool) if mask is None else _mask_pixels(mask, (h, w), name_mask)
    n = int(np.count_nonzero(sel))
    if n == 0:
        raise CompareError(f"mask {name_mask} has no non-zero pixel; nothing to compare")
    d = np.abs(a[:, :, :nc].astype(np.float64) - b[:, :, :nc].astype(np.float64))
    d = np.where(sel[:, :, None], d, 0.0)
    with np.errstate(invalid="ignore", over="ignore"):
        mean = d.sum() / (n * nc)
        rms = math.sqrt((d * d).sum() / (n * nc))
    k = int(np.nanargmax(d)) if not np.all(np.isnan(d)) else 0
    y, x, ch = np.unravel_index(k, d.shape)
    mx = float(np.max(d))
    return _result(mean, rms, mx, {"x": int(x), "y": int(y), "channel": int(ch)}, n, nc,
                   mask is not None)


def compare_arrays(a: np.ndarray, b: np.ndarray, mask: np.ndarray | None = None,
                   name_a: str = "A", name_b: str = "B", name_mask: str = "mask") -> dict:
    """Error metrics of ``b`` against ``a`` (see the module docstring)."""
    if mask is None:
        return oiio_metrics(a, b, name_a, name_b)
    return numpy_metrics(a, b, mask, name_a, name_b, name_mask)


def difference_magnitude(a: np.ndarray, b: np.ndarray, mask: np.ndarray | None = None
                         ) -> np.ndarray:
    """Per-pixel error (H, W), float64: the largest |A - B| over the colour channels;
    0 outside the mask.  Non-finite differences become +inf."""
    a, b, nc = _check_pair(a, b, "A", "B")
    d = np.abs(a[:, :, :nc].astype(np.float64) - b[:, :, :nc].astype(np.float64))
    d = np.where(np.isnan(d), np.inf, d).max(axis=2)
    if mask is not None:
        d = np.where(_mask_pixels(mask, d.shape, "mask"), d, 0.0)
    return d


def false_colour(err: np.ndarray, scale: float | None = None, cmap: str = "inferno"
                 ) -> tuple[np.ndarray, float]:
    """Map a per-pixel error (H, W) to display colours (H, W, 3) in [0, 1].

    ``scale`` is the error shown at the top of the colour map (default: the
    largest finite error; errors above it saturate).  Returns (image, scale used).
    """
    err = np.asarray(err, dtype=np.float64)
    if scale is None:
        finite = err[np.isfinite(err)]
        scale = float(finite.max()) if finite.size else 0.0
    if not (scale > 0 and math.isfinite(scale)):
        t = np.where(err > 0, 1.0, 0.0)  # identical images: all black
    else:
        t = np.clip(np.nan_to_num(err / scale, nan=1.0, posinf=1.0), 0.0, 1.0)
    import matplotlib
    rgb = matplotlib.colormaps[cmap](t)[:, :, :3]
    return np.ascontiguousarray(rgb, dtype=np.float32), float(scale)


def srgb_preview(a: np.ndarray) -> np.ndarray:
    """(H, W, 3) float32: linear light clipped to [0, 1] and sRGB-encoded, as the PNG
    preview shows it (grey images are repeated to three channels; alpha is dropped)."""
    a = _hwc(a, "image")
    nc = colour_channels(a.shape[2])
    x = np.clip(np.nan_to_num(a[:, :, :nc].astype(np.float64), nan=0.0, posinf=1.0), 0.0, 1.0)
    if nc == 1:
        x = np.repeat(x, 3, axis=2)
    enc = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return np.ascontiguousarray(enc, dtype=np.float32)


def flip_error(reference: np.ndarray, test: np.ndarray, mask: np.ndarray | None = None,
               name_a: str = "A", name_b: str = "B", name_mask: str = "mask",
               ppd: float = FLIP_PPD) -> tuple[float, np.ndarray]:
    """The mean FLIP error of ``test`` against ``reference`` and its (H, W) map.

    Both are linear (H, W, C) images; FLIP compares their sRGB previews
    (:func:`srgb_preview`, LDR-FLIP) at ``ppd`` pixels per degree.  The map is in [0, 1]
    (0 where the eye sees no difference); the mean is over the mask's pixels (all
    without a mask).
    """
    a, b, _ = _check_pair(reference, test, name_a, name_b)
    sel = None if mask is None else _mask_pixels(mask, a.shape[:2], name_mask)
    if sel is not None and not sel.any():
        raise CompareError(f"mask {name_mask} has no non-zero pixel; nothing to compare")
    import flip_evaluator
    err, _, _ = flip_evaluator.evaluate(srgb_preview(a), srgb_preview(b), "LDR",
                                        inputsRGB=True, applyMagma=False,
                                        computeMeanError=False,
                                        parameters={"ppd": float(ppd)})
    err = np.asarray(err, dtype=np.float64).reshape(a.shape[:2])
    mean = float(err.mean() if sel is None else err[sel].mean())
    return mean, err
