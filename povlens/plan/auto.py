"""``--method auto``: choose the cheapest render method within an error budget.

The choice is made from measurements, not guesses:

1. **Depth range** — :func:`start_depth_probe` renders a small pinhole depth
   probe (:mod:`povlens.depth_probe`: two fogged POV-Ray renders, run at the
   same time) of the plan's own camera (``povray_camera``: the same film in mm,
   so the same view) at most 64 pixels wide, in a temporary folder in OUTDIR.
   :func:`povlens.convert.convert` starts it before it builds the pupil table and
   measures the plan's model error, and collects it after.  Near and far are
   robust percentiles (1st / 99th) of the
   axial distances of the pixels that hit something; if more than 1 % of the
   pixels see background, far is infinity.  Depths are converted to camera-frame
   z in mm (the thin-lens model's frame: ``centre_z_mm + axial distance``).
2. **Model error over that range** — :func:`povlens.thin_lens.measure_model_error`
   with the exact tracer through the pupil at depths spanning [near, far], with
   the plan's exit-pupil table (built once, kept in OUTDIR/pupil.npz).
3. **Decision** — :func:`decide`, pure:

   * ``pinhole`` when the thin-lens circle of confusion over [near, far], the
     real spot size (aberrations), the distortion and the vignetting all stay
     under the budget (a pinhole camera has the model's projection too);
   * ``focal-blur`` when the real lens's deviations from the equivalent thin lens
     stay under the budget.  Each is measured as how far light lands from where
     the model puts it (pixels): distortion, the displacement of the spot's
     centroid; blur size, half the difference of the equivalent-disc diameters
     (a disc scaled from diameter D to D + d moves its rim by d / 2 and no point
     further); blur shape, half of how far the real spot's long axis reaches
     beyond the equivalent disc (:func:`shape_error_px`, half on each side); and
     vignetting (POV-Ray's focal_blur has none), judged in image terms (below);
   * ``mesh`` otherwise; and also when the thin lens would do but leaving out the
     vignetting alone takes :data:`VIGNETTING_FLOOR_SHARE` of the budget or more
     while the blur needs only the minimum mesh sample count: focal_blur's error
     cannot go below that floor, and a minimum mesh render costs about what the
     adaptive focal blur does.

   **Vignetting in image terms.**  Vignetting is not a displacement, so it is
   judged by its effect on this scene's image: the probe also renders the view
   without fog (the scene as a pinhole camera sees it, at the probe's size), and
   leaving the vignetting out is a deviation when its image RMSE,
   RMS(I (1 - E/E0)) with the lens's relative illumination E/E0 at each pixel
   (:func:`vignetting_rmse`), is at least the RMSE of moving the same image by
   the tolerance (:func:`shift_rmse`, the budget in image terms; ``povlens bench
   --auto`` uses the same definition).  Measured on the bundled scenes and
   lenses (64x48 probe; benchmarks/results/auto.*), the vignetting RMSE predicts
   the error floor of a 256-sample focal_blur render against the 256-sample mesh
   reference within 3 % where vignetting dominates that floor (paper.pov with
   cooke.triplet.50mm 0.0318 against 0.0327, dgauss.50mm 0.2097 against 0.2096;
   chart.pov with cooke.triplet.50mm 0.135 against 0.141).  Vignetting that is
   not wanted (``--no-vignetting``) is no deviation.

   **Samples.**  With N stratified lens samples, the N copies of a point blurred
   into a disc of diameter b pixels lie about ``b sqrt(pi/4) / sqrt(N)`` pixels
   apart.  The target noise is that these copies are at most
   :data:`SAMPLE_SPACING_PX` (1 pixel) apart, so they blend instead of showing
   as separate copies / structured noise:
   ``N = ceil(K b_max^2)`` with ``K = (pi/4) / SAMPLE_SPACING_PX^2`` and b_max
   the largest blur in pixels (real or model) over the depth range, rounded to
   the nearest power of two (the Sobol lens samples are balanced in blocks of
   2^m) and clamped to 8..256 (:func:`samples_for_blur`).
   Pinhole renders use 1 sample.  A chosen focal_blur uses POV-Ray's adaptive
   sampling instead (:data:`FOCAL_BLUR_ADAPTIVE`: 32 to 256 samples per pixel,
   stopping when POV-Ray's confidence test passes), which needs no
   depth-dependent count, so ``povlens render`` can start it while the probe
   runs (:func:`povlens.convert.convert`, ``speculate``).
4. **Adaptive mesh sampling** (``--adaptive``, off by default) — :func:`adaptive_rows`:
   per band of 8 rows the same rule from the probe's blur, thin-lens or real
   spot, whichever is larger (floor 8), and
   :func:`sample_row_ranges`: sample k renders only the rows of the bands that
   need more than k samples (+SR/+ER); the composite divides each pixel by its own
   sample count.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

__all__ = ["FOCAL_BLUR_ADAPTIVE", "decide", "shape_error_px", "vignetting_rmse", "shift_rmse",
           "probe_image_error", "film_radius_map_mm", "real_blur_at", "real_blur_model_error", "blur_range_px", "measure_depth_range", "choose_method", "adaptive_rows",
           "measure_depth_map", "start_depth_probe", "probe_axial_mm", "sample_row_ranges",
           "model_depths", "SAMPLE_K", "MIN_SAMPLES", "MAX_SAMPLES", "VIGNETTING_TOLERANCE",
           "STRONG_VIGNETTING", "VIGNETTING_FLOOR_SHARE", "samples_for_blur", "SAMPLE_RULE"]

#: Largest spacing in pixels between the film copies of one blurred point (target noise).
SAMPLE_SPACING_PX = 1.0
#: Samples per squared pixel of blur diameter: (pi/4) / spacing^2.
SAMPLE_K = (math.pi / 4) / SAMPLE_SPACING_PX ** 2
MIN_SAMPLES, MAX_SAMPLES = 8, 256
SAMPLE_RULE = (f"N = ceil({SAMPLE_K:.3g} b^2) rounded to the nearest power of two, "
               f"{MIN_SAMPLES}..{MAX_SAMPLES}")
#: Share of the error budget (image RMSE of a ``--tolerance`` move) that leaving
#: out the vignetting may take before :func:`decide` prefers a mesh render of the
#: minimum sample count to a focal_blur the thin lens would otherwise allow.  No
#: focal_blur sample count brings its error below that floor, and a mesh render of
#: :data:`MIN_SAMPLES` costs about what the adaptive focal blur does (paper.pov,
#: 160x120: 1.12-1.14 s against 1.04-1.16 s; since the integer mesh vertices of
#: 2026-11-29, 0.88-0.97 s for fixed 8-sample renders with cooke.triplet.50mm and
#: tessar.50mm against 1.15-1.27 s for auto's focal blur with telephoto.250mm and
#: wide, benchmarks/results/auto.txt).  Measured on the bundled scenes
#: (benchmarks/results/auto.*; probe share in brackets): where the mesh render
#: was better at equal time, paper.pov with cooke.triplet.50mm (0.76) and
#: tessar.50mm (0.99), 8 mesh samples reached RMSE 0.027 / 0.027 against the
#: focal_blur floor of 0.033 / 0.042; where focal_blur was better, chart.pov with
#: cooke.triplet.50mm (0.32) and tessar.50mm (0.41), 8 mesh samples left 0.18 /
#: 0.18 against focal_blur's 0.146 / 0.173 (the chart's fine texture needs the
#: focal blur's many samples per pixel as anti-aliasing).
VIGNETTING_FLOOR_SHARE = 0.6
#: focal_blur settings of --method auto: POV-Ray's adaptive sampling (at least
#: ``min`` samples per pixel, more until the confidence / variance test passes, at
#: most ``max``).  Sharp pixels stop at the minimum, so no depth-dependent count is
#: needed and the render can start while the depth probe runs.  Chosen on the seven
#: bundled scene / lens pairs auto renders with focal_blur (160x120, against the
#: 256-sample mesh references of ``povlens bench --auto``, noise-corrected RMSE,
#: POV-Ray time, fastest of 2 runs), by the time fixed ``blur_samples N, N``
#: (N = 32, 64, 128) needs for the same RMSE: ``32, 256`` took 0.65-0.82 of it on
#: all seven (chart.pov / tessar.50mm 0.85 s at RMSE 0.173, where fixed needs
#: ~1.09 s), ``16, 256`` 0.67-1.27 (chart / tessar 0.80 s at 0.206 against ~0.63 s),
#: and confidence 0.99 / variance 1/1000 missed the budget on paper.pov /
#: telephoto.250mm (RMSE 0.0084 against 0.0072; these settings 0.0064).
FOCAL_BLUR_ADAPTIVE = {"min": 32, "max": 256, "confidence": 0.99, "variance": 1.0 / 10000}
#: Without the probe's image (:func:`decide` without ``image_error``): relative
#: illumination below 1 - this counts as vignetting focal_blur cannot render.
VIGNETTING_TOLERANCE = 0.05
#: Relative illumination below which povlens render guesses, before the probe is
#: in, that the vignetting rules out the views (work started early only).  On the
#: bundled scenes every lens below it (0.28-0.33: dgauss.50mm, wide.22mm, the
#: singlet, the fisheye) ended as mesh, every lens above it (0.71-0.98) either way.
STRONG_VIGNETTING = 0.5
#: Probe image width (pixels) and percentiles for near / far.
PROBE_WIDTH = 64
NEAR_PERCENTILE, FAR_PERCENTILE = 1.0, 99.0
#: Far is infinity when more than this fraction of the probe's pixels see background.
BACKGROUND_FRACTION = 0.01


def samples_for_blur(blur_px: float, n_min: int = MIN_SAMPLES, n_max: int = MAX_SAMPLES) -> int:
    """Lens samples for a largest blur of ``blur_px`` pixels: ``ceil(SAMPLE_K b^2)``
    (copies of a blurred point at most :data:`SAMPLE_SPACING_PX` apart), rounded to
    the nearest power of two (in log2) and clamped to ``[n_min, n_max]``.

    Powers of two because the lens samples are a scrambled Sobol sequence
    (:mod:`povlens.sampling`), whose points are balanced only in blocks of 2^m: a
    count between two powers stratifies no better than the lower power.
    Measured (paper.pov, the 100 mm dgauss table, 160x120): 42 samples reached RMSE
    0.0136, where 32 and 64 reached 0.0150 and 0.0102, which is what about 38
    samples would reach interpolating between them."""
    b = float(blur_px)
    k = SAMPLE_K * b * b if abs(b) < 1e9 else math.inf
    if not math.isfinite(k) or k > n_max:
        return int(max(n_min, n_max))
    n = 2 ** round(math.log2(max(1, math.ceil(k))))
    return int(min(n_max, max(n_min, n)))


def blur_range_px(model, near_z_mm: float, far_z_mm: float, pixel_pitch_mm: float) -> dict:
    """Thin-lens blur diameter in pixels at near, far and its max / min over the range.

    The blur |d - s| / d is monotone on each side of the focus s, so its maximum
    over [near, far] is at an end (far = inf: the limit pupil v / s)."""
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
    ``blur_real_px`` of :func:`povlens.thin_lens.measure_model_error`); a uniform
    disc of diameter D has variance D^2 / 16 along any axis, so the extent along an
    axis of variance l is 4 sqrt(l).  The disc of the same RMS has l = rho^2 / 2 on
    both axes; the real spot's long axis, with e = sqrt(l_max / l_min), is
    4 rho e / sqrt(1 + e^2).  Their difference:

        shape error = b (sqrt(2) e / sqrt(1 + e^2) - 1),

    0 for a round spot, at most (sqrt(2) - 1) b for a line.  (Until 2026-11 this
    was (e - 1) b, which grows without bound with e: a 0.4 px spot of elongation
    5 counted as 1.66 px.)"""
    b = np.asarray(blur_real_px, dtype=float)
    e = np.asarray(elongation, dtype=float)
    return b * (math.sqrt(2.0) * e / np.sqrt(1.0 + e * e) - 1.0)


