"""Averaging per-sample renders in linear light.

Each lens sample is rendered to its own (linear, EXR) image; the final image
is their mean, optionally weighted per pixel.  Images are read as float32 and
summed in float64, so half-float EXRs never accumulate in half precision (POV-Ray
writes EXR as half floats; OpenImageIO's own ``add`` keeps its input's format).
"""

from __future__ import annotations

import os
from typing import Iterable, Sequence

import numpy as np

from povlens.errors import PovlensError
from povlens.util.images import read_image

__all__ = ["composite", "accumulate_samples", "measurement_image"]


def accumulate_samples(
    sample_paths: Sequence[str | os.PathLike],
    weight_arrays: Iterable[np.ndarray] | None = None,
    drop_top_rows: int = 0,
    drop_right_columns: int = 0,
    channel_weights: Sequence[np.ndarray] | None = None,
    transform=None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """The sums of a composite, one sample in memory at a time.

    Parameters are those of :func:`composite`; ``weight_arrays`` may be any iterable
    (a generator computing each sample's weights when it is reached).  ``transform``:
    a function applied to each image after its rows and columns are dropped (an
    interleaved field pass puts its pixels in place:
    :func:`povlens.rendering.field_samples.image_layout`).
    ``channel_weights`` (with ``weight_arrays``): K arrays (3,) multiplying sample
    k's weights per colour channel, f_kc (spectral samples,
    :mod:`povlens.rendering.spectral`); the sums are then per channel, and the
    plain ``sum_k w_k`` follows as a 4th.

    Returns
    -------
    total : (H, W, C) float64, ``sum_k w_k I_k`` (or ``sum_k I_k`` without weights;
        channels 0..2 ``sum_k f_kc w_k I_kc`` with channel weights).
    weight_sum : (H, W) float64 ``sum_k w_k`` ((H, W, 4) ``sum_k f_kc w_k`` and
        ``sum_k w_k`` with channel weights), or None without weights.
    """
    paths = list(sample_paths)
    if not paths:
        raise PovlensError("nothing to composite: no sample images were given")
    drop, right = int(drop_top_rows), int(drop_right_columns)
    if drop < 0 or right < 0:
        raise PovlensError(f"drop_top_rows and drop_right_columns must be >= 0, got "
                           f"{drop_top_rows} and {drop_right_columns}")
    weights = None if weight_arrays is None else iter(weight_arrays)
    total = wsum = None
    for k, p in enumerate(paths):
        img = _cropped_image(p, drop, right, transform)
        if total is None:
            total, wsum = _zero_sums(img.shape, weights is not None, channel_weights is not None)
        elif img.shape != total.shape:
            raise PovlensError(
                f"image {p} has shape {img.shape} after dropping {drop} row(s), but "
                f"{paths[0]} has {total.shape}",
                "all samples of one composite must be rendered at the same size",
            )
        if weights is None:
            total += img
            continue
        w = _checked_weight(next(weights, None), k, p, len(paths), total.shape[:2])
        _add_weighted(total, wsum, img, w,
                      None if channel_weights is None else channel_weights[k])
    if weights is not None and next(weights, None) is not None:
        raise PovlensError(f"composite: {len(paths)} sample images but more weight arrays")
    return total, wsum


def _cropped_image(path, drop: int, right: int, transform) -> np.ndarray:
    """Sample image ``path`` without its ``drop`` top rows and ``right`` right columns,
    then ``transform``-ed (when given); refused if a value is NaN or infinite."""
    img = read_image(path)
    if img.shape[0] <= drop:
        raise PovlensError(
            f"image {path} has only {img.shape[0]} rows; cannot drop {drop} top row(s)"
        )
    if img.shape[1] <= right:
        raise PovlensError(
            f"image {path} has only {img.shape[1]} columns; cannot drop {right} column(s)")
    img = img[drop:, :img.shape[1] - right]
    if not np.all(np.isfinite(img)):        # a damaged file: no NaN reaches an image
        raise PovlensError(f"image {path} has {np.count_nonzero(~np.isfinite(img))} values "
                           f"that are NaN or infinite",
                           "the file is damaged; delete it and render again "
                           "('povlens render' or 'make' in the folder)")
    if transform is not None:
        img = transform(img)
    return img


def _zero_sums(shape: tuple, weighted: bool, per_channel: bool):
    """Zero float64 sums for images of ``shape``: ``sum w I`` and (``weighted``) ``sum w``,
    4 channels of it with ``per_channel`` weights (else None)."""
    total = np.zeros(shape, dtype=np.float64)
    wsum = None
    if weighted:
        wsum = np.zeros(shape[:2] + ((4,) if per_channel else ()), dtype=np.float64)
    return total, wsum


def _checked_weight(w, k: int, path, n: int, shape: tuple) -> np.ndarray:
    """Weight array ``k`` (of sample image ``path``, one of ``n``) as float64 (H, W),
    refused when missing, of another shape, negative or not finite."""
    if w is None:
        raise PovlensError(f"composite: {n} sample images but only {k} weight arrays")
    w = np.asarray(w, dtype=np.float64)
    if w.shape != shape:
        raise PovlensError(
            f"weight array {k} (for {path}) has shape {w.shape}, expected {shape}"
        )
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise PovlensError(f"weight array {k} (for {path}) has negative or non-finite values",
                           "its weights file is damaged; delete the sample's files and "
                           "render again ('povlens render' or 'make' in the folder)")
    return w


def _add_weighted(total: np.ndarray, wsum: np.ndarray, img: np.ndarray, w: np.ndarray,
                  channel_weight) -> None:
    """Add ``w I`` to ``total`` and ``w`` to ``wsum`` in place; with ``channel_weight``
    f_c (3,): ``f_c w I_c`` and ``f_c w`` in the colour channels, plain ``w`` as the
    4th of ``wsum``."""
    if channel_weight is not None:
        wc = w[:, :, None] * np.asarray(channel_weight, dtype=np.float64)[None, None, :3]
        total[..., :3] += wc * img[..., :3]
        total[..., 3:] += w[:, :, None] * img[..., 3:]
        wsum[..., :3] += wc
        wsum[..., 3] += w
        return
    total += w[:, :, None] * img
    wsum += w


def measurement_image(total: np.ndarray, wsum: np.ndarray, samples_per_row: np.ndarray,
                      exposure: float | None, illumination: np.ndarray | None = None
                      ) -> np.ndarray:
    """(H, W, 3) float64 image of a mesh composite's sums (:func:`accumulate_samples`).

    ``sum w I / sum w`` per pixel; with vignetting (``exposure`` not None) times the
    measurement's ``exposure * sum w / N_p`` (``samples_per_row`` (H,) N_p), or, given
    ``illumination`` (H, W), times that: the lens's exact relative illumination, a
    ratio estimator (the mean radiance of the passing samples times the known share of
    light that passes) whose vignetting has no steps where samples pass or not over
    whole regions, as field lens samples do.  With
    channel weights (``wsum`` (H, W, 4), ``--dispersion``) each channel is the
    colour-weighted mean ``sum f_c w I_c / sum f_c w`` and the measurement factor the
    plain ``sum w``: a grey scene stays exactly grey at any sample count, the exposure
    is the non-dispersive render's, and vignetting is taken achromatic.
    """
    image = np.zeros(total.shape[:2] + (3,))
    if wsum.ndim == 3:
        wc, w = wsum[..., :3], wsum[..., 3]
        nz = wc > 0
        image[nz] = total[..., :3][nz] / wc[nz]
    else:
        w = wsum
        nz = w > 0
        image[nz] = total[nz][:, :3] / w[nz][:, None]
    if illumination is not None:
        image *= np.asarray(illumination, dtype=np.float64)[..., None]
    elif exposure is not None:
        image *= (w * exposure / samples_per_row[:, None])[..., None]
    return image


def composite(
    sample_paths: Sequence[str | os.PathLike],
    weight_arrays: Iterable[np.ndarray] | None = None,
    drop_top_rows: int = 0,
    drop_right_columns: int = 0,
) -> np.ndarray:
    """Average sample images, returning float32 ``(H, W, C)`` linear light.

    sample_paths : image files (K of them), all the same size ``(H + drop_top_rows, W)``
        and channel count.
    weight_arrays : None for the plain mean ``sum_k I_k / K``; otherwise K arrays of
        shape ``(H, W)`` (after dropping rows) giving per-pixel weights ``w_k >= 0``,
        and the result is ``sum_k w_k I_k / sum_k w_k``.  Pixels whose total weight is
        0 come out as 0 (never NaN).
    drop_top_rows : rows removed from the top of every image first (1 for the
        POV-Ray 3.7.0.x mesh_camera row workaround, see
        :func:`povlens.pov.mesh.render_size`).
    drop_right_columns : columns removed from the right of every image first (1 for
        field meshes, :func:`povlens.pov.field_mesh.uv_model`).

    Raises :class:`PovlensError` naming the offending file for unreadable
    images, mismatched sizes or bad weights.
    """
    paths = list(sample_paths)
    total, wsum = accumulate_samples(paths, weight_arrays, drop_top_rows, drop_right_columns)
    if wsum is None:
        out = total / len(paths)
    else:
        out = np.zeros_like(total)
        nz = wsum > 0
        out[nz] = total[nz] / wsum[nz][:, None]
    return out.astype(np.float32)
