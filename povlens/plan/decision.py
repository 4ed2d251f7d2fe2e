"""The decision of ``--method auto``: the cheapest render method within an error budget.

:func:`decide` is pure: from the scene's depth range (a depth probe,
:mod:`povlens.plan.auto`) and the thin-lens model's measured error over it
(:func:`povlens.thinlens.model_error.measure_model_error`) it chooses

* ``pinhole`` when the thin-lens circle of confusion over [near, far], the real
  spot size (aberrations) and the distortion all stay under the budget (a pinhole
  camera has the model's projection too);
* ``focal-blur`` when the real lens's deviations from the equivalent thin lens
  stay under the budget.  Each is measured as how far light lands from where the
  model puts it (pixels): distortion, the displacement of the spot's centroid;
  blur size, half the difference of the equivalent-disc diameters (a disc scaled
  from diameter D to D + d moves its rim by d / 2 and no point further); blur
  shape, half of how far the real spot's long axis reaches beyond the equivalent
  disc (:func:`shape_error_px`, half on each side); and the cat's eye (below);
* ``mesh`` otherwise; and also when the thin lens would do but the cat's eye alone
  takes :data:`VIGNETTING_FLOOR_SHARE` of the budget or more while the blur needs
  only the minimum mesh sample count: focal_blur's error cannot go below that
  floor, and a minimum mesh render costs about what the adaptive focal blur does.

**Vignetting: applied as a map.**  The pinhole and focal_blur views are multiplied
by the lens's relative illumination E(pixel)/E(centre), exact from the exit-pupil
table (:mod:`povlens.rendering.vignetting`, :mod:`povlens.pupil.illumination`):
where the image is sharp that is what the lens records, so the brightness falloff
rules out neither view.  What a per-pixel factor cannot carry is the shape of
out-of-focus light: a point blurred into a disc of b pixels is, on the real lens,
the pass region of its pixel (the cat's eye off axis, clipped by the rims; the
pupil's off-axis growth or shift too) scaled to b, where focal_blur draws the axial
disc.  It is judged in image terms, on the probe's own view of the scene, as the
vignetting was before: :func:`catseye_rmse` blurs that image at each pixel with
both kernels -- the pixel's real pass region and the axial one, scaled to the
pixel's thin-lens blur at the depth the probe measured there -- and the RMSE of
their difference (what the map leaves out) is a deviation when it is at least the
RMSE of moving the image by the tolerance (:func:`shift_rmse`, the budget in image
terms; ``povlens bench --auto`` uses the same definition).  In focus (b = 0) both
kernels are a point: no error, whatever the vignetting.  Without the probe's image
the cat's eye is judged in pixels, ``b x cut`` over the model's depths and field
heights (:func:`pupil_cut`, :func:`catseye_px`); without the pupil either, a
relative illumination below ``1 - VIGNETTING_TOLERANCE`` counts as a deviation
(nothing known).  Vignetting that is not wanted (``--no-vignetting``) is no
deviation.  Numbers and the derivation: docs/decisions/planning.md ("Vignetting
applied as a map").

**Samples.**  ``N = ceil(K b_max)`` with K = :data:`SAMPLES_PER_BLUR_PX` (2) and
b_max the largest blur diameter in pixels (real or model) over the depth range,
rounded to the nearest power of two (the Sobol lens samples are balanced in blocks of
2^m) and clamped to 8..256 (:func:`samples_for_blur`).  Fitted to what the eye sees
(``benchmarks/fit_sample_rule.py``, docs/decisions/exact-images.md): on 2 scenes x 3
lenses at 640x480 and dgauss.50mm at 1920x1080 the default mesh render reaches the
budget -- the FLIP of moving a converged render by the 0.5 px tolerance -- at N* =
0.5-1.6 b (a law in b fits these seven; the earlier ``0.785 b^2``, copies of a
blurred point 1 px apart, gave 4-30x the samples needed), and K = 2 with the rounding
meets every one.
Pinhole renders use 1 sample.  A chosen focal_blur uses POV-Ray's adaptive
sampling instead (:data:`FOCAL_BLUR_ADAPTIVE`), which needs no depth-dependent
count, so ``povlens render`` can start it while the probe runs
(:mod:`povlens.plan.speculative`).
"""

from __future__ import annotations

import math

