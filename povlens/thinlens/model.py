"""The equivalent focal-plane (thin-lens) model of a focused real lens.

The model is what POV-Ray's perspective camera with ``focal_blur`` can express:
a centre of projection, a linear map from film position to the tangent of the
field angle (no distortion), a circular entrance pupil, and a plane in focus.
It is fitted to the real lens as follows (camera frame, mm):

* **centre of projection** — the entrance-pupil centre, ``z_ep = film distance
  + total track - entrance-pupil position``: object-space chief rays aim at it,
  so it is the lens's perspective centre (realistic-camera.md §9.1).
* **field of view** — real chief rays (through the centre of the stop) traced
  from film points along the diagonal give tan(theta) as a function of film
  height h.  The model uses tan(theta) = h / v_eff, with v_eff the least-squares
  fit over the field (film heights from 0 to the half diagonal).
* **aperture** — the entrance-pupil diameter (paraxial image of the stop).
* **plane in focus** — the object distance the lens is focused at.

:func:`measure_model_error` measures what the model gets wrong against the exact
tracer: distortion (pixels), blur-disc size and shape, and vignetting.
"""

from __future__ import annotations

import dataclasses
import math
import weakref

import numpy as np

from povlens.lens.film import Film
from povlens.lens.focus import pupil_disc_points
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import LensPrescription
from povlens.lens.tracer import trace_from_film, trace_from_scene

__all__ = ["EquivalentThinLens", "fit_thin_lens", "chief_rays", "chief_ray_aim_mm",
           "measure_model_error_reference",
           "measure_model_error"]


def _sub_lens(lens: LensPrescription, first: int) -> LensPrescription:
    """Rows ``first``..end of ``lens`` (same vertex positions for the same film distance)."""
    sl = slice(first, None)
    return lens.replace(radius_mm=lens.radius_mm[sl], thickness_mm=lens.thickness_mm[sl],
                        index_after=lens.index_after[sl],
                        aperture_diameter_mm=lens.aperture_diameter_mm[sl],
                        abbe_vd=lens.abbe_vd[sl], lines=lens.lines[first:])


