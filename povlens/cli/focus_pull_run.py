"""``povlens convert/render --focus A:B --frames N``: a focus pull, one folder per frame
(:func:`povlens.api.convert_frames`, :func:`povlens.api.render_frames`).  Called by
:mod:`povlens.cli.render_cmd`."""

from __future__ import annotations

import os
import sys

from povlens import api
from povlens.cli.common import print_json
from povlens.cli.convert_args import keywords_from_args
from povlens.cli.flags import with_flags


def _table(records, units: str) -> str:
    lines = [f"{'frame':>5}  {'focus (' + units + ')':>11}  {'film distance':>14}  "
             f"{'hfov':>8}  method"]
    for r in records:
        fd = "-" if r.film_distance_mm is None else f"{r.film_distance_mm:.4f} mm"
        hf = "-" if r.hfov_deg is None else f"{r.hfov_deg:.3f}°"
        lines.append(f"{r.frame:>5}  {r.focus:>11.6g}  {fd:>14}  {hf:>8}  "
                     f"{r.method or '-'} {r.samples or ''}")
    return "\n".join(lines)


def _printer(quiet: bool):
    """Print the notes of the first frame's plan only (the frames share the scene)."""
    seen = set()

    def on_plan(plan) -> None:
        if quiet:
            return
        for note in dict.fromkeys(plan.notes):
            if note not in seen:
                seen.add(note)
                print(f"povlens: note: {with_flags(note)}", file=sys.stderr)
    return on_plan


def _keywords(args, frames: list[float]) -> dict:
    kw = keywords_from_args(args)
    kw.update(focus=frames, frames=len(frames))
    return kw


def run_convert_frames(args, frames: list[float]) -> int:
    result = api.convert_frames(args.scene, lens=args.lens, outdir=args.outdir,
                                **_keywords(args, frames))
    if args.json:
        import dataclasses
        print_json({"frames": [dataclasses.asdict(r) for r in result.frames]})
        return 0
    print(_table(result.frames, args.units))
    print(f"wrote {result.index}, {len(result.frames)} frame folders and a Makefile; "
          f"render with 'make -C {args.outdir} -j{os.cpu_count() or 1}'")
    return 0


def run_render_frames(args, frames: list[float], renderer) -> int:
    result = api.render_frames(args.scene, lens=args.lens, outdir=args.outdir,
                               renderer=renderer, progress=not args.quiet,
                               on_plan=_printer(args.quiet), **_keywords(args, frames))
    if not args.quiet:
        print(_table(result.frames, args.units))
        print(f"wrote {result.images_exr[0]} ... {result.images_exr[-1].name} (and .png), "
              f"{result.index}")
    return 0
