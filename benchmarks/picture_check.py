"""The default render against the per-pixel exact render, wide open, stopped down, iris.

    python3 benchmarks/picture_check.py [--size 640x480] [--samples 16]
        [--lens tessar.50mm] [--scenes raddem.pov biscuit.pov] [--out FILE]

The brief's check of a fast path ("Look at the pictures"): for each stock scene and
aperture (wide open, f/16, f/64, a 6-blade iris wide open), ``povlens render --method
mesh`` at its defaults (interleaved field meshes, stacks or runs of their own as the lead
chooses) against ``--ray-mesh pixel`` (one exact ray per pixel and lens sample, a pass
the frame's size): RMSE, FLIP, the two means, and the *phase spread*, the spread of the
mean of the m x m pixel phases of the default image (m its interleave) over the whole
frame, against the same measure of the per-pixel image -- a dot lattice of period m
shows as a spread far above the per-pixel one (docs/decisions/planning.md, "A pattern
in runs of their own").  Both renders' wall times are reported.  Scenes: Debian's
povray-examples, found by file name; radiosity, and a scene without it.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
from povlens.report.compare import flip_error  # noqa: E402
from povlens.util.images import read_image  # noqa: E402

EXAMPLES = Path("/usr/share/doc/povray/examples")
APERTURES = {"open": [], "f/16": ["--f-number", "16"], "f/64": ["--f-number", "64"],
             "iris": ["--aperture-blades", "6"]}


def find_scene(name: str) -> Path:
    found = sorted(EXAMPLES.rglob(name))
    if not found:
        raise SystemExit(f"{name}: not in {EXAMPLES} (apt-get install povray-examples)")
    return found[0]


def render(scene: Path, out: Path, size, n: int, lens: str, extra) -> float:
    cmd = [sys.executable, "-m", "povlens", "render", str(scene), "--lens", lens,
           "--method", "mesh", "--samples", str(n), "--width", str(size[0]),
           "--height", str(size[1]), "-q", "-o", str(out), *extra]
    t = time.perf_counter()
    subprocess.run(cmd, cwd=scene.parent, check=True, capture_output=True, text=True)
    return time.perf_counter() - t


def phase_spread(image: np.ndarray, m: int) -> float:
    """max - min of the mean brightness of the m x m pixel phases (0 for m = 1)."""
    grey = image[..., :3].mean(axis=2)
    means = [grey[i::m, j::m].mean() for i in range(m) for j in range(m)]
    return float(max(means) - min(means))


def check(scene: Path, aperture: str, size, n: int, lens: str, work: Path) -> dict:
    extra = APERTURES[aperture]
    fast_dir, exact_dir = work / "default", work / "pixel"
    fast_s = render(scene, fast_dir, size, n, lens, extra)
    exact_s = render(scene, exact_dir, size, n, lens, [*extra, "--ray-mesh", "pixel"])
    a = read_image(fast_dir / "image.exr")[..., :3].astype(np.float64)
    r = read_image(exact_dir / "image.exr")[..., :3].astype(np.float64)
    plan = json.loads((fast_dir / "plan.json").read_text())
    m = int((plan.get("field_mesh") or {}).get("interleave", 1))
    layout = fast_dir / "samples" / "layout.json"
    runs = ""
    if layout.is_file():
        runs = "own" if json.loads(layout.read_text()).get("bands") == 1 else "stack"
    return {"scene": scene.name, "aperture": aperture, "interleave": m, "runs": runs,
            "default_s": round(fast_s, 2), "pixel_s": round(exact_s, 2),
            "rmse": float(np.sqrt(np.mean((a - r) ** 2))), "flip": flip_error(r, a)[0],
            "mean": float(a.mean()), "pixel_mean": float(r.mean()),
            "spread": phase_spread(a, m), "pixel_spread": phase_spread(r, m)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--lens", default="tessar.50mm")
    ap.add_argument("--scenes", nargs="+", default=["raddem.pov", "biscuit.pov"])
    ap.add_argument("--apertures", nargs="+", default=list(APERTURES), choices=list(APERTURES))
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "picture_check.txt"))
    args = ap.parse_args(argv)
    size = tuple(int(v) for v in args.size.split("x"))
    lines = [f"# python3 benchmarks/picture_check.py --size {args.size} --samples "
             f"{args.samples} --lens {args.lens} --scenes {' '.join(args.scenes)}",
             f"{'scene':<14} {'aperture':<8} {'m':>2} {'runs':>5} {'default s':>9} "
             f"{'pixel s':>8} {'rmse':>7} {'flip':>6} {'mean':>7} {'pixel':>7} "
             f"{'spread':>7} {'pixel':>7}"]
    print("\n".join(lines), flush=True)
    for name in args.scenes:
        scene = find_scene(name)
        for aperture in args.apertures:
            with tempfile.TemporaryDirectory(prefix="povlens-pic-") as tmp:
                r = check(scene, aperture, size, args.samples, args.lens, Path(tmp))
            line = (f"{r['scene']:<14} {r['aperture']:<8} {r['interleave']:>2} {r['runs']:>5} "
                    f"{r['default_s']:>9.2f} {r['pixel_s']:>8.2f} {r['rmse']:>7.4f} "
                    f"{r['flip']:>6.3f} {r['mean']:>7.4f} {r['pixel_mean']:>7.4f} "
                    f"{r['spread']:>7.4f} {r['pixel_spread']:>7.4f}")
            lines.append(line)
            print(line, flush=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