def chief_ray_aim_mm(lens: LensPrescription, film_distance_mm: float, film_radius_mm,
                     iterations: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Where real chief rays from film points (r, 0, 0) cross the rear-vertex plane.

    The chief ray passes through the centre of the stop.  Its aim x_rear on the
    plane z = film_distance_mm is found by the secant method so that its height at
    the stop plane is 0, starting from the paraxial aim at the exit-pupil centre.
    Clear apertures other than the stop's are ignored while aiming (the chief ray
    is a construction).  Returns (x_rear (n,) mm, found (n,) bool).
    """
    p = paraxial_data(lens)
    s = p.stop_index
    r = np.atleast_1d(np.asarray(film_radius_mm, dtype=np.float64)).ravel()
    n = r.size
    # Open every clear aperture (a clear radius cannot exceed |R|) and stop at the stop.
    wide = lens.replace(aperture_diameter_mm=np.where(
        lens.radius_mm != 0, 2 * np.abs(lens.radius_mm) * (1 - 1e-12), 1e6))
    to_stop = _sub_lens(wide, s)
    origin = np.column_stack([r, np.zeros(n), np.zeros(n)])
    z_rear = film_distance_mm

    def stop_height(x_rear):
        d = np.column_stack([x_rear - r, np.zeros(n), np.full(n, z_rear)])
        t = trace_from_film(to_stop, film_distance_mm, origin, d)
        return t.origin_mm[:, 0], t.passed

    z_xp = film_distance_mm - p.exit_pupil_position  # camera-frame z of the exit pupil
    x0 = r * (1.0 - z_rear / z_xp) if z_xp != 0 else np.zeros(n)
    x1 = x0 + 1e-3 * max(1.0, float(np.max(np.abs(r))) if n else 1.0)
    h0, ok0 = stop_height(x0)
    h1, ok1 = stop_height(x1)
    for _ in range(iterations):
        denom = h1 - h0
        step_ok = (denom != 0) & ok0 & ok1
        x2 = np.where(step_ok, x1 - h1 * (x1 - x0) / np.where(denom != 0, denom, 1.0), x1)
        x0, h0, ok0 = x1, h1, ok1
        x1 = x2
        h1, ok1 = stop_height(x1)
        if np.all(~ok1 | (np.abs(h1) < 1e-12)):
            break
    return x1, ok1 & (np.abs(h1) < 1e-9)


def chief_rays(lens: LensPrescription, film_distance_mm: float, film_radius_mm: np.ndarray):
    """Real chief rays from film points (r, 0, 0) through the centre of the stop.

    Returns (TraceResult of the rays leaving the front surface, found (n,) bool);
    the trace's ``passed`` tells whether the chief ray gets through every aperture.
    """
    r = np.atleast_1d(np.asarray(film_radius_mm, dtype=np.float64)).ravel()
    x_rear, found = chief_ray_aim_mm(lens, film_distance_mm, r)
    n = r.size
    origin = np.column_stack([r, np.zeros(n), np.zeros(n)])
    d = np.column_stack([x_rear - r, np.zeros(n), np.full(n, float(film_distance_mm))])
    return trace_from_film(lens, film_distance_mm, origin, d), found


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
        """Film-side blur-disc diameter of axial-depth objects (thin lens, §9.1)."""
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
    h = np.linspace(0.0, film.half_diagonal_mm, n_field)[1:]
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


#: Chief rays of the model-error field heights, per lens object (by identity:
#: prescriptions are frozen; a weak reference tells a new object at the same id)
#: and film distance.  A --method auto conversion measures the model error twice
#: with the same lens, focus and field heights (the plan's standard depths, then
#: the depth probe's); the chief-ray search, ~4 ms of each, is done once.
_CHIEF_RAYS: dict = {}


def _chief_rays_remembered(lens, film_distance_mm: float, hs: np.ndarray):
    """:func:`chief_rays` of ``hs`` (F,), remembered; the arrays are read-only."""
    entry = _CHIEF_RAYS.get(id(lens))
    if entry is None or entry[0]() is not lens:
        if len(_CHIEF_RAYS) >= 8:
            _CHIEF_RAYS.clear()
        entry = _CHIEF_RAYS[id(lens)] = (weakref.ref(lens), {})
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
    hs = np.linspace(0.0, film.half_diagonal_mm, n_field)
    diag_dir = np.array([film.width_mm, film.height_mm]) / math.hypot(film.width_mm, film.height_mm)
    disc = pupil_disc_points(n_rings) * (0.75 * model.pupil_diameter_mm)
    ep_z = model.centre_z_mm
    chief, found = _chief_rays_remembered(lens, film_distance_mm, hs)
    with np.errstate(all="ignore"):
        t = (ep_z - chief.origin_mm[:, 2]) / chief.direction[:, 2]
        x_c = chief.origin_mm[:, 0] + t * chief.direction[:, 0]
    x_c = np.where(found & np.isfinite(x_c), x_c, 0.0)
    centres = -x_c[:, None] * diag_dir[None, :]
    return pitch, depths, hs, diag_dir, disc, ep_z, centres


def measure_model_error(lens: LensPrescription, film_distance_mm: float,
                        model: EquivalentThinLens, film: Film, object_z_mm,
                        n_field: int = 9, n_rings: int = 12, pupil_table=None) -> dict:
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
      (:class:`povlens.pupil.PupilTable`, exact) when given, else the passing
      fraction of the bundle relative to the axis.

    All (depth, field) bundles are traced in one call (D depths x F field heights
    x M pupil points); :func:`measure_model_error_reference` traces them one at a
    time and gives the same numbers.  Returns a dict of per-(depth, field) arrays
    (D, F) and their maxima, in pixels.
    """
    pitch, depths, hs, diag_dir, disc, ep_z, centres = _bundle_geometry(
        lens, film_distance_mm, model, film, object_z_mm, n_field, n_rings)
    m = len(disc)
    nd, nf = len(depths), n_field
    target_film = -hs[:, None] * diag_dir[None, :]            # (F, 2) model image points
    tan = -target_film / model.image_distance_mm              # (F, 2)
    dist = depths - ep_z                                      # (D,)
    obj = np.empty((nd, nf, 3))
    obj[..., :2] = tan[None, :, :] * dist[:, None, None]
    obj[..., 2] = depths[:, None]
    pupil = np.empty((nf, m, 3))
    pupil[..., :2] = disc[None, :, :] + centres[:, None, :]
    pupil[..., 2] = ep_z
    direction = pupil[None, :, :, :] - obj[:, :, None, :]     # (D, F, M, 3)
    origin = np.broadcast_to(obj[:, :, None, :], direction.shape)
    res = trace_from_scene(lens, film_distance_mm, origin.reshape(-1, 3),
                           direction.reshape(-1, 3))
    ok = res.passed.reshape(nd, nf, m)
    o = res.origin_mm.reshape(nd, nf, m, 3)
    d = res.direction.reshape(nd, nf, m, 3)
    with np.errstate(all="ignore"):
        tt = np.where(ok, -o[..., 2] / d[..., 2], 0.0)
    xy = np.where(ok[..., None], o[..., :2] + tt[..., None] * d[..., :2], 0.0)
    cnt = ok.sum(axis=-1)                                     # (D, F)
    frac = cnt / m
    axis_pass = max(float(frac[0, 0]), 1e-300)
    safe = np.maximum(cnt, 1)[..., None]
    c = xy.sum(axis=2) / safe                                 # (D, F, 2) centroids
    dev = np.where(ok[..., None], xy - c[:, :, None, :], 0.0)
    cov = np.einsum("dfmi,dfmj->dfij", dev, dev) / np.maximum(cnt - 1, 1)[..., None, None]
    ev = np.clip(np.linalg.eigvalsh(cov), 0.0, None)          # ascending, (D, F, 2)
    spot = cnt >= 3
    model_blur = model.blur_diameter_mm(depths) / pitch       # (D,)
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
        e = np.asarray(pupil_table.irradiance_factor(hs), dtype=np.float64)
        ri = e / e[0] if e[0] > 0 else np.zeros_like(e)
        out["relative_illumination"] = np.broadcast_to(ri[None, :], (nd, nf)).copy()
    else:
        out["relative_illumination"] = frac / axis_pass
    out["blur_size_error_px"] = np.abs(out["blur_real_px"] - out["blur_model_px"])
    return _model_error_summary(depths, hs, out)