def decide(*, near_z_mm: float, far_z_mm: float, model, model_error: dict,
           pixel_pitch_mm: float, tolerance_px: float = 0.5, vignetting: bool = True,
           image_error: dict | None = None) -> dict:
    """Pure decision: {method, samples, reasons, numbers}.

    ``model_error`` is :func:`povlens.thin_lens.measure_model_error` measured at
    depths spanning [near, far] (camera-frame mm); ``vignetting`` False means the
    lens's vignetting is not wanted in the image (``--no-vignetting``).

    ``image_error``: {vignetting_rmse, shift_rmse} from the depth probe's view of
    the scene (:func:`vignetting_rmse`, :func:`shift_rmse` by ``tolerance_px``):
    leaving out the vignetting is a deviation when it changes the image more than
    moving it by the tolerance does.  Without it, a relative illumination below
    ``1 - VIGNETTING_TOLERANCE`` anywhere is a deviation."""
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
    numbers = {
        "tolerance_px": tol,
        "near_z_mm": near_z_mm, "far_z_mm": far_z_mm,
        "near_distance_mm": near_z_mm - model.centre_z_mm,
        "far_distance_mm": far_z_mm - model.centre_z_mm,
        "blur_near_px": blur["near_px"], "blur_far_px": blur["far_px"],
        "max_model_blur_px": blur["max_px"], "max_real_blur_px": max_real,
        "max_distortion_px": dist, "max_blur_size_error_px": size_err,
        "max_elongation": float(e["max_elongation"]), "max_shape_error_px": shape_err,
        "min_relative_illumination": illum, "vignetting_wanted": bool(vignetting),
        **({f"image_{k}": float(v) for k, v in image_error.items()} if image_error else {}),
        "model_depths_z_mm": list(e.get("object_z_mm", [])),
        "sample_k": SAMPLE_K,
    }
    reasons = []

    def check(name, value, limit, unit="px"):
        ok = value < limit
        reasons.append(f"{name} {value:.3g} {unit} {'<' if ok else '>='} {limit:.3g} {unit}")
        return ok

    vig_ok = not (vignetted and vignetting)
    if image_error is not None:
        v, b = image_error["vignetting_rmse"], image_error["shift_rmse"]
        vig_text = (f"relative illumination >= {illum:.3f} of the centre; leaving it out "
                    f"changes the probe's image by RMSE {v:.3g}, "
                    f"{'at least' if vignetted else 'less than'} the {b:.3g} of a "
                    f"{tol:.3g} px move")
    else:
        vig_text = (f"relative illumination >= {illum:.3f} of the centre "
                    f"({'below' if vignetted else 'not below'} {1 - VIGNETTING_TOLERANCE:.2f})")
    if vignetted and not vignetting:
        vig_text += "; vignetting not wanted (--no-vignetting), so not a deviation"
    elif vignetted:
        vig_text += "; POV-Ray's pinhole and focal_blur cameras have none: a deviation"

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
        return {"method": "pinhole", "samples": 1, "reasons": reasons, "numbers": numbers}
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
        return {"method": "mesh", "samples": samples, "reasons": reasons, "numbers": numbers}
    if all(fb) and vig_ok:
        fb_settings = dict(FOCAL_BLUR_ADAPTIVE)
        numbers["blur_rule_samples"] = samples
        reasons.append(f"-> focal-blur: the equivalent thin lens is within the budget; POV-Ray's "
                       f"adaptive focal blur, {fb_settings['min']} to {fb_settings['max']} "
                       f"samples per pixel (confidence {fb_settings['confidence']:g}, variance "
                       f"{fb_settings['variance']:g}): sharp pixels stop at the minimum, the "
                       f"{b_max:.3g} px blur would need {samples} mesh samples "
                       f"({SAMPLE_RULE})")
        return {"method": "focal-blur", "samples": fb_settings["max"],
                "focal_blur": fb_settings, "reasons": reasons, "numbers": numbers}
    reasons.append(f"-> mesh: the real lens deviates from the equivalent thin lens beyond the "
                   f"budget; {samples} samples for a {b_max:.3g} px blur ({SAMPLE_RULE})")
    return {"method": "mesh", "samples": samples, "reasons": reasons, "numbers": numbers}


