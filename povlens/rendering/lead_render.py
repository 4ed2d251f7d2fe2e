"""The lens samples of ``povlens render`` led by the first: it renders alone and chooses
how the rest run (:mod:`povlens.rendering.run_choice`).  Plans that share radiosity
samples or a photon map are led; a scene with photons only has its parse to share, and
no radiosity to hand on.

:func:`render_led` renders sample ``todo[0]`` (the *lead*) as a pass of its own on
every core, with POV-Ray's statistics.  First, one pinhole render of the frame saves
the radiosity samples every run reads (:mod:`povlens.rendering.radiosity_cache`): a
pass's own pretrace, spaced by the tiled image it renders, left the cache to be filled
tile by tile and drew a dot lattice, and scaled to the frame's spacing it traces m^2
times the frame's pretrace (:func:`povlens.pov.mesh.pretrace_block`; balcony.pov at
320x240, 8 samples: 47.9 s, against 27.5 s reading the frame's).  The lead saves what
it adds for the stacks that may follow (:meth:`RenderFolder.radiosity_chain`; POV-Ray
saves them as it exits, which the first stack waits for).  Beside it, up to
``in_flight - 1`` *companions*, the next samples, render as runs of their own, reading
the frame's radiosity samples, on CPU time nothing else wants (``SCHED_IDLE``): the
lead's start-up and exit idle (0.3 s and 0.35 s: docs/decisions/pov.md) and its
threads' waits.  On a scene whose runs are short that is most of the lead's time, and
the companions are what the choice will be; when the lead chooses stacks, those still
running are stopped (their samples go to the stacks), having taken little from it;
those finished stay.  (Companions at normal priority, stopped once the lead had run
1 s, cost as much as they saved: ``raddem.pov`` at 640x480 took 5.05 s with them,
4.35 s without.)

Passes of their own are drawn alone, not in their band of a stack: a band's run writes
the stack's full height and POV-Ray's UV bins sort its faces only across (``raddem.pov``
at 640x480: 7 samples in their bands 3.6 s and the lead 1.1 s, where 8 passes alone
took 2.9 s).  The folder records the layout its samples took
(:meth:`RenderFolder.sample_layout`): every later render of it (a resume, ``make``, a
cluster worker) lays them out so, and a sample rendered again comes out the same bits;
but the lead and companions of a stacked render, rendered again, are drawn in their
bands, the same rays but for float rounding.
"""

from __future__ import annotations

import threading
from pathlib import Path

from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Plan
from povlens.rendering.mesh_samples import render_samples
from povlens.rendering.radiosity_cache import cancel_radiosity_cache, start_radiosity_cache
from povlens.rendering.run_choice import choose_runs
from povlens.rendering.sample_stacks import StackPlan, pass_faces, record_layout

__all__ = ["render_led"]

class _Companions:
    """Samples ``ks`` rendered as runs of their own in a thread, until :meth:`stop`."""

    def __init__(self, plan: Plan, lens, table, outdir: Path, ks: list[int], on_done):
        self.ks = list(ks)
        self.stop_event = threading.Event()
        self.timing: dict | None = None
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, daemon=True,
                                       args=(plan, lens, table, outdir, on_done))
        if self.ks:
            self.thread.start()

    def _run(self, plan, lens, table, outdir, on_done) -> None:
        try:
            self.timing = render_samples(
                plan, lens, table, outdir, 0, self.ks, in_flight=len(self.ks),
                stop=self.stop_event, on_done=on_done,
                stacking=StackPlan(1, len(self.ks), 1, False), read_shared=True, idle=True)
        except BaseException as e:      # handed to end()
            self.error = e

    def stop(self) -> None:
        self.stop_event.set()

    def end(self, stop: bool) -> dict | None:
        """Wait for the thread (stopping the runs left first when ``stop``); raises what
        it raised; returns its timing."""
        if stop:
            self.stop_event.set()
        if self.ks:
            self.thread.join()
        if self.error is not None:
            raise self.error
        return self.timing


