"""The decision of ``--method auto``: the cheapest render method within an error budget.

:func:`decide` is pure: from the scene's depth range (a depth probe,
:mod:`povlens.plan.auto`) and the thin-lens model's measured error over it
(:func:`povlens.thinlens.model_error.measure_model_error`) it chooses

* ``pinhole`` when the thin-lens circle of confusion over [near, far], the real
  spot size (aberrations), the distortion and the vignetting all stay under the
  budget (a pinhole camera has the model's projection too);
* ``focal-blur`` when the real lens's deviations from the equivalent thin lens
  stay under the budget.  Each is measured as how far light lands from where the
  model puts it (pixels): distortion, the displacement of the spot's centroid;
  blur size, half the difference of the equivalent-disc diameters (a disc scaled
  from diameter D to D + d moves its rim by d / 2 and no point further); blur
  shape, half of how far the real spot's long axis reaches beyond the equivalent
  disc (:func:`shape_error_px`, half on each side); and vignetting (POV-Ray's
  focal_blur has none), judged in image terms (below);
* ``mesh`` otherwise; and also when the thin lens would do but leaving out the
  vignetting alone takes :data:`VIGNETTING_FLOOR_SHARE` of the budget or more
  while the blur needs only the minimum mesh sample count: focal_blur's error
  cannot go below that floor, and a minimum mesh render costs about what the
  adaptive focal blur does.

**Vignetting in image terms.**  Vignetting is not a displacement, so it is judged
by its effect on this scene's image: the probe also renders the view as it is
(the scene as a pinhole camera sees it, at full quality), and leaving the vignetting out is a
deviation when its image RMSE, RMS(I (1 - E/E0)) with the lens's relative
illumination E/E0 at each pixel (:func:`vignetting_rmse`), is at least the RMSE
of moving the same image by the tolerance (:func:`shift_rmse`, the budget in image
terms; ``povlens bench --auto`` uses the same definition).  On the bundled scenes
it predicts the error floor of focal_blur against the mesh reference within 3 %
(docs/decisions/planning.md).  Vignetting that is not wanted (``--no-vignetting``)
is no deviation.

**Samples.**  With N stratified lens samples, the N copies of a point blurred
into a disc of diameter b pixels lie about ``b sqrt(pi/4) / sqrt(N)`` pixels
apart.  The target noise is that these copies are at most
:data:`SAMPLE_SPACING_PX` (1 pixel) apart, so they blend instead of showing as
separate copies / structured noise: ``N = ceil(K b_max^2)`` with ``K = (pi/4) /
SAMPLE_SPACING_PX^2`` and b_max the largest blur in pixels (real or model) over
the depth range, rounded to the nearest power of two (the Sobol lens samples are
balanced in blocks of 2^m) and clamped to 8..256 (:func:`samples_for_blur`).
Pinhole renders use 1 sample.  A chosen focal_blur uses POV-Ray's adaptive
sampling instead (:data:`FOCAL_BLUR_ADAPTIVE`), which needs no depth-dependent
count, so ``povlens render`` can start it while the probe runs
(:mod:`povlens.plan.speculative`).
"""

from __future__ import annotations

import math

import numpy as np

from povlens.plan.schema import Decision, FocalBlurSettings

__all__ = ["FOCAL_BLUR_ADAPTIVE", "decide", "shape_error_px", "vignetting_rmse", "shift_rmse",
           "probe_image_error", "film_radius_map_mm", "blur_range_px", "model_depths",
           "samples_for_blur", "SAMPLE_SPACING_PX", "SAMPLE_K", "MIN_SAMPLES", "MAX_SAMPLES",
           "SAMPLE_RULE", "VIGNETTING_TOLERANCE", "STRONG_VIGNETTING", "VIGNETTING_FLOOR_SHARE"]

