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
vignetting was before (:mod:`povlens.plan.image_error`): :func:`catseye_rmse` blurs
that image at each pixel with both kernels -- the pixel's real pass region and the
axial one, scaled to the pixel's thin-lens blur at the depth the probe measured
there -- and the RMSE of their difference (what the map leaves out) is a deviation
when it is at least the RMSE of moving the image by the tolerance
(:func:`shift_rmse`, the budget in image terms; ``povlens bench --auto`` uses the
same definition).  In focus (b = 0) both
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

import dataclasses
import enum
import math

import numpy as np

from povlens.plan.schema import Decision, FocalBlurSettings
from povlens.thinlens.model_error import ModelError

__all__ = ["FOCAL_BLUR_ADAPTIVE", "decide", "Check", "VignettingCheck", "DecisionChecks",
           "Verdict", "measure_checks", "vignetting_check", "decision_reasons",
           "decision_numbers", "shape_error_px", "blur_range_px", "model_depths",
           "samples_for_blur", "pupil_cut", "shift_tilt_cos", "catseye_px",
           "SAMPLES_PER_BLUR_PX", "MIN_SAMPLES", "MAX_SAMPLES", "SAMPLE_RULE",
           "VIGNETTING_TOLERANCE", "STRONG_VIGNETTING", "VIGNETTING_FLOOR_SHARE",
           "ANAMORPHIC_REASON"]

#: Lens samples per pixel of the largest blur diameter: the least that reaches the FLIP
#: of a 0.5 px move on every measured scene and lens (docs/decisions/exact-images.md).
SAMPLES_PER_BLUR_PX = 2.0
MIN_SAMPLES, MAX_SAMPLES = 8, 256
SAMPLE_RULE = (f"N = ceil({SAMPLES_PER_BLUR_PX:g} b) rounded to the nearest power of two, "
               f"{MIN_SAMPLES}..{MAX_SAMPLES}")
#: Share of the error budget that what the vignetting map cannot carry (the cat's
#: eye, :func:`povlens.plan.image_error.catseye_rmse`) may take before :func:`decide`
#: prefers a minimum mesh render to a focal_blur the thin lens allows: no focal_blur
#: sample count goes below that floor (measurements: docs/decisions/planning.md,
#: "Vignetting floor", where it was the vignetting itself, and "Vignetting applied as
#: a map").
VIGNETTING_FLOOR_SHARE = 0.6
#: The reason line of an anamorphic lens's decision (its description in ``what``).
ANAMORPHIC_REASON = ("focal-blur: cannot draw an anamorphic lens ({what}): POV-Ray's "
                     "focal_blur has one focal length and a round pupil, so its blur is round "
                     "where the lens's is oval: ruled out")
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


@dataclasses.dataclass(frozen=True)
class Check:
    """One deviation from the equivalent thin lens (or from a sharp pinhole view)
    measured against the error budget.

    Attributes
    ----------
    name : what is measured, as its reason line says it (``"pinhole: max distortion"``).
    value_px : the measured deviation, film pixels.
    limit_px : the budget it is compared with, film pixels.
    """

    name: str
    value_px: float
    limit_px: float

    @property
    def passed(self) -> bool:
        """Whether the deviation is under the budget (``value_px < limit_px``)."""
        return self.value_px < self.limit_px


@dataclasses.dataclass(frozen=True)
class VignettingCheck:
    """The lens's vignetting: applied to the views as a map; whether what the map
    cannot carry, the cat's eye of out-of-focus light, rules out focal_blur.

    Attributes
    ----------
    wanted : whether the vignetting is wanted in the image (False: ``--no-vignetting``,
        never a deviation).
    min_relative_illumination : the smallest E / E(centre) of the model error.
    vignetting_rmse : what leaving the vignetting out changes the probe's image by
        (image RMSE; None: no probe image), for the record.
    basis : how the cat's eye was judged: ``"image"`` (the probe's image, an RMSE
        against the RMSE of moving it by the tolerance), ``"pixels"`` (blur x pupil cut
        against the tolerance), ``"illumination"`` (neither known: the relative
        illumination against ``1 - VIGNETTING_TOLERANCE``), or ``"not wanted"``.
    value, limit : what was compared, in the basis's units (image RMSE, film pixels, a
        fraction of the centre's illumination); NaN when not wanted.
    deviation : whether the cat's eye rules out focal_blur.
    tolerance_px : the error budget, film pixels.
    max_catseye_px : the largest blur x pupil cut over the model error's depths and
        film heights, pixels (:func:`catseye_px`; None: no pupil cut given).
    max_pupil_cut : the largest pupil cut (None: no pupil cut given).
    """

    wanted: bool
    min_relative_illumination: float
    vignetting_rmse: float | None
    basis: str
    value: float
    limit: float
    deviation: bool
    tolerance_px: float
    max_catseye_px: float | None = None
    max_pupil_cut: float | None = None


