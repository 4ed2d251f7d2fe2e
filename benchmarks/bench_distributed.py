"""Lens samples on Dask: what a task costs beyond its render, and the scaling it allows.

    python3 benchmarks/bench_distributed.py [--size 640x480] [--samples 16,64]
        [--scene paper.pov] [--lens dgauss.50mm] [--no-1080p] [--no-picture]

The same render (mesh method, field meshes, focus 4 m), converted once per sample
count, is rendered from a copy of that folder (plan, pupil table, wrappers; no samples):

* ``local``: today's pipeline (:func:`povlens.rendering.driver.render_outdir`, all
  cores, 4 POV-Ray processes in flight per core);
* ``LocalCluster 1x1``: Dask's ``LocalCluster``, 1 worker process of 1 thread
  (:func:`povlens.cluster.client.render_outdir_on_cluster`), default group size (a
  task renders its group with 4 POV-Ray in flight per core) and group size 1;
* ``scheduler + 2``: a ``dask scheduler`` and two ``dask worker`` processes (no nanny,
  one thread each) started here on 127.0.0.1, reached over TCP, as a cluster is;
  default group size and group size 1.

Each cluster renders a 2-sample copy first (untimed: the workers' imports and first
trace are a once-per-worker cost, reported apart as ``warm-up``).  Per task, from the
workers' own timings (:func:`povlens.cluster.worker.render_group`): POV-Ray and tracing
time, the partial sums, the task's wall time; on the client, the time to write the
result and add it, the bytes back.

Then at 1920x1080: 2 samples one at a time (a sample's POV-Ray and tracing time on one
core, EXR size, the client's time to read and add it), and a group of 8 samples both
locally and as one task on a 1-worker LocalCluster (its wall time with 4 POV-Ray in
flight per core, the partial's size, the client's time to write and add it).  From
those, the estimate of a 1920x1080, 256-sample render on 10 and 100 machines like this
one: a small simulation of tasks in waves and the client taking results in one at a
time as they arrive, overlapped with the rendering (as the client does).  Writes
``benchmarks/results/distributed.txt`` and (unless ``--no-picture``)
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
from povlens.cluster.client import render_outdir_on_cluster         # noqa: E402
from povlens.plan.convert import ConvertOptions, convert            # noqa: E402
from povlens.plan.schema import read_plan                           # noqa: E402
from povlens.rendering.driver import render_outdir  # noqa: E402
from povlens.rendering.folder_composite import composite_outdir  # noqa: E402
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
    convert(ConvertOptions.of(scene=str(scene), lens=lens, focus=4.0, outdir=str(out),
                           width=size[0], height=size[1], method="mesh", samples=samples))
    return out


def _row(name: str, wall: float, stats: dict | None, local_wall: float | None = None,
         threads: int = 1) -> dict:
    row = {"name": name, "wall_s": wall, "local_wall_s": local_wall}
    if stats:
        t = stats["tasks"]
        samples = sum(len(x["ks"]) for x in t)
        row.update(
            samples=samples, group_size=stats["group_size"], tasks=len(t),
            povray_s=sum(x["povray_s"] for x in t) / samples,
            trace_s=sum(x["rays_and_meshes_s"] for x in t) / samples,
            sums_s=statistics.median(x["sums_s"] for x in t),
            task_s=statistics.median(x["task_s"] for x in t),
            client_s=statistics.median(x["client_s"] for x in t),
            result_bytes=statistics.median(x["result_bytes"] for x in t),
            in_flight=max(x["in_flight"] for x in t),
            bundle_bytes=stats["bundle_bytes"],
            # every second a worker thread spent not rendering, per sample (meaningful
            # with one POV-Ray per task, group size 1)
            overhead_s=(wall * threads - sum(x["povray_s"] + x["rays_and_meshes_s"]
                                             for x in t)) / samples)
    return row


def _timed_cluster(name, scheduler, base, tmp, warm, group_size=None, local_wall=None,
                   threads=1):
    if name not in warm:            # a new cluster: imports and first trace, untimed
        _fresh_copy(base, tmp / f"{name}-warm", samples=2)
        t0 = time.perf_counter()
        render_outdir_on_cluster(tmp / f"{name}-warm", scheduler, quiet=True)
        warm[name] = time.perf_counter() - t0
    out = _fresh_copy(base, tmp / f"{name}-{base.name}-{group_size}".replace(" ", "_"))
    t0 = time.perf_counter()
    _, stats = render_outdir_on_cluster(out, scheduler, quiet=True, group_size=group_size)
    label = f"{name} G={stats['group_size']}"
    return _row(label, time.perf_counter() - t0, stats, local_wall, threads), out


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
    """Per-sample costs at 1920x1080, one sample at a time (group size 1's task)."""
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


def _hd_group(tmp: Path, scene: Path, lens: str, warm_base: Path, n: int = 8) -> dict:
    """A group of ``n`` samples at 1920x1080: rendered here (local pipeline) and as one
    task on a LocalCluster of 1 worker (1 thread, 4 POV-Ray in flight per core)."""
    from distributed import LocalCluster
    base = _convert(tmp, scene, lens, (1920, 1080), n)
    out = _fresh_copy(base, tmp / "hd-local")
    t0 = time.perf_counter()
    render_outdir(out, quiet=True)
    local_wall = time.perf_counter() - t0
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address=None, host="127.0.0.1") as lc:
        _fresh_copy(warm_base, tmp / "hd-warm", samples=2)
        render_outdir_on_cluster(tmp / "hd-warm", lc, quiet=True)
        out = _fresh_copy(base, tmp / "hd-group")
        t0 = time.perf_counter()
        _, stats = render_outdir_on_cluster(out, lc, quiet=True, group_size=n)
        wall = time.perf_counter() - t0
    [task] = stats["tasks"]
    return {"n": n, "local_wall_s": local_wall, "wall_s": wall, "task_s": task["task_s"],
            "povray_s": task["povray_s"], "sums_s": task["sums_s"],
            "client_s": task["client_s"], "result_bytes": task["result_bytes"],
            "in_flight": task["in_flight"], "composite_after_s": stats["composite_after_s"]}