#: Largest spacing in pixels between the film copies of one blurred point (target noise).
SAMPLE_SPACING_PX = 1.0
#: Samples per squared pixel of blur diameter: (pi/4) / spacing^2.
SAMPLE_K = (math.pi / 4) / SAMPLE_SPACING_PX ** 2
MIN_SAMPLES, MAX_SAMPLES = 8, 256
SAMPLE_RULE = (f"N = ceil({SAMPLE_K:.3g} b^2) rounded to the nearest power of two, "
               f"{MIN_SAMPLES}..{MAX_SAMPLES}")
#: Share of the error budget that leaving out the vignetting may take before
#: :func:`decide` prefers a minimum mesh render to a focal_blur the thin lens allows:
#: no focal_blur sample count goes below that floor (measurements:
#: docs/decisions/planning.md, "Vignetting floor").
VIGNETTING_FLOOR_SHARE = 0.6
#: focal_blur sampling of --method auto: POV-Ray's adaptive sampling (sharp pixels stop
#: at the minimum, so no depth-dependent count is needed; docs/decisions/planning.md).
FOCAL_BLUR_ADAPTIVE = FocalBlurSettings(min_samples=32, max_samples=256, confidence=0.99,
                                        variance=1.0 / 10000)
#: Without the probe's image (:func:`decide` without ``image_error``): relative
#: illumination below 1 - this counts as vignetting focal_blur cannot render.
VIGNETTING_TOLERANCE = 0.05
#: Relative illumination below which povlens render guesses, before the probe is in,
#: that the vignetting rules out the views (work started early only).
STRONG_VIGNETTING = 0.5


def samples_for_blur(blur_px: float, n_min: int = MIN_SAMPLES, n_max: int = MAX_SAMPLES) -> int:
    """Lens samples for a largest blur of ``blur_px`` pixels.

    ``ceil(SAMPLE_K b^2)`` (copies of a blurred point at most
    :data:`SAMPLE_SPACING_PX` apart), rounded to the nearest power of two (in
    log2) and clamped to ``[n_min, n_max]``.  Powers of two because the lens
    samples are a scrambled Sobol sequence (:mod:`povlens.pupil.rays`), whose
    points are balanced only in blocks of 2^m: a count between two powers
    stratifies no better than the lower power.

    Parameters
    ----------
    blur_px : largest blur diameter, film pixels (inf: ``n_max``).
    n_min, n_max : the clamp.

    Returns
    -------
    int
    """
    b = float(blur_px)
    k = SAMPLE_K * b * b if abs(b) < 1e9 else math.inf
    if not math.isfinite(k) or k > n_max:
        return int(max(n_min, n_max))
    n = 2 ** round(math.log2(max(1, math.ceil(k))))
    return int(min(n_max, max(n_min, n)))


def blur_range_px(model, near_z_mm: float, far_z_mm: float, pixel_pitch_mm: float) -> dict:
    """Thin-lens blur diameter in pixels at near, far and its max / min over the range.

    The blur |d - s| / d is monotone on each side of the focus s, so its maximum
    over [near, far] is at an end (far = inf: the limit pupil v / s).

    Returns
    -------
    dict
        ``near_px``, ``far_px``, ``max_px``, ``min_px`` (pixels) and
        ``focus_inside_range`` (bool).
    """
    s = model.focus_distance_mm

    def blur(z):
        if math.isinf(z):
            v = model.pupil_diameter_mm * model.image_distance_mm / s if math.isfinite(s) else 0.0
        else:
            v = float(model.blur_diameter_mm(np.array([z]))[0])
        return v / pixel_pitch_mm

    bn, bf = blur(near_z_mm), blur(far_z_mm)
    focus_z = model.focus_z_mm
    inside = near_z_mm <= focus_z <= far_z_mm
    return {"near_px": bn, "far_px": bf, "max_px": max(bn, bf),
            "min_px": 0.0 if inside else min(bn, bf), "focus_inside_range": bool(inside)}


