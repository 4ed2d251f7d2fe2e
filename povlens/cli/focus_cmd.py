"""``povlens focus LENS --distance D``: film distance by thick lens and by real rays."""

from __future__ import annotations

import math

from povlens.lens.focus import LENS_SIDE_UNITS, UNITS_MM, focus, to_mm
from povlens.cli.common import add_lens_command, distance, load_lens, print_json


def register(sub) -> None:
    p = add_lens_command(
        sub, "focus", run,
        help="film distance that focuses an object distance",
        description="Film distance (rear vertex to film, mm) that focuses LENS on "
                    "an object DISTANCE from the film plane (as on a lens barrel): "
                    "by the thick-lens equation and by an exact real-ray focus "
                    "(minimum RMS spot of the on-axis bundle through the stopped "
                    "lens).")
    p.add_argument("--distance", "-d", type=distance, required=True, metavar="D",
                   help="object distance from the film plane ('inf' for infinity)")
    p.add_argument("--units", choices=sorted(UNITS_MM), default=LENS_SIDE_UNITS,
                   help="units of --distance (default %(default)s)")
    p.add_argument("--json", action="store_true", help="print JSON")


def run(args) -> int:
    lens = load_lens(args)
    d_mm = to_mm(args.distance, args.units)
    r = focus(lens, d_mm)
    if args.json:
        out = {"lens": lens.source, "units": args.units}
        out.update(r.to_dict())
        print_json(out)
        return 0
    shown = "infinity" if math.isinf(d_mm) else f"{args.distance:g} {args.units} ({d_mm:g} mm)"
    print(f"{lens.source} focused at {shown} from the film")
    print(f"  film distance, thick lens:  {r.thick_lens_film_distance_mm:10.4f} mm  "
          f"(RMS spot {1000 * r.thick_lens_rms_spot_mm:.2f} um)")
    print(f"  film distance, real rays:   {r.exact_film_distance_mm:10.4f} mm  "
          f"(RMS spot {1000 * r.exact_rms_spot_mm:.2f} um)")
    print(f"  closest focus distance:     {r.closest_focus_mm:10.4f} mm")
    if r.astigmatic_foci_mm is not None:       # anamorphic: the thick lens is the medial
        for m in ("x", "y"):
            f = r.astigmatic_foci_mm[m]
            shown = f"{f:10.4f} mm" if math.isfinite(f) else "      none (no power there)"
            print(f"  paraxial focus in {m}:        {shown}")
    return 0