import numpy as np

from povlens.lens.film import Film
from povlens.lens.tracer import trace_from_film
from povlens.plan.schema import Decision, FocalBlurSettings
from povlens.pupil.illumination import relative_illumination_map
from povlens.pupil.monte_carlo import sobol_points

__all__ = ["FOCAL_BLUR_ADAPTIVE", "decide", "shape_error_px", "vignetting_rmse", "shift_rmse",
           "probe_image_error", "film_radius_map_mm", "blur_range_px", "model_depths",
           "samples_for_blur", "pupil_cut", "shift_tilt_cos", "catseye_px", "catseye_rmse",
           "pixel_blur_mm",
           "SAMPLES_PER_BLUR_PX", "MIN_SAMPLES", "MAX_SAMPLES", "SAMPLE_RULE",
           "VIGNETTING_TOLERANCE", "STRONG_VIGNETTING", "VIGNETTING_FLOOR_SHARE",
           "CATSEYE_SAMPLES", "CATSEYE_RADII"]

#: Lens samples per pixel of the largest blur diameter: the least that reaches the FLIP
#: of a 0.5 px move on every measured scene and lens (docs/decisions/exact-images.md).
SAMPLES_PER_BLUR_PX = 2.0
MIN_SAMPLES, MAX_SAMPLES = 8, 256
SAMPLE_RULE = (f"N = ceil({SAMPLES_PER_BLUR_PX:g} b) rounded to the nearest power of two, "
               f"{MIN_SAMPLES}..{MAX_SAMPLES}")
#: Share of the error budget that what the vignetting map cannot carry (the cat's
#: eye, :func:`catseye_rmse`) may take before :func:`decide` prefers a minimum mesh
#: render to a focal_blur the thin lens allows: no focal_blur sample count goes below
#: that floor (measurements: docs/decisions/planning.md, "Vignetting floor", where it
#: was the vignetting itself, and "Vignetting applied as a map").
VIGNETTING_FLOOR_SHARE = 0.6
#: Lens samples per probe pixel of :func:`catseye_rmse`'s two kernels, and the film
#: radii they are traced at (rotated to each pixel's azimuth, linear between radii).
CATSEYE_SAMPLES = 64
CATSEYE_RADII = 65
#: focal_blur sampling of --method auto: POV-Ray's adaptive sampling (sharp pixels stop
#: at the minimum, so no depth-dependent count is needed; docs/decisions/planning.md).
FOCAL_BLUR_ADAPTIVE = FocalBlurSettings(min_samples=32, max_samples=256, confidence=0.99,
                                        variance=1.0 / 10000)
#: Without the probe's image and the pupil's cut (:func:`decide` without
#: ``image_error`` or ``catseye``): relative illumination below 1 - this counts as
#: vignetting the views cannot carry (nothing tells what the map leaves out).
VIGNETTING_TOLERANCE = 0.05
#: Relative illumination below which povlens render guesses, before the probe is in,
#: that the cat's eye may rule out focal_blur (work started early only:
#: :mod:`povlens.plan.speculative`).
STRONG_VIGNETTING = 0.5


