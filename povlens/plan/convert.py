"""Scene conversion: from a POV-Ray scene and a lens to a render folder.

``convert`` never edits the user's scene.  It writes into OUTDIR:

* ``plan.json`` — every input and derived number: the lens and its focus, the
  film, the placement of the camera frame in the scene, the equivalent
  thin-lens model, what that model gets wrong (measured with the exact tracer),
  and the render method with its sample batches;
* ``pinhole.pov`` and ``focal_blur.pov`` — wrappers that ``#include`` the scene
  and declare their own camera last (POV-Ray uses the last camera);
* for the mesh method, ``samples/batch_NNN.pov`` wrappers that render one lens
  sample each per POV-Ray run (the sample's ray mesh is written just before,
  :mod:`povlens.render`) and ``pupil.npz``, the exit-pupil table;
* ``Makefile`` — ``make -C OUTDIR -j2`` renders and composites; a second
  ``make`` does nothing.

Scene units: ``units`` says what one scene unit is (the lens is in mm).  The
focus distance is measured from the camera ``location``, which is where the
lens's entrance pupil is placed (:mod:`povlens.lens_camera`).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shlex
import sys
from pathlib import Path

import numpy as np

from povlens.errors import PovlensError, UsageError
from povlens.lens.film import Film
from povlens.lens.focus import exact_film_distance_mm, thick_lens_film_distance_mm, UNITS_MM
from povlens.lens.paraxial import paraxial_data, stopped_down
from povlens.pov.process import povray_version
from povlens.pov.mesh import (SINK_RADIUS, _pov_string, _template, _vec, default_sink_centre,
                          focal_blur_wrapper, pinhole_wrapper, render_size, write_text)
from povlens.lens.prescription import read_lens
from povlens.pov.scene_camera import parse_scene_camera
from povlens.pupil.table import build_pupil_table, load_if_current
from povlens.thinlens.model import fit_thin_lens, measure_model_error

__all__ = ["ConvertOptions", "make_plan", "convert", "read_plan", "METHODS"]

METHODS = ("auto", "pinhole", "focal-blur", "mesh")
PLAN_VERSION = 1


@dataclasses.dataclass
class ConvertOptions:
    """What ``povlens convert`` needs (units: scene units unless named)."""

    scene: str
    lens: str
    focus: float                       # distance from the camera location, scene units
    outdir: str
    f_number: float | None = None
    stop_diameter_mm: float | None = None
    film_diagonal_mm: float = 35.0
    film_size_mm: tuple[float, float] | None = None
    units: str = "m"
    width: int = 160
    height: int = 120
    method: str = "mesh"
    samples: int = 16
    batch_size: int | None = None      # samples per POV-Ray process; None = N / cores
    seed: int = 0
    location: tuple[float, float, float] | None = None
    look_at: tuple[float, float, float] | None = None
    sky: tuple[float, float, float] = (0.0, 1.0, 0.0)
    real_focus: bool = True            # film at the real-ray focus (else thick lens)
    vignetting: bool = True            # composite keeps the lens's vignetting
    jitter: bool = True                # film points jittered within each pixel (box filter)
    tolerance_px: float = 0.5          # method "auto": error budget in pixels
    auto_samples: bool = True          # method "auto": the decision sets the sample count
    adaptive: bool = False             # mesh: fewer samples in sharp row bands (depth probe)
    speculate: bool = False            # method "auto": start the likely render while the
                                       # depth probe runs (povlens render; not convert/plan)


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v)
    if not (n > 0 and math.isfinite(n)):
        raise UsageError(f"degenerate camera vector {v.tolist()}")
    return v / n


def _camera_basis(opts: ConvertOptions):
    """(location, right, up, forward, source) from options or the scene's camera."""
    if opts.location is not None or opts.look_at is not None:
        if opts.location is None or opts.look_at is None:
            raise UsageError("--location and --look-at go together",
                             "give both, e.g. --location 0,1.5,-3 --look-at 0,0.7,5")
        loc = np.asarray(opts.location, float)
        fwd = _unit(np.asarray(opts.look_at, float) - loc)
        right = np.cross(np.asarray(opts.sky, float), fwd)
        if np.linalg.norm(right) < 1e-12:
            raise UsageError("--sky is parallel to the view direction", "choose another --sky")
        right = _unit(right)
        up = np.cross(fwd, right)
        return loc, right, up, fwd, "command line"
    cam = parse_scene_camera(opts.scene, opts.width, opts.height)
    if cam.projection != "perspective":
        raise UsageError(f"{cam.source}: the scene's camera is {cam.projection}; povlens replaces "
                         f"it with a lens and needs its position and orientation",
                         "give --location, --look-at and --sky")
    return (np.asarray(cam.location, float), _unit(cam.right), _unit(cam.up),
            _unit(cam.forward), cam.source)


