"""One POV-Ray run for a stack of lens samples, or one run each: measured on the first.

A stack (:mod:`povlens.rendering.sample_stacks`) parses the scene once and lets its
bands share their radiosity samples; it costs POV-Ray's face lookup, which walks the
faces of every band of the run for each pixel, and it starts late, after every pass of
the stack is traced.  Runs of their own overlap their start-ups and tracing on the
cores and look up only their own faces, but each parses the scene and computes its own
radiosity.  Which wins depends on the scene (issue 25, docs/decisions/planning.md, "One
run or a stack, measured"): at 320x240, N = 8 through tessar.50mm, runs of their own
took ``rad_def_test_37.pov`` 2.35 s where a stack took 3.22 s (focal_blur 1.58 s), and
``radiosity/cornell.pov`` 9.67 s where a stack took 8.66 s.

So ``povlens render`` renders its first lens sample (the *lead*) alone, on every core,
with POV-Ray's statistics (:mod:`povlens.pov.render_statistics`), handing on its
radiosity samples to a stack that may follow (:mod:`povlens.rendering.lead_render`);
:func:`choose_runs` then weighs, for the samples left, what a stack would share against
what it would cost:

* shared: the scene's parse and :data:`RADIOSITY_SHARED` of the lead's radiosity work
  (its pretrace and the radiosity rays of its final trace), for every sample left,
  spread over the cores;
* cost: the face lookup, :data:`LOOKUP_S_PER_WORD` for each 32-face word POV-Ray walks
  (half the stack's faces on average) at every pixel of every sample left, spread over
  the cores; the tracing of the stack's passes before its run starts (the lead's own
  tracing time a pass); and one POV-Ray start-up (the lead's wall time outside its
  phases).

The measurement and the choice go to the render's timing file.
"""

from __future__ import annotations

import dataclasses

from povlens.pov.render_statistics import RenderStatistics

__all__ = ["RunChoice", "choose_runs", "LOOKUP_S_PER_WORD", "RADIOSITY_SHARED"]

#: CPU seconds POV-Ray 3.7.0.10 spends on one 32-face word of its distribution-3 face
#: lookup (reference §3.3), measured: ``radiosity/radiosity_36.pov`` at 640x480, eight
#: bands of 2,688 faces, traced 3.9 us a pixel where its pinhole view traced 3.1 us:
#: 0.85 us for the 21,504 / 64 words walked on average.
LOOKUP_S_PER_WORD = 2.5e-9
#: The part of a lens sample's radiosity work the other bands of its stack save (two
#: bands of ``stackerday.pov``: the second computed 45 % of its radiosity lookups, the
#: first 69 %; more bands share more).
RADIOSITY_SHARED = 0.7


@dataclasses.dataclass(frozen=True)
class RunChoice:
    """The samples left render as stacks (``stack``) or one run each; ``shared_s`` and
    ``cost_s`` are the wall seconds a stack would save and add."""

    stack: bool
    shared_s: float
    cost_s: float

    def as_dict(self) -> dict:
        return {"stack": self.stack, "shared_s": round(self.shared_s, 4),
                "cost_s": round(self.cost_s, 4),
                "rule": "stack when the parse and radiosity work a stack shares (the lead "
                        "sample's) outweigh its face lookup, the tracing before its run "
                        "and one start-up"}


def choose_runs(lead: RenderStatistics, lead_wall_s: float, mesh_s: float, rest: int,
                pass_pixels: int, stack_faces: int, cores: int) -> RunChoice:
    """Stacks or one run each for the ``rest`` samples left after the lead.

    Parameters
    ----------
    lead : the statistics of the lead sample's run (alone, on every core).
    lead_wall_s : its run's wall time, s.
    mesh_s : the time to trace and write its mesh, s.
    rest : samples left.
    pass_pixels : pixels a sample's run traces (its band's rows times the columns).
    stack_faces : faces of the mesh of a stack of the samples left.
    cores : cores the runs share.
    """
    cores = max(1, int(cores))
    rest = max(0, int(rest))
    shared = rest * (lead.parse_s + RADIOSITY_SHARED * lead.radiosity_work_cpu_s) / cores
    lookup = rest * pass_pixels * LOOKUP_S_PER_WORD * (stack_faces / 64.0) / cores
    start_up = max(0.0, lead_wall_s - lead.phases_s)
    cost = lookup + rest * max(0.0, mesh_s) + start_up
    return RunChoice(shared > cost, shared, cost)