@dataclasses.dataclass(frozen=True)
class DecisionChecks:
    """What :func:`decide` measured and how each measure compares with the budget.

    Attributes
    ----------
    tolerance_px : the error budget, film pixels.
    near_z_mm, far_z_mm : the scene's depth range, camera-frame z, mm (far may be inf).
    near_distance_mm, far_distance_mm : the same from the entrance pupil, mm.
    focus_inside_range : whether the plane in focus lies within the range.
    blur_near_px, blur_far_px : the thin-lens blur diameter at near and far, pixels.
    max_model_blur_px : the largest thin-lens blur diameter over the range, pixels.
    max_real_blur_px : the largest real spot (equivalent-disc diameter) of the model
        error, pixels.
    max_shape_error_px : the largest blur shape error (:func:`shape_error_px`), pixels.
    max_blur_px : the larger of the model's and the real blur, pixels: what the
        sample count is for.
    blur_rule_samples : the mesh samples that blur needs (:func:`samples_for_blur`).
    pinhole : the pinhole view's checks: thin-lens blur, real spot, distortion.
    focal_blur : focal_blur's geometric checks: distortion, half the blur size error,
        half the shape error and, with a lens shift, what the tilted disc loses.
    shift_tilt_deg : the tilt of POV-Ray's ``direction`` with a lens shift, degrees
        (None: no shift).
    vignetting : the vignetting and its cat's eye.
    aperture_shape : a few words on a shaped stop, which focal_blur cannot draw (None:
        round).
    vignetting_floor_share : the share of the budget the cat's eye takes in the probe's
        image (0: not measured or not wanted).
    image_rmse : the probe image's measures (name, image RMSE) as given, for the record.
    """

    tolerance_px: float
    near_z_mm: float
    far_z_mm: float
    near_distance_mm: float
    far_distance_mm: float
    focus_inside_range: bool
    blur_near_px: float
    blur_far_px: float
    max_model_blur_px: float
    max_real_blur_px: float
    max_shape_error_px: float
    max_blur_px: float
    blur_rule_samples: int
    pinhole: tuple[Check, ...]
    focal_blur: tuple[Check, ...]
    shift_tilt_deg: float | None
    vignetting: VignettingCheck
    aperture_shape: str | None
    vignetting_floor_share: float
    image_rmse: tuple[tuple[str, float], ...] = ()

    @property
    def pinhole_passes(self) -> bool:
        """Every deviation from a sharp pinhole view is under the budget."""
        return all(c.passed for c in self.pinhole)

    @property
    def geometry_passes(self) -> bool:
        """focal_blur's geometric checks all pass."""
        return all(c.passed for c in self.focal_blur)

    @property
    def thin_lens_passes(self) -> bool:
        """The equivalent thin lens with the vignetting map is within the budget: the
        geometry passes, the stop is round and the cat's eye is no deviation."""
        return self.geometry_passes and not self.aperture_shape and not self.vignetting.deviation

    @property
    def floor_prefers_mesh(self) -> bool:
        """The cat's eye takes :data:`VIGNETTING_FLOOR_SHARE` of the budget or more while
        the blur needs only the minimum mesh sample count."""
        return (self.blur_rule_samples == MIN_SAMPLES
                and self.vignetting_floor_share >= VIGNETTING_FLOOR_SHARE)


class Verdict(enum.Enum):
    """What :func:`decide` concluded; the method is the value's first word."""

    PINHOLE = "pinhole"                            # every deviation under the budget
    FOCAL_BLUR = "focal-blur"                      # the equivalent thin lens will do
    MESH_FLOOR = "mesh: the cat's eye floor"       # ... but its cat's eye floor costs more
    MESH_CATSEYE = "mesh: the cat's eye"           # the cat's eye is beyond the budget
    MESH_APERTURE = "mesh: the aperture shape"     # a shaped stop, and visible blur
    MESH_LENS = "mesh: the real lens"              # the real lens deviates from the thin lens
    MESH_ANAMORPHIC = "mesh: an anamorphic lens"   # two focal lengths focal_blur cannot draw

    @property
    def method(self) -> str:
        """The render method: ``pinhole``, ``focal-blur`` or ``mesh``."""
        return self.value.split(":")[0]


