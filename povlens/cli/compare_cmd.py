"""``povlens compare A.exr B.exr``: error metrics between two renders, and a difference image."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from povlens.report.compare import (FLIP_PPD, PSNR_PEAK, CompareError, compare_arrays,
                                    difference_magnitude, false_colour, flip_error,
                                    require_finite)
from povlens.util.files import atomic_output
from povlens.util.images import ImageError, read_image
from povlens.cli.common import positive_float, print_json


def register(sub) -> None:
    p = sub.add_parser("compare", help="error metrics between two images (linear light)",
                       description="Compare image B against image A in linear light over the "
                                   "colour channels (RGB; alpha ignored): RMSE, PSNR (peak "
                                   f"{PSNR_PEAK:g}, i.e. linear white), mean and max absolute "
                                   "error, and the mean FLIP error (NVIDIA's perceptual "
                                   "difference of the sRGB previews, what the eye sees), "
                                   "optionally only where a mask image is non-zero; and "
                                   "optionally write a false-colour difference image and "
                                   "FLIP's error map.")
    p.add_argument("a", metavar="A", help="reference image (EXR for linear light)")
    p.add_argument("b", metavar="B", help="image to compare against A (same size)")
    p.add_argument("-o", "--output", metavar="DIFF",
                   help="write a false-colour image of max-over-RGB |A-B| (e.g. diff.png)")
    p.add_argument("--mask", metavar="MASK",
                   help="only compare pixels where this image (same size) is non-zero")
    p.add_argument("--flip-map", metavar="MAP",
                   help="write FLIP's per-pixel error map (0 black .. 1 yellow, magma), "
                        "e.g. flip.png")
    p.add_argument("--scale", type=positive_float, metavar="E",
                   help="error shown at the top of the colour map of DIFF "
                        "(default: the largest error)")
    p.add_argument("--json", action="store_true", help="print JSON (an infinite PSNR is null)")
    p.set_defaults(func=run)


def _write_colour(path: Path, rgb: np.ndarray) -> None:
    h, w, _ = rgb.shape
    spec = oiio.ImageSpec(w, h, 3, oiio.FLOAT)
    spec.channelnames = ("R", "G", "B")
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(), np.ascontiguousarray(rgb, dtype=np.float32))
    fmt = oiio.FLOAT if path.suffix.lower() in (".exr", ".hdr", ".tif", ".tiff") else oiio.UINT8
    with atomic_output(path) as tmp:
        if not buf.write(str(tmp), fmt) or buf.has_error:
            raise ImageError(f"cannot write image {path}: {buf.geterror().strip()}",
                             "check the file suffix (.png, .exr, ...) and that the folder "
                             "is writable")


def run(args) -> int:
    a = read_image(args.a)
    b = read_image(args.b)
    mask = read_image(args.mask) if args.mask else None
    require_finite({args.a: a, args.b: b}, mask, args.mask or "mask")   # else NaN metrics
    r = compare_arrays(a, b, mask, args.a, args.b, args.mask or "mask")
    flip, flip_map = flip_error(a, b, mask, args.a, args.b, args.mask or "mask")
    if args.flip_map:
        out = Path(args.flip_map)
        if not out.suffix:
            raise CompareError(f"--flip-map {out}: give a file name with a suffix, e.g. flip.png")
        rgb, _ = false_colour(flip_map, 1.0, cmap="magma")
        _write_colour(out, rgb)
    scale = None
    if args.output:
        out = Path(args.output)
        if not out.suffix:
            raise CompareError(f"-o {out}: give a file name with a suffix, e.g. diff.png")
        err = difference_magnitude(a, b, mask)
        rgb, scale = false_colour(err, args.scale)
        _write_colour(out, rgb)
    if args.json:
        d = {"a": args.a, "b": args.b, "mask": args.mask, "width": int(a.shape[1]),
             "height": int(a.shape[0])}
        d.update(r)
        d["flip"] = flip
        d["flip_ppd"] = FLIP_PPD
        if args.flip_map:
            d["flip_map"] = args.flip_map
        for k in ("rmse", "psnr_db", "mean_abs_error", "max_abs_error"):
            if not math.isfinite(d[k]):
                d[k] = None
        if args.output:
            d["diff_image"] = {"path": args.output, "scale": scale}
        print_json(d)
        return 0
    where = r["max_at"]
    ch = "RGB"[where["channel"]] if r["channels"] == 3 else "Y"
    psnr = "inf" if math.isinf(r["psnr_db"]) else f"{r['psnr_db']:.3f}"
    print(f"{args.b} vs {args.a}: {a.shape[1]}x{a.shape[0]}, {r['pixels']} pixels compared"
          + (f" (mask {args.mask})" if args.mask else "")
          + f", {'RGB' if r['channels'] == 3 else 'grey'}, linear light")
    print(f"  RMSE          {r['rmse']:.6g}")
    print(f"  PSNR          {psnr} dB (peak {PSNR_PEAK:g})")
    print(f"  mean |A-B|    {r['mean_abs_error']:.6g}")
    print(f"  max |A-B|     {r['max_abs_error']:.6g} at x={where['x']} y={where['y']} {ch}")
    print(f"  FLIP          {flip:.6g} (mean, LDR on the sRGB previews, {FLIP_PPD:g} px/deg)")
    if args.flip_map:
        print(f"  FLIP map {args.flip_map}")
    if args.output:
        print(f"  difference image {args.output} (colour map top = {scale:.6g})")
    return 0
