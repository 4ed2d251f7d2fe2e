"""Compositing a render folder's lens samples into its image.

Monte-Carlo estimate of the camera measurement equation (Pharr, Jakob and Humphreys,
*Physically Based Rendering*, 3rd ed., §6.4.7): for pixel p and samples k = 1..N with
weights w_k(p) = cos^4(theta) / (z^2 pdf) (0 when blocked),

    image(p) = exposure * (1/N) sum_k w_k(p) I_k(p),

where ``exposure`` = 1 / (E/L at the film centre) makes the frame centre as bright as
the pinhole render, and vignetting shows as it would on film.  The sums are taken one
sample at a time in sample order (:func:`povlens.rendering.composite.accumulate_samples`),
or come from the group files a cluster wrote (:mod:`povlens.rendering.groups`); the
image goes to ``image.exr`` (linear float) and ``image.png`` (sRGB preview).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from povlens.errors import PovlensError
from povlens.plan.folder_lock import folder_lock
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Plan, read_plan
from povlens.rendering.composite import accumulate_samples, measurement_image
from povlens.rendering.field_samples import (field_sample_weight, illumination_map,
                                             image_layout)
from povlens.rendering.folder_inputs import exposure_for, lens_for, pupil_table_for
from povlens.rendering.groups import group_sums
from povlens.rendering.mesh_samples import sample_rows
from povlens.rendering.spectral import plan_channel_factors
from povlens.util.images import write_exr, write_png_srgb

__all__ = ["composite_outdir", "sample_sums", "sample_weight", "samples_per_pixel",
           "write_image"]


def sample_weight(outdir: str | os.PathLike, k: int, plan: Plan | None = None,
                  table=None) -> np.ndarray:
    """(H, W) float32 radiometric weights of rendered lens sample k of a mesh folder
    (0 where its rays are blocked or its rows do not reach): the weight image of
    per-pixel meshes, computed from the pass mask for field meshes.  ``plan`` and
    ``table`` (the pupil table) are read when not given."""
    outdir = Path(outdir)
    plan = read_plan(outdir) if plan is None else plan
    if plan.field_mesh is None:
        return RenderFolder(outdir).read_weight(k)
    if table is None:
        table = pupil_table_for(outdir, plan, lens_for(plan))
    return field_sample_weight(plan, table, outdir, k)


def samples_per_pixel(plan: Plan) -> np.ndarray:
    """(H,) number of samples whose rows include each film row (N_p of a pixel)."""
    h = plan.film.height_px
    n = np.zeros(h, dtype=np.int64)
    for k in range(plan.inputs.samples):
        r0, r1 = sample_rows(plan, k)
        n[r0:r1] += 1
    return n


def write_image(outdir: str | os.PathLike, image: np.ndarray) -> None:
    """Write a folder's image: ``image.exr`` (float32, linear) and ``image.png`` (sRGB
    preview, negative values clipped)."""
    folder = RenderFolder(outdir)
    write_exr(folder.image_exr, image.astype(np.float32))
    write_png_srgb(folder.image_png, np.clip(image, 0.0, None))


def composite_outdir(outdir: str | os.PathLike, vignetting: bool | None = None,
                     write: bool = True, sums=None) -> np.ndarray:
    """Combine the rendered samples of a mesh plan into image.exr and image.png.

    With ``vignetting`` (the plan's setting when None) the image is the camera
    measurement normalised at the frame centre, darker toward the corners as the
    lens makes it.  Without, each pixel is divided by its own mean weight
    (``sum w I / sum w``), which removes natural and mechanical vignetting and
    leaves the lens's geometry and blur: comparable with POV-Ray's cameras.
    Returns the (H, W, 3) float64 image; ``write=False`` only returns it.  ``sums``:
    the sums over the rendered samples, added in sample order by the caller as they
    came (:func:`sample_sums`; :mod:`povlens.cluster`), instead of reading them here.
    The folder's lock is held shared (:func:`povlens.plan.folder_lock.folder_lock`):
    beside make's recipes, but not while ``povlens render`` writes the folder.
    """
    with folder_lock(outdir, shared=True):  # beside make's recipes; not under a render
        image = _composite(Path(outdir), vignetting, sums)
        if write:
            write_image(outdir, image.astype(np.float32))
    return image


def _refuse_missing(folder: RenderFolder, missing: list[int]) -> None:
    """Raise for samples not rendered: the first damaged file among them by name, or
    which are missing."""
    for k in missing:
        damage = folder.sample_damage(k)
        if damage is not None:
            raise PovlensError(f"{damage[0]}: {damage[1]}", folder.redo_hint(k))
    raise PovlensError(f"{folder.path}: samples {missing[:8]}{'...' if len(missing) > 8 else ''} "
                       f"are not rendered yet", "run 'povlens render' or 'make' in the folder")


def _composite(outdir: Path, vignetting: bool | None, sums) -> np.ndarray:
    """:func:`composite_outdir`'s image, not written."""
    folder = RenderFolder(outdir)
    plan = read_plan(outdir)
    if vignetting is None:
        vignetting = plan.inputs.vignetting
    n = plan.inputs.samples
    drop = plan.povray.drop_top_rows
    missing = [k for k in range(n) if not folder.sample_done(k)]
    if missing:
        _refuse_missing(folder, missing)
    lens = lens_for(plan)
    table = pupil_table_for(outdir, plan, lens)
    exposure = exposure_for(outdir, plan, lens, table)
    sums = sums if sums is not None else group_sums(outdir, plan, table, sample_sums)  # groups
    # Blocked samples (all rays blocked) are black with weight 0: they add nothing to
    # the sums but count in N_p.  Adaptive plans: sample k covers only its rows
    # (weight 0 elsewhere) and pixel p's N_p counts the samples covering its row.
    rendered = [k for k in range(n) if not folder.blocked(k)]
    film = plan.film
    n_p = samples_per_pixel(plan).astype(np.float64)
    if not rendered:
        return np.zeros((film.height_px, film.width_px, 3))
    paths = [folder.sample_image(k) for k in rendered]
    # sum w I / sum w, in float64, one sample in memory at a time (composite.py);
    # times sum w / N_p for the measurement
    spectral = plan_channel_factors(plan)    # --dispersion: per-channel weights
    total, wsum = sums if sums is not None else accumulate_samples(
        paths, (sample_weight(outdir, k, plan, table) for k in rendered),
        drop_top_rows=drop, drop_right_columns=plan.povray.drop_right_columns,
        channel_weights=None if spectral is None else spectral[rendered],
        transform=image_layout(plan))
    ri = illumination_map(outdir, plan, table) if vignetting else None   # field meshes
    image = measurement_image(total, wsum, n_p, exposure if vignetting else None, ri)
    bad = np.count_nonzero(~np.isfinite(image))
    if bad:     # every input is checked when read: this is povlens's own fault
        raise PovlensError(f"{outdir}: the composite has {bad} values that are NaN or "
                           f"infinite; no image was written",
                           "this is a bug in povlens; please report it with the folder")
    return image


def sample_sums(outdir: str | os.PathLike, k: int, plan: Plan, table):
    """Sample k's terms of :func:`composite_outdir`'s sums (float64 ``w_k I_k``, ``w_k``),
    None if blocked; added in sample order they are its sums bit for bit."""
    folder = RenderFolder(outdir)
    if folder.blocked(k):
        return None
    spectral = plan_channel_factors(plan)
    return accumulate_samples(
        [folder.sample_image(k)], [sample_weight(outdir, k, plan, table)],
        drop_top_rows=plan.povray.drop_top_rows,
        drop_right_columns=plan.povray.drop_right_columns,
        channel_weights=None if spectral is None else spectral[[k]],
        transform=image_layout(plan))