def vignetting_check(e: ModelError, tol: float, wanted: bool, image_error: dict | None,
                     catseye: dict | None) -> VignettingCheck:
    """Whether what the vignetting map cannot carry rules out focal_blur (the module
    docstring): judged on the probe's image when it has ``catseye_rmse``, else in
    pixels with the pupil's cut ``catseye``, else by the relative illumination."""
    illum = float(e.min_relative_illumination)
    vig_rmse = None
    if image_error is not None and "vignetting_rmse" in image_error:
        vig_rmse = image_error["vignetting_rmse"]
    cat_px = cut = None
    if catseye is not None:
        cat_px, cut = catseye_px(e, catseye), float(np.max(catseye["cut"]))
    if not wanted:
        basis, value, limit, bad = "not wanted", math.nan, math.nan, False
    elif image_error is not None and "catseye_rmse" in image_error:
        basis, value, limit = "image", image_error["catseye_rmse"], image_error["shift_rmse"]
        bad = value >= limit and value > 0      # a flat image: nothing moves, nothing to judge
    elif catseye is not None:
        basis, value, limit = "pixels", cat_px, tol
        bad = value >= limit
    else:
        basis, value, limit = "illumination", illum, 1.0 - VIGNETTING_TOLERANCE
        bad = illum < 1.0 - VIGNETTING_TOLERANCE
    return VignettingCheck(bool(wanted), illum, vig_rmse, basis, value, limit, bad, tol,
                           cat_px, cut)


def _focal_blur_checks(e: ModelError, tol: float, shape_err: float, blur_px: float,
                       shift_tilt_cos: float) -> tuple[tuple[Check, ...], float | None]:
    """focal_blur's geometric checks (distortion, blur size and shape, and with a lens
    shift the width the tilted disc loses, ``blur_px`` x (1 - cos) / 2), and the tilt
    in degrees (None: no shift)."""
    fb = [Check("focal-blur: max distortion", float(e.max_distortion_px), tol),
          Check("focal-blur: max blur size error / 2 (the rim moves by half the diameter "
                "error)", float(e.max_blur_size_error_px) / 2, tol),
          Check("focal-blur: max blur shape error / 2 (the long axis reaches beyond the "
                "disc by half on each side)", shape_err / 2, tol)]
    tilt_deg = None
    if shift_tilt_cos < 1.0:
        tilt_deg = math.degrees(math.acos(max(-1.0, min(1.0, shift_tilt_cos))))
        fb.append(Check(f"focal-blur: lens shift: the disc, tilted {tilt_deg:.2g} deg, is "
                        f"narrower along the shift by the blur x (1 - cos) / 2",
                        blur_px * (1.0 - shift_tilt_cos) / 2, tol))
    return tuple(fb), tilt_deg


def measure_checks(near_z_mm: float, far_z_mm: float, model, model_error: ModelError,
                   pixel_pitch_mm: float, tolerance_px: float, vignetting: bool,
                   image_error: dict | None, catseye: dict | None, aperture_shape: str | None,
                   shift_tilt_cos: float) -> DecisionChecks:
    """Everything :func:`decide` compares with the budget (its parameters, in order)."""
    tol = float(tolerance_px)
    blur = blur_range_px(model, near_z_mm, far_z_mm, pixel_pitch_mm)
    e = model_error
    real = np.asarray(e.blur_real_px, dtype=float)
    elong = np.asarray(e.elongation, dtype=float)
    shape_err = float(np.max(shape_error_px(real, elong))) if real.size else 0.0
    max_real = float(real.max()) if real.size else 0.0
    b_max = max(blur["max_px"], max_real)
    pinhole = (Check("pinhole: max thin-lens blur", blur["max_px"], tol),
               Check("pinhole: max real spot", max_real, tol),
               Check("pinhole: max distortion", float(e.max_distortion_px), tol))
    focal_blur, tilt_deg = _focal_blur_checks(e, tol, shape_err, b_max, shift_tilt_cos)
    floor_share = 0.0
    if (image_error is not None and vignetting and image_error.get("shift_rmse", 0) > 0
            and "catseye_rmse" in image_error):
        floor_share = image_error["catseye_rmse"] / image_error["shift_rmse"]
    return DecisionChecks(
        tol, near_z_mm, far_z_mm, near_z_mm - model.centre_z_mm, far_z_mm - model.centre_z_mm,
        blur["focus_inside_range"], blur["near_px"], blur["far_px"], blur["max_px"], max_real,
        shape_err, b_max, samples_for_blur(b_max), pinhole, focal_blur, tilt_deg,
        vignetting_check(e, tol, vignetting, image_error, catseye), aperture_shape, floor_share,
        tuple((k, float(v)) for k, v in image_error.items()) if image_error else ())


