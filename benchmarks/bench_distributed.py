"""Lens samples on Dask: what a task costs beyond its render, and the scaling it allows.

    python3 benchmarks/bench_distributed.py [--size 640x480] [--samples 16]
        [--scene paper.pov] [--lens dgauss.50mm] [--no-1080p] [--no-picture]

The same render (mesh method, field meshes, focus 4 m), converted once, is rendered
from a copy of that folder (plan, pupil table, wrappers; no samples) four ways:

* ``local``: today's pipeline (:func:`povlens.rendering.samples.render_outdir`, all
  cores, 4 POV-Ray processes in flight per core);
* ``LocalCluster 1`` / ``LocalCluster 2``: Dask's ``LocalCluster`` with 1 and 2 worker
  processes of one thread (:func:`povlens.cluster.render.render_outdir_on_cluster`);
* ``scheduler + 2``: a ``dask scheduler`` and two ``dask worker`` processes (no nanny,
  one thread each) started here on 127.0.0.1, reached over TCP, as a cluster is.

Each cluster renders a 2-sample copy first (untimed: the workers' imports and first
trace are a once-per-worker cost, reported apart as ``warm-up``).  Per sample, from
the workers' own timings (:func:`povlens.cluster.worker.render_sample`): POV-Ray time,
tracing time (mesh and mask), and the task's other time (unpacking the bundle,
loading the plan, reading the files back); on the client, the serialisation
(pickle) time of the job and of a result, the bytes sent (bundle, once per worker) and
returned (the sample's EXR and mask), and the end-to-end overhead per task,
``(wall x workers - sum of POV-Ray and tracing) / samples``: every second a worker's
slot spent not rendering (scheduling, transfer, the client writing the files, the
ramp at the start and end), per sample.

Then one 1920x1080 render of 2 samples measures a sample's POV-Ray and tracing time
and EXR size at that size, and the estimate of a 1920x1080, 256-sample render on 10
and 100 machines like this one follows from the measured numbers (printed with its
formula).  Writes ``benchmarks/results/distributed.txt`` and (unless ``--no-picture``)
``docs/images/cluster_paper.png``: the ``scheduler + 2`` render, halved.
Heavy: run it alone on the machine.
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import pickle
import platform
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from povlens.cluster.bundle import make_bundle                       # noqa: E402
from povlens.cluster.render import render_outdir_on_cluster         # noqa: E402
from povlens.plan.convert import ConvertOptions, convert            # noqa: E402
from povlens.plan.schema import read_plan                           # noqa: E402
from povlens.rendering.samples import composite_outdir, render_outdir  # noqa: E402
from povlens.util.images import read_image, write_png_srgb          # noqa: E402

#: Network bandwidth assumed for the estimate (1 Gbit/s Ethernet, bytes per second).
NETWORK_BYTES_PER_S = 110e6


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _fresh_copy(base: Path, dest: Path, samples: int | None = None) -> Path:
    """The converted folder without rendered samples (``samples`` fewer lens samples)."""
    shutil.copytree(base, dest, ignore=shutil.ignore_patterns("sample_*", "*.done",
                                                              "*.timing.json", "image.*"))
    if samples is not None:
        import json
        p = dest / "plan.json"
        d = json.loads(p.read_text())
        d["inputs"]["samples"] = samples
        p.write_text(json.dumps(d, indent=1) + "\n")
    return dest


def _convert(tmp: Path, scene: Path, lens: str, size: tuple[int, int], samples: int) -> Path:
    out = tmp / f"base_{size[0]}x{size[1]}_{samples}"
    convert(ConvertOptions(scene=str(scene), lens=lens, focus=4.0, outdir=str(out),
                           width=size[0], height=size[1], method="mesh", samples=samples))
    return out


def _row(name: str, wall: float, workers: int, stats: dict | None) -> dict:
    row = {"name": name, "wall_s": wall, "workers": workers}
    if stats:
        t = stats["tasks"]
        row.update(
            povray_s=statistics.median(x["povray_s"] for x in t if x["povray_s"] > 0),
            trace_s=statistics.median(x["rays_and_meshes_s"] for x in t),
            task_other_s=statistics.median(x["task_s"] - x["povray_s"] - x["rays_and_meshes_s"]
                                           for x in t),
            result_bytes=statistics.median(x["result_bytes"] for x in t),
            bundle_bytes=stats["bundle_bytes"],
            end_to_end_overhead_s=(wall * workers - sum(x["povray_s"] + x["rays_and_meshes_s"]
                                                        for x in t)) / len(t),
            scheduled_s=stats["connect_s"] + stats["scatter_s"])
    return row


def _timed_cluster(name, scheduler, base, tmp, workers, samples, warm):
    _fresh_copy(base, tmp / f"{name}-warm", samples=2)
    t0 = time.perf_counter()
    render_outdir_on_cluster(tmp / f"{name}-warm", scheduler, quiet=True)
    warm[name] = time.perf_counter() - t0
    out = _fresh_copy(base, tmp / name)
    t0 = time.perf_counter()
    _, stats = render_outdir_on_cluster(out, scheduler, quiet=True)
    return _row(name, time.perf_counter() - t0, workers, stats), out


def _scheduler_and_workers(tmp: Path, n: int):
    address = f"tcp://127.0.0.1:{_free_port()}"
    env = dict(os.environ, TMPDIR=str(tmp))
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host",
                               "127.0.0.1", "--port", address.rsplit(":", 1)[1],
                               "--no-dashboard"], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, env=env)]
    for _ in range(n):
        procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker",
                                       address, "--nthreads", "1", "--no-nanny",
                                       "--no-dashboard", "--host", "127.0.0.1",
                                       "--local-directory", str(tmp)],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                      env=env))
    from distributed import Client
    with Client(address, timeout="60s", set_as_default=False) as c:
        c.wait_for_workers(n, timeout=120)
    return address, procs


def _serialisation(base: Path) -> dict:
    plan = read_plan(base)
    key, data = make_bundle(base, plan)
    job = {"outdir": str(base), "key": key, "bundle": data, "shared": False}
    t0 = time.perf_counter()
    for _ in range(20):
        pickle.loads(pickle.dumps(job))
    job_s = (time.perf_counter() - t0) / 20
    return {"job_pickle_s": job_s, "bundle_bytes": len(data)}


def _hd_sample(tmp: Path, scene: Path, lens: str) -> dict:
    base = _convert(tmp, scene, lens, (1920, 1080), 2)
    out = _fresh_copy(base, tmp / "hd")
    t0 = time.perf_counter()
    render_outdir(out, jobs=1, quiet=True, in_flight=1)   # one sample at a time
    wall = time.perf_counter() - t0
    import json
    t = json.loads((out / "samples" / "render.timing.json").read_text())
    exr = sorted((out / "samples").glob("sample_*.exr"))
    masks = sorted((out / "samples").glob("sample_*.mask.npy"))
    t1 = time.perf_counter()
    composite_outdir(out, write=False)
    comp = time.perf_counter() - t1
    n = t["samples"]
    return {"povray_s": t["povray_s"] / n, "trace_s": t["rays_and_meshes_s"] / n,
            "wall_s": wall, "result_bytes": (sum(p.stat().st_size for p in exr + masks)
                                             / max(1, len(exr))),
            "composite_per_sample_s": comp / n}


def _estimate(hd: dict, overhead_s: float, cores: int, n: int = 256) -> list[str]:
    """Speed-up of an n-sample 1920x1080 render on M machines of ``cores`` cores."""
    t_sample = hd["povray_s"] + hd["trace_s"]              # one core, one sample
    t_client = hd["result_bytes"] / NETWORK_BYTES_PER_S    # into the client, serial
    t_comp = n * hd["composite_per_sample_s"]
    one = n * t_sample / cores + t_comp                    # today, one machine
    lines = [f"  one sample at 1920x1080: POV-Ray {hd['povray_s']:.2f} s + tracing "
             f"{hd['trace_s']:.2f} s on one core; {hd['result_bytes'] / 1e6:.2f} MB back "
             f"({t_client * 1e3:.0f} ms at {NETWORK_BYTES_PER_S / 1e6:.0f} MB/s); composite "
             f"{hd['composite_per_sample_s'] * 1e3:.0f} ms per sample",
             f"  T(M) = ceil({n} / (M x {cores})) x (t_sample + overhead) + max(0, {n} x "
             f"t_transfer - that) + composite; T(1 machine, local) = {n} x t_sample / "
             f"{cores} + composite = {one:.0f} s"]
    for m in (10, 100):
        waves = math.ceil(n / (m * cores))
        compute = waves * (t_sample + overhead_s)
        t = compute + max(0.0, n * t_client - compute) + t_comp
        lines.append(f"  {m:3d} machines ({m * cores} slots): {waves} wave(s), "
                     f"{t:.1f} s -> speed-up {one / t:.1f}x (ideal {min(n, m * cores) / cores:.0f}x)")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--scene", default="paper.pov")
    ap.add_argument("--lens", default="dgauss.50mm")
    ap.add_argument("--no-1080p", action="store_true")
    ap.add_argument("--no-picture", action="store_true")
    args = ap.parse_args(argv)
    from distributed import LocalCluster
    size = tuple(int(v) for v in args.size.split("x"))
    scene = ROOT / "scenes" / args.scene
    tmp = Path(tempfile.mkdtemp(prefix="bench_distributed."))
    rows, warm = [], {}
    try:
        base = _convert(tmp, scene, args.lens, size, args.samples)
        out = _fresh_copy(base, tmp / "local")
        t0 = time.perf_counter()
        render_outdir(out, quiet=True)
        rows.append(_row("local", time.perf_counter() - t0, os.cpu_count() or 1, None))
        for n in (1, 2):
            with LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                              dashboard_address=None, host="127.0.0.1") as lc:
                rows.append(_timed_cluster(f"LocalCluster {n}", lc, base, tmp, n,
                                           args.samples, warm)[0])
        address, procs = _scheduler_and_workers(tmp, 2)
        try:
            row, cluster_out = _timed_cluster("scheduler + 2", address, base, tmp, 2,
                                              args.samples, warm)
            rows.append(row)
        finally:
            for p in procs:
                p.kill()
                p.wait()
        ser = _serialisation(base)
        hd = None if args.no_1080p else _hd_sample(tmp, scene, args.lens)
        lines = _report(args, size, rows, warm, ser, hd)
        if not args.no_picture:
            img = read_image(cluster_out / "image.exr")[..., :3].astype(np.float64)
            h, w = img.shape[0] // 2 * 2, img.shape[1] // 2 * 2
            half = img[:h, :w].reshape(h // 2, 2, w // 2, 2, 3).mean(axis=(1, 3))
            write_png_srgb(ROOT / "docs" / "images" / "cluster_paper.png", half)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    text = "\n".join(lines) + "\n"
    print(text, end="")
    (ROOT / "benchmarks" / "results" / "distributed.txt").write_text(text)
    return 0


def _report(args, size, rows, warm, ser, hd) -> list[str]:
    from povlens.pov.executable import find_povray
    lines = [f"bench_distributed: {args.scene} {args.lens} {size[0]}x{size[1]}, {args.samples} "
             f"samples (mesh, field meshes); {datetime.date.today()}, {os.cpu_count()} cores, "
             f"Python {platform.python_version()}, {find_povray()}", "",
             f"{'run':16s} {'wall s':>7s} {'POV-Ray/sample':>15s} {'trace/sample':>13s} "
             f"{'task other':>11s} {'overhead/task':>14s} {'back/sample':>12s}"]
    for r in rows:
        if "povray_s" not in r:
            lines.append(f"{r['name']:16s} {r['wall_s']:7.2f}")
            continue
        lines.append(f"{r['name']:16s} {r['wall_s']:7.2f} {r['povray_s']:14.3f}s "
                     f"{r['trace_s']:12.3f}s {r['task_other_s'] * 1e3:9.1f}ms "
                     f"{r['end_to_end_overhead_s'] * 1e3:12.0f}ms "
                     f"{r['result_bytes'] / 1e3:9.1f} kB")
    lines += ["", "warm-up (first 2-sample render on a new cluster, untimed above): "
              + ", ".join(f"{k} {v:.1f} s" for k, v in warm.items()),
              f"bundle (sent once per worker): {ser['bundle_bytes'] / 1e3:.1f} kB, "
              f"pickled and unpickled in {ser['job_pickle_s'] * 1e3:.2f} ms",
              "task other = the task's time beyond POV-Ray and tracing on the worker; "
              "overhead/task = (wall x workers - sum of POV-Ray and tracing) / samples"]
    if hd is not None:
        sched = [r for r in rows if r["name"] == "scheduler + 2"][0]
        lines += ["", "estimate, 1920x1080, 256 samples, machines like this one "
                  f"({os.cpu_count()} cores, one worker thread per core), overhead per task "
                  f"{sched['end_to_end_overhead_s'] * 1e3:.0f} ms (scheduler + 2, measured "
                  "above):", *_estimate(hd, sched["end_to_end_overhead_s"], os.cpu_count() or 1)]
    return lines


if __name__ == "__main__":
    raise SystemExit(main())
