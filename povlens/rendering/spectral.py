"""Wavelengths of lens samples and their colour weights (``--dispersion``).

Each lens sample k of a dispersion plan is traced at one wavelength lambda_k
(:func:`sample_wavelength_nm`).  Its image (the scene's RGB, rendered through the
lens at lambda_k) adds to output channel c in proportion to

    w_c(lambda) = max(0, [M_XYZ->sRGB (xbar, ybar, zbar)(lambda)]_c),

the CIE 1931 2-degree colour-matching functions taken to linear sRGB (the sRGB
primaries' matching functions), each normalised to integrate to 1 over the band.
Their negative lobes (r below ~540 nm, g below ~440 nm and above ~650 nm) are
clipped: a channel collects light only where its own matching function is positive,
so every weight is >= 0 and no pixel goes negative; an equal-energy spectrum still
gives (1, 1, 1).  The CMFs come from colour-science (``colour.MSDS_CMFS``, sRGB's
``matrix_XYZ_to_RGB``), imported only here, when a dispersion plan is rendered.

The lambda_k are importance-sampled from p(lambda) = (w_r + w_g + w_b) / 3: u_k is
the base-3 radical inverse of k (independent of the Sobol' pupil points and
offsets, which are base 2; a prefix of any length is stratified, so added samples
keep the first ones' wavelengths), rotated by the plan's seed, and
lambda_k = P^-1(u_k).  Sample k's channel factors are f_kc = w_c(lambda_k) /
p(lambda_k) divided by their mean over the plan's samples, so that a grey scene
composites to exactly its grey and the exposure matches the render without
dispersion (:func:`channel_factors`).
"""

from __future__ import annotations

import functools

import numpy as np

from povlens.errors import PovlensError
from povlens.lens.dispersion import BAND_NM

__all__ = ["colour_weights", "sample_wavelength_nm", "channel_factors", "row_factor_sums",
           "plan_channel_factors", "spectral_image", "CMF_SOURCE"]

#: What the colour weights are made of (recorded in plan.json).
CMF_SOURCE = ("CIE 1931 2-degree colour-matching functions (colour-science) to linear sRGB, "
              "negative lobes clipped")


@functools.lru_cache(maxsize=1)
def _tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M,) wavelengths nm at 1 nm over the band, (M, 3) normalised weights w_c,
    (M,) cumulative distribution of p."""
    try:
        import colour
    except ImportError:
        raise PovlensError("--dispersion needs the colour-science package (the CIE 1931 "
                           "colour-matching functions)",
                           "install it: python3 -m pip install colour-science") from None
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    lam = np.arange(BAND_NM[0], BAND_NM[1] + 0.5, 1.0)
    xyz = np.asarray(cmfs[lam], dtype=np.float64)                      # (M, 3)
    m = np.asarray(colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB, dtype=np.float64)
    w = np.clip(xyz @ m.T, 0.0, None)
    w /= np.trapezoid(w, lam, axis=0) if hasattr(np, "trapezoid") else np.trapz(w, lam, axis=0)
    p = w.mean(axis=1)
    cdf = np.concatenate(([0.0], np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(lam))))
    return lam, w, cdf / cdf[-1]


def colour_weights(wavelength_nm) -> np.ndarray:
    """(n, 3) normalised channel weights w_c(lambda) (1/nm) at (n,) wavelengths nm."""
    lam, w, _ = _tables()
    x = np.atleast_1d(np.asarray(wavelength_nm, dtype=np.float64))
    return np.stack([np.interp(x, lam, w[:, c], left=0.0, right=0.0) for c in range(3)], axis=1)


def _radical_inverse_3(k: np.ndarray) -> np.ndarray:
    k = np.asarray(k, dtype=np.int64).copy()
    out = np.zeros(k.shape, dtype=np.float64)
    scale = 1.0 / 3.0
    while np.any(k > 0):
        out += (k % 3) * scale
        k //= 3
        scale /= 3.0
    return out


def sample_wavelength_nm(k, seed: int = 0) -> np.ndarray:
    """Wavelengths (nm) of lens samples ``k`` (int or (n,)) of a plan with ``seed``:
    the same for any sample count (module docstring)."""
    lam, _, cdf = _tables()
    u = (_radical_inverse_3(np.atleast_1d(k)) + 0.5 + 0.6180339887498949 * int(seed)) % 1.0
    return np.interp(u, cdf, lam)


def channel_factors(n_samples: int, seed: int = 0) -> np.ndarray:
    """(n_samples, 3) channel factors f_kc of samples 0..n-1, mean 1 per channel."""
    lam = sample_wavelength_nm(np.arange(int(n_samples)), seed)
    w = colour_weights(lam)
    f = w / np.maximum(w.mean(axis=1, keepdims=True), 1e-300)    # w_c / p at lambda_k
    return f / np.maximum(f.mean(axis=0, keepdims=True), 1e-300)


def row_factor_sums(factors: np.ndarray, rows: list[tuple[int, int]], height: int) -> np.ndarray:
    """(height, 3) sum of f_kc over the samples whose rows [r0, r1) cover each film row
    (what replaces the sample count N_p of a pixel in the composite)."""
    out = np.zeros((int(height), 3), dtype=np.float64)
    for f, (r0, r1) in zip(factors, rows):
        out[r0:r1] += f
    return out


def plan_channel_factors(plan) -> tuple[np.ndarray, np.ndarray] | None:
    """A dispersion plan's (n, 3) channel factors of its samples and their (H, 3) sums
    over the samples covering each film row; None for a plan without dispersion."""
    if not plan.inputs.dispersion:
        return None
    n = int(plan.inputs.samples)
    f = channel_factors(n, plan.inputs.seed)
    rows = [plan.rows_of_sample(k) for k in range(n)]
    return f, row_factor_sums(f, rows, plan.film.height_px)


def spectral_image(total: np.ndarray, wsum: np.ndarray, row_sums: np.ndarray,
                   exposure: float | None) -> np.ndarray:
    """(H, W, 3) composite of per-channel sums (:func:`~povlens.rendering.composite.
    accumulate_samples` with channel weights): ``sum f w I / sum f w`` without
    vignetting (``exposure`` None), else ``exposure * sum f w I / sum_k f_kc``
    (``row_sums`` (H, 3)), the measurement with the lens's vignetting."""
    t = total[..., :3]
    image = np.zeros(t.shape)
    if exposure is None:
        nz = wsum > 0
        image[nz] = t[nz] / wsum[nz]
        return image
    rs = row_sums[:, None, :]
    return np.where(rs > 0, exposure * t / np.where(rs > 0, rs, 1.0), 0.0)
