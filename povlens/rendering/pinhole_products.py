"""Files one pinhole render of a render folder makes for every lens sample to read (the
radiosity samples, :mod:`povlens.rendering.radiosity_cache`; the photon map,
:mod:`povlens.rendering.photon_map`): rendered under a name of the render's own and
renamed into place when complete, so renders racing to make one waste time, never read
half a file.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Callable

from povlens.plan.options import povray_options_of
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Plan
from povlens.pov.process import start_render
from povlens.util.files import temporary_path

__all__ = ["pinhole_product", "start_pinhole_product", "PinholeProduct", "start_product",
           "product_ready", "wait_product", "cancel_product", "complete"]


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


# -- made in the background --------------------------------------------------------------
#
# ``povlens render`` starts these renders as soon as the scene and camera are read, and
# the first lens samples' meshes are written while they run; whichever thread needs the
# file first waits for the render, the others for its result.


class _Making:
    """A :class:`PinholeProduct` being made, waited for by whichever thread needs it
    first; the others get its result (or its error)."""

    def __init__(self, job: PinholeProduct):
        self.job = job
        self.lock = threading.Lock()
        self.result: Path | None = None
        self.error: BaseException | None = None
        self.done = False

    def wait(self) -> Path | None:
        with self.lock:
            if not self.done:
                try:
                    self.result = self.job.wait()
                except BaseException as e:
                    self.error = e
                finally:
                    self.done = True
        if self.error is not None:
            raise self.error
        return self.result


#: Files being made in this process: their absolute path -> :class:`_Making`.
_MAKING: dict[Path, _Making] = {}
_MAKING_LOCK = threading.Lock()


def complete(path: Path) -> bool:
    """Whether a product is in place (renamed there whole)."""
    return path.is_file() and path.stat().st_size > 0


def start_product(final: Path, start: Callable[[], PinholeProduct]) -> None:
    """Start making ``final`` with ``start()`` unless it is in place or being made."""
    final = Path(final).absolute()
    if complete(final):
        return
    with _MAKING_LOCK:
        if final not in _MAKING:
            _MAKING[final] = _Making(start())


def product_ready(final: Path) -> bool:
    """False while a render :func:`start_product` started for ``final`` runs; never
    blocks."""
    with _MAKING_LOCK:
        making = _MAKING.get(Path(final).absolute())
    return making is None or making.done or making.job.finished()


def wait_product(final: Path) -> tuple[bool, Path | None]:
    """Wait for the render :func:`start_product` started for ``final``: (True, what it
    made: ``final`` or None), or (False, None) when none was started (or it was
    collected already)."""
    key = Path(final).absolute()
    with _MAKING_LOCK:
        making = _MAKING.get(key)
    if making is None:
        return False, None
    try:
        made = making.wait()
    finally:
        with _MAKING_LOCK:
            if _MAKING.get(key) is making:
                del _MAKING[key]
    return True, None if made is None else Path(final)


def cancel_product(final: Path) -> None:
    """Stop a render :func:`start_product` started for ``final`` that nothing waited for
    (an error, an interrupt, a render that did not need it)."""
    with _MAKING_LOCK:
        making = _MAKING.pop(Path(final).absolute(), None)
    if making is not None:
        with making.lock:
            if not making.done:
                making.done = True
                making.job.cancel()