def _focus(lens, p, focus_from_pupil_mm: float, real: bool):
    """Film distance f and object distance from the film D for a focus measured from
    the entrance pupil.  The pupil moves with the lens, so iterate (3 steps converge
    to 1e-12 relative: the dependence is through the small focus travel)."""
    if math.isinf(focus_from_pupil_mm):
        f = thick_lens_film_distance_mm(lens, math.inf, p)
        d = math.inf
    else:
        f = p.bfl
        for _ in range(6):
            d = focus_from_pupil_mm + f + p.total_track - p.entrance_pupil_position
            f = thick_lens_film_distance_mm(lens, d, p)
    thick = f
    spot = None
    if real:
        f, spot = exact_film_distance_mm(lens, d, p, thick)
    return f, d, thick, spot


def make_plan(opts: ConvertOptions) -> dict:
    """Derive every number of a conversion.  Reads the inputs; its only output file is
    OUTDIR/pupil.npz (the exit-pupil table, which the render reuses while current).

    ``method="auto"`` needs renders (a depth probe): use :func:`convert`."""
    if opts.method == "auto":
        raise UsageError("make_plan: --method auto is decided by convert() (it renders a "
                         "depth probe)", "call convert(), or give a concrete method")
    return _make_plan(opts)[0]


def _make_plan(opts: ConvertOptions):
    """(plan, lens, model, film) of ``opts`` (a concrete method)."""
    start = _start_plan(opts)
    # 'povray --version' (~0.2 s, idle) runs while the pupil table is built
    return _finish_plan(opts, start, version=_in_background(povray_version))[:4]


@dataclasses.dataclass
class _PlanStart:
    """The first part of a plan: validated inputs, the focused lens, its thin-lens
    model and the POV-Ray pinhole camera (no pupil table, no model error yet).
    Nothing in it depends on the method or the sample count."""

    mm_per_unit: float
    lens: object
    paraxial: object
    film: Film
    focus_mm: float
    film_d: float
    object_d: float
    thick_d: float
    spot: float | None
    model: object
    loc: np.ndarray
    right: np.ndarray
    up: np.ndarray
    fwd: np.ndarray
    cam_source: str
    povray_camera: dict


def _start_plan(opts: ConvertOptions) -> _PlanStart:
    """Validate ``opts`` and derive the camera (:class:`_PlanStart`); cheap (no pupil table)."""
    if opts.method not in METHODS:
        raise UsageError(f"--method {opts.method}: unknown method", f"use one of {', '.join(METHODS)}")
    if opts.units not in UNITS_MM:
        raise UsageError(f"--units {opts.units}: unknown unit", "use one of mm, cm, m, in")
    if not (opts.focus > 0):
        raise UsageError(f"--focus {opts.focus}: must be a positive distance in scene units")
    if opts.samples < 1:
        raise UsageError(f"--samples {opts.samples}: must be at least 1")
    if not Path(opts.scene).is_file():
        raise UsageError(f"scene file {opts.scene} does not exist", "check the path")
    mm_per_unit = UNITS_MM[opts.units]
    lens = stopped_down(read_lens(opts.lens), stop_diameter_mm=opts.stop_diameter_mm,
                        f_number=opts.f_number)
    p = paraxial_data(lens)
    if opts.film_size_mm is not None:
        film = Film(float(opts.film_size_mm[0]), float(opts.film_size_mm[1]),
                    int(opts.width), int(opts.height))
    else:
        film = Film.from_diagonal(opts.film_diagonal_mm, opts.width, opts.height)

    focus_mm = opts.focus * mm_per_unit
    film_d, object_d, thick_d, spot = _focus(lens, p, focus_mm, opts.real_focus)
    model = fit_thin_lens(lens, film_d, object_d, film)
    loc, right, up, fwd, cam_source = _camera_basis(opts)
    pov = {
        "location": loc.tolist(), "direction": fwd.tolist(),
        "right": (right * film.width_mm / model.image_distance_mm).tolist(),
        "up": (up * film.height_mm / model.image_distance_mm).tolist(),
        "aperture": 2.0 * model.pupil_diameter_mm / mm_per_unit,
        "focal_distance": (model.focus_distance_mm / mm_per_unit
                           if math.isfinite(model.focus_distance_mm) else 1e9),
        "hfov_deg": math.degrees(2 * math.atan(0.5 * film.width_mm / model.image_distance_mm)),
    }
    return _PlanStart(mm_per_unit, lens, p, film, focus_mm, film_d, object_d, thick_d, spot,
                      model, loc, right, up, fwd, cam_source, pov)


