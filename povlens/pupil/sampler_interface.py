"""The lens-sampler interface shared by the exit-pupil table and its baselines.

A lens sampler proposes, for film points and points u in [0, 1)^2, rays toward a
sampling plane z = z_p (camera frame of :mod:`povlens.lens.coordinates`, mm) with
their density and radiometric weight (:class:`LensSample`); whether a ray gets
through is decided by tracing it.  :func:`finish_sample` turns plane points into
a :class:`LensSample`, and :class:`SamplerMeasurements` gives every sampler its
pass fraction and irradiance estimates.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from povlens.lens.prescription import LensPrescription
from povlens.pupil.monte_carlo import (PassFraction, irradiance_factor, irradiance_factor_at,
                                      pass_fraction, pass_fraction_at)

__all__ = ["LensSample", "finish_sample", "check_sample_arguments", "polar_film_coordinates",
           "SamplerMeasurements"]


@dataclasses.dataclass(frozen=True)
class LensSample:
    """Rays proposed by a lens sampler for n film points (camera frame, mm).

    film_point : (n, 3) ray origins on the film (z = 0).
    pupil_point : (n, 3) where the ray crosses the sampling plane (may lie inside
        the lens: it only fixes the direction; trace from ``film_point``).
    direction : (n, 3) unit vectors from film_point toward pupil_point.
    pdf_per_mm2 : (n,) density of pupil_point on the sampling plane (0 if not valid).
    weight : (n,) cos^4(theta) / z_p^2 / pdf, the radiometric weight of a ray that
        gets through (multiply by the trace's ``passed``); 0 where not valid.
    valid : (n,) False where the film point is vignetted (no ray gets through) or
        outside the film the sampler was built for.
    """

    film_point: np.ndarray
    pupil_point: np.ndarray
    direction: np.ndarray
    pdf_per_mm2: np.ndarray
    weight: np.ndarray
    valid: np.ndarray

    def __len__(self) -> int:
        return int(self.valid.shape[0])


def finish_sample(film_xy: np.ndarray, px: np.ndarray, py: np.ndarray, plane_z_mm: float,
                  area_mm2: np.ndarray, valid: np.ndarray) -> LensSample:
    """Directions, pdf and weights of rays from film points to points of the plane.

    Parameters
    ----------
    film_xy : (n, 2) film points, mm.
    px, py : (n,) where the rays cross the plane z = ``plane_z_mm``, mm.
    plane_z_mm : z of the sampling plane, mm.
    area_mm2 : (n,) area of the region the plane points are uniform in (pdf = 1 / area).
    valid : (n,) bool, False for film points without a region.

    Returns
    -------
    LensSample
        Invalid entries (also non-finite inputs or zero area) get a +z ray, pdf 0
        and weight 0; film points that are not finite become the film centre, so
        no NaN comes out.
    """
    n = film_xy.shape[0]
    finite = np.all(np.isfinite(film_xy), axis=1)
    valid = valid & finite & (area_mm2 > 0) & np.isfinite(px) & np.isfinite(py)
    px = np.where(valid, px, np.where(finite, film_xy[:, 0], 0.0))
    py = np.where(valid, py, np.where(finite, film_xy[:, 1], 0.0))
    film = np.zeros((n, 3))
    film[:, :2] = np.where(finite[:, None], film_xy, 0.0)
    pupil = np.empty((n, 3))
    pupil[:, 0], pupil[:, 1], pupil[:, 2] = px, py, plane_z_mm
    d = pupil - film
    norm = np.sqrt(np.einsum("ij,ij->i", d, d))
    d /= norm[:, None]
    cos = d[:, 2]
    area = np.where(valid, area_mm2, 0.0)
    weight = np.where(valid, cos ** 4 / (plane_z_mm * plane_z_mm) * area, 0.0)
    pdf = np.where(valid, 1.0 / np.where(valid, area, 1.0), 0.0)
    return LensSample(film, pupil, d, pdf, weight, valid)


def check_sample_arguments(film_xy, u) -> tuple[np.ndarray, np.ndarray]:
    """The arguments of a sampler's ``sample`` as float64 arrays.

    Parameters
    ----------
    film_xy : film points, mm, reshaped to (n, 2).
    u : sample points, reshaped to (n, 2).

    Returns
    -------
    film_xy : (n, 2) float64.
    u : (n, 2) float64, clipped to [0, 1) so that every sampler maps it inside.

    Raises
    ------
    ValueError
        If the two do not hold the same number of points.
    """
    f = np.asarray(film_xy, dtype=np.float64).reshape(-1, 2)
    uu = np.asarray(u, dtype=np.float64).reshape(-1, 2)
    if f.shape != uu.shape:
        raise ValueError(f"film_xy {f.shape} and u {uu.shape} must both be (n, 2)")
    return f, np.clip(uu, 0.0, np.nextafter(1.0, 0.0))


def polar_film_coordinates(film_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Film points in polar form, for rotating a region computed on +x to their azimuth.

    Parameters
    ----------
    film_xy : (n, 2) film points, mm.

    Returns
    -------
    r : (n,) radius, mm (NaN or inf kept as they are).
    cos_phi, sin_phi : (n,) the azimuth; (1, 0) at the centre and where r is not finite.
    """
    r = np.hypot(film_xy[:, 0], film_xy[:, 1])
    ok = (r > 0) & np.isfinite(r)
    safe = np.where(ok, r, 1.0)
    with np.errstate(invalid="ignore"):
        cos_phi = np.where(ok, film_xy[:, 0] / safe, 1.0)
        sin_phi = np.where(ok, film_xy[:, 1] / safe, 0.0)
    return r, cos_phi, sin_phi


class SamplerMeasurements:
    """Pass fraction and irradiance estimates shared by every lens sampler.

    A subclass provides ``lens``, ``film_distance_mm`` and ``sample(film_xy, u)``.
    """

    lens: LensPrescription
    film_distance_mm: float

    def pass_fraction(self, film_radius_mm, *, n_samples: int = 1024,
                      seed: int = 0) -> PassFraction:
        """:class:`~povlens.pupil.monte_carlo.PassFraction` of this sampler at each film
        radius."""
        return pass_fraction(self, self.lens, self.film_distance_mm, film_radius_mm,
                             n_samples=n_samples, seed=seed)

    def irradiance_factor(self, film_radius_mm, *, n_samples: int = 4096,
                          seed: int = 0) -> np.ndarray:
        """Estimated E/L at each film radius
        (:func:`povlens.pupil.monte_carlo.irradiance_factor`).

        Remembered per sampler for the radii, sample count and seed (a sampler does
        not change once built): an auto conversion asks for the same radii twice,
        for the plan's model error and again at the depth probe's depths (the
        relative illumination does not depend on depth)."""
        radii = np.atleast_1d(np.asarray(film_radius_mm, dtype=np.float64))
        key = (radii.tobytes(), int(n_samples), int(seed))
        cache = self.__dict__.setdefault("_irradiance_factor_cache", {})
        if key not in cache:
            cache[key] = irradiance_factor(self, self.lens, self.film_distance_mm, radii,
                                           n_samples=n_samples, seed=seed)
        return cache[key].copy()

    def irradiance_factor_at(self, film_xy, *, n_samples: int = 4096,
                             seed: int = 0) -> np.ndarray:
        """Estimated E/L at film points (m, 2) mm
        (:func:`povlens.pupil.monte_carlo.irradiance_factor_at`)."""
        return irradiance_factor_at(self, self.lens, self.film_distance_mm, film_xy,
                                    n_samples=n_samples, seed=seed)

    def pass_fraction_at(self, film_xy, *, n_samples: int = 1024,
                         seed: int = 0) -> PassFraction:
        """:class:`~povlens.pupil.monte_carlo.PassFraction` of this sampler at film
        points (m, 2) mm."""
        return pass_fraction_at(self, self.lens, self.film_distance_mm, film_xy,
                                n_samples=n_samples, seed=seed)