def film_radius_map_mm(film, width_px: int, height_px: int) -> np.ndarray:
    """(H, W) film radius (mm) of the pixel centres of an image of ``film``'s frame
    at ``width_px`` x ``height_px`` pixels (the depth probe's size)."""
    cols = (np.arange(width_px) + 0.5) / width_px - 0.5
    rows = (np.arange(height_px) + 0.5) / height_px - 0.5
    return np.hypot(cols[None, :] * film.width_mm, rows[:, None] * film.height_mm)


def vignetting_rmse(image: np.ndarray, relative_illumination: np.ndarray) -> float:
    """Image RMSE of leaving out the lens's vignetting: ``image`` (H, W, C) linear,
    the view without vignetting (as POV-Ray's pinhole / focal_blur render it);
    ``relative_illumination`` (H, W) E/E(centre) at each pixel.  The lens's image
    is ``image x relative_illumination`` (both normalised at the centre)."""
    err = image * (1.0 - np.asarray(relative_illumination, dtype=float))[..., None]
    return float(np.sqrt(np.mean(err ** 2)))


def shift_rmse(image: np.ndarray, shift_px: float) -> float:
    """Image RMSE of moving ``image`` (H, W, C) by ``shift_px`` >= 0 pixels: the mean
    over +x, -x, +y, -y of RMSE(image, image moved), sub-pixel moves by linear
    interpolation, a border of ``floor(shift_px) + 1`` pixels excluded (where the
    moved image has no data).  The error budget of ``--tolerance`` in image terms,
    here and in ``povlens bench --auto`` (on its reference).  An image too small
    for the border gives 0."""
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