def model_depths(model, near_z_mm: float, far_z_mm: float, n: int = 5) -> list[float]:
    """Camera-frame depths (mm) spanning [near, far], geometric in distance from the
    centre of projection, plus the plane in focus; far = inf -> 1e4 x near (or focus)."""
    c = model.centre_z_mm
    dn = max(near_z_mm - c, 1e-3)
    if math.isinf(far_z_mm):
        ref = model.focus_distance_mm if math.isfinite(model.focus_distance_mm) else dn
        df = max(1e4 * max(dn, ref), 1e6)
    else:
        df = max(far_z_mm - c, dn)
    d = set(np.geomspace(dn, df, n).tolist()) if df > dn else {dn}
    if math.isfinite(model.focus_distance_mm) and dn <= model.focus_distance_mm <= df:
        d.add(model.focus_distance_mm)
    return [c + x for x in sorted(d)]


def shape_error_px(blur_real_px, elongation) -> np.ndarray:
    """How far the real spot's long axis reaches beyond the equivalent disc (pixels).

    A spot with covariance eigenvalues l_max >= l_min has RMS radius
    rho = sqrt(l_max + l_min) and equivalent-disc diameter b = 2 sqrt(2) rho (the
    ``blur_real_px`` of :func:`povlens.thinlens.model_error.measure_model_error`); a
    uniform disc of diameter D has variance D^2 / 16 along any axis, so the extent
    along an axis of variance l is 4 sqrt(l).  The disc of the same RMS has
    l = rho^2 / 2 on both axes; the real spot's long axis, with
    e = sqrt(l_max / l_min), is 4 rho e / sqrt(1 + e^2).  Their difference:

        shape error = b (sqrt(2) e / sqrt(1 + e^2) - 1),

    0 for a round spot, at most (sqrt(2) - 1) b for a line.

    Parameters
    ----------
    blur_real_px : array_like, any shape; equivalent-disc diameters, pixels.
    elongation : array_like, same shape; sqrt(l_max / l_min) >= 1.

    Returns
    -------
    ndarray, the shape of the inputs; pixels.
    """
    b = np.asarray(blur_real_px, dtype=float)
    e = np.asarray(elongation, dtype=float)
    return b * (math.sqrt(2.0) * e / np.sqrt(1.0 + e * e) - 1.0)


def _vignetting_text(illum: float, vignetted: bool, wanted: bool, tol: float,
                     image_error: dict | None) -> str:
    """The reason line on the vignetting, for the pinhole and focal-blur checks."""
    if image_error is not None:
        v, b = image_error["vignetting_rmse"], image_error["shift_rmse"]
        text = (f"relative illumination >= {illum:.3f} of the centre; leaving it out "
                f"changes the probe's image by RMSE {v:.3g}, "
                f"{'at least' if vignetted else 'less than'} the {b:.3g} of a "
                f"{tol:.3g} px move")
    else:
        text = (f"relative illumination >= {illum:.3f} of the centre "
                f"({'below' if vignetted else 'not below'} {1 - VIGNETTING_TOLERANCE:.2f})")
    if vignetted and not wanted:
        text += "; vignetting not wanted (--no-vignetting), so not a deviation"
    elif vignetted:
        text += "; POV-Ray's pinhole and focal_blur cameras have none: a deviation"
    return text


