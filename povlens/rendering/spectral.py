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
``matrix_XYZ_to_RGB``), imported only here, when a dispersion plan is rendered; the
tables made from them are kept in the user's cache folder (:func:`table_cache_path`).

The lambda_k are importance-sampled from p(lambda) = (w_r + w_g + w_b) / 3: u_k is
the base-3 radical inverse of k (independent of the Sobol' pupil points and
offsets, which are base 2; a prefix of any length is stratified, so added samples
keep the first ones' wavelengths), rotated by the plan's seed, and
lambda_k = P^-1(u_k).  Sample k's channel factors are f_kc = w_c(lambda_k) /
p(lambda_k) divided by their mean over the plan's samples, so that a grey scene
composites to exactly its grey and the exposure matches the render without
dispersion (:func:`channel_factors`,
:func:`povlens.rendering.composite.measurement_image`).
"""

from __future__ import annotations

import functools
import importlib.metadata
import importlib.util
import io
from pathlib import Path

import numpy as np

from povlens.errors import PovlensError
from povlens.lens.dispersion import BAND_NM
from povlens.util.files import write_bytes
from povlens.util.user_cache import cache_folder

__all__ = ["band_sampler", "colour_weights", "sample_wavelength_nm", "channel_factors",
           "plan_channel_factors", "CMF_SOURCE", "tables_from_colour_science", "table_cache_path"]

#: Share of every channel each sample keeps whatever its wavelength (channel_factors).
FACTOR_FLOOR = 0.01

#: What the colour weights are made of (recorded in plan.json).
CMF_SOURCE = ("CIE 1931 2-degree colour-matching functions (colour-science) to linear sRGB, "
              "negative lobes clipped")


def table_cache_path(version: str) -> Path:
    """Where the band's tables made from colour-science ``version`` are kept
    (``$XDG_CACHE_HOME/povlens/``): importing colour-science costs about 1 s a process."""
    return cache_folder() / f"cmf-srgb-{version}-{BAND_NM[0]:g}-{BAND_NM[1]:g}nm.npz"


def tables_from_colour_science() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M,) wavelengths nm at 1 nm over the band, (M, 3) normalised weights w_c,
    (M,) cumulative distribution of p, computed with colour-science."""
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


def _colour_importable() -> bool:
    """Whether ``import colour`` would find the package (without importing it)."""
    try:
        return importlib.util.find_spec("colour") is not None
    except (ValueError, ImportError):        # e.g. sys.modules["colour"] is None
        return False


@functools.lru_cache(maxsize=1)
def _tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`tables_from_colour_science`, from the user's cache when it holds them for
    the installed colour-science (its version read without importing it)."""
    try:
        version = importlib.metadata.version("colour-science")
    except importlib.metadata.PackageNotFoundError:
        version = None
    if version is not None and _colour_importable():
        path = table_cache_path(version)
        try:
            with np.load(path, allow_pickle=False) as z:
                return z["lam"], z["w"], z["cdf"]
        except (OSError, ValueError, KeyError):
            pass
    lam, w, cdf = tables_from_colour_science()
    if version is not None:
        buf = io.BytesIO()
        np.savez(buf, lam=lam, w=w, cdf=cdf)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            write_bytes(path, buf.getvalue())
        except OSError:
            pass                     # no cache folder: compute again next time
    return lam, w, cdf


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
    f = f / np.maximum(f.mean(axis=0, keepdims=True), 1e-300)
    # every sample keeps FACTOR_FLOOR of each channel: a pixel that only samples of
    # other colours reach gets their light, not black (fringes 1 % less saturated)
    return (1.0 - FACTOR_FLOOR) * f + FACTOR_FLOOR


def plan_channel_factors(plan) -> np.ndarray | None:
    """A dispersion plan's (n, 3) channel factors of its samples (None without)."""
    if not plan.inputs.dispersion:
        return None
    return channel_factors(int(plan.inputs.samples), plan.inputs.seed)



def band_sampler(plan, table):
    """What per-pixel meshes of a dispersion plan draw pupil points from: ``table``
    (the d line's) with its polygons grown by the plan's ``pupil_dilation``
    (:func:`povlens.pupil.band_table.band_table`), so that every wavelength's pass
    region is held; ``table`` itself for other plans.

    Raises
    ------
    PovlensError
        If the plan's factors do not fit the table (the folder was changed by hand).
    """
    factors = (plan.dispersion or {}).get("pupil_dilation") if plan.inputs.dispersion else None
    if factors is None:
        return table
    from povlens.pupil.band_table import band_table
    try:
        return band_table(table, factors)
    except ValueError as e:
        raise PovlensError(f"the plan's pupil_dilation does not fit its pupil table: {e}",
                           "convert the scene again") from None
