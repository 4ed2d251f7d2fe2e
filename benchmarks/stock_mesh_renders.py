"""Field-mesh renders of stock scenes nobody here wrote (Debian's povray-examples).

    python3 benchmarks/stock_mesh_renders.py [--count 12] [--samples 8] [--size 640x480]
        [--lens dgauss.50mm] [--timeout 120] [--extra "--aperture-blades 6 --dispersion ..."]

Takes every k-th scene that planned in the last stock sweep
(``benchmarks/results/stock_scenes.csv``, plan exit 0, POV-Ray rendering it), renders it with
``povlens render --method mesh`` (field meshes, the default) in the scene's folder, and
reports per scene: exit status, wall time, the field meshes' grid and certified ray error
(``plan.json``), whether the image is finite, and any traceback.  ``--extra`` adds options to
every render (the lens-character options, ``--frames``).  Results to stdout.
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from povlens.util.images import read_image

ROOT = Path(__file__).resolve().parent.parent
STOCK = Path("/usr/share/povray-3.7/scenes")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=12)
    ap.add_argument("--samples", type=int, default=8)
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--lens", default="dgauss.50mm")
    ap.add_argument("--timeout", type=float, default=120)
    ap.add_argument("--extra", default="", help="more povlens render options, one string")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.split("x"))
    with open(ROOT / "benchmarks" / "results" / "stock_scenes.csv") as f:
        ok = [r["scene"] for r in csv.DictReader(f)
              if r["povray_ok"] == "1" and r["plan_exit"] == "0" and float(r["seconds"]) < 10]
    step = max(1, len(ok) // args.count)
    picked = ok[::step][:args.count]
    rows = []
    with tempfile.TemporaryDirectory(prefix="povlens-stock-mesh-") as work:
        for i, name in enumerate(picked):
            scene = STOCK / name
            out = Path(work) / f"s{i}"
            cmd = [sys.executable, "-m", "povlens", "render", scene.name, "--lens", args.lens,
                   "--method", "mesh", "--samples", str(args.samples), "--width", str(w),
                   "--height", str(h), "-o", str(out), "-q", *args.extra.split()]
            t0 = time.perf_counter()
            try:
                r = subprocess.run(cmd, cwd=scene.parent, capture_output=True, text=True,
                                   timeout=args.timeout)
                code, err = r.returncode, r.stderr
            except subprocess.TimeoutExpired:
                code, err = "timeout", ""
            secs = time.perf_counter() - t0
            grid = error = finite = ""
            plans = sorted(out.glob("plan.json")) or sorted(out.glob("frame-*/plan.json"))
            if plans:
                fm = json.loads(plans[0].read_text()).get("field_mesh")
                if fm:
                    grid, error = f"{fm['grid'][0]}x{fm['grid'][1]}", f"{fm['max_ray_error_px']:.3f}"
            images = sorted(out.glob("image*.exr"))       # image.exr, or a pull's image.NNNN.exr
            if images:
                finite = str(all(bool(np.isfinite(read_image(p)).all()) for p in images))
            last = err.strip().splitlines()[-1] if err.strip() else ""
            rows.append((name, code, secs, grid, error, finite, "Traceback" in err, last))
            print(f"{name:45s} exit {code!s:7s} {secs:6.1f} s  grid {grid:6s} ray error "
                  f"{error:6s} px  finite {finite:5s} {'TRACEBACK ' if 'Traceback' in err else ''}"
                  f"{last[:80] if code else ''}", flush=True)
    good = sum(1 for r in rows if r[1] == 0 and r[5] == "True")
    print(f"\n{good} of {len(rows)} rendered with a finite image; "
          f"{sum(r[6] for r in rows)} tracebacks")
    return 0


if __name__ == "__main__":
    sys.exit(main())