def _depth_limits(axial_mm: np.ndarray) -> tuple[float, float, dict]:
    """Near / far axial distances (mm) from a probe's per-pixel axial distances."""
    a = np.asarray(axial_mm, dtype=float).ravel()
    finite = a[np.isfinite(a) & (a > 0)]
    bg = 1.0 - finite.size / max(a.size, 1)
    info = {"probe_pixels": int(a.size), "background_fraction": float(bg)}
    if finite.size == 0:
        return math.inf, math.inf, info
    near = float(np.percentile(finite, NEAR_PERCENTILE))
    far = math.inf if bg > BACKGROUND_FRACTION else float(np.percentile(finite, FAR_PERCENTILE))
    info.update({"closest_mm": float(finite.min()), "farthest_finite_mm": float(finite.max())})
    return near, far, info


def probe_size(film) -> tuple[int, int]:
    """(width, height) in pixels of the depth probe of ``film``: at most
    :data:`PROBE_WIDTH` wide, the film's aspect, at least 2 rows."""
    pw = min(PROBE_WIDTH, film.width_px)
    ph = max(2, round(pw * film.height_px / film.width_px))
    return pw, ph


def start_depth_probe(opts, film, plan: dict, threads: int = 1):
    """Start the small pinhole depth probe of ``opts`` (:func:`probe_size` pixels);
    returns a running :class:`povlens.depth_probe.DepthProbe` (collect it with
    :func:`probe_axial_mm`).

    ``plan`` is a plan of ``opts`` (any method, or the part
    :func:`povlens.convert._start_plan` derives): its ``povray_camera`` is the
    probe's, since the probe's film is the same in mm; only the pixels differ.
    Besides the two fogged renders, the view without fog is rendered (``image``
    of the probe: the vignetting's effect on the image) when the lens's vignetting
    is wanted (``opts.vignetting``); with ``--no-vignetting`` nothing reads it, and
    the probe is one POV-Ray process fewer.  The renders run in a temporary folder
    ``.probe.*`` in OUTDIR (``threads`` POV-Ray threads each)."""
    from povlens.plan.depth_probe import start_probe
    pw, ph = probe_size(film)
    out = Path(opts.outdir)
    out.mkdir(parents=True, exist_ok=True)
    probe_plan = {"povray_camera": plan["povray_camera"], "mm_per_unit": plan["mm_per_unit"],
                  "inputs": {"scene": str(Path(opts.scene).resolve()), "focus": opts.focus}}
    return start_probe(probe_plan, out, width=pw, height=ph, threads=threads,
                       keep_wrappers=False, prefix=".probe.", label=str(opts.scene),
                       view=bool(getattr(opts, "vignetting", True)))


