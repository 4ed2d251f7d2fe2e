"""``povlens convert`` / ``render`` / ``composite`` / ``render-batch`` / ``render-view``.

Each command is argparse -> :mod:`povlens.api` -> print.  The options of a conversion
come from their one declaration (:mod:`povlens.cli.convert_args`); where a render runs
(here or on a Dask cluster) is chosen once, by :func:`povlens.api.renderer_for`.

What povlens replaces or ignores of the scene (the plan's ``notes``) is printed once
per note on stderr, ``povlens: note: ...`` (:func:`print_notes`; ``render --quiet``
prints none).
"""

from __future__ import annotations

import argparse
import os
import sys

from povlens import api
from povlens.cli.common import print_json
from povlens.cli.convert_args import (add_convert_arguments, add_dask_arguments,
                                      dask_keywords_from_args, keywords_from_args)
from povlens.cli.flags import with_flags
from povlens.errors import UsageError


def focus_frames(args) -> list[float] | None:
    """The focus distance of every frame of ``--focus A:B --frames N`` or
    ``--focus D1,D2,...`` (scene units), or None for one focus (no ``--frames``)."""
    frames = getattr(args, "frames", None)
    if args.focus_at is not None and frames is not None:
        raise UsageError(f"--focus-at focuses one frame: a focus pull is --focus A:B "
                         f"--frames {frames} (or --focus D1,D2,...)")
    if not hasattr(args, "frames") and args.focus is not None and any(
            sep in args.focus for sep in ":,"):      # A:B or D1,D2,...
        raise UsageError(f"--focus {args.focus} is a focus pull: 'povlens {args.command}' "
                         f"takes one distance (pulls: 'povlens render --frames')")
    return api.focus_distances(args.focus, frames)


def convert_keywords(args) -> dict:
    """The API keywords of a conversion's parsed arguments (a focus pull: its first
    frame's focus; :func:`focus_frames` gives them all)."""
    kw = keywords_from_args(args)
    frames = focus_frames(args)
    kw["focus"] = frames[0] if frames is not None else args.focus
    return kw


def print_notes(plan) -> None:
    """Print the plan's notes (what povlens replaces or ignores), each once, on stderr
    as ``povlens: note: ...`` with parameters written as options."""
    for note in dict.fromkeys(plan.notes):
        print(f"povlens: note: {with_flags(note)}", file=sys.stderr)


def _summary(plan) -> str:
    f, m, e = plan.focus, plan.thin_lens, plan.model_error
    cam = plan.povray_camera
    return "\n".join([
        f"lens {plan.inputs.lens}  f/{plan.lens.f_number:.3g}  EFL {plan.lens.efl_mm:.2f} mm",
        f"focus {plan.inputs.focus:.6g} {plan.inputs.units} (from "
        f"{plan.inputs.focus_from or 'option'})",
        f"film distance {f.film_distance_mm:.4f} mm (thick lens "
        f"{f.thick_lens_film_distance_mm:.4f} mm)",
        f"equivalent thin lens: hfov {cam.hfov_deg:.3f} deg, pupil "
        f"{m.pupil_diameter_mm:.3f} mm, focal_blur aperture {cam.aperture:.6g}",
        (f"model error: distortion <= {e.max_distortion_px:.3f} px, blur size <= "
         f"{e.max_blur_size_error_px:.3f} px, illumination >= "
         f"{e.min_relative_illumination:.3f} of the centre" if e is not None else
         "model error: not measured (a pinhole render needs none)"),
        *([f"ray meshes: {plan.field_mesh.grid[0]}x{plan.field_mesh.grid[1]} faces, rays within "
           f"{plan.field_mesh.max_ray_error_px:.3f} px of the exact ones (measured); "
           f"{plan.field_mesh.interleave}x{plan.field_mesh.interleave} interleaved tiles, "
           f"pupil ellipses {plan.field_mesh.domain['efficiency']:.2f} filled"]
          if plan.field_mesh is not None and plan.field_mesh.domain else []),
        *([f"colour (F-C): lateral up to {plan.dispersion['max_lateral_colour_px']:.3g} px, "
           f"longitudinal {plan.dispersion['longitudinal_colour_mm'] or 0.0:.3g} mm"
           + ("" if plan.inputs.dispersion else " (not rendered)")]
          if plan.dispersion is not None else []),
        f"method {plan.inputs.method}, {plan.inputs.samples} samples"
        + (" (chosen by --method auto: " + plan.decision.reasons[-1].removeprefix("-> ")
           + ")" if plan.decision is not None else ""),
    ])


