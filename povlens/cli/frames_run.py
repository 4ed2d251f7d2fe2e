"""``povlens convert/render --focus A:B --frames N``: a focus pull, one folder per frame
(:mod:`povlens.rendering.focus_pull`).  Called by :mod:`povlens.cli.render_cmd`."""

from __future__ import annotations

import os
import sys

from povlens.cli.common import print_json
from povlens.cli.flags import with_flags
from povlens.plan.options import ConvertOptions


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


def run_convert_frames(args, opts: ConvertOptions, frames: list[float]) -> int:
    from povlens.rendering.focus_pull import convert_frames
    records = convert_frames(opts, frames)
    if args.json:
        import dataclasses
        print_json({"frames": [dataclasses.asdict(r) for r in records]})
        return 0
    print(_table(records, opts.units))
    from povlens.plan.render_folder import FramesFolder
    folder = FramesFolder(args.outdir)
    print(f"wrote {folder.frames_json}, {len(records)} frame folders and "
          f"{folder.makefile}; render with 'make -C {args.outdir} -j{os.cpu_count() or 1}'")
    return 0


def run_render_frames(args, opts: ConvertOptions, frames: list[float],
                      scheduler: str | None = None) -> int:
    if scheduler is not None:        # every frame's lens samples on one Dask cluster
        from povlens.cluster.client import render_frames_on_cluster
        records = render_frames_on_cluster(opts, frames, scheduler, shared_dir=args.shared_dir,
                                           quiet=args.quiet, on_plan=_printer(args.quiet),
                                           connect_timeout_s=args.scheduler_timeout,
                                           group_size=args.group_size)
    else:
        from povlens.rendering.focus_pull import render_frames
        records = render_frames(opts, frames, jobs=args.jobs, quiet=args.quiet,
                                on_plan=_printer(args.quiet))
    if not args.quiet:
        print(_table(records, opts.units))
        from povlens.plan.render_folder import FramesFolder
        folder = FramesFolder(args.outdir)
        print(f"wrote {folder.path / folder.image_name(1, 'exr')} ... "
              f"{folder.image_name(len(records), 'exr')} (and .png), {folder.frames_json}")
    return 0
