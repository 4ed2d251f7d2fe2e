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
from povlens.pov.process import start_render
from povlens.util.files import temporary_path

__all__ = ["pinhole_product", "start_pinhole_product", "PinholeProduct"]


class PinholeProduct:
    """A pinhole render of a folder making a file for every lens sample to read, started
    by :func:`start_pinhole_product`: :meth:`wait` for the file, or :meth:`cancel`."""

    def __init__(self, outdir: str | os.PathLike, written: Path, final: Path,
                 size: tuple[int, int], extra_args: list[str], scene: str | os.PathLike,
                 povray_options):
        folder = RenderFolder(outdir)
        self.written, self.final = written, final
        self._image = temporary_path(folder.path / f"{final.stem}-render.exr")
        try:
            self._job = start_render(
                folder.wrapper("pinhole"), self._image, *size, threads=os.cpu_count() or 1,
                library_paths=[Path(scene).parent], povray_options=povray_options,
                extra_args=extra_args,
                products=[written])  # whole: a radiosity file ends after the image
        except BaseException:
            written.unlink(missing_ok=True)
            raise

    def finished(self) -> bool:
        """Whether :meth:`wait` would return at once (never blocks)."""
        return self._job.finished()

    def wait(self) -> Path | None:
        """Wait for POV-Ray and rename the file into place; ``final``, None if POV-Ray
        wrote nothing.  Raises what :meth:`povlens.pov.process.RenderJob.wait` raises."""
        try:
            self._job.wait()
            if self.written.is_file() and self.written.stat().st_size > 0:
                os.replace(self.written, self.final)
        finally:
            self.written.unlink(missing_ok=True)
            self._image.unlink(missing_ok=True)
        return self.final if self.final.is_file() else None

    def cancel(self) -> None:
        """Stop POV-Ray and remove what it wrote."""
        self._job.cancel()
        self.written.unlink(missing_ok=True)
        self._image.unlink(missing_ok=True)


def start_pinhole_product(plan: Plan, outdir: str | os.PathLike, written: Path, final: Path,
                          size: tuple[int, int], extra_args: list[str]) -> PinholeProduct:
    """Start the render :func:`pinhole_product` waits for; returns at once."""
    return PinholeProduct(outdir, written, final, size, extra_args, plan.inputs.scene,
                          povray_options_of(plan.inputs))


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
    job = start_pinhole_product(plan, outdir, written, final, size, extra_args)
    try:
        return job.wait()
    except BaseException:
        job.cancel()
        raise
