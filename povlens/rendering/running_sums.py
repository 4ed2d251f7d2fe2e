"""The composite's sums, taken while the lens samples render.

``povlens render`` composites once every sample is in
(:func:`povlens.rendering.folder_composite.composite_outdir`): reading each sample's
image and computing its weights from its pass mask.  :class:`RunningSums` does that in
a thread as the samples come in, in sample order (:class:`povlens.rendering.groups.UnitSums`,
so the sums are the composite's own bit for bit), while POV-Ray still renders the
later ones; the composite is then left with the division and the writing.  On the
cheap radiosity scenes at 320x240 the composite took 0.15-0.18 s of a 2.2 s render
after the last sample (``docs/decisions/planning.md``).

Anything it cannot do (a damaged sample, a render stopped) leaves it without a result,
and the composite reads the samples itself, reporting what it finds.
"""

from __future__ import annotations

import threading
from pathlib import Path

from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Plan
from povlens.rendering.folder_composite import sample_sums
from povlens.rendering.groups import UnitSums, unit_terms

__all__ = ["RunningSums"]

#: How often the thread looks for the next sample (s).
POLL_S = 0.01


class RunningSums:
    """The sums of ``plan``'s samples in ``outdir``, added in a thread as each is
    rendered; :meth:`result` once all are.  Not for a folder holding group files (the
    composite adds those)."""

    def __init__(self, outdir: Path, plan: Plan, table):
        self.folder = RenderFolder(outdir)
        self.samples = plan.inputs.samples
        self.sums = UnitSums(self.samples, unit_terms(outdir, plan, table, sample_sums))
        self.stop_event = threading.Event()
        self.all_rendered = threading.Event()
        self.failed = False
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _in(self, k: int) -> bool:
        """Whether sample k is rendered (its image or blocked marker first: cheap)."""
        return ((self.folder.sample_image(k).exists() or self.folder.sample_blocked(k).exists())
                and self.folder.sample_done(k))

    def _run(self) -> None:
        try:
            for k in range(self.samples):
                while not self._in(k):
                    if self.all_rendered.is_set():
                        if self._in(k):     # came in as the last were being waited for
                            break
                        return          # not rendered after all: the composite says so
                    if self.stop_event.wait(POLL_S):
                        return
                self.sums.add(k, k + 1)
        except Exception:       # the composite reads the samples itself and says why
            self.failed = True

    def stop(self) -> None:
        """Stop the thread (the render failed or was interrupted)."""
        self.stop_event.set()
        self.thread.join()

    def result(self):
        """(total, wsum) as :func:`~povlens.rendering.folder_composite.composite_outdir`
        takes them, or None (stopped, failed, or all blocked): call once every sample
        is rendered."""
        self.all_rendered.set()
        self.thread.join()
        if self.failed or self.sums.next_k != self.samples:
            return None
        return self.sums.result(str(self.folder.path))
