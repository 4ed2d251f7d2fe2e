"""One depth probe for the frames of a focus pull.

The depth probe of ``--method auto`` (:func:`povlens.plan.auto.start_depth_probe`)
measures where the scene's surfaces are; that does not depend on the focus.  The
frames of a pull (:mod:`povlens.rendering.focus_pull`) give each conversion the same
:class:`ProbeReuse`: the first frame runs the probe, the others get its result.
(The probe's camera is the first frame's: a focus pull breathes, so the later frames'
fields of view differ by their breathing, a few per cent at most; the depth range and
the probe's view are taken as the first frame's.)
"""

from __future__ import annotations

import numpy as np

from povlens.plan.auto import start_depth_probe

__all__ = ["ProbeReuse"]


class _FinishedProbe:
    """A collected probe, handed out again: the interface of
    :class:`~povlens.plan.depth_probe.DepthProbe` that the decision reads."""

    def __init__(self, view, distances: np.ndarray, image: np.ndarray | None):
        self.view, self._distances, self.image = view, distances, image

    def result(self) -> np.ndarray:
        return self._distances.copy()

    def cancel(self) -> None:
        pass


class _RecordingProbe:
    """A running probe whose result is kept for the next frames."""

    def __init__(self, probe, reuse: "ProbeReuse"):
        self._probe, self._reuse = probe, reuse
        self.view = probe.view

    @property
    def image(self):
        return self._probe.image

    def result(self) -> np.ndarray:
        d = self._probe.result()
        self._reuse.finished = _FinishedProbe(self._probe.view, np.array(d, copy=True),
                                              self._probe.image)
        return d

    def cancel(self) -> None:
        self._probe.cancel()


class ProbeReuse:
    """A depth-probe starter (``depth_probe`` of :func:`povlens.plan.convert.convert`)
    that runs the probe once and hands its result to every later call.

    Attributes
    ----------
    finished : the collected probe, or None before the first result.
    runs : how many probes were started (1 once the first frame has run).
    """

    def __init__(self):
        self.finished = None
        self.runs = 0

    def __call__(self, opts, film, plan):
        """Like :func:`~povlens.plan.auto.start_depth_probe` ``(opts, film, plan)``."""
        if self.finished is not None:
            return self.finished
        self.runs += 1
        return _RecordingProbe(start_depth_probe(opts, film, plan), self)
