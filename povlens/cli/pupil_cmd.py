"""``povlens pupil LENS --focus D``: build an exit-pupil table and compare it with
pbrt's 64 boxes and with naive rear-element sampling."""

from __future__ import annotations

import argparse
import dataclasses
import math
import re
import sys
import time

import numpy as np

from povlens.errors import UsageError
from povlens.lens.film import DEFAULT_FILM_DIAGONAL_MM, parse_film_size
from povlens.lens.focus import LENS_SIDE_UNITS, UNITS_MM, exact_film_distance_mm, thick_lens_film_distance_mm
from povlens.lens.paraxial import ParaxialData, paraxial_data
from povlens.lens.prescription import LensPrescription
from povlens.pupil.baselines import (PBRT_INTERVALS, PBRT_RAYS_PER_INTERVAL, NaiveRearElement,
                                     PassComparison, PbrtBoxes)
from povlens.pupil.build import DEFAULT_TOLERANCE, PLANES
from povlens.pupil.plot import plot_pupil_shapes
from povlens.pupil.storage import cached_pupil_table
from povlens.pupil.table import PupilTable
from povlens.cli.common import (add_lens_arguments, load_lens, positive_float, positive_int,
                                print_json)


COMPARISON = PassComparison()     # the comparison's defaults

def register(sub) -> None:
    p = sub.add_parser(
        "pupil",
        help="build an exit-pupil sample table and compare it with pbrt and naive sampling",
        description="Build the exit-pupil table of LENS focused at distance D (from the film "
                    "plane): for each film radius, the region of the sampling plane through "
                    "which rays from the film reach the scene.  Prints, per band of film "
                    "radius, the fraction of sampled rays that get through for povlens's "
                    "table, for pbrt-style boxes (64 intervals) and for naive sampling of the "
                    "whole rear element, and the build time of each.")
    add_lens_arguments(p)
    p.add_argument("--focus", required=True, metavar="D",
                   help="object distance from the film plane, in --units (default %(default)s) or with "
                        "a unit suffix (10m, 250cm, 5in); 'inf' for infinity")
    p.add_argument("--units", choices=sorted(UNITS_MM), default=LENS_SIDE_UNITS,
                   help="units of --focus without a suffix (default %(default)s)")
    p.add_argument("--exact-focus", action="store_true",
                   help="place the film by the real-ray focus instead of the thick-lens "
                        "equation (pbrt's method, the default)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--film-diagonal", type=positive_float, metavar="MM",
                   help=f"film diagonal in mm (default {DEFAULT_FILM_DIAGONAL_MM:g})")
    g.add_argument("--film-size", metavar="W,H", help="film width and height in mm, e.g. 36,24")
    p.add_argument("--tolerance", type=positive_float, default=DEFAULT_TOLERANCE, metavar="T",
                   help=f"relative area error of the table's region description "
                        f"(default {DEFAULT_TOLERANCE})")
    p.add_argument("--plane", choices=PLANES, default=PLANES[0],
                   help="sampling plane of the table (default %(default)s)")
    p.add_argument("--bands", type=positive_int, default=COMPARISON.bands, metavar="N",
                   help="film-radius bands in the comparison (default %(default)s)")
    p.add_argument("--radii-per-band", type=positive_int, default=COMPARISON.radii_per_band,
                   metavar="N", help="film radii measured in each band (default %(default)s)")
    p.add_argument("--samples", type=positive_int, default=COMPARISON.samples_per_radius,
                   metavar="N", help="Sobol samples per film radius for the pass fractions "
                                     "(default %(default)s)")
    p.add_argument("--pbrt-rays", type=positive_int,
                   default=COMPARISON.pbrt_rays_per_interval, metavar="N",
                   help=f"rays per interval for the pbrt-style boxes (default %(default)s; "
                        f"pbrt uses {PBRT_RAYS_PER_INTERVAL} -- its build time is then "
                        f"estimated)")
    p.add_argument("--no-compare", action="store_true",
                   help="build (or reuse) the table only; no pbrt or naive comparison")
    p.add_argument("-o", "--output", metavar="TABLE.npz",
                   help="save the table here; an existing table with the same inputs is reused")
    p.add_argument("--plot", metavar="PNG", help="draw the pupil shape at several film radii")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    p.add_argument("--seed", type=int, default=COMPARISON.seed,
                   help="seed of the scrambled Sobol points (default %(default)s)")
    p.set_defaults(func=run)


