"""The default exact path stopped down lands on the pinhole view at the same f-number.

    python3 benchmarks/stopped_down.py [--f-numbers 16,64] [--samples 4] [--size 320x240]
        [--stock 3] [--lens dgauss.50mm]

Issue 22's check on the bundled scenes and on stock scenes nobody here wrote (Debian's
povray-examples, the first ``--stock`` that planned in the last stock sweep): for each
f-number, ``povlens render --method mesh`` (interleaved field meshes, ``--samples``,
``--no-jitter``: pixel centres, as the pinhole view samples them) against ``--method
pinhole`` (the same vignetting map): the means' ratio and the range of 16x16-pixel block
ratios, which a crescent or ring shows as far from 1.  At f/64 the blur is well under a
pixel, so what remains is Monte-Carlo noise at the edges and the lens's distortion.
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from povlens.util.images import read_image

ROOT = Path(__file__).resolve().parent.parent
STOCK = Path("/usr/share/povray-3.7/scenes")


def render(scene: Path, out: Path, lens: str, w: int, h: int, *extra) -> np.ndarray:
    cmd = [sys.executable, "-m", "povlens", "render", str(scene), "--lens", lens,
           "--width", str(w), "--height", str(h), "-q", "-o", str(out), *map(str, extra)]
    subprocess.run(cmd, cwd=scene.parent, check=True, capture_output=True, text=True)
    return read_image(out / "image.exr")[..., :3].astype(np.float64)


def blocks(img: np.ndarray, k: int = 16) -> np.ndarray:
    h, w = (img.shape[0] // k) * k, (img.shape[1] // k) * k
    return img[:h, :w].mean(axis=2).reshape(h // k, k, w // k, k).mean(axis=(1, 3))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--f-numbers", default="16,64")
    ap.add_argument("--samples", type=int, default=4)
    ap.add_argument("--size", default="320x240")
    ap.add_argument("--stock", type=int, default=3)
    ap.add_argument("--lens", default="dgauss.50mm")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.split("x"))
    scenes = [ROOT / "scenes" / "paper.pov", ROOT / "scenes" / "chart.pov"]
    with open(ROOT / "benchmarks" / "results" / "stock_scenes.csv") as f:
        ok = [r["scene"] for r in csv.DictReader(f)
              if r["povray_ok"] == "1" and r["plan_exit"] == "0" and float(r["seconds"]) < 5]
    scenes += [STOCK / s for s in ok[::max(1, len(ok) // max(args.stock, 1))][:args.stock]]
    print(f"# python3 benchmarks/stopped_down.py --f-numbers {args.f_numbers} --samples "
          f"{args.samples} --size {args.size} --stock {args.stock}; {args.lens}, mesh with "
          f"--no-jitter against the pinhole view")
    worst = 0.0
    with tempfile.TemporaryDirectory(prefix="povlens-stopped-") as work:
        for scene in scenes:
            for fn in (float(v) for v in args.f_numbers.split(",")):
                out = Path(work) / f"{scene.stem}-{fn:g}"
                common = ("--f-number", fn)
                mesh = render(scene, out / "mesh", args.lens, w, h, *common, "--method", "mesh",
                              "--samples", args.samples, "--no-jitter")
                pin = render(scene, out / "pin", args.lens, w, h, *common, "--method", "pinhole")
                ratio = mesh.mean() / pin.mean()
                b = blocks(mesh) / np.maximum(blocks(pin), 1e-6)
                b = b[blocks(pin) > 0.02]                   # blocks with light to compare
                worst = max(worst, abs(ratio - 1))
                print(f"{str(scene.relative_to(scene.parent.parent)):45s} f/{fn:<4g} mean "
                      f"{ratio:.4f} x pinhole; 16x16 blocks {b.min():.3f} .. {b.max():.3f}",
                      flush=True)
    print(f"largest departure of the mean from the pinhole view's: {100 * worst:.2f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