def render_led(plan: Plan, lens, table, outdir: Path, todo: list[int], samples, bands: int,
               jobs: int, in_flight: int, on_done) -> dict:
    """Render the samples ``todo`` (at least two) of a plan whose samples stack in
    ``bands``: the lead and its companions, then the rest (``samples(ks)`` yields them)
    as the lead chose; returns the timing record (the rest's, with ``lead``,
    ``companions`` and ``choice``)."""
    radiosity = bool(plan.povray.radiosity_cache)
    chain = RenderFolder(outdir).radiosity_chain
    chain.unlink(missing_ok=True)           # an earlier render's
    exiting: list = []      # the lead's POV-Ray, saving its radiosity samples as it exits
    record_layout(outdir, 1, {"lead_sample": todo[0]})
    # made once, on every core, while the first meshes are written; no run starts
    # before it is done (_SampleRenders.pending)
    start_radiosity_cache(plan, outdir)
    companions = _Companions(plan, lens, table, outdir, todo[1:max(2, in_flight)], on_done)
    try:
        lead = render_samples(plan, lens, table, outdir, 0, todo[:1], in_flight=in_flight,
                              on_done=on_done, stacking=StackPlan(1, 1, jobs, False, radiosity),
                              statistics=True, keep_chain=True, exiting=exiting,
                              read_shared=True)
        rest = [k for k in todo[1:] if k not in companions.ks]
        choice = _run_choice(plan, lead, len(todo) - 1, bands, jobs)
        if choice is None or choice.stack:
            companion_timing = companions.end(stop=True)
            rest = [k for k in todo[1:] if not RenderFolder(outdir).sample_done(k)]
            if companion_timing is not None:    # those stopped render again in the stacks
                companion_timing["samples"] = len(todo) - 1 - len(rest)
            timing = _render_stacks(plan, lens, table, outdir, rest, samples, bands, jobs,
                                    in_flight, on_done, choice, todo[0], exiting)
        else:
            _stop(exiting)      # one run each: the lead's radiosity samples are not read
            record_layout(outdir, 1, {"choice": choice.as_dict(), "lead_sample": todo[0]})
            timing = render_samples(plan, lens, table, outdir, 0, samples(rest),
                                    in_flight=in_flight, on_done=on_done,
                                    stacking=StackPlan(1, len(rest), 1, False),
                                    read_shared=True)
            companion_timing = companions.end(stop=False)
    finally:
        companions.stop()
        if companions.ks:
            companions.thread.join()
        cancel_radiosity_cache(outdir)      # an error before any run waited for it
        _stop(exiting)
        chain.unlink(missing_ok=True)
    return _led_timing(timing, lead, companion_timing, choice)


def _render_stacks(plan: Plan, lens, table, outdir: Path, rest: list[int], samples, bands: int,
                   jobs: int, in_flight: int, on_done, choice, lead_sample: int, exiting):
    """The samples ``rest`` in stacks of ``bands``, in turn when they hand on radiosity
    (the first once the lead has saved its own: ``exiting``)."""
    record_layout(outdir, bands, {"choice": choice and choice.as_dict(),
                                  "lead_sample": lead_sample})
    radiosity = bool(plan.povray.radiosity_cache)
    runs = len({k // bands for k in rest})
    threads = jobs if radiosity else max(1, jobs // max(runs, 1))
    return render_samples(plan, lens, table, outdir, 0, samples(rest), in_flight=in_flight,
                          on_done=on_done, stacking=StackPlan(bands, runs, threads, True,
                                                              radiosity),
                          keep_chain=True, wait_first=exiting, read_shared=True)


def _led_timing(timing: dict, lead: dict, companions: dict | None, choice) -> dict:
    """The rest's timing with the lead's (its statistics as numbers), the companions'
    and the choice."""
    stats = lead.pop("statistics")
    lead["statistics"] = {str(k): {"wall_s": round(w, 4), **st.as_dict()}
                          for k, (w, st) in stats.items()}
    extra = [lead] + ([companions] if companions else [])
    return {**timing, "samples": timing["samples"] + sum(t["samples"] for t in extra),
            "blocked": timing["blocked"] + sum(t["blocked"] for t in extra),
            "lead": lead, "companions": companions,
            "choice": None if choice is None else choice.as_dict()}


def _stop(processes: list) -> None:
    """Kill the POV-Ray processes left (SIGKILL: what is left of them is their idle
    shutdown) and empty the list."""
    while processes:
        proc = processes.pop()
        if proc.poll() is None:
            proc.kill()
        proc.wait()


def _run_choice(plan: Plan, lead: dict, rest: int, bands: int, jobs: int):
    """:func:`~povlens.rendering.run_choice.choose_runs` from the lead's timing for the
    ``rest`` samples after it (None: its rays were all blocked, nothing was
    measured)."""
    if not lead["statistics"] or not rest:
        return None
    (wall_s, stats), = lead["statistics"].values()
    pv = plan.povray
    pass_pixels = (pv.render_width - pv.drop_right_columns) * (pv.render_height
                                                               - pv.drop_top_rows)
    return choose_runs(stats, wall_s, lead["rays_and_meshes_s"], rest, pass_pixels,
                       pass_faces(plan) * min(bands, rest), jobs)
