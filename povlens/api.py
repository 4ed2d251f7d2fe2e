"""The Python API: what a script or notebook calls.

Each function here is a thin, documented entry into one pipeline stage; the command
line (:mod:`povlens.cli`) is a layer over these.  Lengths on the lens side are
millimetres; distances in the scene are scene units (``units`` says what one is).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from povlens.lens.focus import LENS_SIDE_UNITS, UNITS_MM, FocusResult, focus as focus_mm
from povlens.lens.prescription import LensPrescription, read_lens as read_lens_file
from povlens.errors import ParameterError
from povlens.plan.convert import convert as convert_options
from povlens.plan.folder_lock import folder_lock
from povlens.plan.focus_series import FocusPull, focus_series, parse_focus
from povlens.plan.options import SCHEDULER_ENV_VAR, ConvertOptions, DaskOptions
from povlens.plan.render_folder import FramesFolder, RenderFolder
from povlens.plan.schema import Plan
from povlens.util.blas import single_threaded_blas

__all__ = ["read_lens", "focus", "convert", "render", "composite", "compare", "RenderResult",
           "import_lens", "render_frames", "FramesResult", "convert_frames", "focus_distances",
           "renderer_for", "render_batch", "render_view", "RenderFolder"]


def read_lens(name_or_path: str | os.PathLike) -> LensPrescription:
    """Read a lens prescription.

    Parameters
    ----------
    name_or_path : str or path
        A Kolb/pbrt lens file (tab-separated radius, thickness, index, aperture
        diameter, optional Abbe number; millimetres), or the name of a bundled lens
        such as ``"dgauss.50mm"``.

    Returns
    -------
    LensPrescription
        The surfaces from the scene side to the film side.

    Raises
    ------
    povlens.errors.LensFileError
        The file is missing or malformed; the message names the file and line.
    """
    return read_lens_file(name_or_path)


def _as_lens(lens: LensPrescription | str | os.PathLike) -> LensPrescription:
    return lens if isinstance(lens, LensPrescription) else read_lens(lens)


def focus(lens: LensPrescription | str | os.PathLike, distance: float,
          units: str = LENS_SIDE_UNITS) -> FocusResult:
    """Focus ``lens`` on an object ``distance`` from the film.

    Parameters
    ----------
    lens : LensPrescription, str or path
        The lens, or a name or path for :func:`read_lens`.
    distance : float
        Object distance from the film plane, in ``units``; ``inf`` focuses at infinity.
    units : {"mm", "cm", "m", "in"}
        Unit of ``distance``.

    Returns
    -------
    FocusResult
        Film distances (rear vertex to film, mm) by the thick-lens equation and by
        real rays, the RMS spot and the closest focus distance.
    """
    if units not in UNITS_MM:
        raise ParameterError("units", units, f"units={units!r}: unknown unit",
                             f"use one of {', '.join(sorted(UNITS_MM))}")
    return focus_mm(_as_lens(lens), float(distance) * UNITS_MM[units])


def _focus_value(focus):
    """One focus distance: a number, text (``"4"``), or None (from the scene)."""
    if focus is None or not isinstance(focus, str):
        return focus
    spec = parse_focus(focus)
    if isinstance(spec, FocusPull):
        raise ParameterError("focus", focus, f"focus={focus} is a focus pull: one render "
                             f"takes one distance", "render a pull with render_frames")
    return spec


def _options(scene, lens, outdir, focus, options: dict[str, Any]) -> ConvertOptions:
    return ConvertOptions.of(scene, lens, outdir, focus=_focus_value(focus), **options)


def focus_distances(focus, frames: int | None = None) -> list[float] | None:
    """The focus distance of each frame of a focus pull, or None for one focus.

    Parameters
    ----------
    focus : str, float, (A, B) tuple or list of float
        Text as ``--focus`` takes it (``"4"``, ``"2:6"``, ``"1,2,4"``), one distance,
        a pull ``(A, B)`` or a list of distances (scene units).
    frames : int, optional
        Frames of a pull (at least 2); with a list, its length if given.

    Returns
    -------
    list of float or None
        None when ``focus`` is one distance and ``frames`` is None.
    """
    spec = parse_focus(focus) if isinstance(focus, str) else focus
    return focus_series(spec, frames)


@single_threaded_blas
def convert(scene: str | os.PathLike, *, lens: str | os.PathLike, outdir: str | os.PathLike,
            focus: float | str | None = None, **options) -> Plan:
    """Write a render folder for ``scene`` through ``lens`` (no rendering).

    Parameters
    ----------
    scene : str or path
        An ordinary POV-Ray scene; it is not modified.
    lens : str or path
        Lens name or file (see :func:`read_lens`).
    outdir : str or path
        The folder to write: ``plan.json``, POV-Ray wrappers, a ``Makefile``.
    focus : float, optional
        Distance from the camera location to the plane in focus, scene units.  None:
        the scene camera's ``focal_point`` (with focal blur), else the distance to its
        ``look_at``, else what the depth probe sees at the frame's centre, or at
        output pixel ``focus_at=(column, row)`` (:mod:`povlens.plan.autofocus`);
        ``plan.inputs.focus_from`` says which.
    **options
        Any option of :mod:`povlens.plan.options` by name (``method``, ``samples``,
        ``width``, ``height``, ``f_number``, ``units``, ``tolerance_px``, ...; the
        command line's ``povlens convert --help`` lists them with their defaults),
        among them POV-Ray's own options for every POV-Ray run of the scene:
        ``library_paths`` (folders, POV-Ray's ``+L``), ``clock`` (``+K``) and
        ``povray_options`` (switches or INI options, e.g. ``("+A0.3",)``).

    The plan's ``notes`` say what of the scene povlens replaces or ignores.

    Returns
    -------
    Plan
        The plan written to ``outdir/plan.json``.

    Raises
    ------
    ParameterError
        An unknown option, or a value its option refuses; names the option.
    """
    opts = _options(scene, lens, outdir, focus, options)
    with folder_lock(outdir):       # one writer per render folder (waits for another)
        return convert_options(opts)


@single_threaded_blas
def convert_frames(scene: str | os.PathLike, *, lens: str | os.PathLike,
                   outdir: str | os.PathLike, focus, frames: int | None = None,
                   **options) -> "FramesResult":
    """Write the render folders of a focus pull, one per frame (no rendering).

    Parameters are those of :func:`render_frames` without the rendering ones.

    Returns
    -------
    FramesResult
        One record per frame (focus, film distance, field of view, method, folder),
        the images ``make -C outdir`` will write, and the index (``frames.json``).
    """
    from povlens.rendering.focus_pull import convert_frames as convert_pull
    values = _pull(focus, frames)
    records = convert_pull(_options(scene, lens, outdir, values[0], options), values)
    return FramesResult.of(outdir, records)


def renderer_for(scheduler: str | None = None, shared_dir: bool = False,
                 group_size: int | None = None,
                 scheduler_timeout_s: float = DaskOptions.scheduler_timeout_s,
                 jobs: int | None = None):
    """Where a render runs: on this machine, or on a Dask cluster.

    Parameters
    ----------
    scheduler : str, optional
        Address of a Dask scheduler (``tcp://host:8786``); default: the environment's
        ``POVLENS_SCHEDULER``, else render here.
    shared_dir, group_size, scheduler_timeout_s : the Dask options
        (:class:`~povlens.plan.options.DaskOptions`); ``shared_dir`` and
        ``group_size`` need a scheduler.
    jobs : int, optional
        Here: POV-Ray cores (default: the number of cores).

    Returns
    -------
    LocalRenderer or DaskRenderer
        ``render(opts, quiet, on_plan)`` and ``render_frames(opts, values, quiet,
        on_plan)``.
    """
    dask = DaskOptions(scheduler=scheduler or os.environ.get(SCHEDULER_ENV_VAR) or None,
                       shared_dir=shared_dir, group_size=group_size,
                       scheduler_timeout_s=scheduler_timeout_s)
    if dask.scheduler is not None:
        from povlens.cluster.client import DaskRenderer
        return DaskRenderer(dask)
    if shared_dir or group_size is not None:
        name, given = ("shared_dir", "True") if shared_dir else ("group_size", group_size)
        raise ParameterError(name, given, f"'{name}' needs 'scheduler'",
                             f"give the scheduler's address, or leave out '{name}'")
    from povlens.rendering.local_renderer import LocalRenderer    # loads OpenImageIO
    return LocalRenderer(jobs)


@dataclasses.dataclass(frozen=True)
class RenderResult:
    """What :func:`render` made: the plan and the images (linear EXR, sRGB PNG)."""

    plan: Plan
    image_exr: Path
    image_png: Path


@single_threaded_blas
def render(scene: str | os.PathLike, *, lens: str | os.PathLike, outdir: str | os.PathLike,
           focus: float | str | None = None, progress: bool = False,
           on_plan: Callable[[Plan], None] | None = None, renderer=None,
           jobs: int | None = None, scheduler: str | None = None, shared_dir: bool = False,
           group_size: int | None = None,
           scheduler_timeout_s: float = DaskOptions.scheduler_timeout_s,
           **options) -> RenderResult:
    """Convert ``scene`` and render it through ``lens`` with POV-Ray.

    Parameters are those of :func:`convert` (``samples``: by default ``auto``
    chooses, the fixed methods use 16), plus:

    progress : bool
        Show a progress bar on stderr.
    on_plan : callable, optional
        Called with the plan between the conversion and the rendering.
    renderer : optional
        Where to render (:func:`renderer_for`); default: made from ``jobs``,
        ``scheduler``, ``shared_dir``, ``group_size`` and ``scheduler_timeout_s``:
    jobs : int, optional
        POV-Ray processes in parallel here (default: the number of cores).
    scheduler : str, optional
        Address of a Dask scheduler (``tcp://host:8786``; default: the environment's
        ``POVLENS_SCHEDULER``, else render here): the lens samples render on its
        workers (:mod:`povlens.cluster`), the same image as here.
    shared_dir : bool
        With ``scheduler``: the workers see the scene, lens and ``outdir`` at the same
        paths, so nothing is sent to them.
    group_size : int, optional
        With ``scheduler``: lens samples per task, summed on the worker (default
        :func:`povlens.rendering.groups.choose_group_size`; 1: the image is the local
        one bit for bit).
    scheduler_timeout_s : float
        Seconds to wait for the scheduler to answer.

    Returns
    -------
    RenderResult
        The plan and the paths of ``image.exr`` (linear light) and ``image.png``.
        An interrupted render resumes when called again with the same arguments.
    """
    opts = _options(scene, lens, outdir, focus, options)
    if renderer is None:
        renderer = renderer_for(scheduler, shared_dir, group_size, scheduler_timeout_s, jobs)
    with folder_lock(outdir):       # one writer per render folder (waits for another)
        plan, exr = renderer.render(opts, quiet=not progress, on_plan=on_plan)
    exr = Path(exr)
    return RenderResult(plan, exr, exr.with_suffix(".png"))


@dataclasses.dataclass(frozen=True)
class FramesResult:
    """What :func:`render_frames` made: one record per frame (focus, film distance,
    field of view, method, folder), the numbered images (linear EXR, sRGB PNG) and
    the pull's index, ``frames.json``."""

    frames: list
    images_exr: list[Path]
    images_png: list[Path]
    index: Path

    @classmethod
    def of(cls, outdir, records: list) -> "FramesResult":
        out = Path(outdir)
        return cls(records, [out / r.image_exr for r in records],
                   [out / r.image_png for r in records], FramesFolder(out).frames_json)


def _pull(focus, frames) -> list[float]:
    if not isinstance(focus, (tuple, list, str)):
        raise ParameterError("focus", focus, f"focus={focus!r}: a focus pull is (A, B) or a "
                             f"list of distances", "for one focus use povlens.render")
    values = focus_distances(focus, frames)
    if values is None:
        raise ParameterError("focus", focus, f"focus={focus}: a focus pull is A:B with "
                             f"frames=N, or a list of distances",
                             "for one focus use povlens.render")
    return values


@single_threaded_blas
def render_frames(scene: str | os.PathLike, *, lens: str | os.PathLike,
                  outdir: str | os.PathLike, focus, frames: int | None = None,
                  progress: bool = False, on_plan: Callable[[Plan], None] | None = None,
                  renderer=None, jobs: int | None = None, scheduler=None,
                  shared_dir: bool = False, group_size: int | None = None,
                  scheduler_timeout_s: float = DaskOptions.scheduler_timeout_s,
                  **options) -> FramesResult:
    """Render a focus pull: one frame per focus distance (:mod:`povlens.rendering.focus_pull`).

    Parameters are those of :func:`render`, except:

    focus : (A, B) tuple, list of float, or text
        ``(A, B)``: a pull from A to B in ``frames`` frames, even steps in dioptres
        (1/distance); a list: one frame per distance; text as ``--focus`` takes it
        (``"2:6"``, ``"1,2,4"``).  Scene units, positive, finite.
    frames : int, optional
        Frames of a pull (at least 2); with a list, its length if given.
    on_plan : called with each frame's plan.  The renderer (or ``scheduler``, ...)
        renders every frame: one Dask client for all frames.

    Returns
    -------
    FramesResult
        ``outdir/frame-NNNN/`` is each frame's render folder, ``outdir/image.NNNN.exr``
        and ``.png`` its image, ``outdir/frames.json`` the index.  Called again with
        the same arguments, finished frames are skipped and an interrupted one resumes.

    Raises
    ------
    ParameterError
        ``frames`` < 1 or not matching the list, a pull without ``frames`` >= 2, a
        single distance, distances not positive and finite (``focus``).
    """
    values = _pull(focus, frames)
    opts = _options(scene, lens, outdir, values[0], options)
    if renderer is None:
        renderer = renderer_for(scheduler, shared_dir, group_size, scheduler_timeout_s, jobs)
    records = renderer.render_frames(opts, values, quiet=not progress, on_plan=on_plan)
    return FramesResult.of(outdir, records)


@single_threaded_blas
def render_batch(outdir: str | os.PathLike, batch: int, in_flight: int | None = None) -> None:
    """Render batch ``batch`` of a converted folder's lens samples (what ``make`` runs).

    ``in_flight``: POV-Ray processes running at once (default
    :data:`povlens.rendering.mesh_samples.POVRAY_IN_FLIGHT`: each spends most of its
    ~0.6 s start-up idle, so several overlap on one core)."""
    from povlens.rendering.mesh_samples import POVRAY_IN_FLIGHT, render_batch as render_folder_batch
    render_folder_batch(outdir, batch, in_flight=in_flight or POVRAY_IN_FLIGHT)


@single_threaded_blas
def render_view(outdir: str | os.PathLike, view: str) -> Path:
    """Render the ``"pinhole"`` or ``"focal-blur"`` view of a converted folder (what
    ``make`` runs); returns its image's path."""
    from povlens.rendering.views import render_view as render_folder_view
    with folder_lock(outdir):       # one writer per render folder (waits for another)
        return render_folder_view(outdir, view)


@single_threaded_blas
def composite(outdir: str | os.PathLike, vignetting: bool | None = None) -> np.ndarray:
    """Combine a render folder's lens samples into ``image.exr`` and ``image.png``.

    Parameters
    ----------
    outdir : str or path
        A folder written by :func:`convert` and rendered (fully or in part).
    vignetting : bool, optional
        Keep the lens's vignetting (default: the plan's setting).

    Returns
    -------
    numpy.ndarray
        ``(H, W, 3)`` float64, linear light.
    """
    from povlens.rendering.folder_composite import composite_outdir
    return composite_outdir(outdir, vignetting=vignetting)


def compare(a: str | os.PathLike | np.ndarray, b: str | os.PathLike | np.ndarray,
            mask: str | os.PathLike | np.ndarray | None = None) -> dict:
    """Error metrics of image ``b`` against image ``a`` in linear light.

    Parameters
    ----------
    a, b : path or numpy.ndarray
        Images of equal size: file paths (EXR, PNG, ... read by OpenImageIO) or
        ``(H, W)`` / ``(H, W, C)`` arrays.
    mask : path or numpy.ndarray, optional
        ``(H, W)``: only pixels where it is non-zero count.

    Returns
    -------
    dict
        ``rmse``, ``psnr_db``, ``mean_abs_error``, ``max_abs_error`` and ``max_at``
        (where the largest error is), ``pixels``, ``channels``, ``masked``.

    Raises
    ------
    CompareError
        An image holding NaN or infinite pixels (inside the mask): named, with how many.
    """
    from povlens.report.compare import compare_arrays, require_finite
    from povlens.util.images import read_image

    def load(x):
        return x if isinstance(x, np.ndarray) or x is None else read_image(x)

    m = load(mask)
    if m is not None and m.ndim == 3:
        m = m[..., 0]
    ia, ib = load(a), load(b)
    name_a = "array a" if isinstance(a, np.ndarray) else str(a)
    name_b = "array b" if isinstance(b, np.ndarray) else str(b)
    require_finite({name_a: ia, (name_b if name_b != name_a else name_b + " (b)"): ib}, m)
    return compare_arrays(ia, ib, m)


def import_lens(source: str | os.PathLike, out: str | os.PathLike | None = None, *,
                lens_id: str | None = None, efl_mm: float | None = None,
                adjusted: bool = False, glasses: dict | None = None) -> LensPrescription:
    """Import a lens design from a lentil database or a Zemax ``.zmx`` file.

    Parameters
    ----------
    source : str or path
        A lentil ``lenses.json`` (zpelgrims/lentil) or a Zemax sequential ``.zmx``.
    out : str or path, optional
        Write the lens as a Kolb/pbrt file here (atomically), with the source and per
        row its surface and material as comments; it reads back to the same lens.
    lens_id : str, optional
        The lentil entry (``"0001"``); ``povlens.lens.import_lentil.list_lentil`` lists
        them.  Not needed for a database of one lens.
    efl_mm : float, optional
        Scale the design to this focal length, mm (lentil stores most designs at 100).
    adjusted : bool
        lentil: the entry's ``optical-elements-adjusted`` table instead of the patent's.
    glasses : dict, optional
        Zemax: glass name -> (nd, vd) for catalogue glasses the file gives no index for.

    Returns
    -------
    LensPrescription
        The imported lens (as written, when ``out`` is given).

    Raises
    ------
    povlens.errors.LensFileError
        The source cannot be read or holds what a spherical lens file cannot
        (aspheres, mirrors, tilts, no stop); names the file, line and surface.
    povlens.errors.ParameterError
        An unknown ``lens_id``, or an option that does not apply to the format.
    """
    from povlens.lens.importers import import_lens_file
    imported = import_lens_file(source, lens_id=lens_id, adjusted=adjusted, glasses=glasses,
                                efl_mm=efl_mm)
    return imported.lens if out is None else imported.write(out)