def _finish_plan(opts: ConvertOptions, st: _PlanStart, *, pupil_table=None, model_error=None,
                 version=povray_version):
    """(plan, lens, model, film, pupil table) of ``opts`` from :func:`_start_plan`'s part.

    ``pupil_table`` / ``model_error``: already computed for the same lens, focus and
    film (they do not depend on the method or the samples); ``version`` is called
    for POV-Ray's version."""
    from povlens.pupil.rays import ScenePlacement   # (imports scipy.stats: only when needed)
    lens, p, film, model = st.lens, st.paraxial, st.film, st.model
    object_d, film_d, mm_per_unit = st.object_d, st.film_d, st.mm_per_unit
    loc, right, up, fwd = st.loc, st.right, st.up, st.fwd
    placement = ScenePlacement.at_entrance_pupil(loc, right, up, fwd, model.centre_z_mm,
                                                 mm_per_unit)
    # Depths at which the model is checked: half, once, twice and ten times the focus.
    if math.isinf(object_d):
        depths = [model.centre_z_mm + k * 1000.0 * p.efl for k in (1, 10, 100)]
    else:
        s = object_d - model.centre_z_mm
        depths = [model.centre_z_mm + k * s for k in (0.5, 1.0, 2.0, 10.0)]
    # Vignetting from the exact exit-pupil table; saved in OUTDIR for the render to reuse.
    table = pupil_table
    if table is None:
        table_path = Path(opts.outdir) / "pupil.npz"
        table = (load_if_current(table_path, lens, film_d, film.half_diagonal_mm)
                 if table_path.exists() else None)
        if table is None:
            table = build_pupil_table(lens, film_d, film.half_diagonal_mm)
            if table_path.parent.is_dir():
                table.save(table_path)
    if model_error is None:
        model_error = measure_model_error(lens, film_d, model, film, depths, pupil_table=table)

    version = version()
    rw, rh, drop = render_size(film.width_px, film.height_px, version)
    # A batch is the work of one 'povlens render-batch' (make runs them in parallel;
    # each sample is its own POV-Ray process).  By default, one batch per core.  Samples are dealt
    # round-robin, so the samples a plan with fewer samples rendered first
    # (0..n-1: the same for any count) are spread evenly over the batches.
    bs = opts.batch_size or math.ceil(opts.samples / (os.cpu_count() or 1))
    nb = math.ceil(opts.samples / bs)
    batches = [list(range(b, opts.samples, nb)) for b in range(nb)]
    return {
        "povlens_plan": PLAN_VERSION,
        "inputs": {
            "scene": str(Path(opts.scene).resolve()), "lens": lens.source,
            "lens_sha256": lens.sha256(), "focus": opts.focus, "units": opts.units,
            "f_number": opts.f_number, "stop_diameter_mm": opts.stop_diameter_mm,
            "film_diagonal_mm": opts.film_diagonal_mm, "film_size_mm": opts.film_size_mm,
            "width": opts.width, "height": opts.height, "method": opts.method,
            "samples": opts.samples, "batch_size": opts.batch_size, "seed": opts.seed,
            "real_focus": opts.real_focus, "vignetting": opts.vignetting,
            "jitter": opts.jitter, "adaptive": bool(opts.adaptive),
            "camera_from": st.cam_source,
        },
        "lens": {
            "surfaces": lens.n_surfaces, "stop_index": p.stop_index,
            "stop_diameter_mm": float(lens.aperture_diameter_mm[p.stop_index]),
            "efl_mm": p.efl, "f_number": p.f_number,
            "entrance_pupil_diameter_mm": p.entrance_pupil_diameter,
        },
        "focus": {
            "focus_from_camera_mm": st.focus_mm, "object_distance_from_film_mm": object_d,
            "film_distance_mm": film_d, "thick_lens_film_distance_mm": st.thick_d,
            "rms_spot_mm": st.spot,
        },
        "film": dataclasses.asdict(film) | {"pixel_pitch_mm": film.pixel_pitch_mm},
        "mm_per_unit": mm_per_unit,
        "placement": placement.to_dict(),
        "thin_lens": model.to_dict(),
        "povray_camera": dict(st.povray_camera),
        "model_error": model_error,
        "povray": {"version": version, "render_width": rw, "render_height": rh,
                   "drop_top_rows": drop},
        "sink_centre": default_sink_centre(loc, fwd).tolist(),
        "batches": batches,
    }, lens, model, film, table


def _write_if_changed(path: Path, text: str) -> None:
    """Write atomically, but leave an identical file alone (make compares mtimes)."""
    try:
        if path.read_text() == text:
            return
    except OSError:
        pass
    write_text(path, text)


