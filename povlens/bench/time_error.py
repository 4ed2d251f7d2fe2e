"""Run time against error of the lens-sampling methods (``povlens bench``).

For one scene (default ``scenes/paper.pov``, focus 4 m) and each lens, a
high-sample reference is rendered with the per-pixel mesh path (povlens's exit-pupil
table, scrambled Sobol points with a per-pixel Cranley-Patterson shift, its own seed).
Then, for each sample count N, five methods render the same frame and are timed
(wall clock) and scored by RMSE against the reference (linear light, all pixels
and channels):

(a) ``naive-random``   -- the 2012 paper's method: rays toward points spread
    uniformly over the whole rear element (:class:`povlens.pupil.baselines.NaiveRearElement`),
    independent uniform random points (numpy) for film jitter and lens;
(b) ``pbrt-random``    -- pbrt-style 64-box exit-pupil bounds
    (:class:`povlens.pupil.baselines.PbrtBoxes`), independent uniform random points;
(c) ``povlens-sobol``  -- povlens's per-pixel meshes (``--ray-mesh pixel``): exit-pupil
    table and scrambled Sobol points, each pixel its own pupil point;
(d) ``focal-blur``     -- POV-Ray's ``focal_blur`` with the equivalent thin lens
    and ``blur_samples N, N`` (``povlens render-view --view focal-blur``);
(e) ``povlens-field``  -- what ``povlens render`` does by default: field meshes, one
    pupil point per sample for the whole frame (:mod:`povlens.rendering.field_samples`).

(a)-(c) and (e) use the same mesh code as ``povlens render`` (:func:`povlens.rendering.mesh_samples.render_samples`
with a sampler and a point override, then :func:`povlens.rendering.folder_composite.composite_outdir`),
one batch of samples per job, the jobs in parallel.  Timings cover rays, meshes, POV-Ray and compositing; the
one-off per-lens precomputation (table, pbrt boxes) is reported separately, and
conversion (``plan.json``) is excluded for every method.  (d) is timed over its
POV-Ray run (all cores).  Mesh composites keep the lens's vignetting (the plan
default); focal_blur has none, so its error against the reference is printed
both with and against a vignetting-free composite of the reference.

Outputs in OUT (default ``benchmarks/results`` of the source tree):
``time_error.csv`` (method, lens, samples, seconds, rmse), ``time_error.png``
(time against RMSE, log-log, one panel per lens) and ``time_error.txt`` (the
printed summary: per-lens table, the time each method needs to reach the same
RMSE as ratios against (c), interpolated in log-log, (d)'s error floor, and the
tracer throughput in rays/s, vectorized against reference, from
``benchmarks/bench_tracer.py``).  ``--quick`` writes ``time_error_quick.*``.

Settings
--------
full (default): 80x60 pixels, lenses dgauss.50mm, wide.22mm, telephoto.250mm,
    N = 4, 8, 16, 32, 64, reference 256 samples, pbrt boxes with 2^16 rays per
    interval (pbrt uses 2^20; only the build time differs), tracer 200,000 /
    5,000 rays.  About 6 minutes on 2 idle cores.
quick (``--quick``): 48x36 pixels, dgauss.50mm, N = 4, 8, 16, reference 64
    samples, 2^14 pbrt rays per interval, tracer 100,000 / 2,000 rays.  Under a
    minute on 2 idle cores (up to 2 minutes when they are shared).
Any option given explicitly overrides the setting's value.

Every number printed comes from the same run.  The reference has finite
samples: its own error adds (in quadrature) to every measured RMSE, so the
curves of the best methods flatten toward it at large N.
"""

from __future__ import annotations

import csv
import dataclasses
import importlib.util
import math
import os
import platform
import shutil
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from povlens.plan.convert import ConvertOptions, convert
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import read_plan
from povlens.pupil.baselines import NaiveRearElement, PbrtBoxes
from povlens.rendering.folder_composite import composite_outdir
from povlens.rendering.folder_inputs import exposure_for, lens_for, pupil_table_for
from povlens.rendering.mesh_samples import render_samples
from povlens.rendering.views import render_view
from povlens.util.files import atomic_output, write_text
from povlens.util.images import read_image
from povlens.util.resources import SCENE_DIR

__all__ = ["BenchSettings", "Row", "METHODS", "full_settings", "quick_settings", "run_bench",
           "render_mesh", "random_points", "time_to_error", "ROOT"]

