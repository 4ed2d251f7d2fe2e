"""Adaptive mesh sampling (``--adaptive``): sharp row bands get fewer lens samples.

From a depth probe, :func:`adaptive_rows` gives each band of :data:`BAND_ROWS`
rows the lens samples its blur needs (the rule of
:func:`povlens.plan.decision.samples_for_blur`: thin-lens blur or real spot,
whichever is larger, floor :data:`ADAPTIVE_MIN_SAMPLES`), and
:func:`sample_row_ranges` lets sample k render only the rows of the bands that
need more than k samples (POV-Ray ``+SR/+ER``); the composite divides each pixel
by its own sample count.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from povlens.plan.batches import round_robin_batches
from povlens.plan.decision import MIN_SAMPLES, model_depths, samples_for_blur
from povlens.plan.depth_probe import depth_limits
from povlens.plan.schema import AdaptiveSampling, Plan
from povlens.thinlens.model_error import ModelError, measure_model_error

__all__ = ["BAND_ROWS", "ADAPTIVE_MIN_SAMPLES", "real_blur_at", "real_blur_model_error",
           "adaptive_rows", "sample_row_ranges", "limit_samples", "apply_to_plan"]

#: Rows per band, and the fewest samples any pixel gets (anti-aliasing needs them:
#: docs/decisions/planning.md, "Adaptive floor").
BAND_ROWS, ADAPTIVE_MIN_SAMPLES = 8, MIN_SAMPLES


def real_blur_at(model_error: ModelError, model, axial_mm: np.ndarray) -> np.ndarray:
    """Real spot size (px, equivalent-disc diameter, largest over the field) at
    axial distances ``axial_mm`` from the entrance pupil (inf: the farthest depth
    measured), interpolated in log distance between the depths of
    ``model_error`` (:func:`povlens.thinlens.model_error.measure_model_error`), held
    constant beyond them.  Returns an array of the shape of ``axial_mm``."""
    z = np.asarray(model_error.object_z_mm, dtype=float) - model.centre_z_mm
    real = np.asarray(model_error.blur_real_px, dtype=float).max(axis=1)
    order = np.argsort(z)
    z, real = np.log(np.maximum(z[order], 1e-9)), real[order]
    a = np.asarray(axial_mm, dtype=float)
    la = np.log(np.where(np.isfinite(a) & (a > 0), a, np.exp(z[-1])))
    return np.interp(la, z, real)


def real_blur_model_error(lens, plan: Plan, model, film, axial_mm: np.ndarray) -> ModelError:
    """:func:`povlens.thinlens.model_error.measure_model_error` at depths spanning a depth
    probe's range (``axial_mm`` from the entrance pupil), for :func:`real_blur_at`."""
    near, far, _ = depth_limits(axial_mm)
    if math.isinf(near):
        near = far = 1e4 * max(model.focus_distance_mm if math.isfinite(model.focus_distance_mm)
                               else 1e3, 1e3)
    c = model.centre_z_mm
    return measure_model_error(lens, plan.focus.film_distance_mm, model, film,
                               model_depths(model, c + near, c + far))