def probe_axial_mm(probe) -> np.ndarray:
    """Wait for a :func:`start_depth_probe` probe: per-pixel axial distances (mm, from
    the camera location = entrance pupil; inf for background)."""
    from povlens.plan.depth_probe import axial_depth
    d = probe.result()
    return axial_depth(probe.plan, d) * probe.plan["mm_per_unit"]


def measure_depth_map(opts, film, threads: int | None = None,
                      plan: dict | None = None) -> np.ndarray:
    """Per-pixel axial distances (mm, from the camera location = entrance pupil; inf
    for background) of a small pinhole depth probe (:func:`start_depth_probe`,
    at most :data:`PROBE_WIDTH` pixels wide, same film in mm).  ``plan``: a plan
    of ``opts`` for its camera (default: derived, without a pupil table)."""
    if plan is None:
        from povlens.plan.convert import _start_plan
        st = _start_plan(opts)
        plan = {"povray_camera": st.povray_camera, "mm_per_unit": st.mm_per_unit}
    return probe_axial_mm(start_depth_probe(opts, film, plan, threads=threads or 1))


def measure_depth_range(opts, film, threads: int | None = None,
                        axial_mm: np.ndarray | None = None) -> tuple[float, float, dict]:
    """Near / far axial distances (mm, from the camera location = entrance pupil) of
    what the scene shows, from a small pinhole depth probe (:func:`measure_depth_map`,
    or ``axial_mm`` if given)."""
    axial = measure_depth_map(opts, film, threads) if axial_mm is None else axial_mm
    near, far, info = _depth_limits(axial)
    info.update({"probe_width": int(axial.shape[1]), "probe_height": int(axial.shape[0])})
    return near, far, info