def decide(*, near_z_mm: float, far_z_mm: float, model, model_error: ModelError,
           pixel_pitch_mm: float, tolerance_px: float = 0.5, vignetting: bool = True,
           image_error: dict | None = None, catseye: dict | None = None,
           aperture_shape: str | None = None, shift_tilt_cos: float = 1.0,
           anamorphic: str | None = None) -> Decision:
    """Choose the render method and its lens samples (pure; see the module docstring).

    Parameters
    ----------
    near_z_mm, far_z_mm : the scene's depth range, camera-frame z (mm); far may be inf.
    model : the :class:`~povlens.thinlens.model.EquivalentThinLens`.
    model_error : its error measured at depths spanning [near, far]
        (:func:`povlens.thinlens.model_error.measure_model_error`).
    pixel_pitch_mm : the film's pixel size.
    tolerance_px : the error budget, film pixels.
    vignetting : False when the lens's vignetting is not wanted (``--no-vignetting``).
    image_error : the depth probe's view in image terms
        (:func:`povlens.plan.image_error.probe_image_error`): ``shift_rmse`` (the
        budget), ``vignetting_rmse`` (for the record), ``catseye_rmse`` (what the map
        cannot carry: a deviation when at least ``shift_rmse``).
    catseye : :func:`pupil_cut` of the lens's pupil, for the pixel measure when the
        image gives no ``catseye_rmse``.  Without either, a relative illumination
        below ``1 - VIGNETTING_TOLERANCE`` anywhere is a deviation.
    aperture_shape : a few words on a shaped stop (:func:`povlens.plan.aperture.describe`),
        which focal_blur cannot draw: with a visible blur the render is mesh.
    shift_tilt_cos : with a lens shift, cos of the tilt of POV-Ray's ``direction``
        (:func:`shift_tilt_cos`): focal_blur's disc is that much narrower along the
        shift, and half the lost diameter counts against the budget.  1: no shift.
    anamorphic : a few words on an anamorphic lens (its two focal lengths and squeeze,
        :func:`povlens.plan.anamorphic.describe`): focal_blur, with one focal length and
        a round pupil, cannot draw it, so it is ruled out (the pinhole view, framed per
        meridian, stays when everything is sharp).  None: a rotationally symmetric lens.

    Returns
    -------
    Decision
        Method, samples, reasons (:func:`decision_reasons`, the conclusion last) and the
        numbers behind them (:func:`decision_numbers`).
    """
    checks = measure_checks(near_z_mm, far_z_mm, model, model_error, pixel_pitch_mm,
                            tolerance_px, vignetting, image_error, catseye, aperture_shape,
                            shift_tilt_cos)
    if checks.pinhole_passes:
        verdict = Verdict.PINHOLE
    elif anamorphic:
        verdict = Verdict.MESH_ANAMORPHIC
    elif checks.thin_lens_passes:
        verdict = Verdict.MESH_FLOOR if checks.floor_prefers_mesh else Verdict.FOCAL_BLUR
    elif checks.geometry_passes and not checks.aperture_shape:
        verdict = Verdict.MESH_CATSEYE
    elif checks.aperture_shape and checks.geometry_passes and not checks.vignetting.deviation:
        verdict = Verdict.MESH_APERTURE
    else:
        verdict = Verdict.MESH_LENS
    reasons = decision_reasons(checks, verdict, anamorphic)
    numbers = decision_numbers(checks, verdict, model_error)
    if verdict is Verdict.PINHOLE:
        return Decision("pinhole", 1, reasons, numbers)
    if verdict is Verdict.FOCAL_BLUR:
        fbs = FOCAL_BLUR_ADAPTIVE
        return Decision("focal-blur", fbs.max_samples, reasons, numbers, focal_blur=fbs)
    return Decision("mesh", checks.blur_rule_samples, reasons, numbers)


