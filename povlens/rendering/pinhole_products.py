"""Files one pinhole render of a render folder makes for every lens sample to read (the
radiosity samples, :mod:`povlens.rendering.radiosity_cache`; the photon map,
:mod:`povlens.rendering.photon_map`): rendered under a name of the render's own and
renamed into place when complete, so renders racing to make one waste time, never read
half a file.
"""

from __future__ import annotations

import os
from pathlib import Path

from povlens.plan.options import povray_options_of
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Plan
from povlens.pov.process import render as povray_render
from povlens.util.files import temporary_path

__all__ = ["pinhole_product"]


def pinhole_product(plan: Plan, outdir: str | os.PathLike, written: Path, final: Path,
                    size: tuple[int, int], extra_args: list[str]) -> Path | None:
    """A file a pinhole render of the folder writes beside its image (the radiosity
    samples, the photon map), renamed to ``final`` when complete; the image is thrown
    away.

    Parameters
    ----------
    plan, outdir : the folder's plan and the folder.
    written : where POV-Ray writes the file (a name of this render's own, so renders
        racing to make it never read half a file); removed afterwards.
    final : its name once complete.
    size : (width, height) of the render, pixels.
    extra_args : the POV-Ray switches that make it write ``written``.

    Returns
    -------
    Path or None
        ``final``, None if POV-Ray wrote nothing.
    """
    folder = RenderFolder(outdir)
    image = temporary_path(folder.path / f"{final.stem}-render.exr")
    try:
        povray_render(folder.wrapper("pinhole"), image, *size, threads=os.cpu_count() or 1,
                      library_paths=[Path(plan.inputs.scene).parent],
                      povray_options=povray_options_of(plan.inputs), extra_args=extra_args,
                      products=[written])  # whole: a radiosity file ends after the image
        if written.is_file() and written.stat().st_size > 0:
            os.replace(written, final)
    finally:
        written.unlink(missing_ok=True)
        image.unlink(missing_ok=True)
    return final if final.is_file() else None
