"""What the thin-lens model of :mod:`povlens.thinlens.model` gets wrong, measured
with the exact tracer: distortion (pixels), blur-disc size and shape, and
vignetting, over object depths and film heights (camera frame of
:mod:`povlens.lens.coordinates`, mm).
"""

from __future__ import annotations

import dataclasses
import math
import weakref
from typing import Mapping

import numpy as np

from povlens.lens.chief_ray import chief_rays, chief_rays_2d
from povlens.lens.film import Film
from povlens.lens.focus import BUNDLE_START_MM, pupil_disc_points
from povlens.lens.prescription import LensPrescription
from povlens.lens.tracer import trace_from_scene
from povlens.thinlens.model import EquivalentThinLens

__all__ = ["ModelError", "measure_model_error", "measure_model_error_reference", "rays_near_lens",
           "CHIEF_RAY_MEMO"]


#: A (D, F) grid of a measure: one row per object depth, one column per film height.
Grid = tuple[tuple[float, ...], ...]


@dataclasses.dataclass(frozen=True)
class ModelError:
    """What the thin-lens model gets wrong, measured with the exact tracer
    (:func:`measure_model_error`) at D object depths x F film heights.

    The fields are in the order of plan.json's ``model_error`` (:meth:`to_dict`).

    Attributes
    ----------
    object_z_mm : (D,) the object depths measured at, camera-frame z, mm.
    film_height_mm : (F,) the film heights measured at, mm from the axis along the
        film diagonal, 0 to the frame's farthest corner.
    max_distortion_px : the largest of ``distortion_px``, film pixels.
    max_blur_size_error_px : the largest of ``blur_size_error_px``, film pixels.
    max_elongation : the largest of ``elongation`` (1: every spot round).
    min_relative_illumination : the smallest of ``relative_illumination`` (E / E(axis)).
    max_vignetting_error : ``1 - min_relative_illumination``, what the model's
        uniform illumination gets wrong at most (a fraction of the axis's).
    distortion_px : (D, F) how far the real spot's centroid lies from the model's image
        point, film pixels (0 where fewer than 3 rays pass).
    blur_real_px : (D, F) the real spot's equivalent-disc diameter, 2 sqrt(2) x its RMS
        radius, film pixels (0 where fewer than 3 rays pass).
    blur_model_px : (D, F) the model's blur-disc diameter, film pixels (one value per depth).
    elongation : (D, F) the real spot's sqrt(l_max / l_min) of its covariance (1: round,
        or fewer than 3 rays).
    relative_illumination : (D, F) E(h) / E(0): from the exit-pupil table when the
        measurement had one (one value per film height), else the fraction of the bundle
        that passes relative to the axis's.
    blur_size_error_px : (D, F) ``|blur_real_px - blur_model_px|``, film pixels.
    """

    object_z_mm: tuple[float, ...]
    film_height_mm: tuple[float, ...]
    max_distortion_px: float
    max_blur_size_error_px: float
    max_elongation: float
    min_relative_illumination: float
    max_vignetting_error: float
    distortion_px: Grid
    blur_real_px: Grid
    blur_model_px: Grid
    elongation: Grid
    relative_illumination: Grid
    blur_size_error_px: Grid

    def to_dict(self) -> dict:
        """plan.json's ``model_error``: every field in order, the grids as lists of rows."""
        return {f.name: _as_lists(getattr(self, f.name)) for f in dataclasses.fields(self)}

    @classmethod
    def from_dict(cls, d: Mapping) -> "ModelError":
        """The record of a :meth:`to_dict` (plan.json's ``model_error``; ``null``, which
        plan.json writes for NaN, reads as NaN).  KeyError if a field is missing."""
        return cls(**{f.name: _as_tuples(d[f.name]) for f in dataclasses.fields(cls)})


def _as_lists(v):
    """``v`` with its tuples (nested too) as lists: JSON's shape."""
    return [_as_lists(x) for x in v] if isinstance(v, (tuple, list)) else v


