"""Scene conversion: from a POV-Ray scene and a lens to a render folder.

``convert`` never edits the user's scene.  It resolves the focus distance
(:mod:`povlens.plan.autofocus`: the option, the scene camera's, or measured by the
depth probe), derives the plan (:mod:`povlens.plan.plan_start`,
:mod:`povlens.plan.plan_finish`; with ``--method auto`` after measuring the scene and
deciding, :mod:`povlens.plan.auto`) and writes OUTDIR
(:mod:`povlens.plan.folder_writer`): ``plan.json``, the POV-Ray wrappers, the
exit-pupil table ``pupil.npz`` and a ``Makefile`` (``make -C OUTDIR -j2``
renders and composites).
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
from pathlib import Path
from typing import Callable

from povlens.plan import speculative
from povlens.plan.adaptive import adaptive_rows, apply_to_plan, limit_samples, real_blur_model_error
from povlens.plan.auto import choose_method, measure_depth_map, start_depth_probe
from povlens.plan.autofocus import pinhole_focus_note, resolve_focus
from povlens.plan.depth_probe import atmosphere_note, depth_limits, probe_record
from povlens.plan.dispersion_plan import colour_decision
from povlens.plan.plan_finish import (PlanReuse, finish_plan, make_plan, make_plan_with_lens,
                                     shared_photon_settings, shares_radiosity)
from povlens.plan.plan_start import PlanStart, start_plan
from povlens.plan.options import METHODS, ConvertOptions, with_povray_options_checked
from povlens.plan.folder_writer import write_folder, write_pinhole_wrapper
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import AdaptiveSampling, Decision, Plan
from povlens.pov.executable import povray_version
from povlens.util.resources import resolve_scene_path
from povlens.util.threads import run_in_background

__all__ = ["ConvertOptions", "METHODS", "convert", "make_plan"]


@dataclasses.dataclass
class _AutoChoice:
    """What the automatic path of :func:`convert` decided and what it left running."""

    requested: ConvertOptions          # the options as given (method "auto")
    chosen: ConvertOptions             # the decided method and sample count
    start: PlanStart
    reuse: PlanReuse                   # finish_plan's table, model error and version
    decision: Decision
    adaptive: AdaptiveSampling | None
    early: speculative.EarlySamples | None = None
    view: speculative.SpeculativeView | None = None


def _cancel_probe(probe_started: Callable) -> None:
    """Stop a depth probe started in the background (nothing if its start failed).

    A Ctrl-C or SIGTERM while waiting for the start is passed on once the probe is
    stopped (swallowing it here let the render run on to the end)."""
    interrupt, probe = None, None
    while True:
        try:
            probe = probe_started()          # the probe, or its start's error
            break
        except KeyboardInterrupt as e:       # Terminated too: wait on, then pass it on
            interrupt = e
        except Exception:
            break                            # never started: nothing to stop
    if probe is not None:
        probe.cancel()
    if interrupt is not None:
        raise interrupt


def _settle_speculation(choice: _AutoChoice, guess: str) -> None:
    """Keep the early work the decision confirms; stop the rest (with a remark)."""
    decision = choice.decision
    if choice.early is not None:
        if decision.method == "mesh":
            n = choice.early.plan.inputs.samples
            why = ("the lens alone ruled out the views" if guess == "mesh" else
                   "the lens's vignetting could rule out the views")
            decision.add_remark(f"(lens samples 0..{n - 1} were started while the depth probe "
                                f"ran: {why})")
        else:
            choice.early.render.cancel()
            choice.early = None
            decision.add_remark("(the mesh render started while the probe ran was stopped)")
    if choice.view is not None and decision.method != "focal-blur":
        choice.view.cancel()
        choice.view = None
        decision.add_remark("(the focal_blur render started while the probe ran was stopped)")


def _choose_automatically(opts: ConvertOptions, render_early, cleanup: contextlib.ExitStack,
                          depth_probe=None) -> _AutoChoice:
    """``--method auto``: probe the scene, decide, and (``speculate``) start the
    likely render meanwhile.  Everything started is registered on ``cleanup``."""
    base = opts.replace(method="mesh")
    start = start_plan(base)                              # validates the inputs first
    # The depth probe's POV-Ray processes (mostly idle start-up) and 'povray --version'
    # run while the pupil table is built and the model error measured.  The probe is
    # started from a thread: its process starts do not hold up the pupil table.
    starter = depth_probe or start_depth_probe           # a focus pull's frames share one
    probe_started = run_in_background(lambda: starter(base, start.film, start))
    cleanup.callback(_cancel_probe, probe_started)
    plan0, table = finish_plan(base, start,
                               PlanReuse(version=run_in_background(povray_version)))
    probe = probe_started()                               # long started by now
    # The chosen method's plan differs from plan0 only in the method, the samples and
    # the batches: same table, same model error.
    reuse = PlanReuse(pupil_table=table, model_error=plan0.model_error,
                      version=lambda: plan0.povray.version)
    guess = speculative.early_guess(opts, plan0) if opts.auto.speculate else "none"
    early = view = None
    # the lens samples first: where they are wanted, they are the critical path
    if render_early is not None and not opts.sampling.adaptive and guess in ("mesh", "either"):
        early = speculative.start_early_samples(opts, start, reuse, table, render_early)
        cleanup.callback(early.render.cancel)
    if opts.sampling.auto_samples and guess in ("views", "either"):
        view = speculative.start_speculative_focal_blur(opts, plan0)
        cleanup.callback(view.cancel)
    decision, adaptive = choose_method(base, plan0, plan0.thin_lens, start.lens, plan0.film,
                                       probe=probe, pupil_table=table)
    decision = colour_decision(opts, start.lens, plan0, decision)    # --dispersion
    choice = _AutoChoice(opts, opts, start, reuse, decision, adaptive, early, view)
    _settle_speculation(choice, guess)
    samples = decision.samples if opts.sampling.auto_samples else opts.sampling.sample_count
    if not opts.sampling.auto_samples:
        decision.add_remark(f"--samples {opts.sampling.sample_count} given: it replaces the "
                            f"decision's {decision.samples}")
    choice.chosen = opts.replace(method=decision.method, samples=samples)
    return choice


def _adaptive_sampling(opts: ConvertOptions, choice: _AutoChoice | None
                       ) -> tuple[ConvertOptions, AdaptiveSampling | None, dict | None]:
    """The row bands of an adaptive mesh plan (from auto's probe, or a probe of its
    own), the options with the sample count they need, and the numbers of the probe
    run here (None: none ran)."""
    if not (opts.sampling.adaptive and opts.sampling.method == "mesh"):
        return opts, None, None
    adaptive = choice.adaptive if choice is not None else None
    info = None
    if adaptive is None:
        plan1, lens1 = make_plan_with_lens(opts)
        model, film = plan1.thin_lens, plan1.film
        axial = measure_depth_map(opts, film, plan=plan1)
        info = depth_limits(axial)[2] | {"probe_width": int(axial.shape[1]),
                                         "probe_height": int(axial.shape[0])}
        adaptive = adaptive_rows(model, axial, film, opts.sampling.sample_count,
                                 model_error=real_blur_model_error(lens1, plan1, model, film,
                                                                   axial))
    else:
        adaptive = limit_samples(adaptive, opts.sampling.sample_count)
    return opts.replace(samples=max(adaptive.band_samples)), adaptive, info


def _keep_speculative_view(view: speculative.SpeculativeView, outdir: Path) -> None:
    """The decision is the focal_blur render already running: it becomes the view."""
    try:
        view.wait()
    except BaseException:
        Path(view.out_path).unlink(missing_ok=True)
        raise
    os.replace(view.out_path, RenderFolder(outdir).view_image("focal-blur"))


def _shared_early(opts: ConvertOptions, out: Path, start_shared, cleanup):
    """``on_start`` of :func:`make_plan_with_lens`: when the plan will share the
    radiosity samples or a photon map, write ``pinhole.pov`` and
    ``start_shared(opts, start, out)`` (stopped by ``cleanup`` if the conversion
    fails)."""
    if start_shared is None:
        return None

    def on_start(start: PlanStart) -> None:
        photons = shared_photon_settings(opts, start)
        if not (photons or shares_radiosity(opts, start)):
            return
        write_pinhole_wrapper(out, opts.scene, start.povray_camera, photons)
        cancel = start_shared(opts, start, out)
        if cancel is not None:
            cleanup.callback(cancel)
    return on_start


def convert(opts: ConvertOptions, render_early=None, depth_probe=None,
            start_shared=None) -> Plan:
    """Write OUTDIR (plan.json, wrappers, Makefile) and return the plan.

    Parameters
    ----------
    opts : the conversion (:class:`~povlens.plan.options.ConvertOptions`).  With
        ``speculate`` (``povlens render``), ``--method auto`` starts the work the
        decision is likely to need before the depth probe is in
        (:func:`povlens.plan.speculative.early_guess`): the adaptive focal_blur
        view (kept if the decision is focal-blur), the first lens samples, or both.
    render_early : with ``speculate`` and ``auto``, when the lens rules out the
        pinhole and focal_blur views, or may, the render is a mesh render of at
        least :data:`~povlens.plan.decision.MIN_SAMPLES` samples (the given
        ``samples`` without the automatic count).  Lens sample k does not depend
        on the count, so those samples can render while the depth probe runs: a
        provisional plan with that many samples is written to OUTDIR and
        ``render_early(plan, lens, table)`` is called (the stopped-down lens and its
        exit-pupil table); it returns a handle with ``extend(plan)``, ``wait()``
        (raises what the render raised) and ``cancel()``.  If the decision is
        mesh, the handle is given the final plan (it renders the samples that plan
        adds in the same pipeline), the final plan is written (the rendered
        samples stay: only the count changed) and the handle is waited for, so
        the folder is rendered when this returns.  Otherwise it is cancelled.
    depth_probe : with ``auto``, what starts the depth probe, called as
        :func:`~povlens.plan.auto.start_depth_probe` ``(opts, film, plan)`` (default:
        that function); a focus pull's frames share one
        (:class:`povlens.plan.probe_reuse.ProbeReuse`).
    start_shared : for a mesh plan sharing radiosity samples or a photon map, called as
        ``start_shared(opts, start, outdir)`` once the :class:`PlanStart` is known and
        ``pinhole.pov`` written: it starts making them while the plan is finished and
        returns what stops that if the conversion fails (:func:`_shared_early`).

    Returns
    -------
    Plan
        The plan written to OUTDIR/plan.json.

    On any error (and on Ctrl-C) every POV-Ray process this call started is
    stopped and its temporary files removed, and no plan.json of this call is
    left half-written.
    """
    opts = opts.replace(scene=str(resolve_scene_path(opts.scene)))
    opts = with_povray_options_checked(opts)              # before any POV-Ray run
    out = Path(opts.outdir)
    out.mkdir(parents=True, exist_ok=True)
    opts, focus_info = resolve_focus(opts)                # option, camera, or depth probe
    with contextlib.ExitStack() as cleanup:               # unwinds what auto started
        choice = None
        if opts.sampling.method == "auto":
            choice = _choose_automatically(opts, render_early, cleanup, depth_probe)
            opts = choice.chosen
        opts, adaptive, range_info = _adaptive_sampling(opts, choice)
        plan = (make_plan_with_lens(opts, _shared_early(opts, out, start_shared, cleanup))[0]
                if choice is None else finish_plan(opts, choice.start, choice.reuse)[0])
        if adaptive is not None:
            apply_to_plan(plan, adaptive, opts.sampling.batch_size)
        if choice is not None:
            range_info = choice.decision.numbers.get("depth_probe")
        if focus_info is not None or range_info is not None:
            plan.depth_probe = probe_record(range_info, focus_info)
            # the probe's blind spot: the scene's own fog and media
            plan.add_note(atmosphere_note(opts.scene, opts.povray.library_paths))
        plan.add_note(pinhole_focus_note(opts))           # pinhole: no probe for the focus
        if choice is not None:
            req = choice.requested
            plan.record_auto_choice(choice.decision, req.auto.tolerance_px,
                                    req.sampling.auto_samples)
            if choice.early is not None:
                # the samples the final plan adds follow in the same pipeline; what the
                # folder had rendered stays (only the count changed: stale_samples)
                choice.early.render.extend(plan)
        write_folder(out, plan)
        if choice is not None and choice.early is not None:
            choice.early.render.wait()
        if choice is not None and choice.view is not None:
            _keep_speculative_view(choice.view, out)
        cleanup.pop_all()                                 # success: nothing to unwind
    return plan
