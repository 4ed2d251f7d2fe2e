"""The depth probe's view of the scene in image terms: what the decision of
``--method auto`` (:mod:`povlens.plan.decision`) compares with the error budget.

* :func:`shift_rmse`: moving the image by the tolerance, the budget in image terms
  (``povlens bench --auto`` uses the same definition);
* :func:`vignetting_rmse`: leaving the lens's vignetting out of the image (what the
  vignetting map applies, for the record);
* :func:`catseye_rmse`: what the vignetting map cannot carry, the shape of
  out-of-focus light (the cat's eye) -- a deviation when at least the budget;
* :func:`probe_image_error`: the three of a probe's image, as
  :func:`povlens.plan.decision.decide` takes them.

Numbers and the derivation: docs/decisions/planning.md ("Vignetting applied as a map").
"""

from __future__ import annotations

import math

import numpy as np

from povlens.lens.tracer import trace_from_film
from povlens.pupil.illumination import relative_illumination_map
from povlens.pupil.monte_carlo import sobol_points
from povlens.thinlens.model_error import ModelError

__all__ = ["shift_rmse", "vignetting_rmse", "catseye_rmse", "probe_image_error",
           "film_radius_map_mm", "pixel_blur_mm", "CATSEYE_SAMPLES", "CATSEYE_RADII"]

#: Lens samples per probe pixel of :func:`catseye_rmse`'s two kernels, and the film
#: radii they are traced at (rotated to each pixel's azimuth, linear between radii).
CATSEYE_SAMPLES = 64
CATSEYE_RADII = 65


def vignetting_rmse(image: np.ndarray, relative_illumination: np.ndarray) -> float:
    """Image RMSE of leaving out the lens's vignetting.

    Parameters
    ----------
    image : (H, W, C) linear, the view without vignetting (as POV-Ray's pinhole /
        focal_blur render it).
    relative_illumination : (H, W) E/E(centre) at each pixel.  The lens's image is
        ``image x relative_illumination`` (both normalised at the centre).

    Returns
    -------
    float
    """
    err = image * (1.0 - np.asarray(relative_illumination, dtype=float))[..., None]
    return float(np.sqrt(np.mean(err ** 2)))


def shift_rmse(image: np.ndarray, shift_px: float) -> float:
    """Image RMSE of moving ``image`` (H, W, C) by ``shift_px`` >= 0 pixels.

    The mean over +x, -x, +y, -y of RMSE(image, image moved), sub-pixel moves by
    linear interpolation, a border of ``floor(shift_px) + 1`` pixels excluded
    (where the moved image has no data).  The error budget of ``--tolerance`` in
    image terms, here and in ``povlens bench --auto`` (on its reference).  An
    image too small for the border gives 0.
    """
    a = np.asarray(image, dtype=np.float64)[..., :3]
    s = float(shift_px)
    if not (s >= 0 and math.isfinite(s)):
        raise ValueError(f"shift_px must be a finite number >= 0, not {shift_px}")
    k = int(math.floor(s))
    f = s - k
    b = k + 1
    if a.shape[0] <= 2 * b or a.shape[1] <= 2 * b:
        return 0.0
    core = a[b:-b, b:-b]
    out = []
    for axis in (0, 1):
        for step in (1, -1):
            moved = (1 - f) * np.roll(a, step * k, axis=axis) + f * np.roll(a, step * (k + 1),
                                                                         axis=axis)
            d = moved[b:-b, b:-b] - core
            out.append(math.sqrt(float(np.mean(d * d))))
    return float(np.mean(out))


def film_radius_map_mm(film, width_px: int, height_px: int) -> np.ndarray:
    """(H, W) film radius (mm) of the pixel centres of an image of ``film``'s frame
    at ``width_px`` x ``height_px`` pixels (the depth probe's size)."""
    cols = (np.arange(width_px) + 0.5) / width_px - 0.5
    rows = 0.5 - (np.arange(height_px) + 0.5) / height_px
    sx, sy = getattr(film, "shift_mm", (0.0, 0.0))          # lens shift (lens.film)
    return np.hypot(cols[None, :] * film.width_mm + sx, rows[:, None] * film.height_mm + sy)


