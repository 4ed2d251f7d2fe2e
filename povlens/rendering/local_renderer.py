"""Rendering on this machine: :class:`LocalRenderer`, what
:func:`povlens.api.renderer_for` gives when no Dask scheduler is named (its
counterpart is :class:`povlens.cluster.client.DaskRenderer`)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from povlens.plan.options import ConvertOptions
from povlens.plan.schema import Plan
from povlens.rendering.driver import convert_and_render
from povlens.rendering.focus_pull import FrameRecord, render_frames

__all__ = ["LocalRenderer"]


@dataclasses.dataclass(frozen=True)
class LocalRenderer:
    """Renders with ``jobs`` POV-Ray cores of this machine (None: all of them)."""

    jobs: int | None = None

    def render(self, opts: ConvertOptions, quiet: bool = False,
               on_plan=None) -> tuple[Plan, Path]:
        """Convert ``opts`` and render the folder: (plan, path of image.exr)."""
        return convert_and_render(opts, jobs=self.jobs, quiet=quiet, on_plan=on_plan)

    def render_frames(self, opts: ConvertOptions, focus_values: list[float],
                      quiet: bool = False, on_plan=None) -> list[FrameRecord]:
        """Convert and render every frame of a focus pull: the frames' records."""
        return render_frames(opts, focus_values, jobs=self.jobs, quiet=quiet, on_plan=on_plan)