def _numbers(near_z_mm, far_z_mm, model, e: dict, blur: dict, tol: float, vignetting: bool,
             image_error: dict | None, max_real: float, shape_err: float) -> dict:
    """The measurements a decision records (units in the keys)."""
    return {
        "tolerance_px": tol,
        "near_z_mm": near_z_mm, "far_z_mm": far_z_mm,
        "near_distance_mm": near_z_mm - model.centre_z_mm,
        "far_distance_mm": far_z_mm - model.centre_z_mm,
        "blur_near_px": blur["near_px"], "blur_far_px": blur["far_px"],
        "max_model_blur_px": blur["max_px"], "max_real_blur_px": max_real,
        "max_distortion_px": float(e["max_distortion_px"]),
        "max_blur_size_error_px": float(e["max_blur_size_error_px"]),
        "max_elongation": float(e["max_elongation"]), "max_shape_error_px": shape_err,
        "min_relative_illumination": float(e["min_relative_illumination"]),
        "vignetting_wanted": bool(vignetting),
        **({f"image_{k}": float(v) for k, v in image_error.items()} if image_error else {}),
        "model_depths_z_mm": list(e.get("object_z_mm", [])),
        "sample_k": SAMPLE_K,
    }


def decide(*, near_z_mm: float, far_z_mm: float, model, model_error: dict,
           pixel_pitch_mm: float, tolerance_px: float = 0.5, vignetting: bool = True,
           image_error: dict | None = None) -> Decision:
    """Choose the render method and its lens samples (pure; see the module docstring).

    Parameters
    ----------
    near_z_mm, far_z_mm : the scene's depth range, camera-frame z (mm); far may be inf.
    model : the :class:`~povlens.thinlens.model.EquivalentThinLens`.
    model_error : :func:`povlens.thinlens.model_error.measure_model_error` measured at
        depths spanning [near, far].
    pixel_pitch_mm : the film's pixel size.
    tolerance_px : the error budget, film pixels.
    vignetting : False when the lens's vignetting is not wanted in the image
        (``--no-vignetting``).
    image_error : {vignetting_rmse, shift_rmse} from the depth probe's view of the
        scene (:func:`probe_image_error`): leaving out the vignetting is a deviation
        when it changes the image more than moving it by the tolerance does.
        Without it, a relative illumination below ``1 - VIGNETTING_TOLERANCE``
        anywhere is a deviation.

    Returns
    -------
    Decision
        Method, samples, reasons (the conclusion last) and the numbers behind them.
    """
    tol = float(tolerance_px)
    blur = blur_range_px(model, near_z_mm, far_z_mm, pixel_pitch_mm)
    e = model_error
    real = np.asarray(e["blur_real_px"], dtype=float)
    elong = np.asarray(e["elongation"], dtype=float)
    shape_err = float(np.max(shape_error_px(real, elong))) if real.size else 0.0
    max_real = float(real.max()) if real.size else 0.0
    dist = float(e["max_distortion_px"])
    size_err = float(e["max_blur_size_error_px"])
    illum = float(e["min_relative_illumination"])
    if image_error is not None:
        vignetted = image_error["vignetting_rmse"] >= image_error["shift_rmse"]
    else:
        vignetted = illum < 1.0 - VIGNETTING_TOLERANCE
    numbers = _numbers(near_z_mm, far_z_mm, model, e, blur, tol, vignetting, image_error,
                       max_real, shape_err)
    reasons = []

    def check(name, value, limit, unit="px"):
        ok = value < limit
        reasons.append(f"{name} {value:.3g} {unit} {'<' if ok else '>='} {limit:.3g} {unit}")
        return ok

    vig_ok = not (vignetted and vignetting)
    vig_text = _vignetting_text(illum, vignetted, vignetting, tol, image_error)
    reasons.append(f"depth range {numbers['near_distance_mm'] / 1000:.3g} m to "
                   + ("infinity" if math.isinf(far_z_mm)
                      else f"{numbers['far_distance_mm'] / 1000:.3g} m")
                   + " from the entrance pupil; focus "
                   + ("inside" if blur["focus_inside_range"] else "outside") + " the range")
    pin = [check("pinhole: max thin-lens blur", blur["max_px"], tol),
           check("pinhole: max real spot", max_real, tol),
           check("pinhole: max distortion", dist, tol)]
    reasons.append("pinhole: " + vig_text)
    if all(pin) and vig_ok:
        reasons.append("-> pinhole: every deviation from a sharp pinhole view is under the budget")
        return Decision("pinhole", 1, reasons, numbers)
    b_max = max(blur["max_px"], max_real)
    samples = samples_for_blur(b_max)
    numbers["max_blur_px"] = b_max
    fb = [check("focal-blur: max distortion", dist, tol),
          check("focal-blur: max blur size error / 2 (the rim moves by half the diameter "
                "error)", size_err / 2, tol),
          check("focal-blur: max blur shape error / 2 (the long axis reaches beyond the "
                "disc by half on each side)", shape_err / 2, tol)]
    reasons.append("focal-blur: " + vig_text)
    floor_share = 0.0
    if image_error is not None and vignetting and image_error["shift_rmse"] > 0:
        floor_share = image_error["vignetting_rmse"] / image_error["shift_rmse"]
    numbers["vignetting_floor_share"] = floor_share
    if all(fb) and vig_ok and samples == MIN_SAMPLES and floor_share >= VIGNETTING_FLOOR_SHARE:
        reasons.append(
            f"-> mesh: the equivalent thin lens is within the budget, but leaving out the "
            f"vignetting alone uses {floor_share:.2f} of it (>= {VIGNETTING_FLOOR_SHARE:g}: no "
            f"focal_blur sample count goes below that error), and the {b_max:.3g} px blur "
            f"needs only the minimum {MIN_SAMPLES} lens samples, which cost about what the "
            f"adaptive focal blur does, without the floor")
        return Decision("mesh", samples, reasons, numbers)
    if all(fb) and vig_ok:
        fbs = FOCAL_BLUR_ADAPTIVE
        numbers["blur_rule_samples"] = samples
        reasons.append(f"-> focal-blur: the equivalent thin lens is within the budget; POV-Ray's "
                       f"adaptive focal blur, {fbs.min_samples} to {fbs.max_samples} "
                       f"samples per pixel (confidence {fbs.confidence:g}, variance "
                       f"{fbs.variance:g}): sharp pixels stop at the minimum, the "
                       f"{b_max:.3g} px blur would need {samples} mesh samples "
                       f"({SAMPLE_RULE})")
        return Decision("focal-blur", fbs.max_samples, reasons, numbers, focal_blur=fbs)
    reasons.append(f"-> mesh: the real lens deviates from the equivalent thin lens beyond the "
                   f"budget; {samples} samples for a {b_max:.3g} px blur ({SAMPLE_RULE})")
    return Decision("mesh", samples, reasons, numbers)


