"""What per-pixel meshes draw each pixel's pupil point from.

The plan's exit-pupil table, grown to hold every wavelength's pass region with
``--dispersion`` (:func:`povlens.rendering.spectral.band_sampler`), and with an iris
wrapped in :class:`povlens.pupil.iris_sampler.IrisPixelSampler`, which uses the iris's
domain (``plan.pixel_iris``) where it is tighter than the table's region.
"""

from __future__ import annotations

from povlens.pupil.iris_sampler import IrisPixelSampler
from povlens.rendering.spectral import band_sampler

__all__ = ["pixel_sampler"]


def pixel_sampler(plan, lens, table):
    """The sampler of per-pixel meshes of ``plan`` (``lens``: the plan's lens, its
    aperture shape included; ``table``: the plan's exit-pupil table)."""
    sampler = band_sampler(plan, table)
    iris = plan.pixel_iris
    if iris is None or lens.aperture_shape is None:
        return sampler
    return IrisPixelSampler(sampler, lens.aperture_shape, iris["flip"],
                            iris["domain_radius_mm"], iris["disc_radius_mm"])