def _simulate(n: int, machines: int, per_machine: int, t_task: float, t_in: float,
              tasks: int, t_after: float) -> float:
    """Wall time of ``tasks`` tasks of ``t_task`` s, ``per_machine`` at once on each of
    ``machines``, whose results the client takes in one at a time (``t_in`` s each:
    transfer, write, add) as they arrive, overlapped with the rendering, as
    render_outdir_on_cluster does; then ``t_after`` s (the composite's last step)."""
    slots = machines * per_machine
    done = 0.0
    for i in range(tasks):
        arrival = (i // slots + 1) * t_task
        done = max(done, arrival) + t_in
    return done + t_after


def _estimate(hd: dict, grp: dict, overhead_s: float, cores: int, n: int = 256) -> list[str]:
    """Speed-up of an n-sample 1920x1080 render on M machines of ``cores`` cores."""
    from povlens.rendering.groups import choose_group_size
    t_sample = hd["povray_s"] + hd["trace_s"]              # one core, one sample
    t_machine = grp["task_s"] / grp["n"]                   # per sample, a whole machine
    # today, one machine: the same pipeline renders (4 POV-Ray in flight per core), then
    # composites after the rendering (reading each sample back); the group task's time
    # less its partial sums is that rendering
    t_render = (grp["task_s"] - grp["sums_s"]) / grp["n"]
    one = n * t_render + n * hd["composite_per_sample_s"] + grp["composite_after_s"]
    t_in_group = grp["result_bytes"] / NETWORK_BYTES_PER_S + grp["client_s"]
    t_in_sample = hd["result_bytes"] / NETWORK_BYTES_PER_S + hd["composite_per_sample_s"]
    lines = [
        f"  one sample at 1920x1080, one at a time: POV-Ray {hd['povray_s']:.2f} s + tracing "
        f"{hd['trace_s']:.2f} s on one core; {hd['result_bytes'] / 1e6:.2f} MB back; the client "
        f"reads and adds it in {hd['composite_per_sample_s'] * 1e3:.0f} ms",
        f"  a group of {grp['n']} at 1920x1080 on one worker (1 thread, {grp['in_flight']} POV-Ray "
        f"in flight): task {grp['task_s']:.1f} s ({t_machine:.2f} s a sample; the local "
        f"pipeline: {grp['local_wall_s']:.1f} s with its composite), partial sums "
        f"{grp['sums_s'] * 1e3:.0f} ms on the worker, {grp['result_bytes'] / 1e6:.1f} MB back "
        f"({grp['result_bytes'] / NETWORK_BYTES_PER_S * 1e3:.0f} ms at "
        f"{NETWORK_BYTES_PER_S / 1e6:.0f} MB/s), client write + add {grp['client_s'] * 1e3:.0f} ms, "
        f"image from the sums {grp['composite_after_s']:.2f} s",
        f"  T(1 machine, local) = {n} x {t_render:.2f} s (the task less its sums, per sample) + "
        f"{n} x {hd['composite_per_sample_s'] * 1e3:.0f} ms (composite after) + "
        f"{grp['composite_after_s']:.2f} s (image) = {one:.0f} s",
        "  T(M): tasks run in waves on the machines (a group of g: max(g x per-sample time "
        "of a machine, one sample on one core)); the client takes each result in (transfer "
        "+ write + add) one at a time as it arrives, overlapped with the rendering"]
    def t_task(g: int) -> float:    # a group of g on one machine; one sample: one core
        return max(g * t_machine, t_sample)

    for m in (10, 100):
        g = choose_group_size(n, m)
        best = min(range(1, 33), key=lambda gg: _simulate(
            n, m, 1, t_task(gg), t_in_group, math.ceil(n / gg), grp["composite_after_s"]))
        t_g = _simulate(n, m, 1, t_task(g), t_in_group, math.ceil(n / g),
                        grp["composite_after_s"])
        t_b = _simulate(n, m, 1, t_task(best), t_in_group, math.ceil(n / best),
                        grp["composite_after_s"])
        t_1 = _simulate(n, m, cores, t_sample + overhead_s, t_in_sample, n,
                        grp["composite_after_s"])
        lines.append(f"  {m:3d} machines: groups of {g} (default) {t_g:5.1f} s -> {one / t_g:4.1f}x; "
                     f"best group size {best}: {t_b:5.1f} s -> {one / t_b:4.1f}x; "
                     f"group size 1 (each sample back): {t_1:5.1f} s -> {one / t_1:4.1f}x")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--samples", default="16,64")
    ap.add_argument("--scene", default="paper.pov")
    ap.add_argument("--lens", default="dgauss.50mm")
    ap.add_argument("--no-1080p", action="store_true")
    ap.add_argument("--no-picture", action="store_true")
    args = ap.parse_args(argv)
    from distributed import LocalCluster
    size = tuple(int(v) for v in args.size.split("x"))
    counts = [int(v) for v in args.samples.split(",")]
    scene = ROOT / "scenes" / args.scene
    tmp = Path(tempfile.mkdtemp(prefix="bench_distributed."))
    rows, warm = [], {}
    cluster_out = None
    try:
        bases = {n: _convert(tmp, scene, args.lens, size, n) for n in counts}
        local = {}
        for n, base in bases.items():
            out = _fresh_copy(base, tmp / f"local-{n}")
            t0 = time.perf_counter()
            render_outdir(out, quiet=True)
            local[n] = time.perf_counter() - t0
            rows.append(_row(f"local {n}", local[n], None))
        with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                          dashboard_address=None, host="127.0.0.1") as lc:
            for n, base in bases.items():
                rows.append(_timed_cluster("LocalCluster 1x1", lc, base, tmp, warm,
                                           local_wall=local[n])[0])
            rows.append(_timed_cluster("LocalCluster 1x1", lc, bases[counts[0]], tmp, warm,
                                       group_size=1, local_wall=local[counts[0]])[0])
        address, procs = _scheduler_and_workers(tmp, 2)
        try:
            for n, base in bases.items():
                row, out = _timed_cluster("scheduler + 2", address, base, tmp, warm,
                                          local_wall=local[n], threads=2)
                rows.append(row)
                cluster_out = cluster_out or out
            rows.append(_timed_cluster("scheduler + 2", address, bases[counts[0]], tmp, warm,
                                       group_size=1, local_wall=local[counts[0]],
                                       threads=2)[0])
        finally:
            for p in procs:
                p.kill()
                p.wait()
        ser = _serialisation(bases[counts[0]])
        hd = grp = None
        if not args.no_1080p:
            hd = _hd_sample(tmp, scene, args.lens)
            grp = _hd_group(tmp, scene, args.lens, bases[counts[0]])
        lines = _report(args, size, rows, warm, ser, hd, grp)
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


