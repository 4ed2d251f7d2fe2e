"""--dispersion: the measured colour of the bundled lenses with Abbe numbers, and the
time cost of a spectral render at equal noise (issue 16).

1. Lateral colour (F against C chief-ray landing, px, across the field) and
   longitudinal colour (paraxial focus shift F - C, mm) of cooke.triplet.50mm,
   tessar.50mm and singlet.pcx.25mm, from the plans `povlens convert --dispersion`
   writes (640x480 on the default 35 mm diagonal, scenes/chart.pov, its focus).
2. Equal noise: chart.pov at 160x120 through a lens, mesh method, with and without
   --dispersion.  Each mode's noise is its RMSE against its own 256-sample render
   (the two converge to different images); the plain render's RMSE at 16 samples
   is matched by the dispersive one's, interpolated in log N - log RMSE, and the
   costs compared (wall time of `povlens render`, which grows ~linearly in N).

    python3 benchmarks/bench_dispersion.py [--quick] [--lens NAME] [--f-number N]

writes benchmarks/results/dispersion.txt (--quick: a smaller reference, not written).
Run alone (2 cores): the times are wall-clock.
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from povlens.plan.schema import read_plan  # noqa: E402
from povlens.util.images import read_image  # noqa: E402

CHART = ROOT / "scenes" / "chart.pov"
LENSES = ("cooke.triplet.50mm", "tessar.50mm", "singlet.pcx.25mm")


def povlens(*args) -> float:
    t = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "povlens", *map(str, args)], cwd=ROOT,
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(r.stderr)
    return time.perf_counter() - t


def colour_table(tmp: Path) -> list[str]:
    lines = ["lens                 f/#   field: " + " ".join(f"{f:5.1f}" for f in
                                                          np.linspace(0, 1, 6))
             + "   max px   long. mm  blur px"]
    for name in LENSES:
        out = tmp / f"colour-{name}"
        povlens("convert", CHART, "--lens", name, "--method", "mesh", "--dispersion",
                "--samples", "1", "-o", out)
        plan = read_plan(out)
        d = plan.dispersion
        lat = " ".join(f"{v:5.2f}" if v is not None else "    -" for v in d["lateral_colour_px"])
        lines.append(f"{name:20s} {plan.lens.f_number:4.2f}  lateral px: {lat}   "
                     f"{d['max_lateral_colour_px']:6.3f}   {d['longitudinal_colour_mm']:+7.4f}"
                     f"  {d['longitudinal_blur_px']:6.3f}")
    return lines


def render(tmp: Path, tag: str, lens_args: list[str], n: int, seed: int, disp: bool):
    out = tmp / f"{tag}-{n}-{seed}"
    wall = povlens("render", CHART, *lens_args, "--method", "mesh", "--width", "160",
                   "--height", "120", "--samples", n, "--seed", seed, "-q", "-o", out,
                   *(["--dispersion"] if disp else []))
    return read_image(out / "image.exr")[..., :3].astype(np.float64), wall


def equal_noise(tmp: Path, lens_args: list[str], n_ref: int, ns: list[int]) -> list[str]:
    rows, fits = [], {}
    for disp in (False, True):
        tag = "disp" if disp else "plain"
        ref, _ = render(tmp, tag, lens_args, n_ref, 99, disp)
        pts = []
        for n in ns:
            img, wall = render(tmp, tag, lens_args, n, 0, disp)
            rmse = math.sqrt(np.mean((img - ref) ** 2))
            pts.append((n, rmse, wall))
            rows.append(f"{tag:5s} N={n:4d}  RMSE {rmse:.5f}  wall {wall:6.2f} s")
        fits[disp] = pts
    # the plain render at ns[0] samples: the dispersive N of the same RMSE
    n0, e0, w0 = fits[False][0]
    ln = np.log([p[0] for p in fits[True]])
    le = np.log([p[1] for p in fits[True]])
    slope, icpt = np.polyfit(ln, le, 1)
    n_eq = math.exp((math.log(e0) - icpt) / slope)
    lw = np.polyfit(ln, np.log([p[2] for p in fits[True]]), 1)
    w_eq = math.exp(np.polyval(lw, math.log(n_eq)))
    rows.append(f"plain N={n0}: RMSE {e0:.5f}, {w0:.2f} s; dispersion reaches it at "
                f"N = {n_eq:.1f} (RMSE ~ N^{slope:.2f}): {n_eq / n0:.2f}x the lens samples "
                f"(each costs the same POV-Ray pass), {w_eq:.2f} s of 'povlens render' "
                f"wall time (conversion included): {w_eq / w0:.2f}x")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--lens", default="singlet.pcx.25mm")
    ap.add_argument("--f-number", default="4")
    args = ap.parse_args()
    n_ref = 64 if args.quick else 256
    ns = [8, 16] if args.quick else [16, 32, 64]
    lens_args = ["--lens", args.lens, "--f-number", args.f_number]
    with tempfile.TemporaryDirectory(prefix="bench-dispersion-") as t:
        tmp = Path(t)
        out = ["# benchmarks/bench_dispersion.py" + (" --quick" if args.quick else ""),
               "", "## colour of the bundled lenses with V_d (640x480, 35 mm diagonal, "
               "chart.pov focus; + = blue lands outside / focuses behind red)"]
        out += colour_table(tmp)
        out += ["", f"## equal noise: chart.pov 160x120, {' '.join(lens_args)}, mesh, "
                f"reference {n_ref} samples (seed 99) per mode"]
        out += equal_noise(tmp, lens_args, n_ref, ns)
    text = "\n".join(out) + "\n"
    print(text)
    if not args.quick:
        (ROOT / "benchmarks" / "results" / "dispersion.txt").write_text(text)


if __name__ == "__main__":
    main()
