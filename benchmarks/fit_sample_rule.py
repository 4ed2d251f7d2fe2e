"""Re-fit ``--method auto``'s lens-sample rule to what the eye sees (FLIP).

    python3 benchmarks/fit_sample_rule.py [--pairs paper:dgauss.50mm,...] [--size 640x480]
        [--tolerance 0.5] [--references DIR]

The rule (:func:`povlens.plan.decision.samples_for_blur`) gives a mesh render
N = K b lens samples (before issue 22: 0.785 b^2) for the scene's largest blur of b pixels.  For each scene / lens
pair this measures, one run each:

* b: the largest blur ``povlens plan`` finds (its depth probe and the thin-lens model);
* the budget: the mean FLIP (:func:`povlens.report.compare.flip_error`) of moving a
  converged reference by the tolerance (+-x, +-y, linear interpolation, a 2-pixel border
  left out) -- what ``--tolerance`` pixels mean to the eye on this scene;
* the default exact render (``--method mesh``: interleaved field meshes) at N = 2 .. 256
  against that reference (per-pixel meshes, 256 samples or ``--reference-samples``,
  another seed, ``benchmarks/bench_render.py``'s references): N*, the samples at which its FLIP
  reaches the budget (log-log interpolation);

and N* / b and N* / b^2 per pair.  The rule's K is chosen from these (with the rounding
to a power of two, so every pair meets its budget); the last run is in
``benchmarks/results/sample_rule_640x480.txt``.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy import ndimage

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_render import povlens_render, reference_image, time_to_level  # noqa: E402
from povlens.report.compare import flip_error  # noqa: E402
from povlens.util.images import read_image  # noqa: E402

SCENES = ROOT / "povlens" / "data" / "scenes"
SWEEP = (2, 4, 8, 16, 32, 64, 128, 256)


def shift_flip(ref: np.ndarray, tol_px: float) -> float:
    """Mean FLIP of ``ref`` moved by ``tol_px`` along +-x and +-y (2-pixel border left out)."""
    out = []
    for dx, dy in ((tol_px, 0), (-tol_px, 0), (0, tol_px), (0, -tol_px)):
        moved = np.stack([ndimage.shift(ref[..., c], (dy, dx), order=1, mode="nearest")
                          for c in range(3)], -1)
        out.append(flip_error(ref[2:-2, 2:-2], moved[2:-2, 2:-2])[0])
    return float(np.mean(out))


def largest_blur_px(scene: Path, lens: str, width: int, height: int) -> float:
    r = subprocess.run([sys.executable, "-m", "povlens", "plan", str(scene), "--lens", lens,
                        "--focus", "4", "--width", str(width), "--height", str(height),
                        "--json"], cwd=ROOT, capture_output=True, text=True, check=True)
    return float(json.loads(r.stdout)["decision"]["numbers"]["max_blur_px"])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", default="paper:dgauss.50mm,chart:dgauss.50mm")
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--tolerance", type=float, default=0.5)
    ap.add_argument("--references", type=Path, default=ROOT / "benchmarks" / "references")
    ap.add_argument("--reference-samples", type=int, default=None,
                    help="per-pixel samples of the references (default bench_render's)")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.split("x"))
    work = Path(tempfile.mkdtemp(prefix="povlens-fit-rule-"))
    ks = []
    try:
        for pair in args.pairs.split(","):
            name, lens = pair.split(":")
            scene = SCENES / f"{name}.pov"
            ref = read_image(reference_image(args.references, scene, lens, w, h,
                                             args.reference_samples))[..., :3]
            ref = ref.astype(np.float64)
            b = largest_blur_px(scene, lens, w, h)
            budget = shift_flip(ref, args.tolerance)
            points = []
            for n in SWEEP:
                out = work / f"{name}-{lens}-{n}"
                t = povlens_render(out, scene, lens, w, h, "--method", "mesh", "--samples", n)
                img = read_image(out / "image.exr")[..., :3].astype(np.float64)
                f = flip_error(ref, img)[0]
                points.append((float(n), f))
                print(f"  {name} {lens} N={n:3d}: FLIP {f:.4f} ({t:.1f} s)", flush=True)
                shutil.rmtree(out, ignore_errors=True)
                if f <= budget:
                    break
            n_star = time_to_level(points, budget)      # (N, FLIP) interpolated like times
            k = None if n_star is None else n_star / b
            ks.append(k)
            print(f"{name} {lens} {w}x{h}: largest blur {b:.2f} px, budget (FLIP of a "
                  f"{args.tolerance:g} px move) {budget:.4f}, N* = "
                  f"{'-' if n_star is None else f'{n_star:.1f}'}, N*/b = "
                  f"{'-' if k is None else f'{k:.3f}'}, N*/b^2 = "
                  f"{'-' if k is None else f'{k / b:.3f}'}", flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    found = [k for k in ks if k is not None]
    if found:
        print(f"N*/b: largest {max(found):.3f}, median {float(np.median(found)):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
