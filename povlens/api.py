"""The Python API: what a script or notebook calls.

Each function here is a thin, documented entry into one pipeline stage; the command
line (:mod:`povlens.cli`) is a layer over these.  Lengths on the lens side are
millimetres; distances in the scene are scene units (``units`` says what one is).
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

import numpy as np

from povlens.lens.focus import FocusResult, UNITS_MM, focus as focus_mm
from povlens.lens.prescription import LensPrescription, read_lens as read_lens_file
from povlens.plan.convert import convert as convert_options
from povlens.plan.options import ConvertOptions
from povlens.plan.schema import Plan

__all__ = ["read_lens", "focus", "convert", "render", "composite", "compare", "RenderResult",
           "import_lens", "render_frames", "FramesResult"]


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
          units: str = "mm") -> FocusResult:
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
        from povlens.errors import ParameterError
        raise ParameterError("units", units, f"units={units!r}: unknown unit",
                             f"use one of {', '.join(sorted(UNITS_MM))}")
    return focus_mm(_as_lens(lens), float(distance) * UNITS_MM[units])


def _options(scene, lens, focus_distance, outdir, overrides: dict[str, Any]) -> ConvertOptions:
    known = {f.name for f in dataclasses.fields(ConvertOptions)}
    unknown = sorted(set(overrides) - known)
    if unknown:
        from povlens.errors import ParameterError
        raise ParameterError(unknown[0], overrides[unknown[0]],
                             f"{unknown[0]!r} is not an option of a conversion",
                             f"known options: {', '.join(sorted(known))}")
    return ConvertOptions(scene=str(scene), lens=str(lens),
                          focus=None if focus_distance is None else float(focus_distance),
                          outdir=str(outdir), **overrides)


def convert(scene: str | os.PathLike, *, lens: str | os.PathLike, outdir: str | os.PathLike,
            focus: float | None = None, method: str = "auto", **options) -> Plan:
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
    method : {"auto", "pinhole", "focal-blur", "mesh"}
        How the lens is rendered; ``auto`` measures the scene and chooses.
    **options
        Any field of :class:`povlens.plan.options.ConvertOptions` (``samples``,
        ``width``, ``height``, ``f_number``, ``units``, ``tolerance_px``, ...), among
        them POV-Ray's own options for every POV-Ray run of the scene:
        ``library_paths`` (folders, POV-Ray's ``+L``), ``clock`` (``+K``) and
        ``povray_options`` (switches or INI options, e.g. ``("+A0.3",)``).

    The plan's ``notes`` say what of the scene povlens replaces or ignores.

    Returns
    -------
    Plan
        The plan written to ``outdir/plan.json``.
    """
    return convert_options(_options(scene, lens, focus, outdir,
                                    {"method": method, **options}))


def _scheduler_of(scheduler, shared_dir: bool, group_size: int | None):
    """The scheduler to render on (the argument, else ``POVLENS_SCHEDULER``, else None:
    here); ``shared_dir`` and ``group_size`` need one."""
    from povlens.errors import ParameterError
    scheduler = scheduler or os.environ.get("POVLENS_SCHEDULER") or None
    if scheduler is None and (shared_dir or group_size is not None):
        name, given = ("shared_dir", "True") if shared_dir else ("group_size", "...")
        raise ParameterError(name, shared_dir or group_size, f"{name}={given} needs 'scheduler'",
                             f"give the scheduler's address, or leave out '{name}'")
    return scheduler


def _render_overrides(method, samples, width, height, options) -> dict:
    """The :class:`ConvertOptions` fields a render call sets (a given ``samples`` is kept,
    not chosen by ``auto``)."""
    overrides = {"method": method, **options}
    if samples is not None:
        overrides.update(samples=int(samples), auto_samples=False)
    if width is not None:
        overrides["width"] = int(width)
    if height is not None:
        overrides["height"] = int(height)
    return overrides


@dataclasses.dataclass(frozen=True)
class RenderResult:
    """What :func:`render` made: the plan and the images (linear EXR, sRGB PNG)."""

    plan: Plan
    image_exr: Path
    image_png: Path


