"""Exit-pupil sampling: povlens's tables against pbrt's 64 boxes and naive
rear-element sampling, for every shipped lens.

    python benchmarks/bench_pupil.py [--pbrt-rays 1048576] [--samples 1024] [--radii 64]

Every lens focused at 10 m (thick-lens film distance, pbrt's method), stop as in
the file, 35 mm film diagonal.  For each sampler: the fraction of the rays it
proposes that get through the lens (worst and mean over film radii evenly
spread over the radii where any ray gets through; Sobol points), and its build
time.  pbrt's boxes are built by its procedure with ``--pbrt-rays`` per interval
(pbrt: 2^20; fewer gives an estimated build time and boxes grown more,
2 |diag| / sqrt(n)).  povlens's build time is the median of three builds.
A second povlens table on pbrt's plane (rear vertex) shows what the choice of
sampling plane changes.  Everything printed comes from this one run; pin to one
core with ``taskset -c 0`` for a one-core figure (numpy threads are set to 1).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from povlens.lens.focus import thick_lens_film_distance_mm  # noqa: E402
from povlens.lens.paraxial import paraxial_data  # noqa: E402
from povlens.lens.prescription import read_lens  # noqa: E402
from povlens.pupil.build import build_pupil_table  # noqa: E402
from povlens.pupil.baselines import (PBRT_INTERVALS, PBRT_RAYS_PER_INTERVAL,  # noqa: E402
                                     NaiveRearElement, PbrtBoxes)

LENS_DIR = Path(__file__).resolve().parent.parent / "lenses"


def pass_stats(sampler, radii, n, seed):
    pf = sampler.pass_fraction(radii, n_samples=n, seed=seed)
    f = pf.fraction
    return float(f.min()), float(f.mean())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pbrt-rays", type=int, default=PBRT_RAYS_PER_INTERVAL,
                    help="rays per interval for pbrt's boxes (pbrt: 1048576)")
    ap.add_argument("--samples", type=int, default=1024, help="Sobol samples per film radius")
    ap.add_argument("--radii", type=int, default=64, help="film radii per lens")
    ap.add_argument("--lenses", nargs="*", default=None, help="lens names (default: all)")
    args = ap.parse_args(argv)
    names = args.lenses or sorted(p.name for p in LENS_DIR.glob("*.dat"))
    hd = 17.5
    focus = 10_000.0
    scale = PBRT_RAYS_PER_INTERVAL / args.pbrt_rays

    print(f"# bench_pupil.py: {len(names)} lenses, focus 10 m (thick lens), stop as in the file, "
          f"35 mm film diagonal")
    print(f"# python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}, "
          f"{os.cpu_count()} cpus, OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}")
    print(f"# pass fraction: {args.samples} scrambled Sobol samples at the midpoints of "
          f"{args.radii} equal bands of [0, r_max] (r_max = 17.5 mm, or the radius beyond "
          f"which no ray gets through); worst / mean")
    print(f"# pbrt boxes: {PBRT_INTERVALS} intervals x {args.pbrt_rays} Halton rays "
          f"(points already inside the box are not traced, as in pbrt)"
          + ("" if scale == 1 else "; build time at 2^20 estimated from the traced fraction "
             "and the tracer's cost per ray"))
    print()
    rows = []
    for name in names:
        lens = read_lens(LENS_DIR / name)
        fd = thick_lens_film_distance_mm(lens, focus)
        n_f = paraxial_data(lens).f_number
        times, table = [], None
        for _ in range(3):
            t0 = time.perf_counter()
            table = build_pupil_table(lens, fd, hd)
            times.append(time.perf_counter() - t0)
        t_table = statistics.median(times)
        r_max = table.vignetted_beyond_mm or hd
        radii = (np.arange(args.radii) + 0.5) / args.radii * r_max  # band midpoints
        t0 = time.perf_counter()
        rear = build_pupil_table(lens, fd, hd, plane="rear-vertex")
        t_rear = time.perf_counter() - t0
        boxes = PbrtBoxes.build(lens, fd, hd, rays_per_interval=args.pbrt_rays)
        naive = NaiveRearElement.build(lens, fd, hd)
        row = {
            "lens": name.removesuffix(".dat"), "N": n_f, "fd": fd,
            "vig": table.vignetted_beyond_mm,
            "t_table": t_table, "knots": table.n_knots, "angles": table.n_angles,
            "rays_table": table.stats["rays_traced"],
            "pass_table": pass_stats(table, radii, args.samples, 1),
            "t_rear": t_rear, "knots_rear": rear.n_knots, "angles_rear": rear.n_angles,
            "pass_rear": pass_stats(rear, radii, args.samples, 1),
            "t_pbrt": boxes.build_time_s, "t_pbrt_full": boxes.build_time_at_pbrt_count_s(),
            "rays_pbrt": boxes.rays_traced, "pass_pbrt": pass_stats(boxes, radii, args.samples, 1),
            "pass_naive": pass_stats(naive, radii, args.samples, 1),
        }
        if table.vignetted_beyond_mm is not None:
            near = table.vignetted_beyond_mm - np.array([1e-1, 1e-2, 1e-3, 1e-4])
            row["near_cutoff"] = (near, table.pass_fraction(near, n_samples=args.samples,
                                                            seed=1).fraction,
                                  table.area_mm2(near) / table.area_mm2(0.0)[0])
        rows.append(row)
        print(f"  done {row['lens']}", file=sys.stderr, flush=True)

    print("pass fraction of sampled rays (worst / mean over film radii with rays)")
    print(f"{'lens':<20} {'F/':>5} {'r_max':>6}  {'povlens table':>15}  {'pbrt 64 boxes':>15}  "
          f"{'naive rear':>15}  {'table/pbrt':>10}")
    for r in rows:
        rm = f"{r['vig']:.2f}" if r["vig"] else "17.50"
        pt, pb, pn = r["pass_table"], r["pass_pbrt"], r["pass_naive"]
        print(f"{r['lens']:<20} {r['N']:5.2f} {rm:>6}  {pt[0]:6.3f} / {pt[1]:5.3f}  "
              f"{pb[0]:6.3f} / {pb[1]:5.3f}  {pn[0]:6.3f} / {pn[1]:5.3f}  "
              f"{pt[1] / pb[1]:9.2f}x")
    for r in rows:
        if "near_cutoff" in r:
            near, frac, area = r["near_cutoff"]
            print(f"  {r['lens']}: no ray beyond {r['vig']:.4f} mm (vignetted, weight 0); "
                  f"povlens pass fraction at " + ", ".join(
                      f"{r['vig'] - x:.0e} mm inside: {f:.3f} (area {a:.1e} of axial)"
                      for x, f, a in zip(near, frac, area)))
    print()
    print("build time (s)")
    print(f"{'lens':<20} {'povlens':>8} {'knots x M':>10} {'rays':>9}  {'pbrt':>9} "
          f"{'pbrt rays':>11}  {'pbrt/povlens':>12}  {'naive':>6}")
    for r in rows:
        print(f"{r['lens']:<20} {r['t_table']:8.3f} {r['knots']:>4} x {r['angles']:<3} "
              f"{r['rays_table']:>9,}  {r['t_pbrt_full']:9.2f} {r['rays_pbrt']:>11,}  "
              f"{r['t_pbrt_full'] / r['t_table']:11.0f}x  {0.0:6.3f}")
    print()
    print("sampling plane: the same tables on pbrt's rear-vertex plane")
    print(f"{'lens':<20} {'exit-pupil plane':>30}  {'rear-vertex plane':>30}")
    for r in rows:
        pt, pr_ = r["pass_table"], r["pass_rear"]
        print(f"{r['lens']:<20} {r['knots']:>4} x {r['angles']:<3} {r['t_table']:6.3f} s "
              f"{pt[0]:.3f}/{pt[1]:.3f}  {r['knots_rear']:>4} x {r['angles_rear']:<3} "
              f"{r['t_rear']:6.3f} s {pr_[0]:.3f}/{pr_[1]:.3f}")
    print()
    d = next((r for r in rows if r["lens"] == "dgauss.50mm"), None)
    if d:
        print(f"dgauss.50mm at F/{d['N']:.2f}, 35 mm diagonal: povlens table {d['t_table']:.3f} s "
              f"({d['rays_table']:,} rays) vs pbrt's 64 x 2^20 procedure {d['t_pbrt_full']:.1f} s "
              f"({'measured' if scale == 1 else 'estimated'}, {d['rays_pbrt']:,} rays traced): "
              f"{d['t_pbrt_full'] / d['t_table']:.0f}x faster; mean pass fraction "
              f"{d['pass_table'][1]:.3f} vs {d['pass_pbrt'][1]:.3f} (pbrt) and "
              f"{d['pass_naive'][1]:.3f} (naive)")


if __name__ == "__main__":
    main()