def _write_json(path: Path, obj) -> None:
    _write_if_changed(path, json.dumps(obj, indent=2, allow_nan=False, default=_json_default)
                      + "\n")


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)


def _sanitize(obj):
    """JSON has no inf/NaN: write them as null."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _sanitize(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_sanitize(v) for v in obj]
    return obj


def read_plan(outdir: str | os.PathLike) -> dict:
    path = Path(outdir) / "plan.json"
    try:
        plan = json.loads(path.read_text())
    except FileNotFoundError:
        raise PovlensError(f"{path} does not exist",
                           "run 'povlens convert SCENE --lens LENS --focus D -o OUTDIR' first"
                           ) from None
    except json.JSONDecodeError as e:
        raise PovlensError(f"{path}: not valid JSON ({e.msg}, line {e.lineno})",
                           "run 'povlens convert' again to rewrite it") from None
    if plan.get("povlens_plan") != PLAN_VERSION:
        raise PovlensError(f"{path} was written by another version of povlens",
                           "run 'povlens convert' again")
    return plan


def _scene_include(plan: dict, outdir: Path) -> str:
    return os.path.relpath(plan["inputs"]["scene"], outdir)


def convert(opts: ConvertOptions, render_early=None) -> dict:
    """Write OUTDIR (plan.json, wrappers, Makefile) and return the plan.

    ``speculate`` (``povlens render``): work the decision is likely to need starts
    before the depth probe is in (:func:`_early_guess`): the adaptive focal_blur
    view (kept if the decision is focal-blur), the first lens samples, or both.

    ``render_early``: with ``speculate``, ``auto`` and a lens that rules out
    the pinhole and focal_blur views, or may (:func:`_early_guess`), the render is
    a mesh render of at least :data:`povlens.auto_plan.MIN_SAMPLES` samples (the
    given ``--samples`` without the automatic count).  Lens sample k does not
    depend on the count, so those samples can be rendered while the depth probe
    runs: a provisional plan with that many samples is written to OUTDIR and
    ``render_early(plan, lens, table)`` is called (the stopped-down lens and its
    exit-pupil table); it returns a handle with ``extend(plan)``, ``wait()``
    (raises what the render raised) and ``cancel()``.  If the decision is mesh,
    the handle is given the final plan (``extend``: it renders the samples that
    plan adds in the same pipeline), the final plan is written (the rendered
    samples stay: only the count changed) and the handle is waited for, so the
    folder is rendered when this returns.  Otherwise (the guess was wrong) it is
    cancelled.
    """
    out = Path(opts.outdir)
    out.mkdir(parents=True, exist_ok=True)

    decision = None
    requested = opts
    reuse = None
    early = None
    if opts.method == "auto":
        from povlens.plan.auto import choose_method, start_depth_probe
        if not (opts.tolerance_px > 0 and math.isfinite(opts.tolerance_px)):
            raise UsageError(f"--tolerance {opts.tolerance_px}: must be a positive number of "
                             "pixels")
        base = dataclasses.replace(opts, method="mesh")
        start = _start_plan(base)                         # validates the inputs first
        # The depth probe's POV-Ray processes (mostly idle start-up) and 'povray
        # --version' run while the pupil table is built and the model error measured.
        # The probe is started from a thread: its three process starts (~2.5 ms
        # each, Python waits for the exec) do not hold up the pupil table.
        probe_started = _in_background(lambda: start_depth_probe(
            base, start.film, {"povray_camera": start.povray_camera,
                               "mm_per_unit": start.mm_per_unit}))
        speculative = None
        try:
            version = _in_background(povray_version)
            plan0, lens, model, film, table = _finish_plan(base, start, version=version)
            probe = probe_started()                       # long started by now
            # The plan of the chosen method differs from plan0 only in the method, the
            # samples and the batches: same table, same model error.
            reuse = {"pupil_table": table, "model_error": plan0["model_error"],
                     "version": lambda: plan0["povray"]["version"]}
            guess = _early_guess(opts, plan0) if opts.speculate else "none"
            # the lens samples first: where they are wanted, they are the critical path
            if (render_early is not None and not opts.adaptive
                    and guess in ("mesh", "either")):
                early = _render_early(opts, start, reuse, lens, table, render_early)
            if opts.auto_samples and guess in ("views", "either"):
                speculative = _start_speculative_focal_blur(opts, plan0)
            decision = choose_method(base, plan0, model, lens, film, probe=probe,
                                     pupil_table=table)
            if early is not None:
                early_n = early[0]["inputs"]["samples"]
                if decision["method"] == "mesh":
                    why = ("the lens alone ruled out the views" if guess == "mesh" else
                           "the lens's vignetting could rule out the views")
                    _note(decision, f"(lens samples 0..{early_n - 1} were started while the "
                                    f"depth probe ran: {why})")
                else:
                    early[1].cancel()
                    early = None
                    _note(decision, "(the mesh render started while the probe ran was "
                                    "stopped)")
        except BaseException:
            try:
                probe = probe_started()                   # the same probe, or its start error
            except BaseException:
                probe = None                              # never started: nothing to stop
            if probe is not None:
                probe.cancel()
            if speculative is not None:
                speculative.cancel()
            if early is not None:
                early[1].cancel()
            raise
        if speculative is not None and decision["method"] != "focal-blur":
            speculative.cancel()
            _note(decision, "(the focal_blur render started while the probe ran "
                                       "was stopped)")
            speculative = None
        samples = decision["samples"] if opts.auto_samples else opts.samples
        if not opts.auto_samples:
            _note(decision, f"--samples {opts.samples} given: it replaces the "
                                       f"decision's {decision['samples']}")
        opts = dataclasses.replace(opts, method=decision["method"], samples=samples)
    adaptive = None
    if opts.adaptive and opts.method == "mesh":
        adaptive = decision.pop("adaptive", None) if decision is not None else None
        if adaptive is None:
            from povlens.plan.auto import adaptive_rows, measure_depth_map, real_blur_model_error
            plan1, lens1, model, film = _make_plan(opts)
            axial = measure_depth_map(opts, film, plan=plan1)
            adaptive = adaptive_rows(model, axial, film, opts.samples,
                                     model_error=real_blur_model_error(
                                         lens1, plan1, model, film, axial))
        else:
            from povlens.plan.auto import samples_for_blur
            n_min = min(adaptive["n_min"], opts.samples)
            adaptive["n_min"] = n_min
            adaptive["band_samples"] = [samples_for_blur(b, n_min, opts.samples)
                                        for b in adaptive["band_blur_px"]]
        opts = dataclasses.replace(opts, samples=max(adaptive["band_samples"]))
    elif decision is not None:
        decision.pop("adaptive", None)
    try:
        plan = make_plan(opts) if reuse is None else _finish_plan(opts, start, **reuse)[0]
        if adaptive is not None:
            _adaptive_batches(plan, adaptive, opts)
        if decision is not None:
            _mark_auto(plan, requested, decision)
        if early is not None:
            # the samples the final plan adds follow in the same pipeline; what the
            # folder had rendered stays (only the count changed: _stale_samples)
            early[1].extend(plan)
        _write_folder(out, plan)
        if early is not None:
            early[1].wait()
    except BaseException:
        if early is not None:
            early[1].cancel()
        if speculative is not None:
            speculative.cancel()
        raise
    if decision is not None and speculative is not None:
        # the decision is the render already running: it becomes the folder's view
        try:
            speculative.wait()
        except BaseException:
            Path(speculative.out_path).unlink(missing_ok=True)
            raise
        os.replace(speculative.out_path, out / "view-focal-blur.exr")
    return plan


def _note(decision: dict, text: str) -> None:
    """Add a remark to a decision's reasons, before its last line (the "-> method"
    conclusion, which stays last: summaries print it)."""
    reasons = decision["reasons"]
    reasons.insert(max(len(reasons) - 1, 0), text)


def _mark_auto(plan: dict, requested: ConvertOptions, decision: dict) -> None:
    """Record in a plan that --method auto chose it.  inputs.method is the method
    rendered (render, Makefile and report read it); requested_method records that
    it was chosen automatically."""
    plan["inputs"]["requested_method"] = "auto"
    plan["inputs"]["tolerance_px"] = requested.tolerance_px
    plan["inputs"]["auto_samples"] = requested.auto_samples
    plan["decision"] = decision


def _write_folder(out: Path, plan: dict) -> None:
    """Write a plan's files into OUTDIR: plan.json, the wrappers, the Makefile.  What
    an earlier plan rendered that this one cannot use is removed first."""
    old = None
    if (out / "plan.json").exists():
        try:
            old = read_plan(out)
        except PovlensError:
            old = None
    if old is not None and old.get("inputs") != _sanitize(plan["inputs"]):
        _invalidate_outputs(out, _stale_samples(old, _sanitize(plan)))
    scene_inc = _scene_include(plan, out)
    cam = plan["povray_camera"]
    _write_if_changed(out / "pinhole.pov", pinhole_wrapper(
        scene_inc, cam["location"], cam["direction"], cam["right"], cam["up"]))
    _write_if_changed(out / "focal_blur.pov", _focal_blur_text(plan, out))
    if plan["inputs"]["method"] == "mesh":
        (out / "samples").mkdir(exist_ok=True)
        for b, _ in enumerate(plan["batches"]):
            _write_if_changed(out / "samples" / f"batch_{b:03d}.pov", _batch_wrapper(plan, out, b))
    _write_if_changed(out / "Makefile", _makefile(plan))
    _write_json(out / "plan.json", _sanitize(plan))


def _render_early(opts: ConvertOptions, start: "_PlanStart", reuse: dict, lens, table,
                  render_early):
    """Write the provisional mesh plan of an auto conversion whose lens rules out
    the views, and start rendering it (:func:`convert`, ``render_early``).
    Returns (provisional plan, handle)."""
    from povlens.plan.auto import MIN_SAMPLES
    n = MIN_SAMPLES if opts.auto_samples else opts.samples
    eopts = dataclasses.replace(opts, method="mesh", samples=n)
    plan = _finish_plan(eopts, start, **reuse)[0]
    _mark_auto(plan, opts, {
        "method": "mesh", "samples": n, "provisional": True,
        "reasons": ["provisional: the lens alone rules out the pinhole and focal_blur views "
                    "(vignetting or distortion); the depth probe decides the sample count"]})
    _write_folder(Path(opts.outdir), plan)
    return plan, render_early(plan, lens, table)


def _blur_settings(plan: dict) -> dict:
    """focal_blur sampling of a plan: ``blur_samples min, max`` (+ confidence and
    variance for POV-Ray's adaptive sampling, as --method auto chooses it)."""
    d = plan.get("decision", {}).get("focal_blur")
    if d is not None and plan["inputs"].get("auto_samples", True):
        return {"blur_samples": d["min"], "max_blur_samples": d["max"],
                "confidence": d["confidence"], "variance": d["variance"]}
    n = int(plan["inputs"]["samples"])
    return {"blur_samples": n, "max_blur_samples": n, "confidence": None, "variance": None}


def _focal_blur_text(plan: dict, out: Path) -> str:
    cam = plan["povray_camera"]
    return focal_blur_wrapper(
        _scene_include(plan, out), cam["location"], cam["direction"], cam["right"], cam["up"],
        aperture=cam["aperture"], focal_distance=cam["focal_distance"], **_blur_settings(plan))


def _early_guess(opts: ConvertOptions, plan0: dict) -> str:
    """What ``povlens render --method auto`` starts before the depth probe is in
    (:func:`convert`, ``speculate``); the decision itself waits for the probe.

    * ``"mesh"`` -- the lens alone rules out the views
      (:func:`_lens_rules_out_views`): the first lens samples of the mesh render;
    * ``"either"`` -- the thin lens may do, but the vignetting is wanted and
      visible while the blur needs only the minimum mesh sample count
      (:func:`_vignetting_may_choose_mesh`): whether :func:`povlens.auto_plan.decide`
      takes mesh for it depends on the scene's image, so both start: the first
      lens samples, and the adaptive focal_blur view at low priority
      (:data:`SPECULATIVE_IDLE`), which takes the CPU the samples leave;
    * ``"views"`` -- otherwise: the adaptive focal_blur view (low priority).

    Measured (2 cores, 160x120, :func:`povlens.render.convert_and_render` timed in
    fresh processes):
    paper.pov / tessar.50mm (decided mesh 8) took 1.30-1.40 s starting both and
    1.28-1.32 s starting only the samples, against 1.25-1.27 s for a fixed
    8-sample mesh render; chart.pov / cooke.triplet.50mm (decided focal-blur)
    1.01-1.09 s starting both and 1.37-1.39 s starting only the samples."""
    if _lens_rules_out_views(opts, plan0):
        return "mesh"
    if _vignetting_may_choose_mesh(opts, plan0):
        return "either"
    return "views"


def _lens_rules_out_views(opts: ConvertOptions, plan0: dict) -> bool:
    """The guess, before the depth probe is in, that --method auto will choose mesh:
    at the plan's standard depths (half, once, twice and ten times the focus
    distance) the distortion, half the blur-size error or half the shape error
    (:func:`povlens.auto_plan.decide`'s measures) is over the budget, or the
    vignetting is wanted and strong (relative illumination below
    :data:`povlens.auto_plan.STRONG_VIGNETTING` somewhere in the frame)."""
    from povlens.plan.auto import STRONG_VIGNETTING, shape_error_px
    e = plan0["model_error"]
    tol = opts.tolerance_px
    shape = shape_error_px(np.asarray(e["blur_real_px"]), np.asarray(e["elongation"]))
    illum = e["min_relative_illumination"]
    return bool((opts.vignetting and illum < STRONG_VIGNETTING)
                or e["max_distortion_px"] >= tol or e["max_blur_size_error_px"] / 2 >= tol
                or float(np.max(shape)) / 2 >= tol)


def _vignetting_may_choose_mesh(opts: ConvertOptions, plan0: dict) -> bool:
    """The vignetting is wanted and visible (relative illumination below ``1 -
    VIGNETTING_TOLERANCE``) and the largest blur at the plan's standard depths
    needs only the minimum mesh sample count: the case where
    :func:`povlens.auto_plan.decide` prefers mesh when the vignetting takes
    :data:`povlens.auto_plan.VIGNETTING_FLOOR_SHARE` of the budget."""
    from povlens.plan.auto import MIN_SAMPLES, VIGNETTING_TOLERANCE, samples_for_blur
    e = plan0["model_error"]
    illum = e["min_relative_illumination"]
    blur = max(float(np.max(e["blur_real_px"])), float(np.max(e["blur_model_px"])))
    return bool(opts.vignetting and illum < 1.0 - VIGNETTING_TOLERANCE
                and samples_for_blur(blur) == MIN_SAMPLES)


#: The focal_blur render started on a guess runs at idle priority (Linux
#: ``SCHED_IDLE``, :func:`povlens.povray.start_render` ``idle``): it gets only the
#: CPU time the probe, the model error and the early lens samples leave, and all of
#: it once the guess is confirmed (the samples are stopped then).  Measured (2 cores,
#: 160x120, :func:`povlens.render.convert_and_render` in one process, 5 alternating
#: runs each, min / median): paper.pov / cooke.triplet.50mm, an "either" guess
#: decided mesh 8, 1.17 / 1.19 s idle against 1.20 / 1.26 s at nice 10 and 1.11 /
#: 1.14 s for a fixed 8-sample mesh render; chart.pov / cooke.triplet.50mm, decided
#: focal-blur, 0.94 / 1.01 s against 0.98 / 1.03 s; paper.pov / telephoto.250mm
#: (right guess) 1.14 / 1.15 s against 1.15 / 1.15 s and paper.pov with the 100 mm
#: dgauss (wrong guess, mesh 32) 3.48 / 3.55 s against 3.46 / 3.49 s (4 and 3 runs).
#: (Before 2026-11-29 nice 10, which still takes about a tenth of a busy core.)
SPECULATIVE_IDLE = True


def _start_speculative_focal_blur(opts: ConvertOptions, plan0: dict):
    """Start the focal_blur render --method auto may choose (:func:`_early_guess`).  Its
    settings (:data:`povlens.auto_plan.FOCAL_BLUR_ADAPTIVE`) do not depend on the
    depth probe, so it runs while the probe does; :func:`convert` keeps it if the
    decision is focal-blur, else stops it.  Its wrapper is its own file
    (``.speculative-focal-blur.pov``, the text the final ``focal_blur.pov`` gets):
    the provisional mesh plan an "either" guess writes at the same time rewrites
    ``focal_blur.pov`` with its own sample count, possibly before POV-Ray has read
    it.  Returns a :class:`_SpeculativeView`."""
    from povlens.plan.auto import FOCAL_BLUR_ADAPTIVE
    from povlens.pov.process import start_render
    out = Path(opts.outdir)
    guess = dict(plan0, inputs=dict(plan0["inputs"], auto_samples=True),
                 decision={"focal_blur": FOCAL_BLUR_ADAPTIVE})
    pov = out / ".speculative-focal-blur.pov"
    write_text(pov, _focal_blur_text(guess, out))
    film = plan0["film"]
    try:
        job = start_render(pov, out / ".speculative-focal-blur.exr",
                           film["width_px"], film["height_px"], threads=os.cpu_count() or 1,
                           library_paths=[Path(plan0["inputs"]["scene"]).parent],
                           idle=SPECULATIVE_IDLE)
    except BaseException:
        pov.unlink(missing_ok=True)
        raise
    return _SpeculativeView(job, pov)


class _SpeculativeView:
    """A running speculative focal_blur render (:func:`_start_speculative_focal_blur`);
    its wrapper is deleted once it is waited for or cancelled."""

    def __init__(self, job, pov: Path):
        self._job, self._pov = job, pov
        self.out_path = job.out_path

    def wait(self):
        try:
            return self._job.wait()
        finally:
            self._pov.unlink(missing_ok=True)

    def cancel(self) -> None:
        try:
            self._job.cancel()
        finally:
            self._pov.unlink(missing_ok=True)


def _in_background(fn):
    """Run ``fn()`` in a thread; returns a function that waits for its result (or
    raises its exception)."""
    from concurrent.futures import ThreadPoolExecutor
    pool = ThreadPoolExecutor(max_workers=1)
    future = pool.submit(fn)
    pool.shutdown(wait=False)
    return future.result


def _adaptive_batches(plan: dict, adaptive: dict, opts: ConvertOptions) -> None:
    """Per-sample row ranges (``sample_rows``, film rows [start, end)) and batches.

    Every sample is its own POV-Ray process (:func:`povlens.render.render_samples`),
    so a batch may mix row ranges; samples are dealt round-robin to the batches
    (later samples render fewer rows, so contiguous batches would be unequal)."""
    from povlens.plan.auto import sample_row_ranges
    h, w = plan["film"]["height_px"], plan["film"]["width_px"]
    rows = sample_row_ranges(adaptive, h)
    n = len(rows)
    bs = opts.batch_size or math.ceil(n / (os.cpu_count() or 1))
    nb = math.ceil(n / bs)
    plan["batches"] = [list(range(b, n, nb)) for b in range(nb)]
    plan["sample_rows"] = rows
    pixel_samples = sum((r1 - r0) * w for r0, r1 in rows)
    plan["adaptive"] = dict(adaptive, pixel_samples=pixel_samples,
                            uniform_pixel_samples=n * h * w)


#: Plan inputs that do not change what lens sample k renders: the sample count
#: (scrambled-Sobol point k is the same for any count), how samples are batched,
#: and how the method and count were chosen.  A change of these keeps rendered
#: samples whose row range is unchanged.
SAMPLE_INDEPENDENT_INPUTS = ("samples", "batch_size", "adaptive", "requested_method",
                             "tolerance_px", "auto_samples")


def _stale_samples(old: dict, new: dict) -> list[int] | None:
    """Samples of the old plan that the new plan cannot reuse: ``None`` = all (an
    input that changes every sample differs), else those whose rows changed or
    that the new plan no longer has."""
    oi = {k: v for k, v in old.get("inputs", {}).items() if k not in SAMPLE_INDEPENDENT_INPUTS}
    ni = {k: v for k, v in new["inputs"].items() if k not in SAMPLE_INDEPENDENT_INPUTS}
    if oi != ni:
        return None
    n_old, n_new = int(old["inputs"]["samples"]), int(new["inputs"]["samples"])
    full_old = [0, old["film"]["height_px"]]
    full_new = [0, new["film"]["height_px"]]

    def rows(plan, k, full):
        r = plan.get("sample_rows")
        return list(r[k]) if r is not None else full

    return [k for k in range(n_old)
            if k >= n_new or rows(old, k, full_old) != rows(new, k, full_new)]


def _invalidate_outputs(out: Path, stale: list[int] | None = None) -> None:
    """Inputs changed: drop what no longer belongs to the plan.  ``stale`` lists the
    lens samples to drop (None = every sample, and exposure.txt, which depends on
    the lens, focus and film); images, views and batch markers always go."""
    # pupil.npz stays: load_if_current checks its inputs.  A sample's mesh (.inc)
    # goes with the sample: one still wanted may be in use by a running render.
    patterns = ["samples/*.done", "samples/*.timing.json", "image.exr",
                "image.png", "view-*.exr"]
    if stale is None:
        patterns += ["samples/*.exr", "samples/*.blocked", "samples/*.inc", "exposure.txt"]
    for pattern in patterns:
        for f in out.glob(pattern):
            f.unlink()
    for k in stale or []:
        for suffix in (".exr", ".weight.exr", ".blocked", ".inc"):
            (out / "samples" / f"sample_{k:04d}{suffix}").unlink(missing_ok=True)


def _batch_wrapper(plan: dict, out: Path, batch: int) -> str:
    """Animation wrapper (templates/mesh_batch.pov.tmpl): frame k renders sample k."""
    scene = os.path.relpath(plan["inputs"]["scene"], out / "samples")
    return _template("mesh_batch.pov.tmpl").substitute(
        scene_include=_pov_string(scene), sink_centre=_vec(plan["sink_centre"]),
        sink_radius=f"{SINK_RADIUS:.9g}")


def _makefile(plan: dict) -> str:
    """The folder's Makefile (templates/Makefile.tmpl)."""
    method = plan["inputs"]["method"]
    if method == "mesh":
        dones = " ".join(f"samples/batch_{b:03d}.done" for b in range(len(plan["batches"])))
        rules = (f"image.png: {dones}\n\t$(POVLENS) composite .\n\n"
                 "samples/batch_%.done: plan.json\n\t$(POVLENS) render-batch . $*\n")
    else:
        wrapper = "pinhole.pov" if method == "pinhole" else "focal_blur.pov"
        rules = f"image.png: plan.json {wrapper}\n\t$(POVLENS) render-view . --view {method}\n"
    return _template("Makefile.tmpl").substitute(
        povlens=f"{shlex.quote(sys.executable)} -m povlens", rules=rules)