def decision_numbers(c: DecisionChecks, verdict: Verdict, e: ModelError) -> dict:
    """The numbers a decision records (plan.json's ``decision.numbers``; units in the
    keys): the measures of ``c`` and the extremes of the model error ``e``; past a
    pinhole verdict also the blur the samples are for, the shift's tilt, the cat's
    eye's share of the budget and (focal-blur) the mesh samples the blur would need."""
    v = c.vignetting
    numbers = {
        "tolerance_px": c.tolerance_px,
        "near_z_mm": c.near_z_mm, "far_z_mm": c.far_z_mm,
        "near_distance_mm": c.near_distance_mm, "far_distance_mm": c.far_distance_mm,
        "blur_near_px": c.blur_near_px, "blur_far_px": c.blur_far_px,
        "max_model_blur_px": c.max_model_blur_px, "max_real_blur_px": c.max_real_blur_px,
        "max_distortion_px": float(e.max_distortion_px),
        "max_blur_size_error_px": float(e.max_blur_size_error_px),
        "max_elongation": float(e.max_elongation), "max_shape_error_px": c.max_shape_error_px,
        "min_relative_illumination": float(e.min_relative_illumination),
        "vignetting_wanted": v.wanted,
        "vignetting": "applied as a map" if v.wanted else "not wanted",
        **{f"image_{k}": x for k, x in c.image_rmse},
        "model_depths_z_mm": list(e.object_z_mm),
        "samples_per_blur_px": SAMPLES_PER_BLUR_PX,
    }
    if v.max_catseye_px is not None:
        numbers.update(max_catseye_px=v.max_catseye_px, max_pupil_cut=v.max_pupil_cut)
    if verdict is Verdict.PINHOLE:
        return numbers
    numbers["max_blur_px"] = c.max_blur_px
    if c.shift_tilt_deg is not None:
        numbers["shift_tilt_deg"] = c.shift_tilt_deg
    numbers["vignetting_floor_share"] = c.vignetting_floor_share
    if verdict is Verdict.FOCAL_BLUR:
        numbers["blur_rule_samples"] = c.blur_rule_samples
    return numbers


def decision_reasons(c: DecisionChecks, verdict: Verdict,
                     anamorphic: str | None = None) -> list[str]:
    """The reasons of a decision, one line each: the depth range, the pinhole view's
    checks and, past a pinhole verdict, focal_blur's (with an anamorphic lens, why
    focal_blur cannot draw it); the conclusion last."""
    far = "infinity" if math.isinf(c.far_z_mm) else f"{c.far_distance_mm / 1000:.3g} m"
    reasons = [f"depth range {c.near_distance_mm / 1000:.3g} m to {far} from the entrance "
               f"pupil; focus {'inside' if c.focus_inside_range else 'outside'} the range"]
    reasons += [_check_text(k) for k in c.pinhole]
    v = c.vignetting
    reasons.append(f"pinhole: vignetting (relative illumination >= "
                   f"{v.min_relative_illumination:.3f} of the centre): "
                   + ("applied as a map, exact: the view has no blur" if v.wanted
                      else "not wanted (--no-vignetting)"))
    if verdict is not Verdict.PINHOLE:
        reasons += [_check_text(k) for k in c.focal_blur]
        reasons.append("focal-blur: " + _vignetting_text(v))
        if c.aperture_shape:
            reasons.append(f"focal-blur: cannot draw the aperture shape ({c.aperture_shape}); "
                           f"the blur is visible")
        if anamorphic:
            reasons.append(ANAMORPHIC_REASON.format(what=anamorphic))
    reasons.append(_conclusion(c, verdict))
    return reasons


def _check_text(k: Check) -> str:
    """``name value px < limit px`` (or ``>=``)."""
    return f"{k.name} {k.value_px:.3g} px {'<' if k.passed else '>='} {k.limit_px:.3g} px"


