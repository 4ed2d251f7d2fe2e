"""The per-pixel lens sampler for an iris: per film point, the tighter of two regions.

Per-pixel meshes draw each pixel's pupil point from the exit-pupil table
(:mod:`povlens.pupil.table`), which is built for the round stop: with an iris of N blades
only the polygon's share of it passes (0.83 for 6 straight blades on the axis).  The
iris domain D of the field sampler (:mod:`povlens.pupil.aperture_domain`; one region
about the axis holding every film point's pass region) is tighter on and near the axis,
the table's cat's eye far off it.  Both hold every passing ray, so for each film point
the sampler uses the one of smaller area; the choice depends on the film radius only,
so every sample of a pixel uses the same one and the estimate stays unbiased (pdf
1 / area in the table, 1 / (pi rho(theta)^2) in D).

Frames: the camera frame's sampling plane z = ``table.plane_z_mm`` (mm), axis at 0.
"""

from __future__ import annotations

import math

import numpy as np

from povlens.pupil.aperture_domain import iris_scale
from povlens.pupil.field import concentric_disc_mm
from povlens.pupil.sampler_interface import (LensSample, SamplerMeasurements,
                                             check_sample_arguments, finish_sample)

__all__ = ["IrisPixelSampler"]


class IrisPixelSampler(SamplerMeasurements):
    """Rays toward the table's region or the iris domain, whichever is smaller.

    Parameters
    ----------
    table : the exit-pupil table (round stop; or :func:`povlens.pupil.band_table.band_table`).
    shape : the :class:`~povlens.lens.aperture_shape.ApertureShape` (blades).
    flip : the stop image's orientation (:func:`~povlens.pupil.aperture_domain.iris_domain`).
    domain_radius_mm : R_D of the iris domain.
    disc_radius_mm : R_B, the disc that clips it (holds the table's regions).
    """

    def __init__(self, table, shape, flip: bool, domain_radius_mm: float,
                 disc_radius_mm: float):
        self.table, self.shape, self.flip = table, shape, bool(flip)
        self.lens, self.film_distance_mm = table.lens, table.film_distance_mm
        self.plane_z_mm = table.plane_z_mm
        self.domain_radius_mm = float(domain_radius_mm)
        self.disc_radius_mm = float(disc_radius_mm)
        theta = (np.arange(4096) + 0.5) * (2.0 * math.pi / 4096)
        rho = np.minimum(self.domain_radius_mm * iris_scale(shape, theta, self.flip),
                         self.disc_radius_mm)
        self.domain_area_mm2 = float(0.5 * np.mean(rho * rho) * 2.0 * math.pi)

    def uses_domain(self, film_radius_mm) -> np.ndarray:
        """True where the iris domain is the smaller region (film radii, mm)."""
        return self.domain_area_mm2 < self.table.area_mm2(film_radius_mm)

    def sample(self, film_xy, u) -> LensSample:
        """Rays for film points (n, 2) mm and points u (n, 2) in [0, 1) (the table's
        protocol: :meth:`povlens.pupil.table.PupilTable.sample`)."""
        f, uu = check_sample_arguments(film_xy, u)
        s = self.table.sample(f, uu)
        use = s.valid & self.uses_domain(np.hypot(f[:, 0], f[:, 1]))
        c = concentric_disc_mm(uu, 1.0)
        q = iris_scale(self.shape, np.arctan2(c[:, 1], c[:, 0]), self.flip)
        rho = np.minimum(self.domain_radius_mm * q, self.disc_radius_mm)
        with np.errstate(divide="ignore"):
            table_area = np.where(s.pdf_per_mm2 > 0, 1.0 / s.pdf_per_mm2, 0.0)
        px = np.where(use, c[:, 0] * rho, s.pupil_point[:, 0])
        py = np.where(use, c[:, 1] * rho, s.pupil_point[:, 1])
        area = np.where(use, math.pi * rho * rho, table_area)
        return finish_sample(f, px, py, self.plane_z_mm, area, s.valid)
