"""The equivalent focal-plane (thin-lens) model of a focused real lens.

The model is what POV-Ray's perspective camera with ``focal_blur`` can express:
a centre of projection, a linear map from film position to the tangent of the
field angle (no distortion), a circular entrance pupil, and a plane in focus.
It is fitted to the real lens as follows (camera frame of
:mod:`povlens.lens.coordinates`, mm):

* **centre of projection** — the entrance-pupil centre, ``z_ep = film distance
  + total track - entrance-pupil position``: object-space chief rays aim at it,
  so it is the lens's perspective centre (the thin-lens model of Pharr, Jakob &
  Humphreys, *Physically Based Rendering*, 3rd ed., §6.2.3).
* **field of view** — real chief rays (through the centre of the stop) traced
  from film points along the diagonal give tan(theta) as a function of film
  height h.  The model uses tan(theta) = h / v_eff, with v_eff the least-squares
  fit over the field (film heights from 0 to the half diagonal).
* **aperture** — the entrance-pupil diameter (paraxial image of the stop).
* **plane in focus** — the object distance the lens is focused at.

:mod:`povlens.thinlens.model_error` measures what the model gets wrong.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from povlens.lens.chief_ray import chief_rays
from povlens.lens.film import Film
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import LensPrescription

__all__ = ["EquivalentThinLens", "fit_thin_lens"]


@dataclasses.dataclass(frozen=True)
class EquivalentThinLens:
    """Thin-lens camera equivalent to a focused lens.  Camera frame, mm.

    centre_z_mm : z of the centre of projection (entrance-pupil centre).
    image_distance_mm : v_eff, film height per unit tan(field angle).
    pupil_diameter_mm : entrance-pupil diameter.
    focus_z_mm : z of the plane in focus (inf for infinity).
    """

    centre_z_mm: float
    image_distance_mm: float
    pupil_diameter_mm: float
    focus_z_mm: float
    fit_rms_mm: float = 0.0

    @property
    def focus_distance_mm(self) -> float:
        """Distance from the centre of projection to the plane in focus."""
        return self.focus_z_mm - self.centre_z_mm

    def image_of_direction(self, direction: np.ndarray) -> np.ndarray:
        """Film points (n, 2) mm where the model images object-space directions (n, 3)."""
        d = np.asarray(direction, dtype=np.float64)
        return -self.image_distance_mm * d[:, :2] / d[:, 2:3]

    def blur_diameter_mm(self, object_z_mm: np.ndarray) -> np.ndarray:
        """Film-side blur-disc diameter (mm) of objects at camera-frame depths (mm),
        by the thin-lens equation (pbrt, 3rd ed., §6.2.3)."""
        d = np.asarray(object_z_mm, dtype=np.float64) - self.centre_z_mm
        s = self.focus_distance_mm
        if math.isinf(s):
            return self.pupil_diameter_mm * self.image_distance_mm / d
        return self.pupil_diameter_mm * np.abs(d - s) / d * self.image_distance_mm / s

    def to_dict(self) -> dict:
        return {"centre_z_mm": self.centre_z_mm, "image_distance_mm": self.image_distance_mm,
                "pupil_diameter_mm": self.pupil_diameter_mm,
                "focus_z_mm": None if math.isinf(self.focus_z_mm) else self.focus_z_mm,
                "focus_distance_mm": (None if math.isinf(self.focus_distance_mm)
                                      else self.focus_distance_mm),
                "fov_fit_rms_mm": self.fit_rms_mm}


def fit_thin_lens(lens: LensPrescription, film_distance_mm: float, focus_z_mm: float,
                  film: Film, n_field: int = 33) -> EquivalentThinLens:
    """Fit the equivalent thin lens of ``lens`` focused with the film at ``film_distance_mm``
    on the plane ``focus_z_mm`` (camera frame z, mm; inf allowed)."""
    p = paraxial_data(lens)
    centre = film_distance_mm + p.total_track - p.entrance_pupil_position
    h = np.linspace(0.0, film.max_field_radius_mm, n_field)[1:]   # a shifted frame's too
    rays, found = chief_rays(lens, film_distance_mm, h)
    good = found & np.all(np.isfinite(rays.direction), axis=1) & (rays.direction[:, 2] > 0)
    if good.sum() >= 2:
        t = -rays.direction[good, 0] / rays.direction[good, 2]  # tan(theta) toward -x
        hh = h[good]
        v = float(np.sum(hh * hh) / np.sum(hh * t))          # least squares h = v t
        rms = float(np.sqrt(np.mean((hh - v * t) ** 2)))
    else:  # no usable chief ray: fall back to the paraxial image distance
        v = film_distance_mm - p.principal_rear_from_rear_vertex
        rms = math.nan
    return EquivalentThinLens(float(centre), v, p.entrance_pupil_diameter, float(focus_z_mm),
                              rms if math.isfinite(rms) else -1.0)