def _report(args, size, rows, warm, ser, hd, grp) -> list[str]:
    from povlens.pov.executable import find_povray
    lines = [f"bench_distributed: {args.scene} {args.lens} {size[0]}x{size[1]}, {args.samples} "
             f"samples (mesh, field meshes); {datetime.date.today()}, {os.cpu_count()} cores, "
             f"Python {platform.python_version()}, {find_povray()}", "",
             f"{'run':26s} {'wall s':>7s} {'/local':>6s} {'tasks':>5s} {'in flight':>9s} "
             f"{'POV-Ray/sample':>14s} {'trace/sample':>12s} {'task':>7s} {'sums':>7s} "
             f"{'client/task':>11s} {'back/task':>10s}"]
    for r in rows:
        if "povray_s" not in r:
            lines.append(f"{r['name']:26s} {r['wall_s']:7.2f}")
            continue
        lines.append(f"{r['name'] + ' (' + str(r['samples']) + ')':26s} {r['wall_s']:7.2f} "
                     f"{r['wall_s'] / r['local_wall_s']:6.2f} {r['tasks']:5d} {r['in_flight']:9d} "
                     f"{r['povray_s']:13.3f}s {r['trace_s']:11.3f}s {r['task_s']:6.2f}s "
                     f"{r['sums_s'] * 1e3:5.0f}ms {r['client_s'] * 1e3:9.1f}ms "
                     f"{r['result_bytes'] / 1e3:7.0f} kB")
    g1 = [r for r in rows if r["name"] == "scheduler + 2 G=1"]
    lines += ["", "warm-up (first 2-sample render on a new cluster, untimed above): "
              + ", ".join(f"{k} {v:.1f} s" for k, v in warm.items()),
              f"bundle (sent once per worker): {ser['bundle_bytes'] / 1e3:.1f} kB, "
              f"pickled and unpickled in {ser['job_pickle_s'] * 1e3:.2f} ms",
              "POV-Ray/sample: process time summed over the processes in flight / samples; "
              "task, sums, client/task: medians per task (sums: the partial sums on the "
              "worker; client: writing the result and adding it)"]
    if g1:
        lines.append(f"group size 1, scheduler + 2: overhead per task (wall x threads - "
                     f"POV-Ray - tracing) / samples = {g1[0]['overhead_s'] * 1e3:.0f} ms")
    if hd is not None and grp is not None:
        overhead = g1[0]["overhead_s"] if g1 else 0.073
        lines += ["", "estimate, 1920x1080, 256 samples, machines like this one "
                  f"({os.cpu_count()} cores; a worker of 1 thread per machine for groups, "
                  f"1 thread per core for group size 1, {overhead * 1e3:.0f} ms overhead "
                  "per task measured above):",
                  *_estimate(hd, grp, overhead, os.cpu_count() or 1)]
    return lines


if __name__ == "__main__":
    raise SystemExit(main())
