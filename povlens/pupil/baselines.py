"""Baselines for the exit-pupil table: pbrt's 64 boxes and naive rear-element sampling.

Both offer the sampler interface of :class:`povlens.pupil.table.PupilTable`
(:mod:`povlens.pupil.sampler_interface`: ``sample(film_xy, u) -> LensSample``,
``pass_fraction``, ``irradiance_factor``) so benchmarks and renders can swap
them.  Both sample on pbrt's plane, the rear-vertex plane ``z = film_distance``
(camera frame of :mod:`povlens.lens.coordinates`), and weight a ray by
``cos^4(theta) / z^2 / pdf`` (the camera measurement equation, *Physically Based
Rendering*, 3rd ed., §6.4.7), so both are unbiased as long as their regions hold
every ray that passes.

:class:`PbrtBoxes` -- pbrt-v4's ``RealisticCamera::BoundExitPupil`` (``cameras.cpp``;
    the exit-pupil bounds of *Physically Based Rendering*, 3rd ed., §6.4.5):
    64 radial intervals of the film half-diagonal; for interval k, film points
    spread evenly over [k, k+1] hd/64 on +x and rear points on the square
    [-1.5 r, 1.5 r]^2 (r the rear element's clear radius) from the radical
    inverses in bases 2 and 3; the box of the points whose rays pass, grown by
    2 |diag| / sqrt(n).  Like pbrt, points already inside the current box are not
    traced (the box is the same).  pbrt uses n = 2^20 rays per interval; the count
    is a parameter (``rays_per_interval``) and the rays actually traced are
    recorded.  An interval where no ray passes gets an empty box (pbrt-v4: the
    sample is dropped).  ``weighting="simple"`` gives pbrt-v3's book weighting
    w = cos^4(theta), which ignores the box areas: the cause of the 64 rings of
    pbrt-v3 #162 (kept to show the ring detector works).

:class:`NaiveRearElement` -- the method of the 2012 paper the README names: rays
    toward points spread uniformly over the rear element's disc, whatever the film point.  The disc
    is the rear clear aperture, widened just enough to hold every ray that meets
    the curved rear surface inside its aperture from any film point out to the
    half-diagonal (for a curved rear surface a ray crosses the vertex plane a
    little outside the aperture), so that the estimate is unbiased too.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from povlens.errors import UsageError
from povlens.lens.toric import row_sag_range_mm
from povlens.lens.prescription import LensPrescription
from povlens.pupil.sampler_interface import (LensSample, SamplerMeasurements,
                                             check_sample_arguments, finish_sample,
                                             polar_film_coordinates)
from povlens.lens.tracer import trace_from_film

__all__ = ["PbrtBoxes", "NaiveRearElement", "radical_inverse", "PBRT_INTERVALS",
           "PBRT_RAYS_PER_INTERVAL", "PassComparison"]

PBRT_INTERVALS = 64
PBRT_RAYS_PER_INTERVAL = 1 << 20


@dataclasses.dataclass(frozen=True)
class PassComparison:
    """How ``povlens pupil`` compares the pass fractions of povlens's table, pbrt's
    boxes and the naive rear element: film-radius ``bands``, ``radii_per_band`` radii
    measured in each, ``samples_per_radius`` scrambled-Sobol samples (seed ``seed``)
    per radius, and ``pbrt_rays_per_interval`` rays per interval for the boxes (pbrt
    uses :data:`PBRT_RAYS_PER_INTERVAL`; fewer keep the comparison quick, and pbrt's
    build time is then estimated)."""

    bands: int = 8
    radii_per_band: int = 4
    samples_per_radius: int = 1024
    pbrt_rays_per_interval: int = 1 << 14
    seed: int = 0


def radical_inverse(i: np.ndarray, base: int) -> np.ndarray:
    """Van der Corput radical inverse of integers ``i`` in ``base`` (vectorized)."""
    i = np.asarray(i, dtype=np.int64).copy()
    out = np.zeros(i.shape)
    f = 1.0 / base
    while np.any(i > 0):
        out += (i % base) * f
        i //= base
        f /= base
    return out


def _check_common(film_distance_mm, film_half_diagonal_mm):
    for name, v in (("film_distance_mm", film_distance_mm),
                    ("film_half_diagonal_mm", film_half_diagonal_mm)):
        if not (math.isfinite(v) and v > 0):
            raise UsageError(f"{name} = {v!r}: must be a positive number of mm")


class PbrtBoxes(SamplerMeasurements):
    """pbrt-style exit-pupil bounds: one axis-aligned box per radial film interval.

    boxes : (n_intervals, 4) x0, x1, y0, y1 on the rear-vertex plane in the rotated
        frame (film point on +x); rows of NaN-free zeros with ``empty`` True where
        no ray passed.
    """

    def __init__(self, lens: LensPrescription, film_distance_mm: float,
                 film_half_diagonal_mm: float, boxes: np.ndarray, empty: np.ndarray,
                 rays_per_interval: int, rays_traced: int, build_time_s: float,
                 weighting: str = "pdf"):
        if weighting not in ("pdf", "simple"):
            raise ValueError("weighting is 'pdf' or 'simple'")
        self.lens = lens
        self.film_distance_mm = float(film_distance_mm)
        self.film_half_diagonal_mm = float(film_half_diagonal_mm)
        self.plane_z_mm = float(film_distance_mm)
        self.boxes = np.asarray(boxes, dtype=np.float64)
        self.empty = np.asarray(empty, dtype=bool)
        self.rays_per_interval = int(rays_per_interval)
        self.rays_traced = int(rays_traced)
        self.build_time_s = float(build_time_s)
        self.weighting = weighting
        self.areas_mm2 = np.where(self.empty, 0.0, (self.boxes[:, 1] - self.boxes[:, 0])
                                  * (self.boxes[:, 3] - self.boxes[:, 2]))

    @property
    def n_intervals(self) -> int:
        return int(self.boxes.shape[0])

    def with_weighting(self, weighting: str) -> "PbrtBoxes":
        return PbrtBoxes(self.lens, self.film_distance_mm, self.film_half_diagonal_mm,
                         self.boxes, self.empty, self.rays_per_interval, self.rays_traced,
                         self.build_time_s, weighting)

    @classmethod
    def build(cls, lens: LensPrescription, film_distance_mm: float,
              film_half_diagonal_mm: float, *, n_intervals: int = PBRT_INTERVALS,
              rays_per_interval: int = PBRT_RAYS_PER_INTERVAL, chunk: int = 1 << 16,
              progress=None) -> "PbrtBoxes":
        """pbrt-v4's BoundExitPupil for every interval (``progress(1)`` after each)."""
        _check_common(film_distance_mm, film_half_diagonal_mm)
        if rays_per_interval < 1 or n_intervals < 1:
            raise UsageError("rays_per_interval and n_intervals must be at least 1")
        t0 = time.perf_counter()
        F = float(film_distance_mm)
        hd = float(film_half_diagonal_mm)
        r = float(lens.aperture_radius_mm[-1])
        n = int(rays_per_interval)
        grow = 2.0 * (3.0 * math.sqrt(2.0) * r) / math.sqrt(n)
        boxes = np.zeros((n_intervals, 4))
        empty = np.zeros(n_intervals, bool)
        traced = 0
        for k in range(n_intervals):
            x0, x1 = k * hd / n_intervals, (k + 1) * hd / n_intervals
            lo = np.array([np.inf, np.inf])
            hi = np.array([-np.inf, -np.inf])
            start, step = 0, 64
            while start < n:
                # Chunks grow geometrically: pbrt skips points already inside the box
                # it has so far, and small early chunks let the box grow first.
                i = np.arange(start, min(start + step, n))
                start, step = start + step, min(2 * step, chunk)
                fx = x0 + (i + 0.5) / n * (x1 - x0)
                px = -1.5 * r + 3.0 * r * radical_inverse(i, 2)
                py = -1.5 * r + 3.0 * r * radical_inverse(i, 3)
                outside = ~((px >= lo[0]) & (px <= hi[0]) & (py >= lo[1]) & (py <= hi[1]))
                idx = np.nonzero(outside)[0]
                if idx.size == 0:
                    continue
                m = idx.size
                o = np.zeros((m, 3))
                o[:, 0] = fx[idx]
                d = np.empty((m, 3))
                d[:, 0] = px[idx] - fx[idx]
                d[:, 1] = py[idx]
                d[:, 2] = F
                ok = trace_from_film(lens, F, o, d).passed
                traced += m
                if ok.any():
                    lo = np.minimum(lo, [px[idx][ok].min(), py[idx][ok].min()])
                    hi = np.maximum(hi, [px[idx][ok].max(), py[idx][ok].max()])
            if np.all(np.isfinite(lo)):
                boxes[k] = [lo[0] - grow, hi[0] + grow, lo[1] - grow, hi[1] + grow]
            else:
                empty[k] = True
            if progress:
                progress(1)
        out = cls(lens, F, hd, boxes, empty, n, traced, time.perf_counter() - t0)
        if n < PBRT_RAYS_PER_INTERVAL:
            # Calibrate the cost per traced ray in large calls (pbrt's count makes the
            # per-call overhead negligible) on 2^16 rays of the last interval.
            i = np.arange(1 << 16)
            m = i.size
            o = np.zeros((m, 3))
            o[:, 0] = hd * (1 - 0.5 / n_intervals)
            d = np.empty((m, 3))
            d[:, 0] = -1.5 * r + 3.0 * r * radical_inverse(i, 2) - o[:, 0]
            d[:, 1] = -1.5 * r + 3.0 * r * radical_inverse(i, 3)
            d[:, 2] = F
            t1 = time.perf_counter()
            trace_from_film(lens, F, o, d)
            out.seconds_per_traced_ray = (time.perf_counter() - t1) / m
        else:
            out.seconds_per_traced_ray = out.build_time_s / max(traced, 1)
        return out

    def build_time_at_pbrt_count_s(self) -> float:
        """Build time of pbrt's 64 x 2^20 procedure on this machine: measured when built
        with 2^20 rays per interval, else estimated as (rays pbrt would trace, from the
        traced fraction seen here) x (this tracer's cost per ray in a large call,
        timed on 2^16 rays at the end of :meth:`build`; not part of build_time_s)."""
        if self.rays_per_interval == PBRT_RAYS_PER_INTERVAL:
            return self.build_time_s
        frac = self.rays_traced / (self.rays_per_interval * self.n_intervals)
        return (frac * PBRT_RAYS_PER_INTERVAL * self.n_intervals
                * getattr(self, "seconds_per_traced_ray",
                          self.build_time_s / max(self.rays_traced, 1)))

    def interval(self, film_radius_mm) -> np.ndarray:
        """pbrt's interval index: min(floor(r / hd * n), n - 1)."""
        r = np.asarray(film_radius_mm, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            k = np.floor(r / self.film_half_diagonal_mm * self.n_intervals)
        k = np.where(np.isfinite(k), k, self.n_intervals - 1)
        return np.clip(k, 0, self.n_intervals - 1).astype(np.int64)

    def area_mm2(self, film_radius_mm) -> np.ndarray:
        return self.areas_mm2[self.interval(np.atleast_1d(film_radius_mm))]

    def box_on_plane(self, film_radius_mm: float, plane_z_mm: float):
        """The interval's box seen from the film point (r, 0) and projected onto the
        plane z = plane_z_mm (x0, x1, y0, y1), or None if the box is empty."""
        k = int(self.interval(float(film_radius_mm)))
        if self.empty[k]:
            return None
        s = plane_z_mm / self.plane_z_mm
        r = float(film_radius_mm)
        x0, x1, y0, y1 = self.boxes[k]
        return (r + s * (x0 - r), r + s * (x1 - r), s * y0, s * y1)

    def sample(self, film_xy, u) -> LensSample:
        """pbrt's SampleExitPupil: a point of the interval's box, rotated to the film
        point's azimuth; pdf 1 / box area."""
        f, uu = check_sample_arguments(film_xy, u)
        r, cos_phi, sin_phi = polar_film_coordinates(f)
        k = self.interval(r)
        b = self.boxes[k]
        lx = b[:, 0] + uu[:, 0] * (b[:, 1] - b[:, 0])
        ly = b[:, 2] + uu[:, 1] * (b[:, 3] - b[:, 2])
        px = cos_phi * lx - sin_phi * ly
        py = sin_phi * lx + cos_phi * ly
        area = self.areas_mm2[k]
        s = finish_sample(f, px, py, self.plane_z_mm, area, ~self.empty[k] & np.isfinite(r))
        if self.weighting == "simple":
            # pbrt-v3's book weighting: cos^4 only, the box area ignored (rings).
            cos = s.direction[:, 2]
            w = np.where(s.valid, cos ** 4, 0.0)
            s = LensSample(s.film_point, s.pupil_point, s.direction, s.pdf_per_mm2, w, s.valid)
        return s


class NaiveRearElement(SamplerMeasurements):
    """Uniform points on the rear element's disc (the 2012 paper's method)."""

    def __init__(self, lens: LensPrescription, film_distance_mm: float,
                 film_half_diagonal_mm: float, radius_mm: float, build_time_s: float = 0.0):
        self.lens = lens
        self.film_distance_mm = float(film_distance_mm)
        self.film_half_diagonal_mm = float(film_half_diagonal_mm)
        self.plane_z_mm = float(film_distance_mm)
        self.radius_mm = float(radius_mm)
        self.build_time_s = float(build_time_s)
        self.rays_traced = 0

    @classmethod
    def build(cls, lens: LensPrescription, film_distance_mm: float,
              film_half_diagonal_mm: float) -> "NaiveRearElement":
        _check_common(film_distance_mm, film_half_diagonal_mm)
        t0 = time.perf_counter()
        F = float(film_distance_mm)
        R = float(lens.aperture_radius_mm[-1])
        s_lo, s_hi = row_sag_range_mm(lens, lens.n_surfaces - 1, R)  # sphere, asphere, toric
        radius = R
        for qz in (F - s_lo, F - s_hi):  # the z span of the rear surface over its aperture
            if qz > 0:
                lam = F / qz
                radius = max(radius, film_half_diagonal_mm * abs(1.0 - lam) + lam * R)
        return cls(lens, F, film_half_diagonal_mm, radius, time.perf_counter() - t0)

    @property
    def area_mm2_value(self) -> float:
        return math.pi * self.radius_mm ** 2

    def area_mm2(self, film_radius_mm) -> np.ndarray:
        return np.full(np.atleast_1d(film_radius_mm).shape, self.area_mm2_value)

    def sample(self, film_xy, u) -> LensSample:
        """A uniform point of the disc (polar map), the same for every film point."""
        f, uu = check_sample_arguments(film_xy, u)
        rad = self.radius_mm * np.sqrt(uu[:, 1])
        ang = 2.0 * math.pi * uu[:, 0]
        px, py = rad * np.cos(ang), rad * np.sin(ang)
        area = np.full(len(f), self.area_mm2_value)
        return finish_sample(f, px, py, self.plane_z_mm, area, np.all(np.isfinite(f), axis=1))
