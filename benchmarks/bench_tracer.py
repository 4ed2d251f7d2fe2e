"""Tracer throughput: rays per second through dgauss.50mm on one core,
vectorized tracer against the one-ray-at-a-time reference tracer.

    python benchmarks/bench_tracer.py [--rays 1000000] [--reference-rays 20000]

Prints one table and the ratio, all from this run.  Pin to one core with
``taskset -c 0`` and OMP/OPENBLAS threads at 1 (set here) for a one-core figure.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from povlens.lens.focus import thick_lens_film_distance_mm  # noqa: E402
from povlens.lens.prescription import read_lens  # noqa: E402
from povlens.lens.reference_tracer import trace_rays_from_film as reference_trace  # noqa: E402
from povlens.lens.tracer import trace_from_film  # noqa: E402


def make_rays(lens, film_distance_mm, n, seed=0):
    """Film points across a 35 mm diagonal aimed at points over the rear element."""
    rng = np.random.default_rng(seed)
    r_film = 17.5 * np.sqrt(rng.random(n))
    a = 2 * np.pi * rng.random(n)
    film = np.column_stack([r_film * np.cos(a), r_film * np.sin(a), np.zeros(n)])
    rr = lens.aperture_radius_mm[-1] * np.sqrt(rng.random(n))
    b = 2 * np.pi * rng.random(n)
    rear = np.column_stack([rr * np.cos(b), rr * np.sin(b), np.full(n, film_distance_mm)])
    return film, rear - film


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lens", default="dgauss.50mm")
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--reference-rays", type=int, default=20_000)
    args = ap.parse_args(argv)
    lens = read_lens(args.lens)
    film_d = thick_lens_film_distance_mm(lens, 10_000.0)

    o, d = make_rays(lens, film_d, args.rays)
    t0 = time.perf_counter()
    res = trace_from_film(lens, film_d, o, d)
    t_fast = time.perf_counter() - t0

    o2, d2 = o[:args.reference_rays], d[:args.reference_rays]
    t0 = time.perf_counter()
    ref = reference_trace(lens, film_d, o2, d2)
    t_ref = time.perf_counter() - t0

    fast_rate = args.rays / t_fast
    ref_rate = args.reference_rays / t_ref
    print(f"lens {lens.source}, film distance {film_d:.4f} mm, rays across a 35 mm diagonal "
          f"toward the rear element ({res.passed.mean():.1%} pass)")
    print(f"{'tracer':<22}{'rays':>10}{'seconds':>10}{'rays/s':>14}")
    print(f"{'vectorized (numpy)':<22}{args.rays:>10}{t_fast:>10.3f}{fast_rate:>14,.0f}")
    print(f"{'reference (per ray)':<22}{args.reference_rays:>10}{t_ref:>10.3f}{ref_rate:>14,.0f}")
    print(f"speed-up: {fast_rate / ref_rate:.1f}x")
    agree = np.array_equal(res.passed[:args.reference_rays], ref.passed)
    print(f"pass/block agreement on the reference subset: {agree}")


if __name__ == "__main__":
    main()