def measure_model_error_reference(lens: LensPrescription, film_distance_mm: float,
                        model: EquivalentThinLens, film: Film, object_z_mm,
                        n_field: int = 9, n_rings: int = 12, pupil_table=None) -> dict:
    """:func:`measure_model_error` one bundle at a time (the slow, obvious
    reference its vectorized form is tested against): same arguments, same result.
    Returns a dict of per-(depth, field) arrays and their maxima, in pixels.
    """
    pitch, depths, hs, diag_dir, disc, ep_z, centres = _bundle_geometry(
        lens, film_distance_mm, model, film, object_z_mm, n_field, n_rings)
    m = len(disc)
    relative_illumination = None
    if pupil_table is not None:
        e = np.asarray(pupil_table.irradiance_factor(hs), dtype=np.float64)
        relative_illumination = e / e[0] if e[0] > 0 else np.zeros_like(e)
    out = {k: np.zeros((len(depths), n_field)) for k in
           ("distortion_px", "blur_real_px", "blur_model_px", "blur_size_error_px",
            "elongation", "relative_illumination")}
    axis_pass = None
    for a, z in enumerate(depths):
        dist = z - ep_z
        for b, hgt in enumerate(hs):
            target_film = -hgt * diag_dir                     # model image point on the film
            tan = -target_film / model.image_distance_mm       # object direction from the EP
            obj = np.array([tan[0] * dist, tan[1] * dist, z])
            pupil = np.column_stack([disc + centres[b], np.full(m, ep_z)])
            direction = pupil - obj
            res = trace_from_scene(lens, film_distance_mm, np.tile(obj, (m, 1)), direction)
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


def _model_error_summary(depths: np.ndarray, hs: np.ndarray, out: dict) -> dict:
    summary = {
        "object_z_mm": depths.tolist(), "film_height_mm": hs.tolist(),
        "max_distortion_px": float(out["distortion_px"].max()),
        "max_blur_size_error_px": float(out["blur_size_error_px"].max()),
        "max_elongation": float(out["elongation"].max()),
        "min_relative_illumination": float(out["relative_illumination"].min()),
        "max_vignetting_error": float(1.0 - out["relative_illumination"].min()),
    }
    summary.update({k: v.tolist() for k, v in out.items()})
    return summary