_SUFFIX = re.compile(r"^\s*([-+0-9.eE]+)\s*(mm|cm|m|in)?\s*$")


def parse_focus_mm(text: str, units: str) -> float:
    """--focus value -> mm: a number in ``units``, a number with a unit suffix, or inf."""
    t = text.strip().lower()
    if t in ("inf", "infinity"):
        return math.inf
    m = _SUFFIX.match(t)
    value = None
    if m:
        try:
            value = float(m.group(1))
        except ValueError:
            value = None
    if value is None or not math.isfinite(value) or value <= 0:
        raise UsageError(f"--focus {text}: expected a positive distance such as 10m, 2500 "
                         f"(in --units) or inf")
    return value * UNITS_MM[m.group(2) or units]


def _film(args) -> dict:
    if args.film_size is not None:
        w, h = parse_film_size(args.film_size)
        return {"width_mm": w, "height_mm": h, "diagonal_mm": math.hypot(w, h)}
    d = args.film_diagonal if args.film_diagonal is not None else DEFAULT_FILM_DIAGONAL_MM
    return {"diagonal_mm": d}


def _progress(args, desc: str, total=None):
    from tqdm import tqdm
    return tqdm(total=total, desc=desc, unit=" eval" if total is None else " interval",
                file=sys.stderr, leave=False,
                disable=args.quiet or args.json or not sys.stderr.isatty())


def _band_radii(hd: float, bands: int, per_band: int) -> tuple[np.ndarray, np.ndarray]:
    edges = np.linspace(0.0, hd, bands + 1)
    radii = np.concatenate([edges[i] + (np.arange(per_band) + 0.5) / per_band
                            * (edges[i + 1] - edges[i]) for i in range(bands)])
    return edges, radii


def _summarise(pf, bands: int, per_band: int) -> dict:
    frac = pf.fraction.reshape(bands, per_band)
    vig = pf.vignetted.reshape(bands, per_band)
    out = []
    for b in range(bands):
        live = frac[b][~vig[b]]
        out.append(None if live.size == 0 else {"min": float(live.min()),
                                                "mean": float(live.mean()),
                                                "vignetted_radii": int(vig[b].sum())})
    live = pf.fraction[~pf.vignetted]
    total = {"worst": float(live.min()) if live.size else None,
             "mean": float(live.mean()) if live.size else None,
             "vignetted_radii": int(pf.vignetted.sum())}
    return {"bands": out, "all": total}


def run(args) -> int:
    """Build (or reuse) the table, compare it with the baselines, print; exit code 0."""
    lens = load_lens(args)
    focus_mm = parse_focus_mm(args.focus, args.units)
    film = _film(args)
    hd = 0.5 * film["diagonal_mm"]
    p = paraxial_data(lens)
    film_distance, method = _film_distance_mm(lens, focus_mm, p, args.exact_focus)
    meta = {"focus_distance_mm": None if math.isinf(focus_mm) else focus_mm,
            "focus_method": method, "film": film}
    with _progress(args, "pupil table") as bar:
        table, reused = cached_pupil_table(args.output, lens, film_distance, hd,
                                           tolerance=args.tolerance, plane=args.plane,
                                           progress=bar.update, metadata=meta)
    samplers = {"povlens": table}
    builds = {"povlens": {"time_s": table.stats.get("build_time_s"),
                          "rays_traced": table.stats.get("rays_traced"), "reused": reused}}
    boxes = None
    if not args.no_compare:
        boxes, naive, baseline_builds = _build_baselines(args, lens, film_distance, hd)
        samplers.update(pbrt=boxes, naive=naive)
        builds.update(baseline_builds)
    edges, radii = _band_radii(hd, args.bands, args.radii_per_band)
    results = {name: _summarise(s.pass_fraction(radii, n_samples=args.samples, seed=args.seed),
                                args.bands, args.radii_per_band)
               for name, s in samplers.items()}
    if args.plot:
        plot_radii = np.linspace(0.0, hd, 6)
        if table.vignetted_beyond_mm is not None:
            plot_radii = np.linspace(0.0, table.vignetted_beyond_mm * 0.999, 6)
        plot_pupil_shapes(table, args.plot, film_radii=plot_radii, boxes=boxes)
    report = _Report(args, lens, p, focus_mm, film, film_distance, method, table, reused,
                     edges, results, builds)
    if args.json:
        _print_json(report)
    else:
        _print_text(report)
    return 0