#: The source tree (scenes/, benchmarks/) when povlens runs from a checkout.
ROOT = Path(__file__).resolve().parents[2]

#: Method name -> description, in plotting order.
METHODS = {
    "naive-random": "(a) naive rear element, random points",
    "pbrt-random": "(b) pbrt 64 boxes, random points",
    "povlens-sobol": "(c) povlens table, Sobol points",
    "focal-blur": "(d) focal_blur, blur_samples N",
    "povlens-field": "(e) povlens field meshes",
}

REFERENCE_SEED = 7919  # the reference's sample sequence differs from (c)'s (seed 0)


@dataclasses.dataclass
class BenchSettings:
    scene: str = str(SCENE_DIR / "paper.pov")
    focus: float = 4.0                      # scene units (m) from the camera location
    lenses: tuple[str, ...] = ("dgauss.50mm", "wide.22mm", "telephoto.250mm")
    samples: tuple[int, ...] = (4, 8, 16, 32, 64)
    reference_samples: int = 256
    width: int = 80
    height: int = 60
    jobs: int = 0                           # 0 = one per core
    pbrt_rays: int = 1 << 16                # rays per interval of the pbrt boxes
    tracer_rays: int = 200_000              # 0 = skip the tracer throughput
    reference_tracer_rays: int = 5_000
    seed: int = 0
    out: str = str(ROOT / "benchmarks" / "results")
    name: str = "time_error"                # output file stem
    keep: str | None = None                 # keep the render folders here

    def resolved_jobs(self) -> int:
        return self.jobs or os.cpu_count() or 1


def full_settings(**kw) -> BenchSettings:
    return BenchSettings(**kw)


def quick_settings(**kw) -> BenchSettings:
    base = dict(width=48, height=36, lenses=("dgauss.50mm",), samples=(4, 8, 16),
                reference_samples=64, pbrt_rays=1 << 14, tracer_rays=100_000,
                reference_tracer_rays=2_000, name="time_error_quick")
    base.update(kw)
    return BenchSettings(**base)


@dataclasses.dataclass(frozen=True)
class Row:
    method: str
    lens: str
    samples: int
    seconds: float
    rmse: float


# ----- rendering --------------------------------------------------------------------

def random_points(height: int, width: int, seed: int):
    """``points(k) -> (H, W, 4)`` independent uniform random points (numpy), per sample k.

    Drop-in for :func:`povlens.pupil.rays.sample_points` without stratification:
    the point set of plain Monte Carlo.  Each k has its own generator, so the
    points do not depend on the order (or thread) in which samples are made.
    """
    def points(k: int) -> np.ndarray:
        return np.random.default_rng([seed, k]).random((height, width, 4))
    return points


def render_mesh(outdir, sampler=None, points=None, jobs: int | None = None) -> np.ndarray:
    """Render every sample of a mesh plan and return the composite (not written).

    sampler : lens sampler for the rays (default: the plan's exit-pupil table).
    points : ``points(k) -> (H, W, 4)`` overriding the plan's Sobol points.
    Batches run ``jobs`` at a time (threads, each driving several POV-Ray
    processes, as :func:`povlens.rendering.mesh_samples.render_samples` does for
    :func:`povlens.rendering.mesh_samples.render_batch`).  Samples already rendered are redone.
    """
    outdir = Path(outdir)
    plan = read_plan(outdir)
    lens = lens_for(plan)
    table = pupil_table_for(outdir, plan, lens)
    exposure_for(outdir, plan, lens, table)
    sampler = table if sampler is None else sampler

    def run(b: int) -> None:
        render_samples(plan, lens, sampler, outdir, b, plan.batches[b], points=points)

    n_batches = len(plan.batches)
    jobs = max(1, min(jobs or os.cpu_count() or 1, n_batches))
    if jobs == 1:
        for b in range(n_batches):
            run(b)
    else:
        with ThreadPoolExecutor(jobs) as ex:
            list(ex.map(run, range(n_batches)))
    return composite_outdir(outdir, write=False)


def rmse(image: np.ndarray, reference: np.ndarray) -> float:
    d = np.asarray(image, np.float64)[..., :3] - np.asarray(reference, np.float64)[..., :3]
    return float(np.sqrt(np.mean(d * d)))


# ----- analysis ---------------------------------------------------------------------

