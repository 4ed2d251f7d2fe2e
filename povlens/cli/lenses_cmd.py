"""``povlens lenses``: the bundled lenses, with what to pick them by and where they come from."""

from __future__ import annotations

from povlens.lens.bundled import bundled_lenses
from povlens.lens.film import DEFAULT_FILM_DIAGONAL_MM
from povlens.cli.common import positive_float, print_json


def register(sub) -> None:
    p = sub.add_parser(
        "lenses", help="list the bundled lenses: focal length, f-number, field of view, source",
        description="List the lenses that come with povlens (give the name as LENS): paraxial "
                    "focal length, f-number wide open, the diagonal field of view on the film "
                    "(real chief ray from the film corner, focused at infinity), and where "
                    "each lens comes from (SOURCES.md next to the lens files).")
    p.add_argument("--film-diagonal", type=positive_float, default=DEFAULT_FILM_DIAGONAL_MM,
                   metavar="MM", help="film diagonal for the field of view (default %(default)g mm)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=run)


def fov_text(b) -> str:
    """The field of view as the table shows it."""
    if b.field_of_view_deg is None:
        return "-"
    text = f"{b.field_of_view_deg:.1f} deg"
    if b.image_circle_mm is not None:
        text += f" (image circle {b.image_circle_mm:.1f} mm)"
    return text


def run(args) -> int:
    lenses = bundled_lenses(args.film_diagonal)
    if args.json:
        print_json([b.to_dict() for b in lenses])
        return 0
    print(f"{'name':<20} {'EFL mm':>8} {'f-number':>8}  {'diagonal FOV':<32} lens / source")
    for b in lenses:
        print(f"{b.name:<20} {b.efl_mm:>8.2f} {b.f_number:>8.2f}  {fov_text(b):<32} "
              f"{b.description or '-'}")
        print(f"{'':<72} {b.source}")
    print(f"\nfield of view: diagonal, on a {args.film_diagonal:g} mm film diagonal, real chief "
          f"ray at infinity focus; '-' where no chief ray reaches the film")
    return 0
