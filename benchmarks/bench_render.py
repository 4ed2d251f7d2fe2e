"""Exact-lens renders against POV-Ray's focal_blur at the sizes users render, in one run.

    python benchmarks/bench_render.py [--sizes 640x480,1920x1080] [--scenes paper.pov,chart.pov]
        [--lens dgauss.50mm] [--references DIR] [--csv OUT.csv]
    python benchmarks/bench_render.py --ratios [--samples 16,64] [--equal-time] [...]

**Time to FLIP levels (default).**  For each bundled scene and size, against a converged
exact reference -- the per-pixel meshes (``--ray-mesh pixel``, the slow obvious path: a
face per pixel, each pixel's own pupil point), 256 samples at 640x480 and 128 at
1920x1080, another seed, rendered once into ``--references`` (default
``benchmarks/references/``, not in git) -- it renders with the ``povlens`` command, one
run each, timing the whole command (conversion, render, composite):

* ``pinhole``; ``focal-blur N`` (the equivalent thin lens, with the lens's vignetting map)
  for N = 4 .. 128; ``mesh N`` (the default exact path: interleaved field meshes) for
  N = 4 .. 128; ``pixel N`` (per-pixel meshes) for N = 2 .. 16 (2 .. 8 at 1080p);
  ``auto`` (``--method auto``, its own choice);

and reports each render's RMSE and mean FLIP (:func:`povlens.report.compare.flip_error`)
against the reference, then per method the time it takes to reach given FLIP levels
(log-log interpolation between its sample counts): focal_blur's floor (its best FLIP,
the thin-lens model's error), 0.6 x that floor, and fixed levels.  The goals of issue 22
are checked: the exact render reaches focal_blur's floor in no more than focal_blur's
time to reach it, and 0.6 x the floor within twice focal_blur-64's time.

**Ratios at equal N (``--ratios``).**  The earlier comparison: for each bundled scene and
size it measures, one run each, on this machine's cores:

* ``pinhole``: the pinhole view (one POV-Ray pass), after ``convert --method focal-blur``;
* ``focal_blur N``: POV-Ray's focal_blur with ``blur_samples N, N``;
* ``mesh N``: the exact lens through field ray meshes (``--method mesh``, the default
  ``--ray-mesh field``), with where its time goes: conversion (of which the grid
  certification), tracing and writing the meshes and masks (Python), POV-Ray (the
  processes' summed wall time, and one sample's parse and trace time from POV-Ray's
  own statistics), compositing; and the peak memory of the whole process tree
  (povlens and every POV-Ray it runs, summed RSS, polled every 0.1 s).

Ratios are ``mesh N / focal_blur N``, render only (render_outdir against render_view)
and with each method's conversion.  ``--equal-time`` adds, at the first size, the
error against field meshes with 256 samples and another seed of field meshes and of
per-pixel meshes (``--ray-mesh pixel``) at several sample counts, with their times.
Results go to stdout (and ``--csv``); ``benchmarks/results/render_flip.txt`` keeps the
last FLIP run, ``render.txt`` the last ratio run.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from povlens.plan.convert import ConvertOptions, convert
from povlens.plan.schema import read_plan
from povlens.pov.executable import find_povray
from povlens.rendering.field_samples import write_field_sample
from povlens.rendering.driver import render_outdir
from povlens.rendering.folder_composite import composite_outdir
from povlens.rendering.folder_inputs import lens_for, pupil_table_for
from povlens.rendering.views import render_view
from povlens.util.images import read_image

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "povlens" / "data" / "scenes"


class PeakMemory:
    """Peak summed RSS (MB) of this process and all its descendants, polled."""

    def __init__(self, interval_s: float = 0.1):
        self.interval_s, self.peak_mb = interval_s, 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    @staticmethod
    def _tree_rss_mb() -> float:
        parent, rss = {}, {}
        for d in os.listdir("/proc"):
            if not d.isdigit():
                continue
            try:
                with open(f"/proc/{d}/stat") as f:
                    parts = f.read().rsplit(")", 1)[1].split()
                parent[int(d)] = int(parts[1])
                rss[int(d)] = int(parts[21]) * os.sysconf("SC_PAGE_SIZE") / 2 ** 20
            except (OSError, IndexError, ValueError):
                pass
        total, todo = 0.0, [os.getpid()]
        children = {}
        for pid, pp in parent.items():
            children.setdefault(pp, []).append(pid)
        seen = set()
        while todo:
            pid = todo.pop()
            if pid in seen:
                continue
            seen.add(pid)
            total += rss.get(pid, 0.0)
            todo += children.get(pid, [])
        return total

    def _run(self):
        while not self._stop.is_set():
            self.peak_mb = max(self.peak_mb, self._tree_rss_mb())
            time.sleep(self.interval_s)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()


def timed(fn, *a, **kw):
    t0 = time.perf_counter()
    out = fn(*a, **kw)
    return time.perf_counter() - t0, out


def sample_parse_and_trace_s(outdir: Path) -> tuple[float, float]:
    """POV-Ray's own parse and trace time (s) of lens sample 0, rendered again with
    statistics on, one thread."""
    plan = read_plan(outdir)
    lens = lens_for(plan)
    table = pupil_table_for(outdir, plan, lens)
    s = outdir / "samples"
    inc = s / "sample_0000.inc"
    write_field_sample(plan, lens, table, outdir, 0, inc)
    pv = plan.povray
    cmd = [find_povray(), "+Ibatch_000.pov", "+O/dev/null", "-F", f"+W{pv.render_width}",
           f"+H{pv.render_height}", "Declare=PovlensFrame=0", "-D", "+WT1", "-A",
           f"+L{Path(plan.inputs.scene).parent}"]
    out = subprocess.run(cmd, cwd=s, capture_output=True, text=True).stderr
    inc.unlink(missing_ok=True)

    def seconds(label):
        m = re.search(label + r" Time:.*?\(([\d.]+) seconds\)", out)
        return float(m.group(1)) if m else float("nan")

    return seconds("Parse"), seconds("Trace")


def mesh_row(work: Path, base: dict, n: int, jobs: int, ray_mesh: str = "field",
             seed: int = 0) -> dict:
    d = work / f"mesh-{ray_mesh}-{n}-{seed}"
    with PeakMemory() as mem:
        t_conv, _ = timed(convert, ConvertOptions.of(outdir=str(d), method="mesh", samples=n,
                                                  ray_mesh=ray_mesh, seed=seed, **base))
        t_render, _ = timed(render_outdir, d, jobs=jobs, quiet=True)
    plan = read_plan(d)
    t_comp, _ = timed(composite_outdir, d, write=False)
    timing = json.loads((d / "samples" / "render.timing.json").read_text())
    row = {"n": n, "ray_mesh": ray_mesh, "convert_s": t_conv, "render_s": t_render,
           "rays_meshes_s": timing["rays_and_meshes_s"], "povray_summed_s": timing["povray_s"],
           "composite_s": t_comp, "peak_mb": mem.peak_mb, "blocked": timing["blocked"],
           "outdir": d}
    if plan.field_mesh is not None:
        fm = plan.field_mesh
        row.update(grid=f"{fm.grid[0]}x{fm.grid[1]}", eps=fm.eps,
                   max_ray_error_px=fm.max_ray_error_px)
        row["parse_s"], row["trace_s"] = sample_parse_and_trace_s(d)
    return row


def bench_size(scene: Path, lens: str, width: int, height: int, ns: list[int], jobs: int,
               work: Path) -> list[dict]:
    base = dict(scene=str(scene), lens=lens, focus=4.0, width=width, height=height)
    rows = []
    views = work / f"views-{scene.stem}-{width}"
    t_conv_fb, _ = timed(convert, ConvertOptions.of(outdir=str(views), method="focal-blur",
                                                 samples=ns[0], **base))
    t_pin, _ = timed(render_view, views, "pinhole")
    print(f"\n{scene.name}, {lens}, {width}x{height}, {jobs} cores")
    print(f"  pinhole                 {t_pin:8.2f} s")
    for n in ns:
        d = work / f"fb-{scene.stem}-{width}-{n}"
        t_c, _ = timed(convert, ConvertOptions.of(outdir=str(d), method="focal-blur", samples=n,
                                               **base))
        with PeakMemory() as mem:
            t_fb, _ = timed(render_view, d, "focal-blur")
        m = mesh_row(work / f"{scene.stem}-{width}", base, n, jobs)
        m.update(scene=scene.name, size=f"{width}x{height}", pinhole_s=t_pin, focal_blur_s=t_fb,
                 focal_blur_convert_s=t_c, focal_blur_peak_mb=mem.peak_mb)
        m["ratio_render"] = m["render_s"] / t_fb
        m["ratio_with_convert"] = (m["render_s"] + m["convert_s"]) / (t_fb + t_c)
        rows.append(m)
        print(f"  focal_blur {n:3d}          {t_fb:8.2f} s (+ convert {t_c:.2f} s, peak "
              f"{mem.peak_mb:.0f} MB)")
        print(f"  mesh {n:3d}                {m['render_s']:8.2f} s (+ convert {m['convert_s']:.2f} s)"
              f"  = {m['ratio_render']:.2f}x focal_blur ({m['ratio_with_convert']:.2f}x with "
              f"conversion); grid {m.get('grid')} eps {m.get('eps')}, max ray error "
              f"{m.get('max_ray_error_px', float('nan')):.3f} px")
        print(f"      where it goes: tracing+meshes+masks {m['rays_meshes_s']:.2f} s (Python), "
              f"POV-Ray {m['povray_summed_s']:.2f} s summed over processes; one sample: parse "
              f"{m.get('parse_s', float('nan')):.3f} s, trace {m.get('trace_s', float('nan')):.3f} s;"
              f" composite {m['composite_s']:.2f} s; {m['blocked']} samples all blocked; peak "
              f"{m['peak_mb']:.0f} MB")
        _drop_samples(m.pop("outdir"))
    return rows


def _drop_samples(d: Path) -> None:
    shutil.rmtree(d / "samples", ignore_errors=True)


def equal_time(scene: Path, lens: str, width: int, height: int, jobs: int, work: Path) -> list:
    """Error against a converged exact reference, and time, of field and per-pixel meshes."""
    base = dict(scene=str(scene), lens=lens, focus=4.0, width=width, height=height)
    ref_row = mesh_row(work / "eq", base, 256, jobs, seed=1000)
    ref = composite_outdir(ref_row["outdir"], write=False)
    out = []
    print(f"\nerror at equal time, {scene.name}, {lens}, {width}x{height}: reference = field "
          f"meshes, 256 samples, seed 1000 ({ref_row['render_s']:.1f} s)")
    for kind, ns in (("field", (8, 16, 32, 64)), ("pixel", (4, 8, 16))):
        for n in ns:
            r = mesh_row(work / "eq", base, n, jobs, ray_mesh=kind)
            img = composite_outdir(r["outdir"], write=False)
            rmse = float(np.sqrt(np.mean((img - ref) ** 2)))
            t = r["render_s"] + r["convert_s"]
            out.append({"ray_mesh": kind, "n": n, "time_s": t, "rmse": rmse})
            print(f"  {kind:5s} meshes, {n:3d} samples: {t:7.2f} s (convert + render), RMSE "
                  f"{rmse:.5f}")
            _drop_samples(r["outdir"])
    return out


# ---------------------------------------------------------------------------
# time to FLIP levels

FOCUS = 4.0
REFERENCE_SAMPLES = {640: 256, 1920: 64}
REFERENCE_SEED = 7
SWEEPS = {"focal-blur": (4, 8, 16, 32, 64, 128), "mesh": (4, 8, 16, 32, 64, 128)}
PIXEL_SWEEP = {640: (2, 4, 8, 16), 1920: (2, 4, 8)}
FIXED_LEVELS = (0.05, 0.04, 0.03, 0.02)


def write_csv(path: Path, rows: list[dict]) -> None:
    keys = sorted({k for r in rows for k in r})
    with open(path, "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=keys)
        wr.writeheader()
        wr.writerows(rows)


def povlens_render(out: Path, scene: Path, lens: str, width: int, height: int, *extra) -> float:
    """Wall time (s) of one ``povlens render`` (conversion, render, composite)."""
    cmd = [sys.executable, "-m", "povlens", "render", str(scene), "--lens", lens, "--focus",
           str(FOCUS), "--width", str(width), "--height", str(height), "-q", "-o", str(out),
           *map(str, extra)]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    t = time.perf_counter() - t0
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{r.stderr}")
    return t


def reference_image(refdir: Path, scene: Path, lens: str, width: int, height: int,
                    samples: int | None = None) -> Path:
    """The converged per-pixel reference (rendered once, kept in ``refdir``): ``samples``
    per-pixel samples (default :data:`REFERENCE_SAMPLES` for the width)."""
    n = samples or REFERENCE_SAMPLES.get(width, 128)
    out = refdir / f"{scene.stem}-{lens}-{width}x{height}-pixel{n}-seed{REFERENCE_SEED}"
    if not (out / "image.exr").exists():
        print(f"  rendering the reference ({n} per-pixel samples) into {out} ...", flush=True)
        t = povlens_render(out, scene, lens, width, height, "--method", "mesh", "--ray-mesh",
                           "pixel", "--samples", n, "--seed", REFERENCE_SEED)
        print(f"  reference rendered in {t:.0f} s", flush=True)
    return out / "image.exr"


def time_to_level(points: list[tuple[float, float]], level: float) -> float | None:
    """When a method's FLIP first gets to ``level``: points (time, FLIP) in the order of
    their sample counts, log-log interpolated between the last one above and the first
    at or below it (the first point's time if it is already there); None if never."""
    for i, (t, f) in enumerate(points):
        if f <= level:
            if i == 0:
                return t
            t0, f0 = points[i - 1]
            if f0 <= f:
                return t
            a = (math.log(level) - math.log(f0)) / (math.log(f) - math.log(f0))
            return math.exp(math.log(t0) + a * (math.log(t) - math.log(t0)))
    return None


def flip_sweep(scene: Path, lens: str, width: int, height: int, work: Path,
               refdir: Path, methods=None) -> tuple[list[dict], dict | None]:
    """Every method's renders against the reference, and the time-to-level summary."""
    from povlens.report.compare import flip_error
    ref_path = reference_image(refdir, scene, lens, width, height)
    ref = read_image(ref_path)[..., :3].astype(np.float64)
    rows = []
    label = f"{scene.name}, {lens}, {width}x{height}"
    print(f"\n{label}: reference {ref_path.parent.name}", flush=True)
    runs = [("pinhole", None, ("--method", "pinhole"))]
    runs += [("focal-blur", n, ("--method", "focal-blur", "--samples", n))
             for n in SWEEPS["focal-blur"]]
    runs += [("mesh", n, ("--method", "mesh", "--samples", n)) for n in SWEEPS["mesh"]]
    runs += [("pixel", n, ("--method", "mesh", "--ray-mesh", "pixel", "--samples", n))
             for n in PIXEL_SWEEP.get(width, (2, 4))]
    runs += [("auto", None, ())]
    if methods:
        runs = [r for r in runs if r[0] in methods]
    for method, n, extra in runs:
        out = work / f"{scene.stem}-{width}-{method}-{n}"
        t = povlens_render(out, scene, lens, width, height, *extra)
        img = read_image(out / "image.exr")[..., :3].astype(np.float64)
        flip, _ = flip_error(ref, img)
        row = {"scene": scene.name, "size": f"{width}x{height}", "method": method, "n": n,
               "time_s": t, "rmse": float(np.sqrt(np.mean((img - ref) ** 2))), "flip": flip,
               "mean_ratio": float(img.mean() / ref.mean())}
        if method == "auto":
            plan = read_plan(out)
            row["auto_choice"] = f"{plan.inputs.method} {plan.inputs.samples}"
        rows.append(row)
        print(f"  {method:10s} {'' if n is None else n:>4} {t:8.2f} s  RMSE {row['rmse']:.5f}  "
              f"FLIP {flip:.4f}  mean/ref {row['mean_ratio']:.4f}"
              + (f"  (chose {row['auto_choice']})" if method == "auto" else ""), flush=True)
        shutil.rmtree(out, ignore_errors=True)
    if methods:                         # a partial sweep: no levels
        return rows, None
    curves = {m: [(r["time_s"], r["flip"]) for r in rows if r["method"] == m]
              for m in ("focal-blur", "mesh", "pixel")}
    fb = [r for r in rows if r["method"] == "focal-blur"]
    floor = min(r["flip"] for r in fb)
    t_floor_fb = time_to_level(curves["focal-blur"], floor)
    t_fb64 = next(r["time_s"] for r in fb if r["n"] == 64)
    levels = [("focal_blur floor", floor), ("0.6 x floor", 0.6 * floor)]
    levels += [(f"{v:g}", v) for v in FIXED_LEVELS]
    summary = {"scene": scene.name, "size": f"{width}x{height}", "floor": floor,
               "focal_blur_time_to_floor_s": t_floor_fb, "focal_blur_64_s": t_fb64,
               "times": {}}
    print(f"  time to reach FLIP levels (s; '-' = not reached):")
    print(f"    {'level':18s} {'FLIP':>7s} " + " ".join(f"{m:>10s}" for m in curves))
    for name, v in levels:
        ts = {m: time_to_level(c, v) for m, c in curves.items()}
        summary["times"][name] = {"level": v, **ts}
        print(f"    {name:18s} {v:7.4f} " + " ".join(
            f"{'-' if t is None else f'{t:.1f}':>10s}" for t in ts.values()))
    t_mesh_floor = summary["times"]["focal_blur floor"]["mesh"]
    t_mesh_06 = summary["times"]["0.6 x floor"]["mesh"]
    summary["goal_floor"] = t_mesh_floor is not None and t_mesh_floor <= t_floor_fb
    summary["goal_06"] = t_mesh_06 is not None and t_mesh_06 <= 2 * t_fb64
    print(f"  goal 1: mesh reaches the floor {floor:.4f} in "
          f"{'-' if t_mesh_floor is None else f'{t_mesh_floor:.1f}'} s, focal_blur in "
          f"{t_floor_fb:.1f} s: {'met' if summary['goal_floor'] else 'NOT met'}")
    print(f"  goal 2: mesh reaches 0.6 x floor in "
          f"{'-' if t_mesh_06 is None else f'{t_mesh_06:.1f}'} s, 2 x focal_blur-64 = "
          f"{2 * t_fb64:.1f} s: {'met' if summary['goal_06'] else 'NOT met'}", flush=True)
    return rows, summary


def main_flip(args) -> int:
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    work = Path(tempfile.mkdtemp(prefix="povlens-bench-flip-"))
    rows, summaries = [], []
    print(f"# python3 benchmarks/bench_render.py, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}"
          f", {os.cpu_count()} cores; focus {FOCUS} m; one run each")
    try:
        for name in args.scenes.split(","):
            for w, h in sizes:
                r, s = flip_sweep(SCENES / name, args.lens, w, h, work, args.references,
                                  args.methods.split(",") if args.methods else None)
                rows += r
                if s is not None:
                    summaries.append(s)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    if not summaries:
        return 0
    print("\nsummary: goals (mesh to focal_blur's floor within focal_blur's time; to 0.6 x "
          "floor within 2 x focal_blur-64)")
    for s in summaries:
        print(f"  {s['scene']:10s} {s['size']:10s} floor {s['floor']:.4f}: "
              f"{'met' if s['goal_floor'] else 'NOT met'}; "
              f"{'met' if s['goal_06'] else 'NOT met'}")
    if args.csv:
        write_csv(args.csv, rows)
    return 0 if all(s["goal_floor"] and s["goal_06"] for s in summaries) else 1


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="paper.pov,chart.pov")
    ap.add_argument("--lens", default="dgauss.50mm")
    ap.add_argument("--sizes", default="640x480,1920x1080")
    ap.add_argument("--references", type=Path, default=ROOT / "benchmarks" / "references")
    ap.add_argument("--methods", help="only these (pinhole,focal-blur,mesh,pixel,auto): no "
                    "time-to-level table")
    ap.add_argument("--ratios", action="store_true",
                    help="the ratios at equal N against focal_blur (the earlier benchmark)")
    ap.add_argument("--samples", default="16,64")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--equal-time", action="store_true")
    ap.add_argument("--csv", type=Path)
    args = ap.parse_args(argv)
    if not args.ratios:
        return main_flip(args)
    ns = [int(n) for n in args.samples.split(",")]
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    work = Path(tempfile.mkdtemp(prefix="povlens-bench-render-"))
    rows = []
    try:
        for name in args.scenes.split(","):
            for w, h in sizes:
                rows += bench_size(SCENES / name, args.lens, w, h, ns, args.jobs, work)
        if args.equal_time:
            equal_time(SCENES / args.scenes.split(",")[0], args.lens, *sizes[0], args.jobs, work)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print("\nsummary: mesh N / focal_blur N (render only; with conversion)")
    for r in rows:
        print(f"  {r['scene']:10s} {r['size']:10s} N={r['n']:3d}: {r['ratio_render']:.2f}x; "
              f"{r['ratio_with_convert']:.2f}x; peak {r['peak_mb']:.0f} MB")
    if args.csv:
        write_csv(args.csv, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