def _as_tuples(v):
    """``v`` read from JSON: lists (nested too) as tuples, ``None`` as NaN."""
    if isinstance(v, (tuple, list)):
        return tuple(_as_tuples(x) for x in v)
    return math.nan if v is None else v


def _grid(a: np.ndarray) -> Grid:
    """A (D, F) array as a :data:`Grid` of Python floats."""
    return tuple(tuple(row) for row in a.tolist())


#: Chief rays of the model-error field heights, per lens object (by identity:
#: prescriptions are frozen; a weak reference tells a new object at the same id)
#: and film distance: a --method auto conversion measures the model error twice with
#: the same lens, focus and field heights, and the chief-ray search is done once.
#: ``CHIEF_RAY_MEMO.clear()`` forgets them.
CHIEF_RAY_MEMO: dict = {}


def _chief_rays_remembered(lens, film_distance_mm: float, hs: np.ndarray):
    """:func:`chief_rays` of ``hs`` (F,), remembered; the arrays are read-only."""
    entry = CHIEF_RAY_MEMO.get(id(lens))
    if entry is None or entry[0]() is not lens:
        if len(CHIEF_RAY_MEMO) >= 8:
            CHIEF_RAY_MEMO.clear()
        entry = CHIEF_RAY_MEMO[id(lens)] = (weakref.ref(lens), {})
    per_lens = entry[1]
    key = (float(film_distance_mm), np.asarray(hs, dtype=np.float64).tobytes())
    if key not in per_lens:
        rays, found = chief_rays(lens, film_distance_mm, hs)
        for a in (rays.origin_mm, rays.direction, rays.passed, rays.blocked_at, found):
            a.flags.writeable = False
        per_lens[key] = rays, found
    return per_lens[key]


def _bundle_geometry(lens, film_distance_mm, model, film, object_z_mm, n_field, n_rings):
    """What both model-error measurements share: pixel pitch, depths (D,), film
    heights (F,), the diagonal direction, the pupil disc points (M, 2), the
    entrance-pupil plane z, and per film height where the real chief ray crosses
    that plane (F, 2) (the film point lies along -diagonal)."""
    pitch = film.pixel_pitch_mm
    depths = np.atleast_1d(np.asarray(object_z_mm, dtype=np.float64))
    hs = np.linspace(0.0, film.max_field_radius_mm, n_field)   # out to a shifted frame's corner
    diag_dir = np.array([film.width_mm, film.height_mm]) / math.hypot(film.width_mm, film.height_mm)
    # an anamorphic lens's bundle covers the larger of its two pupils
    disc = pupil_disc_points(n_rings) * (0.75 * max(model.pupil_diameter_mm,
                                                    model.pupil_diameter_x_mm or 0.0))
    ep_z = model.centre_z_mm
    if model.anamorphic:        # no rotational symmetry: the chief rays of the diagonal
        chief, found = chief_rays_2d(lens, film_distance_mm, -hs[:, None] * diag_dir[None, :])
    else:
        chief, found = _chief_rays_remembered(lens, film_distance_mm, hs)
    with np.errstate(all="ignore"):
        t = (ep_z - chief.origin_mm[:, 2]) / chief.direction[:, 2]
        c = chief.origin_mm[:, :2] + t[:, None] * chief.direction[:, :2]
    if model.anamorphic:
        return pitch, depths, hs, diag_dir, disc, ep_z, np.where(
            (found[:, None] & np.isfinite(c)), c, 0.0)
    x_c = np.where(found & np.isfinite(c[:, 0]), c[:, 0], 0.0)
    centres = -x_c[:, None] * diag_dir[None, :]
    return pitch, depths, hs, diag_dir, disc, ep_z, centres


