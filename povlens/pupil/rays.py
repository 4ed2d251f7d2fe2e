"""Exact lens rays per pixel and sample, placed in the POV-Ray scene.

Placement (camera frame of :mod:`povlens.lens.coordinates` -> POV-Ray world)
------------------------------------------------------------------
The scene's camera ``location`` is taken as the lens's **entrance-pupil centre**,
the perspective centre of the real lens, so a pinhole render from ``location``
frames the scene as the lens does.  The film centre therefore sits
``centre_z_mm`` (the pupil's camera-frame z) behind it along the view direction:

    world(p) = film_centre + (p_x right + p_y up + p_z forward) / mm_per_unit

with unit ``right``, ``up``, ``forward`` from the scene camera (POV-Ray: right =
normalize(sky x forward), up = forward x right).  Film x maps to world right, so
the image inversion of :mod:`povlens.lens.film` makes pixel columns run left to right
in the scene as POV-Ray's own cameras do.

Samples
-------
Sample k of pixel p uses the k-th point of a scrambled 4-D Sobol sequence
(film jitter, pupil u), shifted per pixel by a random Cranley-Patterson
rotation so that neighbouring pixels do not share sample positions (shared
positions show as ghosting).  The pupil sampler (:mod:`povlens.pupil.sampler_interface`) turns
(film point, u) into a ray toward the exit pupil with its radiometric weight.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from povlens.lens.film import Film
from povlens.lens.prescription import LensPrescription
from povlens.lens.tracer import stop_hits_from_film, trace_from_film
from povlens.pupil.monte_carlo import sobol_points

__all__ = ["ScenePlacement", "SampleRays", "sample_points", "sample_rays"]


@dataclasses.dataclass(frozen=True)
class ScenePlacement:
    """Where the camera frame sits in the POV-Ray world.

    film_centre : (3,) world position of the film centre (scene units).
    right, up, forward : (3,) unit world vectors of camera x, y, z.
    mm_per_unit : millimetres per scene unit.
    """

    film_centre: np.ndarray
    right: np.ndarray
    up: np.ndarray
    forward: np.ndarray
    mm_per_unit: float

    @classmethod
    def at_entrance_pupil(cls, location, right, up, forward, centre_z_mm: float,
                          mm_per_unit: float) -> "ScenePlacement":
        fwd = np.asarray(forward, dtype=np.float64)
        film = np.asarray(location, dtype=np.float64) - fwd * (centre_z_mm / mm_per_unit)
        return cls(film, np.asarray(right, float), np.asarray(up, float), fwd, float(mm_per_unit))

    @property
    def basis(self) -> np.ndarray:
        """(3, 3) rows = world images of camera x, y, z."""
        return np.stack([self.right, self.up, self.forward])

    def points_to_world(self, p_mm: np.ndarray) -> np.ndarray:
        """Camera-frame points (..., 3) mm -> world points (..., 3) scene units."""
        return self.film_centre + (np.asarray(p_mm) @ self.basis) / self.mm_per_unit

    def directions_to_world(self, d: np.ndarray) -> np.ndarray:
        """Camera-frame unit directions (..., 3) -> world unit directions (..., 3)."""
        return np.asarray(d) @ self.basis

    def to_dict(self) -> dict:
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v)
                for k, v in dataclasses.asdict(self).items()}


def sample_points(n_samples: int, height: int, width: int, seed: int = 0):
    """Per-pixel low-discrepancy sample points.

    Returns a function ``points(k) -> (H, W, 4)`` in [0, 1): components 0-1 are
    the sub-pixel jitter, 2-3 the pupil coordinates u of sample k.
    """
    sobol = sobol_points(max(n_samples, 1), 4, seed=seed)
    shift = np.random.default_rng(seed + 1).random((height, width, 4))

    def points(k: int) -> np.ndarray:
        return np.mod(sobol[k][None, None, :] + shift, 1.0)

    return points


@dataclasses.dataclass(frozen=True)
class SampleRays:
    """One lens sample for every pixel, in the world.

    origin, direction : (H, W, 3) where each ray leaves the front surface, scene
        units / unit vectors.
    valid : (H, W) bool; False where the pupil sample or the lens blocked the ray.
    weight : (H, W) radiometric weight (0 where not valid).
    """

    origin: np.ndarray
    direction: np.ndarray
    valid: np.ndarray
    weight: np.ndarray


def _mask_transmission(lens: LensPrescription, film_distance_mm: float, film_point,
                       direction, ok: np.ndarray) -> np.ndarray | float:
    """(n,) transmission of a mask stop where the passing rays cross it (exact hit points,
    :func:`povlens.lens.tracer.stop_hits_from_film`), 1 elsewhere; 1.0 without a mask."""
    shape = lens.aperture_shape
    if shape is None or shape.mask is None or not ok.any():
        return 1.0
    t = np.ones(len(ok))
    idx = np.nonzero(ok)[0]
    hits = stop_hits_from_film(lens, film_distance_mm, film_point[idx], direction[idx])
    t[idx] = shape.transmission(hits[:, 0], hits[:, 1],
                                float(lens.aperture_radius_mm[lens.aperture_shape_row]))
    return t


def sample_rays(lens: LensPrescription, film_distance_mm: float, film: Film, sampler,
                placement: ScenePlacement, points: np.ndarray,
                rows: tuple[int, int] | None = None) -> SampleRays:
    """Trace one sample per pixel through the real lens and place it in the world.

    sampler : an object with ``sample(film_xy (n, 2), u (n, 2))`` returning
        ``film_point``, ``direction``, ``weight`` and ``valid`` arrays (see
        :mod:`povlens.pupil.sampler_interface`).
    points : (H, W, 4) from :func:`sample_points`.
    rows : film rows [start, end) to sample (default all); the other rows get no
        ray (``valid`` False, weight 0) and cost nothing.
    """
    h, w = film.height_px, film.width_px
    r0, r1 = (0, h) if rows is None else (int(rows[0]), int(rows[1]))
    if not 0 <= r0 <= r1 <= h:
        raise ValueError(f"rows [{r0}, {r1}) outside the film's {h} rows")
    origin = np.zeros((h * w, 3))
    direction = np.tile([0.0, 0.0, 1.0], (h * w, 1))
    valid = np.zeros(h * w, dtype=bool)
    weight = np.zeros(h * w)
    if r1 > r0:
        span = slice(r0 * w, r1 * w)
        film_xy = film.film_points_mm(points[..., :2])[r0:r1].reshape(-1, 2)
        s = sampler.sample(film_xy, points[r0:r1, :, 2:].reshape(-1, 2))
        ok = np.asarray(s.valid, bool).copy()
        idx = np.nonzero(ok)[0]
        if idx.size:
            t = trace_from_film(lens, film_distance_mm, s.film_point[idx], s.direction[idx])
            origin[r0 * w + idx] = t.origin_mm
            direction[r0 * w + idx] = t.direction
            ok[idx] = t.passed
        valid[span] = ok
        weight[span] = np.where(ok, s.weight, 0.0) * _mask_transmission(
            lens, film_distance_mm, s.film_point, s.direction, ok)
    return SampleRays(placement.points_to_world(origin).reshape(h, w, 3),
                      placement.directions_to_world(direction).reshape(h, w, 3),
                      valid.reshape(h, w), weight.reshape(h, w))
