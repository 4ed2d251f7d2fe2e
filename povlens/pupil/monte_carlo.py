"""Monte Carlo over the lens: its sample points (QMC point sets) and the estimates built
on a lens sampler (pass fraction, irradiance factor, exposure normalisation).

Point sets (all float64 in [0, 1)^d, reproducible from ``seed``)
----------------------------------------------------------------
* :func:`sobol_points` -- scrambled Sobol' (Owen scrambling with a random digital
  shift, ``scipy.stats.qmc.Sobol``).  Generated in a power-of-two block and cut,
  so that every prefix keeps scipy's balance properties as far as possible.
* :func:`halton_points` -- scrambled Halton (``scipy.stats.qmc.Halton``).
* :func:`stratified_points` -- jittered grid: one uniform random point in each
  cell of a k x k grid (n = k^2); for n not a square, the first n cells of the
  next larger grid in a random order.
* :func:`lens_points` picks one of them by name; :func:`cranley_patterson`
  shifts a point set modulo 1 (a different random shift per pixel keeps the
  set's stratification while decorrelating neighbouring pixels).

Lens samplers
-------------
Any object with ``sample(film_xy (n, 2) mm, u (n, 2)) -> LensSample`` (see
:mod:`povlens.pupil.sampler_interface`): the exit-pupil table
(:class:`povlens.pupil.table.PupilTable`) and the baselines of
:mod:`povlens.pupil.baselines`.  ``sample`` only proposes a ray and its weight;
whether the ray gets through is decided by tracing it.  The estimate of the
irradiance factor E/L at a film point (the irradiance a uniform scene of unit
radiance produces there: the camera measurement equation, *Physically Based
Rendering*, 3rd ed., §6.4.7) is the mean of ``weight * passed``; it is unbiased
whenever the sampler's region contains every ray that passes.

:func:`exposure_normalisation` returns the factor that scales weights so that
the centre of the frame has the brightness of a pinhole render of the same
scene: a pinhole camera records the scene radiance L itself, the lens records
(E/L)(0) L at the film centre, so the factor is 1 / (E/L)(0).  On axis
(E/L)(0) = pi sin^2(alpha') ~ pi / (4 N^2) for an aplanatic lens focused at
infinity.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from povlens.errors import OpticsError, UsageError
from povlens.lens.prescription import LensPrescription
from povlens.lens.tracer import trace_from_film
from povlens.util.signals import interrupts_deferred
from povlens.util.user_cache import cached_array

__all__ = ["sobol_points", "halton_points", "stratified_points", "lens_points",
           "cranley_patterson", "POINT_SETS", "PassFraction", "pass_fraction",
           "irradiance_factor", "exposure_normalisation", "irradiance_factor_at",
           "pass_fraction_at"]


def _check_n(n: int) -> int:
    n = int(n)
    if n < 0:
        raise UsageError(f"number of sample points {n}: must not be negative")
    return n


def sobol_points(n: int, d: int = 2, *, seed: int = 0) -> np.ndarray:
    """n scrambled Sobol' points in [0, 1)^d, shape (n, d)."""
    n = _check_n(n)
    if n == 0:
        return np.zeros((0, d))
    m = max(0, math.ceil(math.log2(n)))
    if isinstance(seed, (int, np.integer)) and m <= CACHED_SOBOL_LOG2:
        block = _cached_sobol_block(d, m, int(seed))
    else:
        block = _sobol_block(d, m, seed)
    return np.minimum(block[:n], np.nextafter(1.0, 0.0))


@functools.lru_cache(maxsize=16)
def _cached_sobol_block(d: int, m: int, seed: int) -> np.ndarray:
    """:func:`_sobol_block` from the user's cache, kept in memory too: a render asks for
    the same block for every lens sample (read-only: callers get copies)."""
    name = f"sobol-d{d}-seed{seed}-m{m}-scipy{_scipy_version()}.npy"
    block = cached_array(name, lambda: _sobol_block(d, m, seed),
                         lambda a: a.shape == (2 ** m, d) and a.dtype == np.float64
                         and bool(np.all((a >= 0.0) & (a < 1.0))))
    block.setflags(write=False)
    return block


#: Sobol' blocks up to 2**this points are kept in the user's cache
#: (:mod:`povlens.util.user_cache`): importing scipy.stats costs 0.6 s of every
#: command's start-up (most of a 32x24 conversion's 1.9 s), the points never change.
CACHED_SOBOL_LOG2 = 16


@functools.lru_cache(maxsize=1)
def _scipy_version() -> str:
    from importlib.metadata import version      # without importing scipy.stats
    return version("scipy")


def _sobol_block(d: int, m: int, seed) -> np.ndarray:
    """The first 2**m scrambled Sobol' points of dimension d, shape (2**m, d)."""
    from scipy.stats import qmc  # heavy: imported when points are first needed
    with interrupts_deferred():          # its Cython set-up would swallow a Ctrl-C
        return qmc.Sobol(d=d, scramble=True, seed=seed).random_base2(m)


