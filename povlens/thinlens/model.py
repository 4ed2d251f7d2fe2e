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

**Anamorphic lenses** (toric rows, ``lens.is_anamorphic``) have two focal lengths: the
model keeps the y-z meridian's image distance, entrance pupil and centre of projection
as its own (``image_distance_mm``, ``pupil_diameter_mm``: what POV-Ray's ``focal_blur``
can be given, with one focal length and a round pupil) and adds the x-z meridian's
image distance ``image_distance_x_mm`` (fitted to real chief rays along the film's x
axis, as the y one is along its y axis) and entrance-pupil diameter
``pupil_diameter_x_mm``.  Its projection (:meth:`EquivalentThinLens.image_of_direction`)
uses both, which is what a pinhole camera with POV-Ray's ``right`` and ``up`` scaled
per meridian renders; its blur is the y meridian's.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from povlens.lens.chief_ray import chief_rays, chief_rays_2d
from povlens.lens.film import Film
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import LensPrescription

__all__ = ["EquivalentThinLens", "fit_thin_lens", "chief_ray_tangents_y"]


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
    #: Anamorphic lenses: the x-z meridian's image distance and entrance-pupil diameter
    #: (mm); None for a rotationally symmetric lens (the y values are both meridians').
    image_distance_x_mm: float | None = None
    pupil_diameter_x_mm: float | None = None

    @property
    def anamorphic(self) -> bool:
        """True when the model has an x-z meridian of its own."""
        return self.image_distance_x_mm is not None

    @property
    def image_distances_mm(self) -> tuple[float, float]:
        """(v_x, v_y): film length per unit tangent of the field angle along x and y."""
        v = self.image_distance_mm
        return (v if self.image_distance_x_mm is None else self.image_distance_x_mm), v

    def tan_of_film(self, film_xy) -> np.ndarray:
        """(n, 2) tangents (x/z, y/z) of the object-space directions the model images at
        film points (n, 2) mm (the inverse of :meth:`image_of_direction`)."""
        vx, vy = self.image_distances_mm
        f = np.asarray(film_xy, dtype=np.float64).reshape(-1, 2)
        return -f / np.array([vx, vy])

    @property
    def focus_distance_mm(self) -> float:
        """Distance from the centre of projection to the plane in focus."""
        return self.focus_z_mm - self.centre_z_mm

    def image_of_direction(self, direction: np.ndarray) -> np.ndarray:
        """Film points (n, 2) mm where the model images object-space directions (n, 3)."""
        d = np.asarray(direction, dtype=np.float64)
        return -np.array(self.image_distances_mm) * d[:, :2] / d[:, 2:3]

    def blur_diameter_mm(self, object_z_mm: np.ndarray) -> np.ndarray:
        """Film-side blur-disc diameter (mm) of objects at camera-frame depths (mm),
        by the thin-lens equation (pbrt, 3rd ed., §6.2.3)."""
        d = np.asarray(object_z_mm, dtype=np.float64) - self.centre_z_mm
        s = self.focus_distance_mm
        if math.isinf(s):
            return self.pupil_diameter_mm * self.image_distance_mm / d
        return self.pupil_diameter_mm * np.abs(d - s) / d * self.image_distance_mm / s

    def to_dict(self) -> dict:
        d = {"centre_z_mm": self.centre_z_mm, "image_distance_mm": self.image_distance_mm,
             "pupil_diameter_mm": self.pupil_diameter_mm,
             "focus_z_mm": None if math.isinf(self.focus_z_mm) else self.focus_z_mm,
             "focus_distance_mm": (None if math.isinf(self.focus_distance_mm)
                                   else self.focus_distance_mm),
             "fov_fit_rms_mm": self.fit_rms_mm}
        if self.anamorphic:                 # rotationally symmetric plans keep their keys
            d.update(image_distance_x_mm=self.image_distance_x_mm,
                     pupil_diameter_x_mm=self.pupil_diameter_x_mm)
        return d


def _fitted_image_distance(h: np.ndarray, t: np.ndarray) -> tuple[float, float]:
    """Least squares h = v t over film heights h (mm) and tangents t: (v, rms mm)."""
    v = float(np.sum(h * h) / np.sum(h * t))
    return v, float(np.sqrt(np.mean((h - v * t) ** 2)))