def _film_distance_mm(lens, focus_mm: float, p, exact: bool) -> tuple[float, str]:
    """Film distance for the focus: real-ray (``exact``) or thick-lens; and the method name."""
    if exact:
        return exact_film_distance_mm(lens, focus_mm, p)[0], "exact"
    return thick_lens_film_distance_mm(lens, focus_mm, p), "thick-lens"


def _build_baselines(args, lens, film_distance: float, hd: float):
    """pbrt's boxes and naive rear-element sampling, and their build records."""
    with _progress(args, "pbrt boxes", PBRT_INTERVALS) as bar:
        boxes = PbrtBoxes.build(lens, film_distance, hd, rays_per_interval=args.pbrt_rays,
                                progress=bar.update)
    t0 = time.perf_counter()
    naive = NaiveRearElement.build(lens, film_distance, hd)
    naive_time = time.perf_counter() - t0
    measured = boxes.rays_per_interval == PBRT_RAYS_PER_INTERVAL
    builds = {"pbrt": {"time_s": boxes.build_time_s, "rays_per_interval": args.pbrt_rays,
                       "rays_traced": boxes.rays_traced,
                       "time_at_pbrt_count_s": boxes.build_time_at_pbrt_count_s(),
                       "time_at_pbrt_count_is": (
                           "measured" if measured else
                           "estimated: traced fraction x 64 x 2^20 x cost per traced ray")},
              "naive": {"time_s": naive_time, "rays_traced": 0}}
    return boxes, naive, builds


@dataclasses.dataclass(frozen=True)
class _Report:
    """Everything the command prints."""

    args: argparse.Namespace
    lens: LensPrescription
    paraxial: ParaxialData
    focus_mm: float
    film: dict
    film_distance: float
    method: str
    table: PupilTable
    reused: bool
    edges: np.ndarray
    results: dict
    builds: dict


def _print_json(r: _Report) -> None:
    """The whole report as one JSON object."""
    args, p, table = r.args, r.paraxial, r.table
    print_json({
        "lens": r.lens.source, "focus_distance_mm": None if math.isinf(r.focus_mm) else r.focus_mm,
        "focus_method": r.method, "film_distance_mm": r.film_distance,
        "f_number": p.f_number, "stop_diameter_mm": p.stop_diameter, "film": r.film,
        "table": table.describe(), "table_file": args.output, "table_reused": r.reused,
        "axial_irradiance_factor": table.axial_irradiance_factor,
        "exposure_normalisation": table.exposure_normalisation(),
        "samples_per_radius": args.samples,
        "bands": [{"film_radius_mm": [float(r.edges[i]), float(r.edges[i + 1])],
                   **{name: r.results[name]["bands"][i] for name in r.results}}
                  for i in range(args.bands)],
        "all": {name: r.results[name]["all"] for name in r.results},
        "build": r.builds, "plot": args.plot})


def _print_text(r: _Report) -> None:
    """The report for a reader: the table, then the comparison."""
    _print_table_summary(r)
    _print_comparison(r)
    if r.args.plot:
        print(f"plot: {r.args.plot}")