def adaptive_rows(model, axial_mm: np.ndarray, film, n_max: int, band_rows: int = BAND_ROWS,
                  n_min: int = ADAPTIVE_MIN_SAMPLES,
                  model_error: ModelError | None = None) -> AdaptiveSampling:
    """Samples each band of ``band_rows`` image rows needs, from a depth probe.

    Per probe pixel the blur b (px of ``film``) at its depth: the thin-lens blur,
    or the real spot (:func:`real_blur_at`) where ``model_error`` is given and it
    is larger (aberrations: a fast singlet's spot is far larger than its thin-lens
    blur).  A row's blur is the largest b of any probe pixel within b/2 + 1 rows of
    it (a blurred point spreads over b rows, so light from a blurred neighbour
    counts too); a band's is its rows' maximum; its samples
    :func:`~povlens.plan.decision.samples_for_blur` ``(b, n_min, n_max)``.

    Parameters
    ----------
    model : the equivalent thin lens.
    axial_mm : (h, w) axial distances of the probe's pixels from the entrance pupil.
    film : the plan's film (its rows are banded).
    n_max, n_min : the sample-count clamp.
    """
    a = np.asarray(axial_mm, dtype=float)
    ph = a.shape[0]
    h = film.height_px
    pitch = film.pixel_pitch_mm
    s = model.focus_distance_mm
    inf_blur = (model.pupil_diameter_mm * model.image_distance_mm / s / pitch
                if math.isfinite(s) else 0.0)
    blur = np.full(a.shape, inf_blur)
    fin = np.isfinite(a) & (a > 0)
    if fin.any():
        blur[fin] = model.blur_diameter_mm(model.centre_z_mm + a[fin]) / pitch
    if model_error is not None:
        blur = np.maximum(blur, real_blur_at(model_error, model, a))
    probe_row_blur = blur.max(axis=1)                       # (ph,)
    # film rows covered by probe row i: [i h / ph, (i + 1) h / ph)
    row_blur = np.zeros(h)
    for i, b in enumerate(probe_row_blur):
        r0 = math.floor(i * h / ph)
        r1 = math.ceil((i + 1) * h / ph)
        reach = math.ceil(b / 2) + 1
        lo, hi = max(0, r0 - reach), min(h, r1 + reach)
        row_blur[lo:hi] = np.maximum(row_blur[lo:hi], b)
    nb = math.ceil(h / band_rows)
    band_blur = [float(row_blur[j * band_rows:(j + 1) * band_rows].max()) for j in range(nb)]
    n_min = max(1, min(int(n_min), int(n_max)))
    band_samples = [samples_for_blur(b, n_min, n_max) for b in band_blur]
    return AdaptiveSampling(int(band_rows), n_min, band_blur, band_samples)


def limit_samples(adaptive: AdaptiveSampling, n_max: int) -> AdaptiveSampling:
    """``adaptive`` with every band's samples recomputed for at most ``n_max``."""
    n_min = min(adaptive.n_min, n_max)
    return dataclasses.replace(adaptive, n_min=n_min, band_samples=[
        samples_for_blur(b, n_min, n_max) for b in adaptive.band_blur_px])


def sample_row_ranges(adaptive: AdaptiveSampling, height: int) -> list[tuple[int, int]]:
    """Film rows [start, end) each sample renders: samples below n_min the whole
    frame, sample k the rows from the first to the last band needing more than k
    samples (POV-Ray renders one row range per frame).  Length = max band samples."""
    br, need = adaptive.band_rows, adaptive.band_samples
    rows = []
    for k in range(max(need)):
        if k < adaptive.n_min:
            rows.append((0, height))
            continue
        bands = [j for j, n in enumerate(need) if n > k]
        rows.append((bands[0] * br, min(height, (bands[-1] + 1) * br)))
    return rows


def apply_to_plan(plan: Plan, adaptive: AdaptiveSampling, batch_size: int | None) -> None:
    """Give ``plan`` the per-sample row ranges of ``adaptive`` and its batches.

    Every sample is its own POV-Ray process (:func:`povlens.rendering.mesh_samples.render_samples`),
    so a batch may mix row ranges; samples are dealt round-robin
    (:func:`~povlens.plan.batches.round_robin_batches`: later samples render fewer
    rows, so contiguous batches would be unequal)."""
    h, w = plan.film.height_px, plan.film.width_px
    rows = sample_row_ranges(adaptive, h)
    n = len(rows)
    plan.batches = round_robin_batches(n, batch_size)
    plan.sample_rows = rows
    pixel_samples = sum((r1 - r0) * w for r0, r1 in rows)
    plan.adaptive = dataclasses.replace(adaptive, pixel_samples=pixel_samples,
                                        uniform_pixel_samples=n * h * w)
