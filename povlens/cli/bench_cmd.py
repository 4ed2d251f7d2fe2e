"""``povlens bench``: run time against error of the lens-sampling methods."""

from __future__ import annotations

import argparse

from ..errors import UsageError
from .common import positive_float, positive_int


def _counts(text: str) -> tuple[int, ...]:
    try:
        v = tuple(int(t) for t in text.split(",") if t.strip())
    except ValueError:
        v = ()
    if not v or min(v) < 1:
        raise argparse.ArgumentTypeError(f"'{text}' is not a list of positive counts, e.g. 4,8,16")
    return v




def register(sub) -> None:
    from .. import bench
    p = sub.add_parser(
        "bench", help="measure run time against error: naive, pbrt-box and povlens lens "
                      "sampling, and focal_blur",
        description=bench.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
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
    p.set_defaults(func=run)


def run(args) -> int:
    from ..bench import full_settings, quick_settings
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
    from ..bench import run_bench
    _, summary = run_bench(settings)
    print(summary)
    print(f"\nwrote {settings.out}/{settings.name}.csv, .png, .txt")
    return 0