def measure_model_error(lens: LensPrescription, film_distance_mm: float,
                        model: EquivalentThinLens, film: Film, object_z_mm,
                        n_field: int = 9, n_rings: int = 12, pupil_table=None) -> ModelError:
    """What the thin-lens model gets wrong, measured with the exact tracer.

    For object points at depths ``object_z_mm`` (camera-frame z) placed where
    the model images them at film heights 0..half diagonal (along the diagonal
    direction), traces a bundle to the film and compares with the model.  The
    bundle fills a disc of 1.5 x the entrance-pupil diameter on the pupil plane,
    centred where the real chief ray of that film height crosses it (the real
    pupil moves off axis with the field); rays the lens blocks are dropped.

    * distortion: centroid of the real spot vs the model's image point (pixels);
    * blur size: real equivalent-disc diameter (2 sqrt(2) x RMS radius) vs the
      model's blur-disc diameter (pixels);
    * blur shape: elongation sqrt(l_max / l_min) of the spot's covariance;
    * vignetting: relative illumination E(h) / E(0) from ``pupil_table``
      (:class:`povlens.pupil.table.PupilTable`, exact) when given, else the passing
      fraction of the bundle relative to the axis.

    All (depth, field) bundles are traced in one call (D depths x F field heights
    x M pupil points); :func:`measure_model_error_reference` traces them one at a
    time and gives the same numbers.

    Parameters
    ----------
    lens, film_distance_mm : the focused lens (rear vertex to film, mm).
    model : its thin-lens model (:func:`povlens.thinlens.model.fit_thin_lens`).
    film : the film (size in mm, pixels).
    object_z_mm : (D,) object depths, camera-frame z, mm.
    n_field : F, film heights from 0 to the half-diagonal.
    n_rings : rings of the pupil disc's sample points.
    pupil_table : optional exit-pupil table for the relative illumination.

    Returns
    -------
    ModelError
        The (D, F) grids of each measure, their extremes, and the depths and film
        heights they were measured at.
    """
    pitch, depths, hs, diag_dir, disc, ep_z, centres = _bundle_geometry(
        lens, film_distance_mm, model, film, object_z_mm, n_field, n_rings)
    target_film = -hs[:, None] * diag_dir[None, :]            # (F, 2) model image points
    ok, xy = _trace_bundles(lens, film_distance_mm, model, depths, target_film, disc, ep_z,
                            centres)
    cnt, c, ev = _spot_moments(ok, xy)
    spot = cnt >= 3
    model_blur = model.blur_diameter_mm(depths) / pitch       # (D,)
    nd, nf = len(depths), n_field
    out = {
        "distortion_px": np.where(spot, np.hypot(*np.moveaxis(c - target_film[None], -1, 0))
                                  / pitch, 0.0),
        "blur_real_px": np.where(spot, 2 * math.sqrt(2) * np.sqrt(ev.sum(axis=-1)) / pitch, 0.0),
        "blur_model_px": np.broadcast_to(model_blur[:, None], (nd, nf)).astype(np.float64),
    }
    with np.errstate(all="ignore"):
        elong = np.where(ev[..., 0] > 0, np.sqrt(ev[..., 1] / ev[..., 0]), 1.0)
    out["elongation"] = np.where(spot, elong, 1.0)
    if pupil_table is not None:
        ri = _table_relative_illumination(pupil_table, hs, diag_dir)
        out["relative_illumination"] = np.broadcast_to(ri[None, :], (nd, nf)).copy()
    else:
        frac = cnt / len(disc)
        out["relative_illumination"] = frac / max(float(frac[0, 0]), 1e-300)
    out["blur_size_error_px"] = np.abs(out["blur_real_px"] - out["blur_model_px"])
    return _model_error_summary(depths, hs, out)