def _print_table_summary(r: _Report) -> None:
    """Lens, focus and film; the table's plane, size, exposure and warnings."""
    args, p, table, film = r.args, r.paraxial, r.table, r.film
    typed = args.focus.strip().replace(" ", "")
    if not typed[-1:].isalpha():
        typed = f"{typed} {args.units}"
    focus_txt = ("infinity" if math.isinf(r.focus_mm) else
                 typed if typed.endswith("mm") else f"{typed} = {r.focus_mm:g} mm")
    film_txt = (f"{film['width_mm']:g} x {film['height_mm']:g} mm film"
                if "width_mm" in film else f"{film['diagonal_mm']:g} mm film diagonal")
    print(f"{r.lens.source} focused at {focus_txt}: film distance {r.film_distance:.4f} mm "
          f"({r.method}); F/{p.f_number:.3g} (stop {p.stop_diameter:.4g} mm); {film_txt}")
    st = table.stats
    print(f"pupil table: {table.plane} plane at z = {table.plane_z_mm:.3f} mm, "
          + (f"a {table.grid_shape[0]}x{table.grid_shape[1]} grid of film points over x and y "
             f"(anamorphic lens)" if getattr(table, "kind", "") == "grid"
             else f"{table.n_knots} knots") + f" x {table.n_angles} angles, "
          f"tolerance {table.tolerance:g}, "
          f"{st.get('rays_traced', 0):,} rays, {st.get('build_time_s', 0):.3f} s")
    print(f"  on-axis irradiance factor E/L = {table.axial_irradiance_factor:.5f} "
          f"(pi/(4 N^2) = {math.pi / (4 * p.f_number ** 2):.5f}); exposure normalisation "
          f"x{table.exposure_normalisation():.4g} makes the frame centre as bright as a "
          f"pinhole render")
    if table.vignetted_beyond_mm is not None:
        print(f"  no ray leaves the film beyond radius {table.vignetted_beyond_mm:.4f} mm: "
              f"vignetted there (weight 0)")
    if st.get("non_star_shaped_radii"):
        print(f"  warning: from film radius {st['non_star_shaped_from_mm']:.3f} mm the pass "
              f"region is not star-shaped (horns or holes); thin parts between the probe "
              f"rays can be missed there")
    if st.get("knot_limit_reached"):
        print("  warning: the knot limit was reached before the tolerance was met; the "
              "table is conservative by measured margins but looser there")
    if args.output:
        print(f"  {'reused' if r.reused else 'saved to'} {args.output}"
              + (" (inputs unchanged)" if r.reused else ""))


def _print_comparison(r: _Report) -> None:
    """Pass fractions per band of film radius, and the build times."""
    args, results, builds = r.args, r.results, r.builds
    names = list(results)
    labels = {"povlens": "povlens table", "pbrt": f"pbrt {PBRT_INTERVALS} boxes",
              "naive": "naive rear element"}
    print()
    print(f"fraction of sampled rays that get through ({args.samples} Sobol samples at "
          f"{args.radii_per_band} radii per band; min / mean):")
    print(f"  {'film radius (mm)':<18}" + "".join(f"{labels[n]:>22}" for n in names))

    def cell(v):
        return f"{'vignetted':>22}" if v is None else f"{v['min']:>13.3f} / {v['mean']:.3f}"

    for i in range(args.bands):
        print(f"  {r.edges[i]:6.2f} - {r.edges[i + 1]:6.2f}    "
              + "".join(cell(results[n]["bands"][i]) for n in names))
    print(f"  {'all radii':<18}" + "".join(
        f"{'(none)':>22}" if results[n]['all']['worst'] is None else
        f"{results[n]['all']['worst']:>13.3f} / {results[n]['all']['mean']:.3f}" for n in names))
    print()
    print("build time:")
    b = builds["povlens"]
    print(f"  {'povlens table':<20} {b['time_s']:9.3f} s  ({b['rays_traced']:,} rays"
          + (", reused from file" if r.reused else "") + ")")
    if "pbrt" in builds:
        b = builds["pbrt"]
        print(f"  {labels['pbrt']:<20} {b['time_s']:9.3f} s  ({b['rays_per_interval']:,} rays per "
              f"interval, {b['rays_traced']:,} traced)")
        if b["rays_per_interval"] != PBRT_RAYS_PER_INTERVAL:
            print(f"  {'  at pbrt 2^20/interval':<20} {b['time_at_pbrt_count_s']:9.1f} s  "
                  f"(estimated from the traced fraction and the cost per traced ray)")
        print(f"  {labels['naive']:<20} {builds['naive']['time_s']:9.3f} s  (no table)")
