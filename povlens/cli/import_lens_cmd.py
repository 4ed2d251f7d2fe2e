"""``povlens import-lens SOURCE -o OUT.dat``: a lentil or Zemax design as a Kolb/pbrt lens file."""

from __future__ import annotations

import argparse
import math

from povlens.api import import_lens
from povlens.errors import UsageError
from povlens.lens.importers import ZEMAX, source_format
from povlens.lens.import_lentil import list_lentil
from povlens.lens.paraxial import anamorphic_data, paraxial_data, primary_meridian
from povlens.cli.common import positive_float, print_json


def register(sub) -> None:
    p = sub.add_parser(
        "import-lens", help="import a lens from a lentil database or a Zemax .zmx file",
        description="Read a lens design from a lentil lens database (lenses.json: pick the "
                    "entry with --id, list them with --list) or a Zemax sequential .zmx file, "
                    "and write it as a Kolb/pbrt lens file that every povlens command takes "
                    "as LENS.  The file reads back to the same paraxial data; the source and, "
                    "per row, its surface and material are kept as comments.  Aspheres, "
                    "mirrors, tilts and other surfaces a spherical lens file cannot hold are "
                    "refused, naming the surface.")
    p.add_argument("source", metavar="SOURCE", help="lentil lenses.json or Zemax .zmx file")
    p.add_argument("-o", "--output", metavar="OUT.dat", help="the lens file to write")
    p.add_argument("--id", dest="lens_id", metavar="ID",
                   help="lentil: the entry to import (e.g. 0001)")
    p.add_argument("--adjusted", action="store_true",
                   help="lentil: the entry's optical-elements-adjusted table instead of the "
                        "patent's")
    p.add_argument("--efl", type=positive_float, metavar="MM",
                   help="scale the design to this focal length (lentil stores most designs "
                        "at 100 mm)")
    p.add_argument("--glass", action="append", type=glass_option, default=[], metavar="NAME=ND[,VD]",
                   help="Zemax: refractive index (d line) and Abbe number of a catalogue glass "
                        "the file gives none for (repeatable)")
    p.add_argument("--list", action="store_true",
                   help="lentil: list the entries (id, company, name, year, focal length)")
    p.add_argument("--json", action="store_true", help="with --list: print JSON")
    p.set_defaults(func=run)


def glass_option(text: str) -> tuple[str, tuple[float, float]]:
    """``NAME=ND[,VD]`` -> (NAME, (nd, vd)) (argparse type)."""
    name, sep, values = text.partition("=")
    try:
        nums = [float(v) for v in values.split(",")] if sep else []
    except ValueError:
        nums = []
    if not name.strip() or len(nums) not in (1, 2) or not all(map(math.isfinite, nums)) \
            or nums[0] < 1 or (len(nums) == 2 and nums[1] < 0):
        raise argparse.ArgumentTypeError(
            f"'{text}': give NAME=ND or NAME=ND,VD (e.g. N-BK7=1.5168,64.17)")
    return name.strip(), (nums[0], nums[1] if len(nums) == 2 else 0.0)


def _list(args) -> int:
    if source_format(args.source) == ZEMAX:
        raise UsageError(f"{args.source} is a Zemax file, which holds one lens; --list is for "
                         f"a lentil database", "leave out --list and give -o OUT.dat")
    entries = list_lentil(args.source)
    if args.json:
        print_json([e.to_dict() for e in entries])
        return 0
    print(f"{'id':<6} {'company':<22} {'name':<24} {'year':>4} {'focal length':>12}  surfaces")
    for e in entries:
        fl = "" if e.focal_length_mm is None else f"{e.focal_length_mm:g} mm"
        adj = "  (+ adjusted)" if e.has_adjusted else ""
        print(f"{e.lens_id:<6} {e.company:<22} {e.name:<24} {e.year or '':>4} {fl:>12}  "
              f"{e.surfaces}{adj}")
    return 0


def run(args) -> int:
    if args.list:
        return _list(args)
    if not args.output:
        raise UsageError("give the lens file to write with -o OUT.dat",
                         "or --list to see the entries of a lentil database")
    lens = import_lens(args.source, args.output, lens_id=args.lens_id, efl_mm=args.efl,
                       adjusted=args.adjusted, glasses=dict(args.glass) or None)
    p = paraxial_data(lens, primary_meridian(lens))
    title = lens.comments[0] if lens.comments else args.source
    print(f"wrote {args.output}: {title}")
    print(f"  {lens.n_surfaces} rows, EFL {p.efl:.4f} mm, F/{p.f_number:.3f}, "
          f"stop diameter {p.stop_diameter:.4f} mm, total track {p.total_track:.4f} mm")
    if lens.is_anamorphic:
        a = anamorphic_data(lens)
        efl = {m: f"{v:.4f} mm" if math.isfinite(v) else "none (afocal)"
               for m, v in (("x", a.efl_x_mm), ("y", a.efl_y_mm))}
        print(f"  anamorphic: EFL_x {efl['x']}, EFL_y {efl['y']}, squeeze EFL_y/EFL_x "
              f"{a.squeeze:.4f}")
    return 0
