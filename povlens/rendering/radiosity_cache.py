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
racing to make it waste time, never read half a file.
"""

from __future__ import annotations

import os
from pathlib import Path

from povlens.plan.options import povray_options_of
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Plan
from povlens.pov.process import render as povray_render
from povlens.util.files import temporary_path

__all__ = ["radiosity_cache_for", "radiosity_read_args"]


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
        folder's ``pinhole.pov`` at the image's size, all cores.
    """
    if not plan.povray.radiosity_cache:
        return None
    folder = RenderFolder(outdir)
    cache = folder.radiosity_cache
    if cache.is_file() and cache.stat().st_size > 0:
        return cache
    tmp = temporary_path(cache)
    image = temporary_path(folder.path / "radiosity-pretrace.exr")
    try:
        povray_render(folder.wrapper("pinhole"), image, plan.film.width_px, plan.film.height_px,
                      threads=os.cpu_count() or 1,
                      library_paths=[Path(plan.inputs.scene).parent],
                      povray_options=povray_options_of(plan.inputs),
                      extra_args=[f"Radiosity_File_Name={tmp.name}", "+RFO"])
        if tmp.is_file() and tmp.stat().st_size > 0:
            os.replace(tmp, cache)
    finally:
        tmp.unlink(missing_ok=True)
        image.unlink(missing_ok=True)
    return cache if cache.is_file() else None


def radiosity_read_args(cache: Path | None, cwd: Path) -> list[str]:
    """POV-Ray's switches that read ``cache`` (none without one), its name relative to
    POV-Ray's working folder ``cwd`` (a render folder's path may hold spaces)."""
    if cache is None:
        return []
    return [f"Radiosity_File_Name={os.path.relpath(cache, cwd)}", "+RFI"]
