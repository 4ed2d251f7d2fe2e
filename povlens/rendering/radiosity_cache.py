"""Radiosity computed once for every lens sample of a mesh render.

A mesh render runs POV-Ray once per lens sample, and each run of a scene with
radiosity redoes the radiosity pretrace, which dominates such scenes (issue 25). The
radiosity samples depend on the scene, not on the camera ray, within POV-Ray's own
tolerances, and a lens's sample rays start millimetres apart: so one pinhole render of
the plan's view saves them (POV-Ray 3.7's ``Radiosity_File_Name=F +RFO``; the
``save_file`` keyword of 3.6 is ignored by 3.7) and every lens sample reads them
(``+RFI``), computing only the few more it needs. Measured on
``radiosity/cornell.pov`` at 160x120, one thread: 4.0 s a render without the file,
2.0 s reading it, the image within RMSE 6.4e-4 of the plain one (POV-Ray against
itself at 1 and 2 threads: RMSE 2.1e-3; docs/decisions/planning.md).

The plan says whether a render shares them (``plan.povray.radiosity_cache``, set for a
mesh plan of a scene whose ``global_settings`` hold ``radiosity``). The file is made by
the first render that needs it (``povlens render``, each batch of ``make``, each
worker's copy of a cluster render) and renamed into place when complete, so renders
racing to make it waste time, never read half a file.  ``povlens render`` starts that
render as soon as it has read the scene and camera (:func:`start_radiosity_cache_early`),
and its lens samples' meshes are written while it runs; a run that reads the file waits
for it (:mod:`povlens.rendering.pinhole_products`: raddem.pov at 320x240, 8 samples,
3.07 s -> 2.2-2.4 s).

``povlens render`` reads them in every run (:mod:`povlens.rendering.lead_render`): a
field pass's own pretrace is spaced by the tiled image it renders, and either leaves
the cache to the final trace, tile by tile (a dot lattice), or, scaled to the frame's
spacing, traces m^2 times its pretrace (:func:`povlens.pov.mesh.pretrace_block`).  The
measurement below stays for ``make``'s batches and cluster groups of a folder it has
not started (and for the record: the "own" side of the gamma_showcase and patio figures
was the unscaled pretrace, faster for its sparse cache).

Whether sharing pays is measured, not guessed: a scene whose radiosity is cheap beside
its tracing can lose by it (the pinhole render's cost, and lens samples that trace slower
through the denser shared samples: ``gamma/gamma_showcase.pov``'s field-mesh sample
traces in 1.3 s computing its own radiosity, 2.3 s reading the file), while
``radiosity/cornell.pov``'s sample drops from 2.54 s to 1.05 s with the file. POV-Ray's
"Radiosity Time" alone does not tell (patio-radio's sample spends 0.43 s in it and 3.9 s
tracing, yet gains from the file: samples computed during the final trace count as
trace time). So a render that has not chosen yet makes the shared samples first, then
renders one lens sample with its own radiosity and one reading them, side by side, and
the faster, wall clock, decides for the rest (:func:`choice_from`): the first to finish,
since the other has then taken as long already (or, across batches, when both have). ``radiosity.json`` keeps the measurements (with POV-Ray's
phase times, ``+GS``) and the choice for every later batch; a batch that renders one
probe records it for the next. The pinhole render that saves the samples is the image's size: a quarter-size one is cheaper (cornell 3.0 s at 80x60
against 4.6 s at 320x240, its samples then 1.88 s against 1.80 s), but balcony's samples
trace 6.8 s reading a quarter-size one against 4.8 s reading a full one (36.3 s against
40.9 s for the render).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from povlens.plan.options import povray_options_of
from povlens.plan.plan_finish import no_pretrace
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Plan
from povlens.pov.render_statistics import render_statistics
from povlens.rendering.pinhole_products import (PinholeProduct, cancel_product, product_ready,
                                                start_product, wait_product)
from povlens.util.files import temporary_path, write_text

__all__ = ["radiosity_cache_for", "start_radiosity_cache", "start_radiosity_cache_early",
           "radiosity_cache_ready",
           "cancel_radiosity_cache", "radiosity_read_args", "sharing_chosen", "probes_missing",
           "choice_from", "probe_measurement", "record_probes", "PROBES"]

#: The two measurements the choice compares: a lens sample computing its own radiosity,
#: and one reading the shared samples.
PROBES = ("own", "shared")


def _shared_file(plan: Plan, outdir) -> Path | None:
    """The folder's radiosity file if the plan shares one, else None (also for a scene
    without a pretrace: :func:`povlens.plan.plan_finish.no_pretrace`)."""
    if (not plan.povray.radiosity_cache or sharing_chosen(outdir) is False
            or no_pretrace(plan.povray.radiosity_pretrace)):
        return None
    return RenderFolder(outdir).radiosity_cache.absolute()


def start_radiosity_cache(plan: Plan, outdir: str | os.PathLike) -> None:
    """Start making the folder's radiosity samples, if the plan shares them and they are
    missing, and return at once: :func:`radiosity_cache_for` then waits for that render
    (in any thread), :func:`radiosity_cache_ready` says whether it is done and
    :func:`cancel_radiosity_cache` stops it.  The time it takes (a pinhole render: on a
    small scene mostly POV-Ray's idle start-up and exit) goes to writing the first lens
    samples' meshes meanwhile."""
    cache = _shared_file(plan, outdir)
    if cache is not None:
        _start(cache, outdir, (plan.film.width_px, plan.film.height_px), plan.inputs.scene,
               povray_options_of(plan.inputs))


def start_radiosity_cache_early(opts, start, outdir: str | os.PathLike) -> None:
    """:func:`start_radiosity_cache` for a plan not finished yet, as soon as the scene
    and camera are known (``start``, the
    :class:`~povlens.plan.plan_start.PlanStart` of ``opts``, whose plan shares
    the radiosity samples: :func:`povlens.plan.plan_finish.shares_radiosity`; the
    folder's ``pinhole.pov`` is written): the pupil table and the field meshes are
    derived meanwhile (``raddem.pov`` at 320x240: 0.4 s).  Nothing starts when the
    folder has the file, or chose not to share it."""
    if sharing_chosen(outdir) is False or no_pretrace(start.scene_pretrace):
        return
    _start(RenderFolder(outdir).radiosity_cache.absolute(), outdir,
           (start.film.width_px, start.film.height_px), opts.scene, start.povray)


def _start(cache: Path, outdir, size: tuple[int, int], scene, povray_options) -> None:
    """Start the pinhole render making ``cache`` unless it is complete or being made."""
    def start():
        tmp = temporary_path(cache)
        return PinholeProduct(outdir, tmp, cache, size,
                              [f"Radiosity_File_Name={tmp.name}", "+RFO"], scene,
                              povray_options)
    start_product(cache, start)


def radiosity_cache_ready(plan: Plan, outdir: str | os.PathLike) -> bool:
    """False while :func:`start_radiosity_cache`'s render of the folder's radiosity
    samples runs; True otherwise (:func:`radiosity_cache_for` then returns without
    waiting for a render this process started).  Never blocks."""
    cache = _shared_file(plan, outdir)
    return cache is None or product_ready(cache)


def cancel_radiosity_cache(outdir: str | os.PathLike) -> None:
    """Stop a render of the folder's radiosity samples that
    :func:`start_radiosity_cache` started and nothing waited for (an error, an
    interrupt, a render that did not need them)."""
    cancel_product(RenderFolder(outdir).radiosity_cache)


def radiosity_cache_for(plan: Plan, outdir: str | os.PathLike) -> Path | None:
    """The folder's radiosity samples, made now if the plan shares them and they are
    missing; None when the plan does not share them.

    Parameters
    ----------
    plan : the folder's plan.
    outdir : the render folder.

    Returns
    -------
    Path or None
        ``RenderFolder(outdir).radiosity_cache``; made by one pinhole render of the
        folder's ``pinhole.pov`` at the image's size, all cores
        (:class:`povlens.rendering.pinhole_products.PinholeProduct`), or by the one
        :func:`start_radiosity_cache` started, waited for.
        None also when the folder's first lens sample found that sharing does not pay
        (:func:`sharing_chosen`).
    """
    if _shared_file(plan, outdir) is None:
        return None
    start_radiosity_cache(plan, outdir)     # unless in place or being made
    return wait_product(RenderFolder(outdir).radiosity_cache)


def radiosity_read_args(cache: Path | None, cwd: Path) -> list[str]:
    """POV-Ray's switches that read ``cache`` (none without one), its name relative to
    POV-Ray's working folder ``cwd`` (a render folder's path may hold spaces)."""
    if cache is None:
        return []
    return [f"Radiosity_File_Name={os.path.relpath(cache, cwd)}", "+RFI"]


def _record(outdir) -> dict:
    """``radiosity.json`` as a dict ({} when missing or unreadable: measured again)."""
    try:
        rec = json.loads(RenderFolder(outdir).radiosity_choice.read_text())
    except (OSError, ValueError):
        return {}
    return rec if isinstance(rec, dict) else {}


def sharing_chosen(outdir: str | os.PathLike) -> bool | None:
    """Whether the lens samples of the folder share the radiosity samples, as
    :func:`record_probes` chose it; None when not chosen yet."""
    share = _record(outdir).get("share")
    return share if isinstance(share, bool) else None


def probes_missing(outdir: str | os.PathLike) -> list[str]:
    """The measurements the choice still needs, in the order to make them:
    ``"own"`` (a lens sample computing its own radiosity) and ``"shared"`` (one
    reading the shared samples)."""
    rec = _record(outdir)
    return [kind for kind in PROBES if not isinstance(rec.get(kind), dict)]


def choice_from(measurements: dict) -> bool | None:
    """The choice from the probes' measurements: {kind: {"wall_s", "finished", ...}}.

    True (share) when the sample reading the shared samples took no longer, wall clock,
    than the one computing its own; decided as soon as one has finished and the other,
    still running, has already taken longer; None while that is not known.
    """
    own, shared = measurements.get("own"), measurements.get("shared")
    if not (isinstance(own, dict) and isinstance(shared, dict)):
        return None
    own_done, shared_done = bool(own.get("finished")), bool(shared.get("finished"))
    if own_done and shared_done:
        return shared["wall_s"] <= own["wall_s"]
    if shared_done and own["wall_s"] >= shared["wall_s"]:
        return True
    if own_done and shared["wall_s"] > own["wall_s"]:
        return False
    return None


def probe_measurement(sample: int, wall_s: float, statistics: str | None = None) -> dict:
    """A probe's record: its sample, wall time (s) and, once finished (``statistics``:
    what its POV-Ray printed with
    :data:`povlens.pov.render_statistics.STATISTICS_SWITCHES`), POV-Ray's radiosity and
    trace times; without statistics it is still running and ``wall_s`` a lower bound."""
    m = {"sample": int(sample), "wall_s": round(float(wall_s), 4),
         "finished": statistics is not None}
    if statistics is not None:
        stats = render_statistics(statistics)
        m["radiosity_s"], m["trace_s"] = stats.radiosity_s, stats.trace_s
    return m


def record_probes(outdir: str | os.PathLike, measurements: dict) -> bool | None:
    """Merge probe measurements ({kind: :func:`probe_measurement`}) into
    ``radiosity.json`` (a finished one is never replaced by a running one) and record the
    choice once :func:`choice_from` makes it.

    Returns
    -------
    bool or None
        The choice, None while it is not made.
    """
    rec = _record(outdir)
    for kind, m in measurements.items():
        old = rec.get(kind)
        if not (isinstance(old, dict) and old.get("finished") and not m.get("finished")):
            rec[kind] = m
    share = choice_from(rec)
    if share is not None:
        rec["share"] = share
        rec["rule"] = ("share when a lens sample reading the shared samples takes no longer "
                       "(wall clock) than one computing its own radiosity")
    write_text(RenderFolder(outdir).radiosity_choice, json.dumps(rec) + "\n")
    return share
