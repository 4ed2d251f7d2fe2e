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

from povlens.plan.render_folder import RenderFolder
from povlens.pov.process import start_render
from povlens.util.files import temporary_path

__all__ = ["PinholeProduct", "start_product", "product_started", "product_ready",
           "wait_product", "cancel_product", "complete"]


class PinholeProduct:
    """A pinhole render of a folder making a file for every lens sample to read (the
    image is thrown away), started at once: :meth:`wait` for the file (renamed to
    ``final`` when whole), or :meth:`cancel`.  ``written`` is where POV-Ray writes it,
    a name of this render's own, so renders racing to make it never read half a file;
    ``size`` (width, height) pixels; ``extra_args`` the switches that make it write
    ``written``."""

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


def product_started(final: Path) -> bool:
    """Whether a render :func:`start_product` started for ``final`` is registered and
    nothing has waited for it yet (it may have finished); never blocks."""
    with _MAKING_LOCK:
        return Path(final).absolute() in _MAKING


def product_ready(final: Path) -> bool:
    """False while a render :func:`start_product` started for ``final`` runs; never
    blocks."""
    with _MAKING_LOCK:
        making = _MAKING.get(Path(final).absolute())
    return making is None or making.done or making.job.finished()


def wait_product(final: Path) -> Path | None:
    """``final`` once whole, after waiting for the render :func:`start_product` started
    for it (raising what that render raised); None if it is not in place."""
    key = Path(final).absolute()
    with _MAKING_LOCK:
        making = _MAKING.get(key)
    if making is not None:
        try:
            making.wait()
        finally:
            with _MAKING_LOCK:
                if _MAKING.get(key) is making:
                    del _MAKING[key]
    return Path(final) if complete(Path(final)) else None


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