def _vignetting_text(v: VignettingCheck) -> str:
    """focal_blur's vignetting line: applied as a map, and how its cat's eye was judged."""
    state = "applied as a map" if v.wanted else "not wanted (--no-vignetting)"
    text = (f"vignetting: {state} (relative illumination >= {v.min_relative_illumination:.3f} "
            f"of the centre, exact from the exit-pupil table)")
    if v.vignetting_rmse is not None:
        text += (f"; leaving it out would change the probe's image by RMSE "
                 f"{v.vignetting_rmse:.3g}")
    if not v.wanted:
        return text + "; not applied, and its cat's eye is not a deviation"
    if v.basis == "image":
        text += (f"; what the map cannot carry, the cat's-eye shape of out-of-focus light, "
                 f"changes it by RMSE {v.value:.3g}, "
                 f"{'at least' if v.deviation else 'less than'} the {v.limit:.3g} of a "
                 f"{v.tolerance_px:.3g} px move")
    elif v.basis == "pixels":
        text += (f"; what the map cannot carry, the cat's eye of out-of-focus light (blur x "
                 f"pupil cut, up to {v.max_pupil_cut:.3g}), reaches {v.value:.3g} px "
                 f"{'>=' if v.deviation else '<'} {v.limit:.3g} px (without the probe's image)")
    else:
        text += ("; without the probe's image or the pupil's cut, what the map cannot carry "
                 f"is not known: judged by the relative illumination, "
                 f"{'below' if v.deviation else 'not below'} {v.limit:.2f}")
    return text + (": a deviation" if v.deviation else "")


def _conclusion(c: DecisionChecks, verdict: Verdict) -> str:
    """The last reason: ``-> method: why``."""
    as_map = "; the lens's vignetting is applied as a map" if c.vignetting.wanted else ""
    if verdict is Verdict.PINHOLE:
        return ("-> pinhole: every deviation from a sharp pinhole view is under the budget"
                + as_map)
    if verdict is Verdict.FOCAL_BLUR:
        fbs = FOCAL_BLUR_ADAPTIVE
        return ("-> focal-blur: the equivalent thin lens is within the budget" + as_map
                + f"; POV-Ray's adaptive focal blur, {fbs.min_samples} to "
                f"{fbs.max_samples} samples per pixel (confidence {fbs.confidence:g}, "
                f"variance {fbs.variance:g}): sharp pixels stop at the minimum, the "
                f"{c.max_blur_px:.3g} px blur would need {c.blur_rule_samples} mesh samples "
                f"({SAMPLE_RULE})")
    if verdict is Verdict.MESH_FLOOR:
        return (f"-> mesh: the equivalent thin lens with the vignetting map is within the "
                f"budget, but what the map cannot carry (the cat's eye) uses "
                f"{c.vignetting_floor_share:.2f} of it (>= {VIGNETTING_FLOOR_SHARE:g}: no "
                f"focal_blur sample count goes below that error), and the "
                f"{c.max_blur_px:.3g} px blur needs only the minimum {MIN_SAMPLES} lens "
                f"samples, which cost about what the adaptive focal blur does, without the "
                f"floor")
    why = {Verdict.MESH_CATSEYE: "the cat's eye of out-of-focus light, which the vignetting "
                                 "map cannot carry, is beyond the budget",
           Verdict.MESH_APERTURE: f"focal_blur cannot draw the aperture shape "
                                  f"({c.aperture_shape}) and the blur is visible",
           Verdict.MESH_LENS: "the real lens deviates from the equivalent thin lens beyond "
                              "the budget",
           Verdict.MESH_ANAMORPHIC: "the lens is anamorphic, with two focal lengths and oval "
                                    "out-of-focus light that focal_blur cannot draw, and the "
                                    "pinhole view is not sharp enough"}[verdict]
    return (f"-> mesh: {why}; {c.blur_rule_samples} samples for a {c.max_blur_px:.3g} px "
            f"blur ({SAMPLE_RULE})")


def shift_tilt_cos(shift_mm, image_distance_mm: float) -> float:
    """cos of the tilt of POV-Ray's ``direction`` for a film shifted by ``shift_mm``
    (x, y mm on the image plane) behind a thin lens of image distance
    ``image_distance_mm`` (:func:`povlens.plan.camera_setup.off_axis_direction`); 1 unshifted."""
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


def catseye_px(model_error: ModelError, catseye: dict) -> float:
    """Largest cat's-eye deviation ``b x cut`` (pixels) over the model error's depths
    and film heights: the thin-lens blur at each depth times the pupil cut
    (:func:`pupil_cut`) at each height."""
    b = np.asarray(model_error.blur_model_px, dtype=float)           # (D, F)
    h = np.asarray(model_error.film_height_mm, dtype=float)          # (F,)
    cut = np.interp(h, catseye["film_radius_mm"], catseye["cut"])
    return float(np.max(b * cut[None, :])) if b.size else 0.0


