"""``povlens convert`` / ``render`` / ``composite`` / ``render-batch`` / ``render-view``.

The rendering commands import :mod:`povlens.rendering` when they run: it loads
OpenImageIO and tqdm (~0.3 s), which ``povlens convert`` does not need.

What povlens replaces or ignores of the scene (the plan's ``notes``) is printed once
per note on stderr, ``povlens: note: ...`` (:func:`print_notes`; ``render --quiet``
prints none).
"""

from __future__ import annotations

import argparse
import math
import os
import sys

from povlens.cli.common import positive_float, positive_int, print_json
from povlens.cli.flags import with_flags
from povlens.errors import UsageError
from povlens.lens.film import parse_film_size, parse_shift
from povlens.lens.focus import UNITS_MM
from povlens.plan.convert import METHODS, ConvertOptions, convert
from povlens.plan.focus_series import FocusPull, focus_series, parse_focus
from povlens.plan.schema import Plan


def _vector(text: str):
    try:
        v = tuple(float(t) for t in text.replace("<", "").replace(">", "").split(","))
    except ValueError:
        v = ()
    if len(v) != 3:
        raise argparse.ArgumentTypeError(f"'{text}' is not a vector x,y,z")
    return v


def _pixel(text: str) -> tuple[int, int]:
    """``X,Y``: the 0-based column and row of an output pixel (argparse type)."""
    try:
        x, y = (int(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a pixel X,Y (column, row: "
                                         f"whole numbers from 0)") from None
    if x < 0 or y < 0:
        raise argparse.ArgumentTypeError(f"'{text}': the column and row count from 0")
    return x, y


def _clock(text: str) -> float:
    """A finite number: POV-Ray's clock (argparse type)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"'{text}' must be a finite number")
    return v


def _add_povray_arguments(p: argparse.ArgumentParser) -> None:
    """POV-Ray's own options, given to every POV-Ray run of the scene and kept in the
    plan (``make`` and ``render-batch`` use them)."""
    g = p.add_argument_group("POV-Ray options (every POV-Ray run of the scene; kept in "
                             "plan.json)")
    g.add_argument("--library-path", action="append", default=[], metavar="DIR",
                   dest="library_paths",
                   help="a folder where POV-Ray looks for #include files and image maps, "
                        "as its +L (repeatable; after the scene's own folder)")
    g.add_argument("--clock", type=_clock, metavar="V",
                   help="POV-Ray's clock for the frame, as its +K (default: a still, "
                        "clock 0); the scene's camera is read at it too")
    g.add_argument("--povray-option", action="append", default=[], metavar="OPT",
                   dest="povray_options",
                   help="a further POV-Ray switch or INI option, e.g. +A0.3 or "
                        "Jitter=off (repeatable; write --povray-option=-J for one "
                        "starting with '-'); options povlens sets itself (image size, "
                        "output, display, threads, animation) are refused; mesh lens "
                        "samples ignore anti-aliasing")


def _add_aperture_arguments(p: argparse.ArgumentParser) -> None:
    """The stop's shape (povlens.lens.aperture_shape): an iris of blades, or a mask."""
    g = p.add_argument_group("aperture shape (the exact-ray methods draw it; focal_blur "
                             "cannot)")
    g.add_argument("--aperture-blades", type=float, metavar="N",
                   help="an iris of N >= 3 straight blades inscribed in the stop's circle "
                        "(the f-number is the circle's)")
    g.add_argument("--blade-curvature", type=float, default=0.0, metavar="K",
                   help="blade edges from 0 straight (default) to 1 round")
    g.add_argument("--blade-rotation", type=float, default=0.0, metavar="DEG",
                   help="turn the iris counter-clockwise in degrees (0: a corner at the top)")
    g.add_argument("--aperture-image", metavar="MASK.png",
                   help="a grey-level mask over the stop's disc (white open, black opaque; "
                        "grey transmits part); the image spans the stop's diameter")


def _add_cluster_arguments(p: argparse.ArgumentParser) -> None:
    """``render``'s Dask options (:mod:`povlens.cluster`; Dask is imported only with one)."""
    g = p.add_argument_group("distributed rendering (Dask; pip install 'povlens[distributed]')")
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="render the lens samples on the Dask cluster of this scheduler "
                        "(tcp://HOST:8786; default: $POVLENS_SCHEDULER, else this machine); "
                        "the workers need POV-Ray and povlens; the scene's folder (include "
                        "files, image maps) is sent to them")
    g.add_argument("--shared-dir", action="store_true",
                   help="with --scheduler: the workers see the scene, lens and OUTDIR at the "
                        "same paths (a shared filesystem), so nothing is sent and they write "
                        "the samples in place")
    g.add_argument("--scheduler-timeout", type=positive_float, default=10.0, metavar="S",
                   help="seconds to wait for the scheduler to answer (default 10)")
    g.add_argument("--group-size", type=positive_int, metavar="N",
                   help="with --scheduler: lens samples per task, summed on the worker "
                        "(default: the larger of samples/(2 workers) and sqrt(samples/2), "
                        "at most 16; 1: each sample comes back, the image bit for bit the "
                        "local one)")


def _scheduler_of(args) -> str | None:
    """The scheduler of ``render``: --scheduler, else $POVLENS_SCHEDULER, else None."""
    scheduler = args.scheduler or os.environ.get("POVLENS_SCHEDULER") or None
    if scheduler is None and args.shared_dir:
        raise UsageError("--shared-dir needs --scheduler (or POVLENS_SCHEDULER)")
    if scheduler is None and getattr(args, "group_size", None) is not None:
        raise UsageError("--group-size needs --scheduler (or POVLENS_SCHEDULER)")
    return scheduler


def add_convert_arguments(p: argparse.ArgumentParser) -> None:
    """The options of a conversion (SCENE, --lens, --focus, ..., -o OUTDIR, --json):
    ``convert``, ``render`` and ``plan`` take them (:func:`options_from_args`)."""
    p.add_argument("scene", metavar="SCENE.pov", help="an ordinary POV-Ray scene (not modified)")
    p.add_argument("--lens", required=True, help="lens file or bundled lens name")
    f = p.add_mutually_exclusive_group()
    f.add_argument("--focus", metavar="DIST",       # parsed by _focus_of (pulls too)
                   help="distance from the camera location to the plane in focus, scene "
                        "units (default: the scene camera's focal_point if it has focal "
                        "blur, else the distance to its look_at, else what the depth probe "
                        "sees at the centre of the frame); convert/render: A:B with "
                        "--frames N is a focus pull from A to B (even steps in dioptres), "
                        "D1,D2,... one frame per distance")
    f.add_argument("--focus-at", type=_pixel, metavar="X,Y",
                   help="focus on what the depth probe sees at output pixel X,Y (column "
                        "and row from the top left, 0-based; the median distance of the "
                        "surface under it in a 5x5 pixel window)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--f-number", type=positive_float, metavar="N", help="stop down to f/N")
    g.add_argument("--stop-diameter", type=positive_float, metavar="MM",
                   help="aperture-stop diameter in mm")
    _add_aperture_arguments(p)
    p.add_argument("--film-diagonal", type=positive_float, default=35.0, metavar="MM",
                   help="film diagonal in mm; the film takes the image's aspect (default 35)")
    p.add_argument("--film-size", metavar="W,H", help="film width and height in mm instead")
    p.add_argument("--shift-mm", metavar="X,Y",
                   help="lens shift in mm on the film: the frame's centre moves X right and Y "
                        "up off the lens axis (+Y shows more of the scene above, a view "
                        "camera's rising front), so verticals stay vertical; beyond the "
                        "lens's image circle the corners go dark")
    p.add_argument("--units", choices=sorted(UNITS_MM), default="m",
                   help="what one scene unit is (default m)")
    p.add_argument("--width", type=int, default=640, help="image width in pixels (default 640)")
    p.add_argument("--height", type=int, default=480, help="image height in pixels (default 480)")
    p.add_argument("--method", choices=METHODS, default="auto",
                   help="auto (default: the cheapest method within --tolerance, decided from a "
                        "depth probe of the scene and the measured model error), pinhole, "
                        "focal-blur (equivalent thin lens) or mesh (exact lens rays per sample)")
    p.add_argument("--tolerance", type=positive_float, default=0.5, metavar="PX",
                   help="error budget of --method auto, in pixels (default 0.5)")
    p.add_argument("--samples", type=int, default=None,
                   help="lens samples per pixel (mesh renders, or focal_blur's blur_samples); "
                        "default: chosen by --method auto, else 16")
    p.add_argument("--batch-size", type=int, default=None,
                   help="lens samples per POV-Ray process (default: samples / cores, so "
                        "each core runs one process)")
    p.add_argument("--seed", type=int, default=0, help="seed of the sample sequence")
    p.add_argument("--location", type=_vector, metavar="X,Y,Z",
                   help="camera location (instead of the scene's camera)")
    p.add_argument("--look-at", type=_vector, metavar="X,Y,Z", help="camera look_at point")
    p.add_argument("--sky", type=_vector, default=(0.0, 1.0, 0.0), metavar="X,Y,Z",
                   help="camera sky vector (default 0,1,0)")
    p.add_argument("--thick-lens-focus", action="store_true",
                   help="place the film by the thick-lens equation, not the real-ray focus")
    p.add_argument("--no-vignetting", action="store_true",
                   help="composite without the lens's vignetting (each pixel divided by its "
                        "mean sample weight), for comparison with POV-Ray's own cameras")
    p.add_argument("--no-jitter", action="store_true",
                   help="trace every pixel from its centre (no sub-pixel box filter), as "
                        "POV-Ray's perspective camera without anti-aliasing does")
    p.add_argument("--adaptive", action=argparse.BooleanOptionalAction, default=None,
                   help="mesh renders: from a depth probe, give sharp row bands fewer lens "
                        "samples than bands deep in blur (later samples render only the "
                        "blurred rows, POV-Ray +SR/+ER); default off: each partial sample "
                        "still costs a POV-Ray run and a full mesh, so on the bundled scenes "
                        "it saved no time at equal error")
    p.add_argument("--ray-mesh", choices=("field", "pixel"), default="field",
                   help="mesh renders: field (default: a coarse interpolated ray mesh per lens "
                        "sample, one pupil point for the whole frame, rays within 0.05 px of the "
                        "exact ones, measured) or pixel (a mesh face per pixel, each pixel its "
                        "own pupil point; slower, kept for comparison)")
    p.add_argument("--dispersion", action="store_true",
                   help="mesh renders: trace each lens sample at its own wavelength (from "
                        "the lens file's Abbe numbers, 5th column) and composite through the "
                        "CIE 1931 colour-matching functions: lateral and longitudinal colour")
    p.add_argument("-o", "--outdir", required=True, metavar="OUTDIR", help="output folder")
    p.add_argument("--json", action="store_true", help="print the plan as JSON")
    _add_povray_arguments(p)


def focus_frames(args) -> list[float] | None:
    """The focus distance of every frame of ``--focus A:B --frames N`` or
    ``--focus D1,D2,...`` (scene units), or None for one focus (no ``--frames``)."""
    frames = getattr(args, "frames", None)
    if args.focus_at is not None and frames is not None:
        raise UsageError(f"--focus-at focuses one frame: a focus pull is --focus A:B "
                         f"--frames {frames} (or --focus D1,D2,...)")
    spec = None if args.focus is None else parse_focus(args.focus)
    if isinstance(spec, FocusPull) and not hasattr(args, "frames"):
        raise UsageError(f"--focus {args.focus} is a focus pull: 'povlens {args.command}' "
                         f"takes one distance (pulls: 'povlens render --frames')")
    return focus_series(spec, frames)


def _focus_of(args) -> float | None:
    """The one focus distance of ``args`` (the first frame's for a pull)."""
    frames = focus_frames(args)
    if frames is not None:
        return frames[0]
    return None if args.focus is None else parse_focus(args.focus)


def options_from_args(args) -> ConvertOptions:
    """The :class:`~povlens.plan.options.ConvertOptions` of parsed
    :func:`add_convert_arguments` options (a focus pull: at its first frame's focus,
    :func:`focus_frames` gives them all)."""
    if args.width < 1 or args.height < 1:
        raise UsageError(f"--width/--height {args.width}x{args.height}: must be at least 1 pixel")
    if args.samples is not None and args.samples < 1:
        raise UsageError(f"--samples {args.samples}: must be at least 1")
    if args.batch_size is not None and args.batch_size < 1:
        raise UsageError(f"--batch-size {args.batch_size}: must be at least 1")
    return ConvertOptions(
        scene=args.scene, lens=args.lens, focus=_focus_of(args), focus_at=args.focus_at,
        outdir=args.outdir,
        f_number=args.f_number, stop_diameter_mm=args.stop_diameter,
        film_diagonal_mm=args.film_diagonal,
        film_size_mm=parse_film_size(args.film_size) if args.film_size else None,
        shift_mm=parse_shift(args.shift_mm) if getattr(args, "shift_mm", None) else None,
        aperture_blades=getattr(args, "aperture_blades", None),
        blade_curvature=getattr(args, "blade_curvature", 0.0),
        blade_rotation_deg=getattr(args, "blade_rotation", 0.0),
        aperture_image=getattr(args, "aperture_image", None),
        units=args.units, width=args.width, height=args.height, method=args.method,
        samples=16 if args.samples is None else args.samples, batch_size=args.batch_size, seed=args.seed,
        location=args.location, look_at=args.look_at, sky=args.sky,
        real_focus=not args.thick_lens_focus, vignetting=not args.no_vignetting,
        jitter=not args.no_jitter, tolerance_px=args.tolerance,
        auto_samples=args.samples is None,
        adaptive=bool(args.adaptive), ray_mesh=args.ray_mesh,
        dispersion=bool(getattr(args, "dispersion", False)),
        library_paths=tuple(args.library_paths), clock=args.clock,
        povray_options=tuple(args.povray_options))


def print_notes(plan: Plan) -> None:
    """Print the plan's notes (what povlens replaces or ignores), each once, on stderr
    as ``povlens: note: ...`` with parameters written as options."""
    for note in dict.fromkeys(plan.notes):
        print(f"povlens: note: {with_flags(note)}", file=sys.stderr)


def _summary(plan: Plan) -> str:
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
        from povlens.cli.frames_run import run_convert_frames
        return run_convert_frames(args, options_from_args(args), frames)
    plan = convert(options_from_args(args))
    print_notes(plan)
    if args.json:
        print_json(plan.to_dict())
    else:
        print(_summary(plan))
        from povlens.plan.render_folder import RenderFolder
        folder = RenderFolder(args.outdir)
        print(f"wrote {folder.plan_json} and {folder.makefile}; "
              f"render with 'make -C {args.outdir} -j{os.cpu_count() or 1}'")
    return 0


def run_render(args) -> int:
    frames = focus_frames(args)
    if frames is not None:                   # a focus pull: one folder per frame
        from povlens.cli.frames_run import run_render_frames
        return run_render_frames(args, options_from_args(args), frames, _scheduler_of(args))
    from povlens.rendering.driver import convert_and_render

    def on_plan(plan: Plan) -> None:
        print_notes(plan)
        print(_summary(plan))

    scheduler = _scheduler_of(args)
    if scheduler is not None:           # lens samples on a Dask cluster (povlens.cluster)
        from povlens.cluster.client import convert_and_render_on_cluster
        _, out = convert_and_render_on_cluster(
            options_from_args(args), scheduler, shared_dir=args.shared_dir, quiet=args.quiet,
            on_plan=None if args.quiet else on_plan, connect_timeout_s=args.scheduler_timeout,
            group_size=args.group_size)
    else:
        _, out = convert_and_render(options_from_args(args), jobs=args.jobs, quiet=args.quiet,
                                    on_plan=None if args.quiet else on_plan)
    if not args.quiet:
        print(f"wrote {out} and {out.with_suffix('.png')}")
    return 0


def run_composite(args) -> int:
    from povlens.rendering.folder_composite import composite_outdir
    composite_outdir(args.outdir)
    return 0


def run_batch(args) -> int:
    from povlens.rendering.mesh_samples import render_batch
    render_batch(args.outdir, args.batch, in_flight=args.in_flight)
    return 0


def run_view(args) -> int:
    from povlens.rendering.views import render_view
    render_view(args.outdir, args.view)
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
    p.add_argument("-j", "--jobs", type=int, default=os.cpu_count() or 1,
                   help="cores to use: up to 4 POV-Ray processes per core run at once "
                        "(each spends most of its ~0.6 s start-up idle; default: number "
                        "of cores)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
    _add_cluster_arguments(p)
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
    p.add_argument("--in-flight", type=int, default=4, metavar="N",
                   help="POV-Ray processes running at once (default 4: each spends most of "
                        "its ~0.6 s start-up idle, so several overlap on one core)")
    p.set_defaults(func=run_batch)

    p = sub.add_parser("render-view", help="render the pinhole or focal-blur view (used by make)")
    p.add_argument("outdir", metavar="OUTDIR")
    p.add_argument("--view", choices=["pinhole", "focal-blur"], required=True)
    p.set_defaults(func=run_view)