def samples_for_blur(blur_px: float, n_min: int = MIN_SAMPLES, n_max: int = MAX_SAMPLES) -> int:
    """Lens samples for a largest blur of ``blur_px`` pixels.

    ``ceil(SAMPLES_PER_BLUR_PX b)`` (fitted to FLIP: module docstring), rounded to
    the nearest power of two (in log2) and clamped to ``[n_min, n_max]``.  Powers of two because the lens
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
    k = SAMPLES_PER_BLUR_PX * abs(b) if abs(b) < 1e9 else math.inf
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


def _catseye_judgement(e: dict, tol: float, wanted: bool, image_error: dict | None,
                       catseye: dict | None) -> tuple[bool, str, dict]:
    """Whether what the vignetting map cannot carry rules out focal_blur, the reason
    text, and its numbers (see the module docstring)."""
    illum = float(e["min_relative_illumination"])
    head = (f"vignetting: applied as a map (relative illumination >= {illum:.3f} of the "
            f"centre, exact from the exit-pupil table)")
    numbers: dict = {}
    if image_error is not None and "vignetting_rmse" in image_error:
        head += (f"; leaving it out would change the probe's image by RMSE "
                 f"{image_error['vignetting_rmse']:.3g}")
    if catseye is not None:
        numbers["max_catseye_px"] = catseye_px(e, catseye)
        numbers["max_pupil_cut"] = float(np.max(catseye["cut"]))
    if not wanted:
        return False, (head.replace("applied as a map", "not wanted (--no-vignetting)")
                       + "; not applied, and its cat's eye is not a deviation"), numbers
    if image_error is not None and "catseye_rmse" in image_error:
        c, b = image_error["catseye_rmse"], image_error["shift_rmse"]
        bad = c >= b and c > 0          # a flat image: nothing moves, nothing to judge
        text = (f"; what the map cannot carry, the cat's-eye shape of out-of-focus light, "
                f"changes it by RMSE {c:.3g}, {'at least' if bad else 'less than'} the "
                f"{b:.3g} of a {tol:.3g} px move")
    elif catseye is not None:
        d = numbers["max_catseye_px"]
        bad = d >= tol
        text = (f"; what the map cannot carry, the cat's eye of out-of-focus light (blur x "
                f"pupil cut, up to {numbers['max_pupil_cut']:.3g}), reaches {d:.3g} px "
                f"{'>=' if bad else '<'} {tol:.3g} px (without the probe's image)")
    else:
        bad = illum < 1.0 - VIGNETTING_TOLERANCE
        text = ("; without the probe's image or the pupil's cut, what the map cannot carry "
                f"is not known: judged by the relative illumination, "
                f"{'below' if bad else 'not below'} {1 - VIGNETTING_TOLERANCE:.2f}")
    if bad:
        text += ": a deviation"
    return bad, head + text, numbers


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
        "vignetting": "applied as a map" if vignetting else "not wanted",
        **({f"image_{k}": float(v) for k, v in image_error.items()} if image_error else {}),
        "model_depths_z_mm": list(e.get("object_z_mm", [])),
        "samples_per_blur_px": SAMPLES_PER_BLUR_PX,
    }


def _aperture_shape_check(aperture_shape: str | None, reasons: list, fb: list) -> None:
    """A shaped stop rules focal_blur out (it samples a round aperture only)."""
    if aperture_shape:
        reasons.append(f"focal-blur: cannot draw the aperture shape ({aperture_shape}); "
                       f"the blur is visible")
        fb.append(False)


def _focal_blur_checks(check, tol: float, dist: float, size_err: float, shape_err: float,
                       blur_px: float, shift_tilt_cos: float, numbers: dict) -> list:
    """focal_blur's geometric checks (distortion, blur size and shape, and with a lens
    shift the width the tilted disc loses, ``blur_px`` x (1 - cos) / 2): passed flags."""
    fb = [check("focal-blur: max distortion", dist, tol),
          check("focal-blur: max blur size error / 2 (the rim moves by half the diameter "
                "error)", size_err / 2, tol),
          check("focal-blur: max blur shape error / 2 (the long axis reaches beyond the "
                "disc by half on each side)", shape_err / 2, tol)]
    if shift_tilt_cos < 1.0:
        tilt_deg = math.degrees(math.acos(max(-1.0, min(1.0, shift_tilt_cos))))
        numbers["shift_tilt_deg"] = tilt_deg
        fb.append(check(f"focal-blur: lens shift: the disc, tilted {tilt_deg:.2g} deg, is "
                        f"narrower along the shift by the blur x (1 - cos) / 2",
                        blur_px * (1.0 - shift_tilt_cos) / 2, tol))
    return fb


def decide(*, near_z_mm: float, far_z_mm: float, model, model_error: dict,
           pixel_pitch_mm: float, tolerance_px: float = 0.5, vignetting: bool = True,
           image_error: dict | None = None, catseye: dict | None = None,
           aperture_shape: str | None = None,
           shift_tilt_cos: float = 1.0) -> Decision:
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
    image_error : from the depth probe's view of the scene (:func:`probe_image_error`):
        ``shift_rmse`` (the budget in image terms), ``vignetting_rmse`` (what the map
        applies, for the record) and ``catseye_rmse`` (what it cannot carry: a
        deviation when at least ``shift_rmse``).
    catseye : :func:`pupil_cut` of the lens's pupil, for the pixel measure when the
        image gives no ``catseye_rmse``.  Without either, a relative illumination
        below ``1 - VIGNETTING_TOLERANCE`` anywhere is a deviation.
    aperture_shape : a few words on a shaped stop (iris, mask;
        :func:`povlens.plan.aperture.describe`), which focal_blur cannot draw: with a
        visible blur the render is mesh.
    shift_tilt_cos : with a lens shift, cos of the angle between POV-Ray's tilted
        ``direction`` and the axis (:func:`shift_tilt_cos`): focal_blur's lens disc is
        perpendicular to that direction, so its blur is this much narrower along the
        shift, and half the lost diameter counts against the budget.  1: no shift.

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
    numbers = _numbers(near_z_mm, far_z_mm, model, e, blur, tol, vignetting, image_error,
                       max_real, shape_err)
    catseye_bad, vig_text, vig_numbers = _catseye_judgement(e, tol, vignetting, image_error,
                                                            catseye)
    numbers.update(vig_numbers)
    reasons = []

    def check(name, value, limit, unit="px"):
        ok = value < limit
        reasons.append(f"{name} {value:.3g} {unit} {'<' if ok else '>='} {limit:.3g} {unit}")
        return ok

    reasons.append(f"depth range {numbers['near_distance_mm'] / 1000:.3g} m to "
                   + ("infinity" if math.isinf(far_z_mm)
                      else f"{numbers['far_distance_mm'] / 1000:.3g} m")
                   + " from the entrance pupil; focus "
                   + ("inside" if blur["focus_inside_range"] else "outside") + " the range")
    pin = [check("pinhole: max thin-lens blur", blur["max_px"], tol),
           check("pinhole: max real spot", max_real, tol),
           check("pinhole: max distortion", dist, tol)]
    illum = float(e["min_relative_illumination"])
    reasons.append(f"pinhole: vignetting (relative illumination >= {illum:.3f} of the centre): "
                   + ("applied as a map, exact: the view has no blur" if vignetting
                      else "not wanted (--no-vignetting)"))
    if all(pin):
        reasons.append("-> pinhole: every deviation from a sharp pinhole view is under the budget"
                       + ("; the lens's vignetting is applied as a map" if vignetting else ""))
        return Decision("pinhole", 1, reasons, numbers)
    b_max = max(blur["max_px"], max_real)
    samples = samples_for_blur(b_max)
    numbers["max_blur_px"] = b_max
    fb = _focal_blur_checks(check, tol, dist, size_err, shape_err, b_max, shift_tilt_cos, numbers)
    reasons.append("focal-blur: " + vig_text)
    _aperture_shape_check(aperture_shape, reasons, fb)
    floor_share = 0.0
    if (image_error is not None and vignetting and image_error.get("shift_rmse", 0) > 0
            and "catseye_rmse" in image_error):
        floor_share = image_error["catseye_rmse"] / image_error["shift_rmse"]
    numbers["vignetting_floor_share"] = floor_share
    fb_ok = all(fb) and not catseye_bad
    if fb_ok and samples == MIN_SAMPLES and floor_share >= VIGNETTING_FLOOR_SHARE:
        reasons.append(
            f"-> mesh: the equivalent thin lens with the vignetting map is within the budget, "
            f"but what the map cannot carry (the cat's eye) uses {floor_share:.2f} of it "
            f"(>= {VIGNETTING_FLOOR_SHARE:g}: no focal_blur sample count goes below that "
            f"error), and the {b_max:.3g} px blur needs only the minimum {MIN_SAMPLES} lens "
            f"samples, which cost about what the adaptive focal blur does, without the floor")
        return Decision("mesh", samples, reasons, numbers)
    if fb_ok:
        fbs = FOCAL_BLUR_ADAPTIVE
        numbers["blur_rule_samples"] = samples
        reasons.append("-> focal-blur: the equivalent thin lens is within the budget"
                       + ("; the lens's vignetting is applied as a map" if vignetting else "")
                       + f"; POV-Ray's adaptive focal blur, {fbs.min_samples} to "
                       f"{fbs.max_samples} samples per pixel (confidence {fbs.confidence:g}, "
                       f"variance {fbs.variance:g}): sharp pixels stop at the minimum, the "
                       f"{b_max:.3g} px blur would need {samples} mesh samples ({SAMPLE_RULE})")
        return Decision("focal-blur", fbs.max_samples, reasons, numbers, focal_blur=fbs)
    why = ("the cat's eye of out-of-focus light, which the vignetting map cannot carry, "
           "is beyond the budget" if all(fb) else
           f"focal_blur cannot draw the aperture shape ({aperture_shape}) and the blur is "
           f"visible" if aperture_shape and all(fb[:-1]) and not catseye_bad else
           "the real lens deviates from the equivalent thin lens beyond the budget")
    reasons.append(f"-> mesh: {why}; {samples} samples for a {b_max:.3g} px blur "
                   f"({SAMPLE_RULE})")
    return Decision("mesh", samples, reasons, numbers)


def shift_tilt_cos(shift_mm, image_distance_mm: float) -> float:
    """cos of the tilt of POV-Ray's ``direction`` for a film shifted by ``shift_mm``
    (x, y mm on the image plane) behind a thin lens of image distance
    ``image_distance_mm`` (:func:`povlens.plan.fixed.off_axis_direction`); 1 unshifted."""
    sx, sy = (float(v) for v in shift_mm)
    v = abs(float(image_distance_mm))
    return v / math.sqrt(v * v + sx * sx + sy * sy) if (sx or sy) else 1.0


def pupil_cut(profile) -> dict:
    """How much of the axial pupil the pass region lacks at each film radius.

    ``cut(r) = max(0, 1 - w_r(r) / w_r(0), 1 - w_t(r) / w_t(0))`` with w_r, w_t the
    region's exact widths along the film point's radius and across it
    (:class:`povlens.pupil.illumination.IlluminationProfile`): a blur disc of b
    pixels is clipped by up to ``b x cut`` on that side (the cat's eye); the
    pupil's off-axis growth (no clipping) gives 0.

    Returns
    -------
    dict
        ``film_radius_mm`` (m,) and ``cut`` (m,) in [0, 1] (1 where vignetted).
    """
    r = np.asarray(profile.film_radius_mm, dtype=float)
    wr = np.asarray(profile.radial_width_mm, dtype=float)
    wt = np.asarray(profile.tangential_width_mm, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        cut = np.maximum.reduce([np.zeros_like(r), 1.0 - wr / wr[0], 1.0 - wt / wt[0]])
    cut = np.where(np.isfinite(cut), np.clip(cut, 0.0, 1.0), 1.0)
    return {"film_radius_mm": r.tolist(), "cut": cut.tolist()}


def catseye_px(model_error: dict, catseye: dict) -> float:
    """Largest cat's-eye deviation ``b x cut`` (pixels) over the model error's depths
    and film heights: the thin-lens blur at each depth times the pupil cut
    (:func:`pupil_cut`) at each height."""
    b = np.asarray(model_error["blur_model_px"], dtype=float)        # (D, F)
    h = np.asarray(model_error["film_height_mm"], dtype=float)        # (F,)
    cut = np.interp(h, catseye["film_radius_mm"], catseye["cut"])
    return float(np.max(b * cut[None, :])) if b.size else 0.0


def film_radius_map_mm(film, width_px: int, height_px: int) -> np.ndarray:
    """(H, W) film radius (mm) of the pixel centres of an image of ``film``'s frame
    at ``width_px`` x ``height_px`` pixels (the depth probe's size)."""
    cols = (np.arange(width_px) + 0.5) / width_px - 0.5
    rows = 0.5 - (np.arange(height_px) + 0.5) / height_px
    sx, sy = getattr(film, "shift_mm", (0.0, 0.0))          # lens shift (lens.film)
    return np.hypot(cols[None, :] * film.width_mm + sx, rows[:, None] * film.height_mm + sy)


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


def probe_image_error(image: np.ndarray, film, model_error: dict, tolerance_px: float, *,
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
        heights = np.asarray(model_error["film_height_mm"], dtype=float)
        ri = np.asarray(model_error["relative_illumination"], dtype=float)[0]
        ri_map = np.interp(film_radius_map_mm(film, w, h), heights, ri)
    out = {"vignetting_rmse": vignetting_rmse(image, ri_map),
           "shift_rmse": shift_rmse(image, tolerance_px * w / film.width_px)}
    if table is not None and model is not None and axial_mm is not None:
        out["catseye_rmse"] = catseye_rmse(image, film, table, model, axial_mm)
    return out