def render(scene: str | os.PathLike, *, lens: str | os.PathLike, outdir: str | os.PathLike,
           focus: float | None = None, method: str = "auto", samples: int | None = None,
           width: int | None = None, height: int | None = None, jobs: int | None = None,
           progress: bool = False, scheduler: str | None = None, shared_dir: bool = False,
           group_size: int | None = None, **options) -> RenderResult:
    """Convert ``scene`` and render it through ``lens`` with POV-Ray.

    Parameters are those of :func:`convert`, plus:

    samples : int, optional
        Lens samples per pixel; by default ``auto`` chooses, the fixed methods use 16.
    width, height : int, optional
        Image size in pixels (defaults of :class:`~povlens.plan.options.ConvertOptions`).
    jobs : int, optional
        POV-Ray processes in parallel (default: the number of cores).
    progress : bool
        Show a progress bar on stderr.
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

    Returns
    -------
    RenderResult
        The plan and the paths of ``image.exr`` (linear light) and ``image.png``.
        An interrupted render resumes when called again with the same arguments.
    """
    from povlens.rendering.driver import convert_and_render
    scheduler = _scheduler_of(scheduler, shared_dir, group_size)
    overrides = _render_overrides(method, samples, width, height, options)
    opts = _options(scene, lens, focus, outdir, overrides)
    if scheduler is not None:
        from povlens.cluster.client import convert_and_render_on_cluster
        plan, exr = convert_and_render_on_cluster(opts, scheduler, shared_dir=shared_dir,
                                                  quiet=not progress, group_size=group_size)
    else:
        plan, exr = convert_and_render(opts, jobs=jobs, quiet=not progress)
    exr = Path(exr)
    return RenderResult(plan, exr, exr.with_suffix(".png"))


@dataclasses.dataclass(frozen=True)
class FramesResult:
    """What :func:`render_frames` made: one record per frame (focus, film distance,
    field of view, method, folder) and the numbered images (linear EXR, sRGB PNG)."""

    frames: list
    images_exr: list[Path]
    images_png: list[Path]


def render_frames(scene: str | os.PathLike, *, lens: str | os.PathLike,
                  outdir: str | os.PathLike, focus, frames: int | None = None,
                  method: str = "auto", samples: int | None = None, width: int | None = None,
                  height: int | None = None, jobs: int | None = None, progress: bool = False,
                  scheduler=None, shared_dir: bool = False, group_size: int | None = None,
                  **options) -> FramesResult:
    """Render a focus pull: one frame per focus distance (:mod:`povlens.rendering.focus_pull`).

    Parameters are those of :func:`render`, except:

    focus : (A, B) tuple or list of float
        ``(A, B)``: a pull from A to B in ``frames`` frames, even steps in dioptres
        (1/distance); a list: one frame per distance.  Scene units, positive, finite.
    frames : int, optional
        Frames of a pull (at least 2); with a list, its length if given.
    scheduler, shared_dir, group_size : as :func:`render`: every frame's lens samples
        on that Dask cluster, one client for all frames.

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
    from povlens.errors import ParameterError
    from povlens.plan.focus_series import focus_series
    from povlens.rendering.focus_pull import render_frames as render_pull
    if not isinstance(focus, (tuple, list)):
        raise ParameterError("focus", focus, f"focus={focus!r}: a focus pull is (A, B) or a "
                             f"list of distances", "for one focus use povlens.render")
    values = focus_series(list(focus) if isinstance(focus, list) else tuple(focus), frames)
    overrides = _render_overrides(method, samples, width, height, options)
    opts = _options(scene, lens, values[0], outdir, overrides)
    scheduler = _scheduler_of(scheduler, shared_dir, group_size)
    if scheduler is not None:
        from povlens.cluster.client import render_frames_on_cluster
        records = render_frames_on_cluster(opts, values, scheduler, shared_dir=shared_dir,
                                           quiet=not progress, group_size=group_size)
    else:
        records = render_pull(opts, values, jobs=jobs, quiet=not progress)
    out = Path(outdir)
    return FramesResult(records, [out / r.image_exr for r in records],
                        [out / r.image_png for r in records])


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
    """
    from povlens.report.compare import compare_arrays
    from povlens.util.images import read_image

    def load(x):
        return x if isinstance(x, np.ndarray) or x is None else read_image(x)

    m = load(mask)
    if m is not None and m.ndim == 3:
        m = m[..., 0]
    return compare_arrays(load(a), load(b), m)


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