#: Adaptive sampling: rows per band, and the fewest samples any pixel gets (the
#: decision's floor: with 4, sharp bands showed 1.5x the RMSE of 8 on paper.pov,
#: dgauss.50mm, 160x120 -- 0.0366 against 0.0247 -- anti-aliasing needs them).
BAND_ROWS, ADAPTIVE_MIN_SAMPLES = 8, MIN_SAMPLES


def real_blur_at(model_error: dict, model, axial_mm: np.ndarray) -> np.ndarray:
    """Real spot size (px, equivalent-disc diameter, largest over the field) at
    axial distances ``axial_mm`` from the entrance pupil (inf: the farthest depth
    measured), interpolated in log distance between the depths of
    ``model_error`` (:func:`povlens.thin_lens.measure_model_error`), held
    constant beyond them."""
    z = np.asarray(model_error["object_z_mm"], dtype=float) - model.centre_z_mm
    real = np.asarray(model_error["blur_real_px"], dtype=float).max(axis=1)
    order = np.argsort(z)
    z, real = np.log(np.maximum(z[order], 1e-9)), real[order]
    a = np.asarray(axial_mm, dtype=float)
    la = np.log(np.where(np.isfinite(a) & (a > 0), a, np.exp(z[-1])))
    return np.interp(la, z, real)


def real_blur_model_error(lens, plan: dict, model, film, axial_mm: np.ndarray) -> dict:
    """:func:`povlens.thin_lens.measure_model_error` at depths spanning a depth
    probe's range (``axial_mm`` from the entrance pupil), for :func:`real_blur_at`."""
    from povlens.thinlens.model import measure_model_error
    near, far, _ = _depth_limits(axial_mm)
    if math.isinf(near):
        near = far = 1e4 * max(model.focus_distance_mm if math.isfinite(model.focus_distance_mm)
                               else 1e3, 1e3)
    c = model.centre_z_mm
    return measure_model_error(lens, plan["focus"]["film_distance_mm"], model, film,
                               model_depths(model, c + near, c + far))