def time_to_error(rows: list[Row], target: float) -> tuple[float, bool]:
    """Seconds one method needs to reach RMSE ``target``, interpolated in log-log.

    ``rows`` are one method's measurements.  Takes the first segment (by sample
    count) whose RMSE crosses the target; outside the measured range,
    extrapolates the nearest two points' power law.  Returns (seconds,
    extrapolated).
    """
    pts = sorted(rows, key=lambda r: r.samples)
    lt = np.log([r.seconds for r in pts])
    le = np.log([max(r.rmse, 1e-300) for r in pts])
    lg = math.log(target)
    if len(pts) == 1:
        # one point: assume the Monte-Carlo rate, error ~ time^-1/2
        return float(math.exp(lt[0] + 2.0 * (le[0] - lg))), True
    for i in range(len(pts) - 1):
        lo, hi = sorted((le[i], le[i + 1]))
        if lo <= lg <= hi and le[i] != le[i + 1]:
            f = (lg - le[i]) / (le[i + 1] - le[i])
            return float(math.exp(lt[i] + f * (lt[i + 1] - lt[i]))), False
    i = 0 if lg > le[0] else len(pts) - 2
    slope = (le[i + 1] - le[i]) / (lt[i + 1] - lt[i]) if lt[i + 1] != lt[i] else 0.0
    if slope >= 0:
        slope = -0.5
    return float(math.exp(lt[i] + (lg - le[i]) / slope)), True


def _slope_in_samples(rows: list[Row]) -> float:
    """Least-squares slope of log RMSE against log N (-1/2: plain Monte Carlo)."""
    if len(rows) < 2:
        return float("nan")
    x = np.log([r.samples for r in rows])
    y = np.log([r.rmse for r in rows])
    return float(np.polyfit(x, y, 1)[0])


def _equal_error_ratio(slow: list[Row], fast: list[Row]) -> tuple[float, float, bool]:
    """(target rmse, time ratio slow/fast, extrapolated) at the lowest error both reach.

    Without overlap of their error ranges, the target is the slow method's lowest
    error and the fast method's time is extrapolated (flagged).
    """
    lo = max(min(r.rmse for r in slow), min(r.rmse for r in fast))
    hi = min(max(r.rmse for r in slow), max(r.rmse for r in fast))
    target = lo if lo <= hi else min(r.rmse for r in slow)
    ts, xs = time_to_error(slow, target)
    tf, xf = time_to_error(fast, target)
    return target, ts / tf, xs or xf


def summarize(rows: list[Row], extra: dict) -> str:
    """The printed summary: per-lens tables, ratios to equal error, (d)'s floor."""
    out = []
    lenses = list(dict.fromkeys(r.lens for r in rows))
    for lens in lenses:
        info = extra.get(lens, {})
        out.append(f"\n== {lens} ==  reference: {info.get('reference_samples')} Sobol samples "
                   f"in {info.get('reference_s', float('nan')):.1f} s, mean pixel value "
                   f"{info.get('reference_mean', float('nan')):.4f}")
        out.append(f"precomputation (once per lens, not in the times below): povlens table "
                   f"{info.get('table_s', float('nan')):.2f} s, pbrt boxes "
                   f"{info.get('pbrt_s', float('nan')):.2f} s "
                   f"({info.get('pbrt_rays', 0):,} rays/interval), naive 0 s")
        out.append(f"{'method':<42}{'N':>5}{'seconds':>10}{'rmse':>12}")
        by = {m: sorted([r for r in rows if r.lens == lens and r.method == m],
                        key=lambda r: r.samples) for m in METHODS}
        for m, rs in by.items():
            for r in rs:
                out.append(f"{METHODS[m]:<42}{r.samples:>5}{r.seconds:>10.2f}{r.rmse:>12.5f}")
        slopes = ", ".join(f"{m} {_slope_in_samples(rs):+.2f}" for m, rs in by.items() if rs)
        out.append(f"log-log slope of rmse against N: {slopes}")
        if by.get("povlens-sobol"):
            for m in ("naive-random", "pbrt-random"):
                if by.get(m):
                    target, ratio, x = _equal_error_ratio(by[m], by["povlens-sobol"])
                    out.append(f"time to equal rmse {target:.5f} (log-log interpolation): "
                               f"{m} / povlens-sobol = {ratio:.1f}x"
                               f"{' (extrapolated)' if x else ''}")
        if by.get("focal-blur"):
            fb = by["focal-blur"]
            best = min(fb, key=lambda r: r.rmse)
            still = len(fb) > 1 and fb[-1].rmse < 0.8 * fb[-2].rmse
            nv = info.get("focal_blur_rmse_no_vignetting")
            line = (f"(d) focal_blur error floor: "
                    f"{'none yet, still falling; ' if still else ''}"
                    f"rmse {best.rmse:.5f} at N = {best.samples} "
                    f"({best.rmse / max(info.get('reference_mean', 1.0), 1e-300):.1%} of the mean "
                    f"pixel value)")
            if nv is not None:
                line += (f"; against the reference without vignetting {nv:.5f}")
            if by.get("povlens-sobol"):
                c = by["povlens-sobol"]
                below = [r for r in c if r.rmse < best.rmse]
                line += ("; (c) is below it from N = " + str(below[0].samples)
                         + f" ({below[0].seconds:.2f} s against {best.seconds:.2f} s)" if below
                         else "; (c) never gets below it here")
            out.append(line)
    return "\n".join(out)


