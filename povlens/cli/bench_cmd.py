"""``povlens bench``: run time against error of the lens-sampling methods."""

from __future__ import annotations

import argparse

from povlens.errors import UsageError
from povlens.cli.common import positive_float, positive_int


def _counts(text: str) -> tuple[int, ...]:
    try:
        v = tuple(int(t) for t in text.split(",") if t.strip())
    except ValueError:
        v = ()
    if not v or min(v) < 1:
        raise argparse.ArgumentTypeError(f"'{text}' is not a list of positive counts, e.g. 4,8,16")
    return v


def register(sub) -> None:
    from povlens.bench import time_error as bench
    p = sub.add_parser(
        "bench", help="measure run time against error: naive, pbrt-box and povlens lens "
                      "sampling, and focal_blur",
        description=bench.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--auto", action="store_true",
                   help="benchmark --method auto against the fixed methods at equal error, "
                        "on each bundled scene and lens (see povlens/bench/auto.py; writes "
                        "auto.csv / auto.txt); uses --lenses, --reference-samples, --width, "
                        "--height, --jobs, --out, --keep, --quick and --scenes")
    p.add_argument("--scenes", help="--auto: comma-separated bundled scenes (default paper,chart)")
    p.add_argument("--quick", action="store_true",
                   help="the quick setting (48x36, one lens, N = 4,8,16; 1-2 minutes)")
    p.add_argument("--scene", help="POV-Ray scene (default scenes/paper.pov)")
    p.add_argument("--focus", type=positive_float, help="focus distance in m (default 4)")
    p.add_argument("--lenses", help="comma-separated lenses (default dgauss.50mm,wide.22mm,"
                                    "telephoto.250mm; quick: dgauss.50mm)")
    p.add_argument("--samples", type=_counts, metavar="N,N,...",
                   help="sample counts (default 4,8,16,32,64; quick: 4,8,16)")
    p.add_argument("--reference-samples", type=positive_int, metavar="N",
                   help="samples of the reference (default 256; quick: 64)")
    p.add_argument("--width", type=positive_int, help="image width (default 80; quick: 48)")
    p.add_argument("--height", type=positive_int, help="image height (default 60; quick: 36)")
    p.add_argument("--jobs", type=positive_int, help="parallel POV-Ray jobs (default: cores)")
    p.add_argument("--pbrt-rays", type=positive_int, metavar="N",
                   help="rays per interval of the pbrt boxes (default 65536; quick: 16384)")
    p.add_argument("--tracer-rays", type=int, metavar="N",
                   help="rays for the tracer throughput (0 skips it; default 200000)")
    p.add_argument("--out", metavar="DIR",
                   help="where the CSV, plot and summary go (default benchmarks/results)")
    p.add_argument("--keep", metavar="DIR", help="keep the render folders in DIR")
    p.add_argument("--repeats", type=positive_int, metavar="N",
                   help="--auto: runs of each timed configuration, the fastest counts "
                        "(default 2; quick: 1)")
    p.set_defaults(func=run)


def run_auto(args) -> int:
    from povlens.bench.auto import AutoBenchSettings, run_auto_bench, SCENE_FOCUS
    kw = {}
    if args.quick:
        kw.update(lenses=("telephoto.250mm",), scenes=("paper",), width=48, height=36,
                  reference_samples=64, mesh_samples=(4, 8, 16), focal_blur_samples=(4, 8, 16),
                  repeats=1, name="auto_quick")
    for name in ("reference_samples", "width", "height", "jobs", "out", "keep", "repeats"):
        v = getattr(args, name)
        if v is not None:
            kw[name] = v
    if args.samples:
        kw["mesh_samples"] = kw["focal_blur_samples"] = args.samples
    if args.lenses:
        kw["lenses"] = tuple(t.strip() for t in args.lenses.split(",") if t.strip())
    if args.scenes:
        kw["scenes"] = tuple(t.strip() for t in args.scenes.split(",") if t.strip())
        unknown = [x for x in kw["scenes"] if x not in SCENE_FOCUS]
        if unknown:
            raise UsageError(f"--scenes: {', '.join(unknown)} not a bundled scene",
                             f"use some of {', '.join(SCENE_FOCUS)}")
    if args.scene or args.focus:
        raise UsageError("--auto runs the bundled scenes at their own focus distances",
                         "use --scenes instead of --scene / --focus")
    settings = AutoBenchSettings(**kw)
    _, summary = run_auto_bench(settings, log=lambda m: print(m, flush=True))
    print(summary)
    print(f"\nwrote {settings.out}/{settings.name}.csv, .txt")
    return 0


def run(args) -> int:
    if args.auto:
        return run_auto(args)
    from povlens.bench.time_error import full_settings, quick_settings
    kw = {}
    for name in ("scene", "focus", "samples", "reference_samples", "width", "height", "jobs",
                 "pbrt_rays", "tracer_rays", "out", "keep"):
        v = getattr(args, name)
        if v is not None:
            kw[name] = v
    if args.lenses:
        kw["lenses"] = tuple(t.strip() for t in args.lenses.split(",") if t.strip())
        if not kw["lenses"]:
            raise UsageError("--lenses: no lens given")
    if args.tracer_rays is not None and args.tracer_rays < 0:
        raise UsageError("--tracer-rays: must not be negative")
    settings = (quick_settings if args.quick else full_settings)(**kw)
    from povlens.bench.time_error import run_bench
    _, summary = run_bench(settings)
    print(summary)
    print(f"\nwrote {settings.out}/{settings.name}.csv, .png, .txt")
    return 0