def adaptive_rows(model, axial_mm: np.ndarray, film, n_max: int, band_rows: int = BAND_ROWS,
                  n_min: int = ADAPTIVE_MIN_SAMPLES, model_error: dict | None = None) -> dict:
    """Samples each band of ``band_rows`` image rows needs, from a depth probe.

    Per probe pixel the blur b (px of ``film``) at its depth: the thin-lens blur,
    or the real spot (:func:`real_blur_at`) where ``model_error`` is given and it
    is larger (aberrations: a fast singlet's spot is far larger than its thin-lens
    blur).  A row's blur is the largest b of any probe pixel within b/2 + 1 rows of
    it (a blurred point spreads over b rows, so light from a blurred neighbour
    counts too); a band's is its rows' maximum; its samples
    :func:`samples_for_blur` ``(b, n_min, n_max)``, the rule of :func:`decide`.
    Returns {band_rows, n_min, band_blur_px, band_samples}.
    """
    a = np.asarray(axial_mm, dtype=float)
    ph = a.shape[0]
    h = film.height_px
    pitch = film.pixel_pitch_mm
    s = model.focus_distance_mm
    inf_blur = (model.pupil_diameter_mm * model.image_distance_mm / s / pitch
                if math.isfinite(s) else 0.0)
    blur = np.full(a.shape, inf_blur)
    fin = np.isfinite(a) & (a > 0)
    if fin.any():
        blur[fin] = model.blur_diameter_mm(model.centre_z_mm + a[fin]) / pitch
    if model_error is not None:
        blur = np.maximum(blur, real_blur_at(model_error, model, a))
    probe_row_blur = blur.max(axis=1)                       # (ph,)
    # film rows covered by probe row i: [i h / ph, (i + 1) h / ph)
    row_blur = np.zeros(h)
    for i, b in enumerate(probe_row_blur):
        r0 = math.floor(i * h / ph)
        r1 = math.ceil((i + 1) * h / ph)
        reach = math.ceil(b / 2) + 1
        lo, hi = max(0, r0 - reach), min(h, r1 + reach)
        row_blur[lo:hi] = np.maximum(row_blur[lo:hi], b)
    nb = math.ceil(h / band_rows)
    band_blur = [float(row_blur[j * band_rows:(j + 1) * band_rows].max()) for j in range(nb)]
    n_min = max(1, min(int(n_min), int(n_max)))
    band_samples = [samples_for_blur(b, n_min, n_max) for b in band_blur]
    return {"band_rows": int(band_rows), "n_min": n_min, "band_blur_px": band_blur,
            "band_samples": band_samples}


def sample_row_ranges(adaptive: dict, height: int) -> list[list[int]]:
    """Film rows [start, end) each sample renders: samples below n_min the whole
    frame, sample k the rows from the first to the last band needing more than k
    samples (POV-Ray renders one row range per frame).  Length = max band samples."""
    br, need = adaptive["band_rows"], adaptive["band_samples"]
    rows = []
    for k in range(max(need)):
        if k < adaptive["n_min"]:
            rows.append([0, height])
            continue
        bands = [j for j, n in enumerate(need) if n > k]
        rows.append([bands[0] * br, min(height, (bands[-1] + 1) * br)])
    return rows


def choose_method(opts, plan: dict, model, lens, film, *, probe=None,
                  pupil_table=None) -> dict:
    """Measure the scene's depth range and the model error over it, and decide.

    ``plan`` / ``model`` / ``lens`` / ``film`` are those of ``opts`` (any method).
    ``probe``: the depth probe, already started (:func:`start_depth_probe`;
    default: started here).  ``pupil_table``: the plan's exit-pupil table (default:
    OUTDIR/pupil.npz if current, else built)."""
    from povlens.thinlens.model import measure_model_error
    if probe is None:
        probe = start_depth_probe(opts, film, plan)
    fd = plan["focus"]["film_distance_mm"]
    table = pupil_table
    try:
        if table is None:  # exact vignetting; normally saved by the plan
            from povlens.pupil.table import build_pupil_table, load_if_current
            table = load_if_current(Path(opts.outdir) / "pupil.npz", lens, fd,
                                    film.half_diagonal_mm)
            if table is None:
                table = build_pupil_table(lens, fd, film.half_diagonal_mm)
    except BaseException:
        probe.cancel()
        raise
    axial = probe_axial_mm(probe)
    near_d, far_d, info = measure_depth_range(opts, film, axial_mm=axial)
    if math.isinf(near_d):  # nothing but background: everything at infinity
        near_d = 1e4 * max(model.focus_distance_mm if math.isfinite(model.focus_distance_mm)
                           else 1e3, 1e3)
    c = model.centre_z_mm
    near_z, far_z = c + near_d, c + far_d
    depths = model_depths(model, near_z, far_z)
    err = measure_model_error(lens, fd, model, film, depths, pupil_table=table)
    image_error = None
    if probe.image is not None:
        image_error = probe_image_error(probe.image, film, err, opts.tolerance_px)
    d = decide(near_z_mm=near_z, far_z_mm=far_z, model=model, model_error=err,
               pixel_pitch_mm=film.pixel_pitch_mm, tolerance_px=opts.tolerance_px,
               vignetting=opts.vignetting, image_error=image_error)
    d["numbers"]["depth_probe"] = info
    if getattr(opts, "adaptive", False):
        d["adaptive"] = adaptive_rows(model, axial, film, d["samples"], model_error=err)
    return d
