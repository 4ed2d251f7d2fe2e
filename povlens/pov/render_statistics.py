"""POV-Ray's render statistics (``+GS``, printed to stderr as it exits) as numbers.

What a run spent where, for choices made by measurement: whether the lens samples of a
render share one POV-Ray run (:mod:`povlens.rendering.run_choice`) and whether they read
one radiosity file (:mod:`povlens.rendering.radiosity_cache`).  POV-Ray 3.7 prints, per
phase, the wall time and the CPU time of its threads::

    Radiosity Time:   0 hours  0 minutes  3 seconds (3.148 seconds)
                using 1 thread(s) with 3.146 CPU-seconds total

and the ray counts (``Rays:``, ``Radiosity sample rays shot:``, ``Radiosity (final)
rays shot:``).  A phase or count the run did not print is 0.
"""

from __future__ import annotations

import dataclasses
import re

__all__ = ["RenderStatistics", "render_statistics", "statistics_complete", "phase_seconds",
           "STATISTICS_SWITCHES"]

#: POV-Ray switches (after povlens's quiet ones) that print the statistics.
STATISTICS_SWITCHES = ("+GS",)

_PHASE = r"{}:[^(\n]*\(([0-9.]+) seconds\)(?:\s*using \d+ thread\(s\) with ([0-9.]+) CPU-seconds)?"


def phase_seconds(statistics: str, phase: str) -> tuple[float, float]:
    """(wall, CPU) seconds of a phase ("Radiosity Time", "Trace Time", ...); the CPU
    time is the wall time when POV-Ray does not print it, (0, 0) without the phase."""
    m = re.search(_PHASE.format(re.escape(phase)), statistics)
    if not m:
        return 0.0, 0.0
    wall = float(m.group(1))
    return wall, float(m.group(2)) if m.group(2) else wall


_LAST_LINE = re.compile(r"Trace Time:[^\n]*\n\s*using \d+ thread\(s\) with [0-9.]+ CPU-seconds")


def statistics_complete(stderr: str) -> bool:
    """Whether POV-Ray has printed its statistics to their last line (the trace's CPU
    time), which it does right after the render, before it idles ~0.35 s and exits."""
    return _LAST_LINE.search(stderr) is not None


def _count(statistics: str, label: str) -> int:
    m = re.search(re.escape(label) + r"\s+([0-9]+)", statistics)
    return int(m.group(1)) if m else 0


@dataclasses.dataclass(frozen=True)
class RenderStatistics:
    """One POV-Ray run's phases (wall and CPU seconds) and ray counts."""

    parse_s: float = 0.0
    photon_s: float = 0.0
    radiosity_s: float = 0.0
    radiosity_cpu_s: float = 0.0
    trace_s: float = 0.0
    trace_cpu_s: float = 0.0
    #: every ray the run traced, radiosity's included
    rays: int = 0
    #: radiosity's rays: all of them, and those shot during the final trace
    radiosity_rays: int = 0
    final_radiosity_rays: int = 0

    @property
    def phases_s(self) -> float:
        """Wall seconds of the phases (what is left of a run's wall time is start-up,
        loading and writing)."""
        return self.parse_s + self.photon_s + self.radiosity_s + self.trace_s

    @property
    def radiosity_work_cpu_s(self) -> float:
        """CPU seconds the run spent on radiosity: the pretrace, and the share of the
        final trace that shot radiosity's rays (POV-Ray computes samples as it traces
        when ``pretrace_end`` leaves them to it: ``stackerday.pov`` computes 99.5 % of
        its rays so, in what it counts as trace time)."""
        trace_rays = self.rays - (self.radiosity_rays - self.final_radiosity_rays)
        share = self.final_radiosity_rays / trace_rays if trace_rays > 0 else 0.0
        return self.radiosity_cpu_s + self.trace_cpu_s * min(max(share, 0.0), 1.0)

    def as_dict(self) -> dict:
        d = {k: round(v, 4) if isinstance(v, float) else v
             for k, v in dataclasses.asdict(self).items()}
        d["radiosity_work_cpu_s"] = round(self.radiosity_work_cpu_s, 4)
        return d


def render_statistics(stderr: str) -> RenderStatistics:
    """The statistics in what a POV-Ray run with :data:`STATISTICS_SWITCHES` printed."""
    parse = phase_seconds(stderr, "Parse Time")
    photon = phase_seconds(stderr, "Photon Time")
    radiosity = phase_seconds(stderr, "Radiosity Time")
    trace = phase_seconds(stderr, "Trace Time")
    return RenderStatistics(
        parse_s=parse[0], photon_s=photon[0], radiosity_s=radiosity[0],
        radiosity_cpu_s=radiosity[1], trace_s=trace[0], trace_cpu_s=trace[1],
        rays=_count(stderr, "Rays:"),
        radiosity_rays=_count(stderr, "Radiosity sample rays shot:"),
        final_radiosity_rays=_count(stderr, "Radiosity (final) rays shot:"))