def rays_near_lens(lens: LensPrescription, film_distance_mm: float, depth_z_mm, tan,
                   pupil_xy, ep_z: float) -> tuple[np.ndarray, np.ndarray]:
    """Rays from object points through pupil points, started just in front of the lens.

    The object point at camera-frame depth ``depth_z_mm`` lies in the direction ``tan``
    (x/z, y/z) seen from the entrance-pupil centre on the plane z = ``ep_z``; its ray
    passes the pupil point ``pupil_xy`` on that plane.  Arrays broadcast: ``depth_z_mm``
    (...), ``tan`` and ``pupil_xy`` (..., 2).  A far object's rays are written as slopes
    (a ratio of nearby lengths) and start 1 mm in front of the front vertex (the object
    itself when it is closer), so a depth of 1e14 mm, or ``inf`` (a collimated beam),
    is as exact as 1 m: no coordinate of the size of the depth reaches the tracer.

    Returns
    -------
    origin, direction : (..., 3) arrays (mm; unit-free, not normalised).
    """
    depth = np.asarray(depth_z_mm, dtype=np.float64)
    dist = depth - ep_z                                       # object beyond the pupil
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = tan - pupil_xy / dist[..., None]              # (x - x_p) / (z - z_p)
    start = np.minimum(film_distance_mm + lens.total_track_mm + BUNDLE_START_MM, depth)
    shape = np.broadcast_shapes(slope.shape[:-1], np.shape(start))
    origin = np.empty(shape + (3,))
    origin[..., :2] = pupil_xy + slope * (start - ep_z)[..., None]
    origin[..., 2] = start
    direction = np.empty(shape + (3,))
    direction[..., :2] = -slope
    direction[..., 2] = -1.0
    return origin, direction


def _trace_bundles(lens, film_distance_mm, model, depths, target_film, disc, ep_z, centres):
    """Trace every (depth, film height) bundle of :func:`measure_model_error` in one call.

    The object point of depth d and film height h lies along the direction the model
    images at ``target_film`` (F, 2); its bundle aims at the pupil disc points ``disc``
    (M, 2) moved to ``centres`` (F, 2) on the plane z = ``ep_z``.  Returns which rays
    passed (D, F, M) and where they land on the film (D, F, M, 2; 0 where blocked)."""
    m = len(disc)
    nd, nf = len(depths), len(target_film)
    tan = model.tan_of_film(target_film)                      # (F, 2); per meridian
    pupil = disc[None, :, :] + centres[:, None, :]            # (F, M, 2) on z = ep_z
    origin, direction = rays_near_lens(lens, film_distance_mm, depths[:, None, None],
                                       tan[None, :, None, :], pupil[None], ep_z)
    res = trace_from_scene(lens, film_distance_mm, origin.reshape(-1, 3),
                           direction.reshape(-1, 3))
    ok = res.passed.reshape(nd, nf, m)
    o = res.origin_mm.reshape(nd, nf, m, 3)
    d = res.direction.reshape(nd, nf, m, 3)
    with np.errstate(all="ignore"):
        tt = np.where(ok, -o[..., 2] / d[..., 2], 0.0)
    xy = np.where(ok[..., None], o[..., :2] + tt[..., None] * d[..., :2], 0.0)
    return ok, xy


def _spot_moments(ok: np.ndarray, xy: np.ndarray):
    """Of each spot (the passing rays ``ok`` (D, F, M) of ``xy`` (D, F, M, 2) on the
    film): the ray count (D, F), the centroid (D, F, 2) and the eigenvalues of the
    covariance (D, F, 2; ascending, >= 0)."""
    cnt = ok.sum(axis=-1)                                     # (D, F)
    safe = np.maximum(cnt, 1)[..., None]
    c = xy.sum(axis=2) / safe                                 # (D, F, 2) centroids
    dev = np.where(ok[..., None], xy - c[:, :, None, :], 0.0)
    cov = np.einsum("dfmi,dfmj->dfij", dev, dev) / np.maximum(cnt - 1, 1)[..., None, None]
    ev = np.clip(np.linalg.eigvalsh(cov), 0.0, None)          # ascending, (D, F, 2)
    return cnt, c, ev


def _table_relative_illumination(pupil_table, hs: np.ndarray,
                                 diag_dir: np.ndarray | None = None) -> np.ndarray:
    """E(h) / E(0) at the film heights ``hs`` (F,), exact from the exit-pupil table; for a
    table over the film's x and y (an anamorphic lens) at the film points -h ``diag_dir``
    (the model error's own)."""
    if getattr(pupil_table, "kind", "radial") == "grid" and diag_dir is not None:
        e = pupil_table.irradiance_factor_at(-np.asarray(hs)[:, None] * diag_dir[None, :])
    else:
        e = pupil_table.irradiance_factor(hs)
    e = np.asarray(e, dtype=np.float64)
    return e / e[0] if e[0] > 0 else np.zeros_like(e)