def tracer_throughput(rays: int, reference_rays: int) -> str | None:
    """Rays/s of the vectorized and reference tracers, via benchmarks/bench_tracer.py."""
    path = ROOT / "benchmarks" / "bench_tracer.py"
    if rays <= 0 or not path.exists():
        return None
    spec = importlib.util.spec_from_file_location("povlens_bench_tracer", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    lens = mod.read_lens("dgauss.50mm")
    fd = mod.thick_lens_film_distance_mm(lens, 10_000.0)
    o, d = mod.make_rays(lens, fd, rays)
    t0 = time.perf_counter()
    res = mod.trace_from_film(lens, fd, o, d)
    t_fast = time.perf_counter() - t0
    t0 = time.perf_counter()
    ref = mod.reference_trace(lens, fd, o[:reference_rays], d[:reference_rays])
    t_ref = time.perf_counter() - t0
    fast, slow = rays / t_fast, reference_rays / t_ref
    agree = bool(np.array_equal(res.passed[:reference_rays], ref.passed))
    return (f"tracer throughput (dgauss.50mm, one thread, rays toward the rear element): "
            f"vectorized {fast:,.0f} rays/s ({rays:,} rays), reference {slow:,.0f} rays/s "
            f"({reference_rays:,} rays), {fast / slow:.1f}x; pass/block agreement {agree}")


def plot(rows: list[Row], path: Path, title: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    lenses = list(dict.fromkeys(r.lens for r in rows))
    fig, axes = plt.subplots(1, len(lenses), figsize=(5.2 * len(lenses), 4.4), squeeze=False)
    for ax, lens in zip(axes[0], lenses):
        for m, label in METHODS.items():
            rs = sorted([r for r in rows if r.lens == lens and r.method == m],
                        key=lambda r: r.samples)
            if not rs:
                continue
            ax.loglog([r.seconds for r in rs], [r.rmse for r in rs], "o-", label=label)
            for r in rs:
                ax.annotate(str(r.samples), (r.seconds, r.rmse), textcoords="offset points",
                            xytext=(3, 3), fontsize=7)
        ax.set_title(lens)
        ax.set_xlabel("wall time (s)")
        ax.set_ylabel("RMSE against reference (linear)")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ----- the benchmark ----------------------------------------------------------------

def _log(msg: str, quiet: bool) -> None:
    if not quiet:
        print(msg, file=sys.stderr, flush=True)


def run_bench(s: BenchSettings, quiet: bool = False) -> tuple[list[Row], str]:
    """Run the benchmark; write CSV, plot and summary to ``s.out``; return (rows, summary)."""
    jobs = s.resolved_jobs()
    samples = sorted(set(int(n) for n in s.samples))
    out = Path(s.out)
    out.mkdir(parents=True, exist_ok=True)
    work = Path(s.keep) if s.keep else Path(tempfile.mkdtemp(prefix="povlens-bench-"))
    work.mkdir(parents=True, exist_ok=True)
    rows: list[Row] = []
    extra: dict = {}
    t_start = time.perf_counter()

    def conv(name: str, lens: str, n: int, method: str, seed: int,
             ray_mesh: str = "pixel") -> Path:
        d = work / name
        convert(ConvertOptions.of(scene=s.scene, lens=lens, focus=s.focus, outdir=str(d),
                               width=s.width, height=s.height, method=method, samples=n,
                               batch_size=math.ceil(n / jobs), seed=seed, ray_mesh=ray_mesh))
        return d

    try:
        tracer = tracer_throughput(s.tracer_rays, s.reference_tracer_rays)
        for lens_name in s.lenses:
            info = extra.setdefault(lens_name, {})
            _log(f"{lens_name}: reference, {s.reference_samples} samples", quiet)
            ref_dir = conv(f"{lens_name}-reference", lens_name, s.reference_samples, "mesh",
                           REFERENCE_SEED)
            plan = read_plan(ref_dir)
            lens = lens_for(plan)
            t0 = time.perf_counter()
            pupil_table_for(ref_dir, plan, lens)
            info["table_s"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            reference = render_mesh(ref_dir, jobs=jobs)
            info["reference_s"] = time.perf_counter() - t0
            info["reference_samples"] = s.reference_samples
            info["reference_mean"] = float(reference.mean())
            reference_nv = composite_outdir(ref_dir, vignetting=False, write=False)
            fd = plan.focus.film_distance_mm
            hd = plan.film.half_diagonal_mm
            samplers = {
                "naive-random": NaiveRearElement.build(lens, fd, hd),
                "pbrt-random": PbrtBoxes.build(lens, fd, hd, rays_per_interval=s.pbrt_rays),
            }
            info["pbrt_s"] = samplers["pbrt-random"].build_time_s
            info["pbrt_rays"] = s.pbrt_rays
            cached = [RenderFolder(ref_dir).pupil_npz, RenderFolder(ref_dir).exposure_txt]
            for n in samples:
                for m in METHODS:
                    _log(f"{lens_name}: {m}, N = {n}", quiet)
                    if m == "focal-blur":
                        d = conv(f"{lens_name}-{m}-{n}", lens_name, n, "focal-blur", s.seed)
                        t0 = time.perf_counter()
                        exr = render_view(d, "focal-blur")
                        secs = time.perf_counter() - t0
                        img = read_image(exr)[..., :3].astype(np.float64)
                        if n == samples[-1]:
                            info["focal_blur_rmse_no_vignetting"] = rmse(img, reference_nv)
                    else:
                        d = conv(f"{lens_name}-{m}-{n}", lens_name, n, "mesh", s.seed,
                                 "field" if m == "povlens-field" else "pixel")
                        for f in cached:  # same lens, focus and film: reuse table/exposure
                            shutil.copy2(f, d / f.name)
                        sampler = samplers.get(m)
                        pts = (random_points(s.height, s.width,
                                             s.seed + 1000 * (1 + list(METHODS).index(m)))
                               if m not in ("povlens-sobol", "povlens-field") else None)
                        t0 = time.perf_counter()
                        img = render_mesh(d, sampler=sampler, points=pts, jobs=jobs)
                        secs = time.perf_counter() - t0
                    rows.append(Row(m, lens_name, n, secs, rmse(img, reference)))
                    if not s.keep:
                        shutil.rmtree(d, ignore_errors=True)
    finally:
        if not s.keep:
            shutil.rmtree(work, ignore_errors=True)

    total = time.perf_counter() - t_start
    header = (f"povlens bench: scene {Path(s.scene).name}, focus {s.focus} m, "
              f"{s.width}x{s.height}, N = {', '.join(map(str, samples))}, reference "
              f"{s.reference_samples} samples (seed {REFERENCE_SEED}), {jobs} jobs; "
              f"python {platform.python_version()}, {platform.machine()}, "
              f"{os.cpu_count()} cpus; total {total:.0f} s")
    summary = header + "\n" + summarize(rows, extra)
    if tracer:
        summary += "\n\n" + tracer
    csv_path = out / f"{s.name}.csv"
    with atomic_output(csv_path) as part, open(part, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["method", "lens", "samples", "seconds", "rmse"])
        for r in rows:
            w.writerow([r.method, r.lens, r.samples, f"{r.seconds:.4f}", f"{r.rmse:.6g}"])
    plot(rows, out / f"{s.name}.png",
         f"{Path(s.scene).name}, {s.width}x{s.height}, reference {s.reference_samples} samples")
    write_text(out / f"{s.name}.txt", summary + "\n")
    return rows, summary