def halton_points(n: int, d: int = 2, *, seed: int = 0) -> np.ndarray:
    """n scrambled Halton points in [0, 1)^d, shape (n, d)."""
    n = _check_n(n)
    if n == 0:
        return np.zeros((0, d))
    from scipy.stats import qmc  # heavy: imported when points are first needed
    pts = qmc.Halton(d=d, scramble=True, seed=seed).random(n)
    return np.minimum(pts, np.nextafter(1.0, 0.0))


def stratified_points(n: int, d: int = 2, *, seed: int = 0) -> np.ndarray:
    """n jittered-grid points in [0, 1)^2 (d must be 2), shape (n, 2)."""
    n = _check_n(n)
    if d != 2:
        raise ValueError("stratified_points makes 2-D points only")
    if n == 0:
        return np.zeros((0, 2))
    rng = np.random.default_rng(seed)
    k = math.isqrt(n)
    if k * k < n:
        k += 1
    cells = np.arange(k * k)
    if k * k != n:
        cells = rng.permutation(cells)[:n]
    i, j = np.divmod(cells, k)
    pts = (np.stack([j, i], axis=1) + rng.random((n, 2))) / k
    return np.minimum(pts, np.nextafter(1.0, 0.0))


#: Point-set generators by name, for command-line options.
POINT_SETS = {"sobol": sobol_points, "halton": halton_points, "stratified": stratified_points}


def lens_points(n: int, *, method: str = "sobol", seed: int = 0) -> np.ndarray:
    """n points in [0, 1)^2 from the named point set (sobol, halton, stratified)."""
    try:
        gen = POINT_SETS[method]
    except KeyError:
        raise UsageError(f"point set '{method}': unknown",
                         f"use one of {', '.join(sorted(POINT_SETS))}") from None
    return gen(n, 2, seed=seed)