def measure_model_error_reference(lens: LensPrescription, film_distance_mm: float,
                                  model: EquivalentThinLens, film: Film, object_z_mm,
                                  n_field: int = 9, n_rings: int = 12,
                                  pupil_table=None) -> ModelError:
    """:func:`measure_model_error` one bundle at a time (the slow, obvious
    reference its vectorized form is tested against).

    Parameters and Returns are those of :func:`measure_model_error`: same
    arguments, same result.
    """
    pitch, depths, hs, diag_dir, disc, ep_z, centres = _bundle_geometry(
        lens, film_distance_mm, model, film, object_z_mm, n_field, n_rings)
    m = len(disc)
    relative_illumination = None
    if pupil_table is not None:
        relative_illumination = _table_relative_illumination(pupil_table, hs, diag_dir)
    out = {k: np.zeros((len(depths), n_field)) for k in
           ("distortion_px", "blur_real_px", "blur_model_px", "elongation",
            "relative_illumination")}
    axis_pass = None
    for a, z in enumerate(depths):
        for b, hgt in enumerate(hs):
            target_film = -hgt * diag_dir                     # model image point on the film
            tan = model.tan_of_film(target_film)               # object direction from the EP
            origin, direction = rays_near_lens(lens, film_distance_mm, np.full(m, z), tan,
                                               disc + centres[b], ep_z)
            res = trace_from_scene(lens, film_distance_mm, origin, direction)
            o, d = res.origin_mm[res.passed], res.direction[res.passed]
            frac = len(o) / m
            if axis_pass is None:
                axis_pass = max(frac, 1e-300)
            out["relative_illumination"][a, b] = (frac / axis_pass
                                                  if relative_illumination is None
                                                  else relative_illumination[b])
            model_blur = float(model.blur_diameter_mm(np.array([z]))[0]) / pitch
            out["blur_model_px"][a, b] = model_blur
            if len(o) < 3:
                out["distortion_px"][a, b] = 0.0
                out["blur_real_px"][a, b] = 0.0
                out["elongation"][a, b] = 1.0
                continue
            t = -o[:, 2] / d[:, 2]
            xy = o[:, :2] + t[:, None] * d[:, :2]
            c = xy.mean(axis=0)
            out["distortion_px"][a, b] = float(np.hypot(*(c - target_film))) / pitch
            cov = np.cov((xy - c).T)
            ev = np.clip(np.linalg.eigvalsh(cov), 0.0, None)
            rms = math.sqrt(float(ev.sum()))
            out["blur_real_px"][a, b] = 2 * math.sqrt(2) * rms / pitch
            out["elongation"][a, b] = math.sqrt(ev[1] / ev[0]) if ev[0] > 0 else 1.0
    out["blur_size_error_px"] = np.abs(out["blur_real_px"] - out["blur_model_px"])
    return _model_error_summary(depths, hs, out)


def _model_error_summary(depths: np.ndarray, hs: np.ndarray, out: dict) -> ModelError:
    """The record of the (D, F) grids ``out`` measured at ``depths`` x ``hs``."""
    ri = out["relative_illumination"]
    return ModelError(
        object_z_mm=tuple(depths.tolist()), film_height_mm=tuple(hs.tolist()),
        max_distortion_px=float(out["distortion_px"].max()),
        max_blur_size_error_px=float(out["blur_size_error_px"].max()),
        max_elongation=float(out["elongation"].max()),
        min_relative_illumination=float(ri.min()),
        max_vignetting_error=float(1.0 - ri.min()),
        distortion_px=_grid(out["distortion_px"]), blur_real_px=_grid(out["blur_real_px"]),
        blur_model_px=_grid(out["blur_model_px"]), elongation=_grid(out["elongation"]),
        relative_illumination=_grid(ri), blur_size_error_px=_grid(out["blur_size_error_px"]))