def run_convert(args) -> int:
    frames = focus_frames(args)
    if frames is not None:                   # a focus pull: one folder per frame
        from povlens.cli.focus_pull_run import run_convert_frames
        return run_convert_frames(args, frames)
    plan = api.convert(args.scene, lens=args.lens, outdir=args.outdir, **convert_keywords(args))
    print_notes(plan)
    if args.json:
        print_json(plan.to_dict())
    else:
        print(_summary(plan))
        folder = api.RenderFolder(args.outdir)
        print(f"wrote {folder.plan_json} and {folder.makefile}; "
              f"render with 'make -C {args.outdir} -j{os.cpu_count() or 1}'")
    return 0


def run_render(args) -> int:
    renderer = api.renderer_for(jobs=args.jobs, **dask_keywords_from_args(args))
    frames = focus_frames(args)
    if frames is not None:                   # a focus pull: one folder per frame
        from povlens.cli.focus_pull_run import run_render_frames
        return run_render_frames(args, frames, renderer)

    def on_plan(plan) -> None:
        print_notes(plan)
        print(_summary(plan))

    result = api.render(args.scene, lens=args.lens, outdir=args.outdir, renderer=renderer,
                        progress=not args.quiet, on_plan=None if args.quiet else on_plan,
                        **convert_keywords(args))
    if not args.quiet:
        print(f"wrote {result.image_exr} and {result.image_png}")
    return 0


def run_composite(args) -> int:
    api.composite(args.outdir)
    return 0


def run_batch(args) -> int:
    api.render_batch(args.outdir, args.batch, in_flight=args.in_flight)
    return 0


def run_view(args) -> int:
    api.render_view(args.outdir, args.view)
    return 0


def _add_frames_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("--frames", type=int, metavar="N",
                   help="a focus pull of N frames with --focus A:B (or the count of "
                        "--focus D1,D2,...): OUTDIR/frame-0001/... render folders, numbered "
                        "OUTDIR/image.0001.exr/.png, frames.json, a Makefile target per frame")


def register(sub) -> None:
    p = sub.add_parser("convert", help="write a render folder for a scene through a lens",
                       description="Write OUTDIR with a plan (plan.json), POV-Ray wrappers that "
                                   "include SCENE and replace its camera, and a Makefile that "
                                   "renders them ('make -C OUTDIR -j2').  SCENE is not modified.")
    add_convert_arguments(p)
    _add_frames_argument(p)
    p.set_defaults(func=run_convert)

    p = sub.add_parser("render", help="convert, render with POV-Ray and composite in one go",
                       description="Like 'convert', then render every lens sample with POV-Ray "
                                   "(in parallel) and composite OUTDIR/image.exr and image.png. "
                                   "Re-running resumes an interrupted render.")
    add_convert_arguments(p)
    _add_frames_argument(p)
    p.add_argument("-j", "--jobs", type=int, metavar="N",
                   help="cores to use: up to 4 POV-Ray processes per core run at once "
                        "(each spends most of its ~0.6 s start-up idle; default: number "
                        "of cores)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
    add_dask_arguments(p)
    p.set_defaults(func=run_render)

    p = sub.add_parser("composite", help="combine rendered lens samples into image.exr/.png",
                       description="Average OUTDIR's rendered lens samples with their per-pixel "
                                   "weights, in linear light, into OUTDIR/image.exr and an sRGB "
                                   "OUTDIR/image.png.")
    p.add_argument("outdir", metavar="OUTDIR")
    p.set_defaults(func=run_composite)

    p = sub.add_parser("render-batch", help="render one batch of lens samples (used by make)")
    p.add_argument("outdir", metavar="OUTDIR")
    p.add_argument("batch", type=int, metavar="BATCH")
    p.add_argument("--in-flight", type=int, metavar="N",
                   help="POV-Ray processes running at once (default: several, as 'render' "
                        "runs per core: each spends most of its ~0.6 s start-up idle, so "
                        "several overlap on one core)")
    p.set_defaults(func=run_batch)

    p = sub.add_parser("render-view", help="render the pinhole or focal-blur view (used by make)")
    p.add_argument("outdir", metavar="OUTDIR")
    p.add_argument("--view", choices=["pinhole", "focal-blur"], required=True)
    p.set_defaults(func=run_view)