def cranley_patterson(points: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """points + shift modulo 1 (shift broadcasts against points)."""
    out = np.mod(np.asarray(points, dtype=np.float64) + shift, 1.0)
    return np.minimum(out, np.nextafter(1.0, 0.0))


# ----- estimates over a lens sampler ------------------------------------------------

@dataclasses.dataclass(frozen=True)
class PassFraction:
    """Per film radius: how many proposed rays were valid, and the fraction that passed.

    fraction : (m,) passed / valid; 0 where no sample was valid.
    n_valid : (m,) valid samples (0: the sampler reports the film point vignetted).
    n_samples : samples proposed per radius.
    """

    film_radius_mm: np.ndarray
    fraction: np.ndarray
    n_valid: np.ndarray
    n_samples: int

    @property
    def vignetted(self) -> np.ndarray:
        """(m,) True where the sampler proposes no ray at all."""
        return self.n_valid == 0


def _film_points(r: float, n: int, azimuth: float) -> np.ndarray:
    xy = np.empty((n, 2))
    xy[:, 0] = r * math.cos(azimuth)
    xy[:, 1] = r * math.sin(azimuth)
    return xy


def _trace_samples(sampler, lens, film_distance_mm, film_radius_mm, n_samples, seed, chunk):
    """Yield (radius index, LensSample, passed) with azimuths spread over the film."""
    radii = np.atleast_1d(np.asarray(film_radius_mm, dtype=np.float64))
    u = sobol_points(n_samples, 2, seed=seed)
    per = max(1, chunk // max(n_samples, 1))
    for start in range(0, len(radii), per):
        idx = np.arange(start, min(start + per, len(radii)))
        # Azimuths differ per radius (golden-angle steps) to exercise the rotation.
        film = np.concatenate([_film_points(radii[i], n_samples, 2.399963229728653 * i)
                               for i in idx])
        uu = np.tile(u, (len(idx), 1))
        s = sampler.sample(film, uu)
        passed = np.zeros(len(film), bool)
        v = np.nonzero(s.valid)[0]
        if v.size:
            passed[v] = trace_from_film(lens, film_distance_mm, s.film_point[v],
                                        s.direction[v]).passed
        yield idx, s, passed


def pass_fraction(sampler, lens: LensPrescription, film_distance_mm: float, film_radius_mm,
                  *, n_samples: int = 1024, seed: int = 0, chunk: int = 1 << 17) -> PassFraction:
    """Fraction of the rays ``sampler`` proposes at each film radius that get through."""
    radii = np.atleast_1d(np.asarray(film_radius_mm, dtype=np.float64))
    frac = np.zeros(len(radii))
    nv = np.zeros(len(radii), dtype=np.int64)
    for idx, s, passed in _trace_samples(sampler, lens, film_distance_mm, radii, n_samples,
                                         seed, chunk):
        valid = np.asarray(s.valid, bool).reshape(len(idx), n_samples)
        ps = passed.reshape(len(idx), n_samples)
        nv[idx] = valid.sum(axis=1)
        frac[idx] = np.where(nv[idx] > 0, ps.sum(axis=1) / np.maximum(nv[idx], 1), 0.0)
    return PassFraction(radii, frac, nv, int(n_samples))


def irradiance_factor(sampler, lens: LensPrescription, film_distance_mm: float, film_radius_mm,
                      *, n_samples: int = 4096, seed: int = 0, chunk: int = 1 << 17
                      ) -> np.ndarray:
    """Estimated E/L (irradiance per unit scene radiance) at each film radius, (m,).

    The mean of ``weight * passed`` over ``n_samples`` scrambled Sobol' points;
    the same points at every radius (common random numbers), so the curve over
    the film is smooth up to the flips of single samples.  0 where vignetted.
    """
    radii = np.atleast_1d(np.asarray(film_radius_mm, dtype=np.float64))
    out = np.zeros(len(radii))
    for idx, s, passed in _trace_samples(sampler, lens, film_distance_mm, radii, n_samples,
                                         seed, chunk):
        w = np.where(passed, s.weight, 0.0).reshape(len(idx), n_samples)
        out[idx] = w.mean(axis=1)
    return out


def _trace_at(sampler, lens, film_distance_mm, film_xy, n_samples, seed, chunk):
    """Yield (point indices, LensSample, passed) for ``n_samples`` Sobol' points at each
    film point of ``film_xy`` (m, 2), a few points per call."""
    pts = np.asarray(film_xy, dtype=np.float64).reshape(-1, 2)
    u = sobol_points(n_samples, 2, seed=seed)
    per = max(1, chunk // max(n_samples, 1))
    for start in range(0, len(pts), per):
        idx = np.arange(start, min(start + per, len(pts)))
        film = np.repeat(pts[idx], n_samples, axis=0)
        s = sampler.sample(film, np.tile(u, (len(idx), 1)))
        passed = np.zeros(len(film), bool)
        v = np.nonzero(s.valid)[0]
        if v.size:
            passed[v] = trace_from_film(lens, film_distance_mm, s.film_point[v],
                                        s.direction[v]).passed
        yield idx, s, passed


def irradiance_factor_at(sampler, lens: LensPrescription, film_distance_mm: float, film_xy,
                         *, n_samples: int = 4096, seed: int = 0, chunk: int = 1 << 17
                         ) -> np.ndarray:
    """Estimated E/L at film points ``film_xy`` (m, 2) mm, (m,): as
    :func:`irradiance_factor`, at points given by both coordinates (for lenses whose
    illumination depends on more than the film radius)."""
    pts = np.asarray(film_xy, dtype=np.float64).reshape(-1, 2)
    out = np.zeros(len(pts))
    for idx, s, passed in _trace_at(sampler, lens, film_distance_mm, pts, n_samples, seed,
                                    chunk):
        out[idx] = np.where(passed, s.weight, 0.0).reshape(len(idx), n_samples).mean(axis=1)
    return out


def pass_fraction_at(sampler, lens: LensPrescription, film_distance_mm: float, film_xy,
                     *, n_samples: int = 1024, seed: int = 0, chunk: int = 1 << 17
                     ) -> PassFraction:
    """:func:`pass_fraction` at film points ``film_xy`` (m, 2) mm; its ``film_radius_mm``
    holds their radii."""
    pts = np.asarray(film_xy, dtype=np.float64).reshape(-1, 2)
    frac, nv = np.zeros(len(pts)), np.zeros(len(pts), dtype=np.int64)
    for idx, s, passed in _trace_at(sampler, lens, film_distance_mm, pts, n_samples, seed,
                                    chunk):
        valid = np.asarray(s.valid, bool).reshape(len(idx), n_samples)
        nv[idx] = valid.sum(axis=1)
        ps = passed.reshape(len(idx), n_samples).sum(axis=1)
        frac[idx] = np.where(nv[idx] > 0, ps / np.maximum(nv[idx], 1), 0.0)
    return PassFraction(np.hypot(pts[:, 0], pts[:, 1]), frac, nv, int(n_samples))


def exposure_normalisation(sampler, lens: LensPrescription, film_distance_mm: float, *,
                           n_samples: int = 1 << 14, seed: int = 0) -> float:
    """Factor for the weights that makes the frame centre as bright as a pinhole render.

    Returns 1 / (E/L)(0), estimated with ``n_samples`` traced Sobol' samples at the
    film centre.  Raises OpticsError when no ray leaves the film centre.
    """
    e0 = float(irradiance_factor(sampler, lens, film_distance_mm, [0.0],
                                 n_samples=n_samples, seed=seed)[0])
    if not (e0 > 0 and math.isfinite(e0)):
        raise OpticsError(f"{lens.source}: no ray from the film centre gets through the lens; "
                          f"there is no exposure to normalise")
    return 1.0 / e0