def chief_ray_tangents_y(lens: LensPrescription, film_distance_mm: float,
                         film_y_mm: np.ndarray):
    """tan(theta) (y/z, toward -y) of real chief rays from film points (0, h, 0)
    (:func:`chief_rays_2d`), and whether each was found and got through.  Returns
    (tangents (n,), found (n,))."""
    h = np.atleast_1d(np.asarray(film_y_mm, dtype=np.float64))
    full, found = chief_rays_2d(lens, film_distance_mm, np.column_stack([np.zeros(h.size), h]))
    d = full.direction
    with np.errstate(all="ignore"):
        tan = np.where(found & full.passed & (d[:, 2] > 0), -d[:, 1] / d[:, 2], np.nan)
    return tan, found & np.isfinite(tan)


def fit_thin_lens(lens: LensPrescription, film_distance_mm: float, focus_z_mm: float,
                  film: Film, n_field: int = 33) -> EquivalentThinLens:
    """Fit the equivalent thin lens of ``lens`` focused with the film at ``film_distance_mm``
    on the plane ``focus_z_mm`` (camera frame z, mm; inf allowed).  An anamorphic lens
    gets the x-z meridian's image distance and pupil too (module docstring)."""
    p = paraxial_data(lens)
    centre = film_distance_mm + p.total_track - p.entrance_pupil_position
    h = np.linspace(0.0, film.max_field_radius_mm, n_field)[1:]   # a shifted frame's too
    rays, found = chief_rays(lens, film_distance_mm, h)
    good = found & np.all(np.isfinite(rays.direction), axis=1) & (rays.direction[:, 2] > 0)
    if good.sum() >= 2:
        t = -rays.direction[good, 0] / rays.direction[good, 2]  # tan(theta) toward -x
        v, rms = _fitted_image_distance(h[good], t)
    else:  # no usable chief ray: fall back to the paraxial image distance
        v = film_distance_mm - p.principal_rear_from_rear_vertex
        rms = math.nan
    if not getattr(lens, "is_anamorphic", False):
        return EquivalentThinLens(float(centre), v, p.entrance_pupil_diameter, float(focus_z_mm),
                                  rms if math.isfinite(rms) else -1.0)
    return _anamorphic_model(lens, film_distance_mm, focus_z_mm, film, n_field, centre)


def _anamorphic_model(lens, film_distance_mm, focus_z_mm, film, n_field, centre):
    """The model of an anamorphic lens: each meridian's image distance fitted to real
    chief rays along its own film axis, out to the frame's edge there."""
    p, px = paraxial_data(lens), paraxial_data(lens, meridian="x")
    hx = np.linspace(0.0, 0.5 * film.width_mm + abs(film.shift_x_mm), n_field)[1:]
    hy = np.linspace(0.0, 0.5 * film.height_mm + abs(film.shift_y_mm), n_field)[1:]
    rays, found = chief_rays(lens, film_distance_mm, hx)
    good = found & np.all(np.isfinite(rays.direction), axis=1) & (rays.direction[:, 2] > 0)
    if good.sum() >= 2:
        vx, rms_x = _fitted_image_distance(hx[good], -rays.direction[good, 0]
                                           / rays.direction[good, 2])
    else:
        vx, rms_x = film_distance_mm - px.principal_rear_from_rear_vertex, math.nan
    ty, found_y = chief_ray_tangents_y(lens, film_distance_mm, hy)
    if found_y.sum() >= 2:
        vy, rms_y = _fitted_image_distance(hy[found_y], ty[found_y])
    else:
        vy, rms_y = film_distance_mm - p.principal_rear_from_rear_vertex, math.nan
    rms = max(rms_x, rms_y)
    return EquivalentThinLens(float(centre), vy, p.entrance_pupil_diameter, float(focus_z_mm),
                              rms if math.isfinite(rms) else -1.0, image_distance_x_mm=vx,
                              pupil_diameter_x_mm=px.entrance_pupil_diameter)
