"""``povlens check LENS``: the vectorized tracer against the reference tracer."""

from __future__ import annotations

import math

from povlens.lens.check import check_lens
from povlens.lens.film import DEFAULT_FILM_DIAGONAL_MM
from povlens.lens.focus import LENS_SIDE_UNITS, UNITS_MM, thick_lens_film_distance_mm, to_mm
from povlens.cli.common import add_lens_command, distance, load_lens, positive_float, print_json


def register(sub) -> None:
    p = add_lens_command(
        sub, "check", run,
        help="check the fast tracer against the reference tracer",
        description="Trace many rays from film points across the frame toward "
                    "points across the rear element with both the vectorized and "
                    "the one-ray-at-a-time reference tracer, and report the "
                    "largest differences.  Exit status 1 when positions differ "
                    "by more than 1e-9 mm, directions by more than 1e-12, or the "
                    "two disagree on a blocked ray away from an aperture edge.")
    p.add_argument("--film-distance", type=positive_float, metavar="MM",
                   help="rear vertex to film, mm (default: focused by --focus)")
    p.add_argument("--focus", type=distance, default=math.inf, metavar="D",
                   help="object distance from the film in --units (default inf)")
    p.add_argument("--units", default=LENS_SIDE_UNITS, choices=sorted(UNITS_MM))
    p.add_argument("--film-diagonal", type=positive_float, default=DEFAULT_FILM_DIAGONAL_MM,
                   metavar="MM", help="film diagonal in mm (default %(default)g)")
    p.add_argument("--json", action="store_true", help="print JSON")


def run(args) -> int:
    lens = load_lens(args)
    film = args.film_distance
    if film is None:
        film = thick_lens_film_distance_mm(lens, to_mm(args.focus, args.units))
    report = check_lens(lens, film, film_diagonal_mm=args.film_diagonal)
    if args.json:
        print_json(report.to_dict())
    else:
        print(report.format_text())
    return 0 if report.ok else 1