def pixel_blur_mm(model, axial_mm: np.ndarray) -> np.ndarray:
    """Thin-lens blur diameter (mm on the film) at axial distances ``axial_mm`` (any
    shape) from the entrance pupil; inf (background) and nan (no depth: emissive,
    black or clear surfaces) take the limit at infinity."""
    a = np.asarray(axial_mm, dtype=float)
    s = model.focus_distance_mm
    far = model.pupil_diameter_mm * model.image_distance_mm / s if math.isfinite(s) else 0.0
    out = np.full(a.shape, far)
    fin = np.isfinite(a) & (a > 0)
    if fin.any():
        out[fin] = model.blur_diameter_mm(model.centre_z_mm + a[fin])
    return out


def _bilinear(image: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """``image`` (H, W, C) at fractional pixel positions (any shape, centres at
    integers), clamped to the edge; returns (..., C)."""
    h, w = image.shape[:2]
    r = np.clip(rows, 0.0, h - 1.0)
    c = np.clip(cols, 0.0, w - 1.0)
    r0 = np.minimum(np.floor(r).astype(np.int64), max(h - 2, 0))
    c0 = np.minimum(np.floor(c).astype(np.int64), max(w - 2, 0))
    fr, fc = (r - r0)[..., None], (c - c0)[..., None]
    r1, c1 = np.minimum(r0 + 1, h - 1), np.minimum(c0 + 1, w - 1)
    return ((1 - fr) * ((1 - fc) * image[r0, c0] + fc * image[r0, c1])
            + fr * ((1 - fc) * image[r1, c0] + fc * image[r1, c1]))


def _kernels(table, film_xy: np.ndarray, n_samples: int):
    """Pupil points (n, S, 2) on the sampling plane and their weights (n, S) for the
    film points ``film_xy`` (n, 2), and the same for the axis (S, 2), (S,).

    The same ``n_samples`` Sobol' points everywhere, traced (blocked rays weigh 0)
    at :data:`CATSEYE_RADII` film radii on the +x axis; a film point's kernel is the
    one of its radius (linear between those, as the sampler's map is continuous in
    the radius) rotated to its azimuth (the lens is rotationally symmetric)."""
    u = sobol_points(n_samples, 2, seed=12345)
    S = u.shape[0]
    r = np.hypot(film_xy[:, 0], film_xy[:, 1])
    radii = np.linspace(0.0, max(float(r.max()), 1e-9), CATSEYE_RADII)
    f = np.zeros((radii.size * S, 2))
    f[:, 0] = np.repeat(radii, S)
    s = table.sample(f, np.tile(u, (radii.size, 1)))
    w = np.zeros(s.weight.shape)
    ok = np.nonzero(s.valid)[0]
    if ok.size:
        passed = trace_from_film(table.lens, table.film_distance_mm, s.film_point[ok],
                                 s.direction[ok]).passed
        w[ok] = np.where(passed, s.weight[ok], 0.0)
    pk = s.pupil_point[:, :2].reshape(radii.size, S, 2)
    wk = w.reshape(radii.size, S)
    x = r / radii[-1] * (radii.size - 1)
    k = np.clip(np.floor(x).astype(np.int64), 0, radii.size - 2)
    t = np.clip(x - k, 0.0, 1.0)[:, None]
    p = (1 - t[..., None]) * pk[k] + t[..., None] * pk[k + 1]          # (n, S, 2)
    wt = (1 - t) * wk[k] + t * wk[k + 1]
    safe = np.where(r > 0, r, 1.0)
    c, sn = (np.where(r > 0, film_xy[:, 0] / safe, 1.0)[:, None],
             np.where(r > 0, film_xy[:, 1] / safe, 0.0)[:, None])
    rot = np.stack([c * p[..., 0] - sn * p[..., 1], sn * p[..., 0] + c * p[..., 1]], axis=-1)
    return rot, wt, pk[0], wk[0]


def catseye_rmse(image: np.ndarray, film, table, model, axial_mm: np.ndarray,
                 n_samples: int = CATSEYE_SAMPLES) -> float:
    """Image RMSE of what the vignetting map cannot carry: the shape of out-of-focus light.

    At each pixel p of ``image`` (the depth probe's view, sharp), the real lens
    gathers light through its pass region R(p) and focal_blur through the axial
    disc; with the map both carry the same total, so what differs is the kernel.
    A pupil point P (sampling plane, mm from the axis) looks at the sharp image
    ``b(p) P / D0`` away (paraxial defocus; b(p) the thin-lens blur diameter at the
    depth the probe measured at p, D0 the axial region's width), so

        I_real(p) = sum_k w_k I(p + b P_k / D0) / sum_k w_k,   P_k in R(p),
        I_blur(p) = the same with the axial region's points,

    (``n_samples`` Sobol' points of the pupil table, traced: weights ``cos^4 / pdf``
    of the rays that pass), and the result is RMS(I_real - I_blur), the mean over the
    kernels and their point reflections (in front of the focus the blur is reversed)
    like :func:`shift_rmse`'s +-x, +-y.  0 where p is in focus or vignetted (black
    in both), and for a flat image (below 1e-9 of the image's RMS: rounding).

    Parameters
    ----------
    image : (h, w, C) linear, the probe's view of ``film``'s frame.
    film : the plan's film (mm; its pixels only convert the blur).
    table : the plan's exit-pupil table.
    model : the equivalent thin lens.
    axial_mm : (h, w) the probe's axial distances from the entrance pupil (mm; inf
        background, nan no depth: both blurred as at infinity).
    n_samples : pupil points per kernel.

    Returns
    -------
    float, in the image's units.
    """
    img = np.asarray(image, dtype=np.float64)[..., :3]
    h, w = img.shape[:2]
    probe = film.resized(film.width_mm, film.height_mm, w, h)
    fxy = probe.film_points_mm().reshape(-1, 2)
    p, wt, p0, w0 = _kernels(table, fxy, n_samples)
    d0 = float(p0[w0 > 0, 0].max() - p0[w0 > 0, 0].min()) if np.any(w0 > 0) else 0.0
    if not d0 > 0:
        return 0.0
    blur = pixel_blur_mm(model, axial_mm).reshape(-1)               # (n,) mm on the film
    # a film displacement (dx, dy) is an image displacement of (-dx, +dy) / pitch
    k_col = -(blur / d0) / (film.width_mm / w)
    k_row = (blur / d0) / (film.height_mm / h)
    rows = np.repeat(np.arange(h), w).astype(float)
    cols = np.tile(np.arange(w), h).astype(float)
    out = []
    for sign in (1.0, -1.0):
        def gather(points, weights):
            rr = rows[:, None] + sign * k_row[:, None] * points[..., 1]
            cc = cols[:, None] + sign * k_col[:, None] * points[..., 0]
            v = _bilinear(img, rr, cc)                                # (n, S, C)
            tot = weights.sum(axis=-1)
            with np.errstate(invalid="ignore", divide="ignore"):
                g = np.einsum("ns,nsc->nc", weights, v) / tot[:, None]
            return g, tot > 0
        real, lit = gather(p, wt)
        axial, _ = gather(np.broadcast_to(p0, p.shape), np.broadcast_to(w0, wt.shape))
        diff = np.where(lit[:, None], real - axial, 0.0)
        out.append(math.sqrt(float(np.mean(diff * diff))))
    e = float(np.mean(out))
    # rounding of the two weighted means (a flat image): no error
    return e if e > 1e-9 * math.sqrt(float(np.mean(img * img))) else 0.0


def probe_image_error(image: np.ndarray, film, model_error: ModelError, tolerance_px: float, *,
                      profile=None, table=None, model=None, axial_mm=None) -> dict:
    """The depth probe's view ``image`` (H, W, 3) of ``film``'s frame in image terms.

    Returns
    -------
    dict
        ``shift_rmse``: moving the image by the tolerance (film pixels converted to
        the probe's); ``vignetting_rmse``: leaving the lens's relative illumination
        out (the map of ``profile``, :func:`povlens.pupil.illumination.relative_illumination_map`,
        when given, else ``model_error``'s over film height interpolated at each
        pixel's radius); with ``table``, ``model`` and ``axial_mm`` (the probe's
        depths) also ``catseye_rmse`` (:func:`catseye_rmse`: what the map cannot carry).
    """
    h, w = image.shape[:2]
    if profile is not None:
        ri_map = relative_illumination_map(profile, film.width_mm, film.height_mm, w, h,
                                           shift_mm=film.shift_mm)
    else:
        heights = np.asarray(model_error.film_height_mm, dtype=float)
        ri = np.asarray(model_error.relative_illumination, dtype=float)[0]
        ri_map = np.interp(film_radius_map_mm(film, w, h), heights, ri)
    out = {"vignetting_rmse": vignetting_rmse(image, ri_map),
           "shift_rmse": shift_rmse(image, tolerance_px * w / film.width_px)}
    if table is not None and model is not None and axial_mm is not None:
        out["catseye_rmse"] = catseye_rmse(image, film, table, model, axial_mm)
    return out
