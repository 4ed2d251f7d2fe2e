"""Image files: reading renders as float32, writing EXR and sRGB PNG previews.

All arrays are ``(H, W, C)`` float32 in *linear* light, row 0 = top of the
image, column 0 = left (POV-Ray and OpenImageIO agree on this,
docs/reference/povray-mesh-camera.md §9.4).  POV-Ray's EXR output is half float; it is
always read as float32 so that sums never accumulate in half precision (§9.3 there).

Every write goes to a temporary file in the destination folder that is
renamed on success, so a half-written image never appears under the final
name.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from povlens.errors import PovlensError
from povlens.util.files import atomic_output

__all__ = ["ImageError", "read_image", "write_exr", "write_png_srgb"]


class ImageError(PovlensError):
    """An image file that cannot be read or written."""


def _oiio_message(text: str) -> str:
    lines = []
    for ln in (text or "").splitlines():
        ln = ln.strip()
        if ln and ln not in lines:
            lines.append(ln)
    return "; ".join(lines) or "unknown OpenImageIO error"


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read an image file as float32 ``(H, W, C)``, values as stored.

    EXR/HDR values are linear; 8/16-bit formats are returned normalized to
    [0, 1] but still encoded (e.g. sRGB) -- nothing is linearized.
    Raises :class:`ImageError` naming the file when it cannot be read.
    """
    path = Path(path)
    if not path.is_file():
        raise ImageError(f"image file {path} does not exist", "check the path (was the render run?)")
    buf = oiio.ImageBuf(str(path))
    ok = buf.read(0, 0, True, oiio.FLOAT)
    if not ok or buf.has_error:
        raise ImageError(
            f"cannot read image {path}: {_oiio_message(buf.geterror())}",
            "the file is damaged or not an image; delete it and render again",
        )
    spec = buf.spec()
    if spec.depth > 1:
        raise ImageError(f"cannot read image {path}: volume images are not supported")
    arr = np.asarray(buf.get_pixels(oiio.FLOAT), dtype=np.float32)
    if buf.has_error:
        raise ImageError(f"cannot read image {path}: {_oiio_message(buf.geterror())}")
    return arr.reshape(spec.height, spec.width, spec.nchannels)


def _as_hwc(array: np.ndarray, what: str) -> np.ndarray:
    a = np.asarray(array)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[0] < 1 or a.shape[1] < 1 or not 1 <= a.shape[2] <= 4:
        raise ImageError(f"cannot write {what}: expected an (H, W) or (H, W, C<=4) array, got shape {a.shape}")
    return np.ascontiguousarray(a, dtype=np.float32)


def _channel_names(n: int) -> tuple[str, ...]:
    return {1: ("Y",), 2: ("Y", "A"), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}[n]


def _write(buf: oiio.ImageBuf, path: Path, fmt) -> None:
    with atomic_output(path) as tmp:
        ok = buf.write(str(tmp), fmt)
        if not ok or buf.has_error:
            raise ImageError(
                f"cannot write image {path}: {_oiio_message(buf.geterror())}",
                "check that the folder is writable and has free space",
            )


def write_exr(path: str | os.PathLike, array: np.ndarray, *, half: bool = False) -> Path:
    """Write ``array`` ((H, W) or (H, W, C), linear) as a ZIP-compressed EXR.

    Stored as 32-bit float, or half float with ``half=True``.  Returns the path.
    """
    path = Path(path)
    a = _as_hwc(array, str(path))
    h, w, c = a.shape
    spec = oiio.ImageSpec(w, h, c, oiio.FLOAT)
    spec.channelnames = _channel_names(c)
    if c in (2, 4):
        spec.alpha_channel = c - 1
    spec.attribute("compression", "zip")
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(), a)
    _write(buf, path, oiio.HALF if half else oiio.FLOAT)
    return path


def write_png_srgb(path: str | os.PathLike, linear_array: np.ndarray) -> Path:
    """Write a linear ``(H, W[, C])`` array as an 8-bit sRGB PNG preview.

    The colour channels are converted linear -> sRGB with OpenImageIO's
    ``colorconvert``; values are clipped to [0, 1] (NaN/inf become 0/1); an
    alpha channel (C = 2 or 4) is written unconverted.  Returns the path.
    """
    path = Path(path)
    a = _as_hwc(linear_array, str(path))
    a = np.nan_to_num(a, nan=0.0, posinf=1.0, neginf=0.0)
    h, w, c = a.shape
    spec = oiio.ImageSpec(w, h, c, oiio.FLOAT)
    spec.channelnames = _channel_names(c)
    if c in (2, 4):
        spec.alpha_channel = c - 1
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(), a)
    ncolour = c - 1 if c in (2, 4) else c
    out = oiio.ImageBufAlgo.colorconvert(
        buf, "linear", "sRGB", unpremult=False, roi=oiio.ROI(0, w, 0, h, 0, 1, 0, ncolour)
    )
    if out.has_error:
        raise ImageError(f"cannot convert {path} to sRGB: {_oiio_message(out.geterror())}")
    px = np.asarray(out.get_pixels(oiio.FLOAT), dtype=np.float32).reshape(h, w, -1)
    if ncolour < c:
        px = np.concatenate([px[:, :, :ncolour], a[:, :, ncolour:]], axis=2)
    px = np.clip(px, 0.0, 1.0)
    buf8 = oiio.ImageBuf(oiio.ImageSpec(w, h, c, oiio.FLOAT))
    buf8.specmod().channelnames = spec.channelnames
    if c in (2, 4):
        buf8.specmod().alpha_channel = c - 1
    buf8.set_pixels(oiio.ROI(), np.ascontiguousarray(px))
    _write(buf8, path, oiio.UINT8)
    return path
