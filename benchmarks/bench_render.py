"""Where the time of an N-sample mesh render goes, against focal_blur with N samples.

    python benchmarks/bench_render.py [--samples 16] [--width 160 --height 120]
                                      [--scene scenes/paper.pov] [--lens dgauss.50mm]

One run measures, on the same scene and size:
* the pinhole render (one POV-Ray pass: the trace cost of one sample plus start-up);
* focal_blur with ``blur_samples N, N`` (the equivalent thin lens);
* the mesh path (``render_outdir``: one process traces the lens samples and writes
  their meshes; every sample is its own POV-Ray process) with 2, 4, 8 and 16
  POV-Ray processes in flight, with its parts: exit-pupil table, rays and mesh
  files (Python), POV-Ray, composite;
and prints the ratios.  Results go to stdout; redirect to benchmarks/results/.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

from povlens.plan.convert import ConvertOptions, convert
from povlens.rendering.samples import composite_outdir, lens_for, pupil_table_for, render_outdir, render_view
from povlens.plan.schema import read_plan

ROOT = Path(__file__).resolve().parent.parent


def timed(fn, *a, **kw):
    t0 = time.perf_counter()
    out = fn(*a, **kw)
    return time.perf_counter() - t0, out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=str(ROOT / "scenes" / "paper.pov"))
    ap.add_argument("--lens", default="dgauss.50mm")
    ap.add_argument("--focus", type=float, default=4.0)
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--width", type=int, default=160)
    ap.add_argument("--height", type=int, default=120)
    ap.add_argument("--in-flight", default="2,4,8,16")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    args = ap.parse_args(argv)
    base = dict(scene=args.scene, lens=args.lens, focus=args.focus, width=args.width,
                height=args.height, samples=args.samples)
    tmp = Path(tempfile.mkdtemp(prefix="povlens-bench-"))
    rows = []
    try:
        d = tmp / "views"
        convert(ConvertOptions(outdir=str(d), method="focal-blur", **base))
        t_pin, _ = timed(render_view, d, "pinhole")
        t_fb, _ = timed(render_view, d, "focal-blur")
        print(f"scene {args.scene}, lens {args.lens}, {args.width}x{args.height}, "
              f"N = {args.samples} samples, {args.jobs} jobs")
        print(f"pinhole (1 pass)                     {t_pin:8.2f} s")
        print(f"focal_blur blur_samples N,N          {t_fb:8.2f} s")
        for bs in [int(b) for b in args.in_flight.split(",")]:
            d = tmp / f"mesh{bs}"
            t_conv, _ = timed(convert, ConvertOptions(outdir=str(d), method="mesh", **base))
            plan = read_plan(d)
            t_table, _ = timed(pupil_table_for, d, plan, lens_for(plan))
            t_render, _ = timed(render_outdir, d, jobs=args.jobs, quiet=True, in_flight=bs)
            t_comp, _ = timed(composite_outdir, d)
            parts = [json.loads(p.read_text()) for p in (d / "samples").glob("*.timing.json")]
            rays = sum(p["rays_and_meshes_s"] for p in parts)
            pov = sum(p["povray_s"] for p in parts)
            total = t_conv + t_table + t_render
            rows.append((bs, total))
            print(f"mesh, {bs:2d} POV-Ray in flight: total {total:7.2f} s = convert {t_conv:.2f} "
                  f"+ pupil table {t_table:.2f} + render {t_render:.2f} (of which "
                  f"rays+meshes {rays:.2f}, POV-Ray processes {pov:.2f} summed; composite "
                  f"{t_comp:.2f}); "
                  f"{total / t_fb:.1f}x focal_blur, {total / (args.samples * t_pin):.2f}x "
                  f"N pinhole passes")
        best = min(rows, key=lambda r: r[1])
        print(f"best mesh setting: {best[0]} POV-Ray processes in flight, "
              f"{best[1]:.2f} s = "
              f"{best[1] / t_fb:.1f}x focal_blur with the same N")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