def film_radius_map_mm(film, width_px: int, height_px: int) -> np.ndarray:
    """(H, W) film radius (mm) of the pixel centres of an image of ``film``'s frame
    at ``width_px`` x ``height_px`` pixels (the depth probe's size)."""
    cols = (np.arange(width_px) + 0.5) / width_px - 0.5
    rows = (np.arange(height_px) + 0.5) / height_px - 0.5
    return np.hypot(cols[None, :] * film.width_mm, rows[:, None] * film.height_mm)


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


def probe_image_error(image: np.ndarray, film, model_error: dict, tolerance_px: float) -> dict:
    """{vignetting_rmse, shift_rmse} of the depth probe's view ``image`` (H, W, 3)
    of ``film``'s frame: the relative illumination of ``model_error`` (over film
    height, first depth: from the pupil table it does not depend on depth),
    interpolated at each pixel's film radius; the tolerance in film pixels
    converted to the probe's pixels."""
    h, w = image.shape[:2]
    heights = np.asarray(model_error["film_height_mm"], dtype=float)
    ri = np.asarray(model_error["relative_illumination"], dtype=float)[0]
    ri_map = np.interp(film_radius_map_mm(film, w, h), heights, ri)
    return {"vignetting_rmse": vignetting_rmse(image, ri_map),
            "shift_rmse": shift_rmse(image, tolerance_px * w / film.width_px)}
