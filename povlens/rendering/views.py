"""A render folder's single views: POV-Ray's own pinhole and focal_blur cameras.

``povlens render-view OUTDIR --view pinhole|focal-blur`` (make's rule of a pinhole or
focal-blur plan) renders the view's wrapper to ``view-<view>.exr``, kept as POV-Ray
rendered it; when the view is the plan's method it also becomes the folder's image,
times the lens's vignetting when the plan wants it (:mod:`povlens.rendering.vignetting`).
A view already rendered is not rendered again.
"""

from __future__ import annotations

import os
from pathlib import Path

from povlens.errors import ParameterError
from povlens.plan.options import povray_options_of
from povlens.plan.render_folder import VIEWS, RenderFolder
from povlens.plan.schema import read_plan
from povlens.pov.process import render as povray_render
from povlens.rendering.folder_composite import write_image
from povlens.rendering.folder_inputs import lens_for, pupil_table_for
from povlens.util.images import read_image

__all__ = ["render_view"]


def render_view(outdir: str | os.PathLike, view: str) -> Path:
    """Render ``pinhole`` or ``focal-blur`` of a converted folder to ``view-<view>.exr``."""
    outdir = Path(outdir)
    folder = RenderFolder(outdir)
    plan = read_plan(outdir)
    film = plan.film
    if view not in VIEWS:
        raise ParameterError("view", view, f"view={view!r}: unknown view",
                             "use pinhole or focal-blur")
    out = folder.view_image(view)
    final = plan.inputs.method == view.replace("_", "-")
    # the lens's vignetting as a per-pixel map, computed while POV-Ray renders
    # (rendering/vignetting.py); the view itself stays as POV-Ray rendered it
    from povlens.rendering.vignetting import start_vignetting_map
    vignetting = None if not final else start_vignetting_map(
        outdir, plan, lambda: pupil_table_for(outdir, plan, lens_for(plan)))
    if not out.exists():
        povray_render(folder.wrapper(view), out, film.width_px, film.height_px,
                      threads=os.cpu_count() or 1,
                      library_paths=[Path(plan.inputs.scene).parent],
                      povray_options=povray_options_of(plan.inputs))
    if final:
        image = read_image(out)[..., :3]
        write_image(outdir, image if vignetting is None else vignetting.apply(image))
    return out
