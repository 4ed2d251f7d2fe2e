"""Per-pixel scene distance of a pinhole view, measured by a light that fades with distance.

POV-Ray has no depth output.  The probe renders the view three times, identical but
for one added light at the camera location (the eye):

* B0: the scene as it is;
* B1: plus ``light_source { <eye> color rgb L fade_distance D fade_power p shadowless }``;
* B2: plus the same light without fade.

POV-Ray multiplies a fading light's colour by 2 / (1 + (d/D)^p), d the distance from
the light to the lit point (POV-Ray 3.7 ``Attenuate_Light``).  Everything else the
light adds -- diffuse, highlights, whatever the material and the surface normal -- is
proportional to its colour, so per pixel (channel means)

    r = (B1 - B0) / (B2 - B0) = 2 / (1 + (d/D)^p),      d = D (2/r - 1)^(1/p).

The light sits at the eye, so the line from it to every visible point is the primary
ray: ``shadowless`` loses nothing and d is the distance along the pixel's ray.  The
scene's own lighting (B0) cancels.

**Quality** (``+Q6``, :data:`PROBE_SWITCHES`; POV-Ray 3.7 quality flags, ``frame.h``):
transmitted rays are traced (through a clear window or a media container one sees
what is behind it), but no reflected rays (``Q_REFLECT`` at 8: a mirror would add
light from points at other distances), and no fog, atmospheric or object media,
rainbow, radiosity or subsurface light (``Q_VOLUME``, ``Q_ADVANCED_LIGHT``,
``Q_SUBSURFACE`` at 9).  The scene's own fog and media are therefore not seen by the
probe: distances are to surfaces, as if there were none (a camera inside a solid
object, which stops POV-Ray's fog, makes no difference either).  Shadows of the
scene's lights (area lights included) are computed but are the same in the three
renders; the renders run single-threaded (``+WT1``) so that jittered area lights draw
the same random numbers in each.  The light is kept out of any media
(``media_interaction off``, ``media_attenuation off``) and shoots no photons.  All
three renders set ``assumed_gamma 1`` before the scene (POV-Ray keeps the first
``assumed_gamma`` it reads): the EXR then holds the sums of light linearly, whatever
gamma the scene asks for.

**The user's POV-Ray options** (:class:`ProbeView`'s ``povray_options``: library
paths, clock, passthrough options) go to every render of the probe, so it sees the
scene POV-Ray renders with them; :data:`PROBE_SWITCHES` come after them and win
(``+Q6``, and ``-A``: anti-aliasing supersamples where neighbouring pixels differ,
which is not the same pixels in the three renders).

**Background** is made transparent (``background`` and ``sky_sphere`` fully
transmitting, after the scene) and the renders write alpha (``+UA``): a pixel whose
ray hits nothing has alpha 0 and is infinitely far (``inf``).

**No depth of its own** (``nan``): a pixel that hits something whose response to the
light is too small to resolve r to :data:`RATIO_TOLERANCE` (black, emissive or clear
surfaces; objects in a ``light_group`` without global lights; extremely far surfaces).
The planner leaves these pixels out of the depth range (:func:`depth_limits`) and
records their count (``no_depth_pixels``); a semi-transparent surface gives a depth
between it and what lies behind it.

**Precision** (:data:`FADE_POWER`, :data:`LIGHT_COLOUR`): POV-Ray writes EXR as half
floats (relative rounding 2^-11).  With p = 1 the depth's relative error is about
(2^-11 .. 2^-10) x (1 + x)/x for x = d/D: measured (docs/decisions/planning.md,
"Depth probe by a fading light") within 1 % from d = D/20 to 100 D and 0.25 % from
D/5, where p = 2 (the prototype's) loses 5.5 % at D/20 and 0.9 % at 100 D.  D
defaults to the focus distance.  L = 1000 makes B2 - B0 (L x diffuse x colour x cos) large against the
scene's own light B0 (usually below 1-2) and keeps B1 <= 2 L x (diffuse + highlights)
far below the half-float maximum 65504.

The three renders run as POV-Ray processes at the same time (:func:`start_probe`):
a small render spends most of its ~0.7 s wall time idle in POV-Ray's start-up.  With
``with_image`` a fourth renders the view as it is, at full quality (what the scene
looks like, for estimates of image error).  Images go to a temporary folder that is
removed afterwards; if a render fails, the others are stopped and POV-Ray's message
is raised (:class:`~povlens.errors.PovrayError`).  :func:`probe_depth` probes a
render folder (its wrappers next to ``pinhole.pov``).  Distances are along each
pixel's ray from the camera location (the entrance pupil) in scene units; see
:func:`axial_depth` for the distance along the viewing direction.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import shutil
import tempfile
from pathlib import Path

import numpy as np

from povlens.errors import PovlensError
from povlens.lens.film import Film
from povlens.plan.options import povray_options_of
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import DepthProbeRecord, Plan, PovrayCamera, read_plan
from povlens.pov.mesh import pinhole_wrapper
from povlens.pov.povray_options import PovrayOptions
from povlens.pov.povray_paths import include_text
from povlens.pov.process import start_render
from povlens.pov.sdl import pov_vector
from povlens.util.files import write_text
from povlens.util.signals import interrupts_deferred

__all__ = ["ProbeView", "probe_depth", "start_probe", "DepthProbe", "probe_wrapper",
           "ray_directions", "axial_depth", "distance_from_fade", "depth_limits",
           "probe_record", "scene_atmosphere", "atmosphere_note", "FADE_POWER", "LIGHT_COLOUR",
           "PROBE_SWITCHES", "RATIO_TOLERANCE", "BACKGROUND_ALPHA", "NEAR_PERCENTILE",
           "FAR_PERCENTILE", "BACKGROUND_FRACTION", "METHOD", "TREATMENT"]

#: Fade power p of the probe's light (module docstring: 1 resolves d from D/20 to 100 D
#: within 1 %; 2 loses 5.5 % at D/20).
FADE_POWER = 1.0
#: Colour (all channels) of the probe's light: B2 - B0 large against B0, B1 << 65504.
LIGHT_COLOUR = 1000.0
#: POV-Ray switches of the three renders, after the user's options: transmitted rays but
#: no reflections, media, fog or radiosity (+Q6), alpha marks background (+UA), no
#: anti-aliasing (-A: the same rays in the three renders).
PROBE_SWITCHES = ("+Q6", "+UA", "-A")
#: Largest relative error of r (from half-float rounding) a pixel's depth may have.
RATIO_TOLERANCE = 0.05
#: Alpha at or below which a pixel without depth is background (its ray hit nothing).
BACKGROUND_ALPHA = 1e-3
#: Relative rounding of a half float.
_HALF_EPS = 2.0 ** -11
#: Percentiles of the hit pixels' distances taken as near and far (:func:`depth_limits`).
NEAR_PERCENTILE, FAR_PERCENTILE = 1.0, 99.0
#: Far is infinity when more than this fraction of the probe's pixels see background.
BACKGROUND_FRACTION = 0.01
#: Default fade distance when a view has no finite focus (scene units).
_DEFAULT_FADE_DISTANCE = 10.0

#: How the probe measures (plan.json ``depth_probe.method``).
METHOD = ("light fade: 3 renders at +Q6 (no reflections, media, fog or radiosity), with an "
          "added light at the eye without and with fade_distance D fade_power 1; "
          "d = D (2/r - 1), r = (B1 - B0) / (B2 - B0)")
#: How the planner treats pixels without a depth (plan.json ``depth_probe.treatment``).
TREATMENT = ("background (alpha 0: nothing hit) is infinitely far; a pixel that hits a "
             "surface with no measurable response to the light (black, emissive, clear) "
             "has no depth and is left out of the depth range (no_depth_pixels)")


@dataclasses.dataclass(frozen=True)
class ProbeView:
    """The pinhole view a depth probe renders.

    ``povray_camera`` is the plan's (or any perspective camera: location, direction,
    right, up in scene units); ``film`` the probe's (its pixels set the image size;
    the plan's film in mm); ``scene`` the scene file and ``focus`` the focus distance
    (scene units; the default fade distance); ``povray_options`` the user's POV-Ray
    options, given to every render of the probe.  A :class:`~povlens.plan.schema.Plan`
    has the attributes :func:`ray_directions` and :func:`axial_depth` read, too.
    """

    povray_camera: PovrayCamera
    film: Film
    mm_per_unit: float
    scene: str
    focus: float
    povray_options: PovrayOptions = PovrayOptions()

    @classmethod
    def of_plan(cls, plan: Plan, width_px: int | None = None,
                height_px: int | None = None) -> "ProbeView":
        """The view of ``plan``'s pinhole camera, at ``width_px`` x ``height_px``
        (default: the plan's film)."""
        f = plan.film
        film = f.resized(f.width_mm, f.height_mm, int(width_px or f.width_px),
                         int(height_px or f.height_px))
        return cls(plan.povray_camera, film, plan.mm_per_unit, plan.inputs.scene,
                   float(plan.inputs.focus), povray_options_of(plan.inputs))


def probe_wrapper(linear_pinhole_text: str, eye, fade_distance: float | None,
                  light: bool = True) -> str:
    """One of the three renders' wrapper text.

    Parameters
    ----------
    linear_pinhole_text : the pinhole wrapper with ``assumed_gamma 1`` before the scene.
    eye : (3,) the camera location (scene units): where the light sits.
    fade_distance : D (scene units) for B1, None for B2 (no fade).
    light : False for B0 (no light; ``fade_distance`` unused).

    Returns
    -------
    str
        The text: the wrapper, transparent background and sky sphere, and the light.
    """
    text = (linear_pinhole_text.rstrip("\n") + "\n"
            "// povlens depth probe (povlens/plan/depth_probe.py): background transparent\n"
            "background { rgbt <0, 0, 0, 1> }\n"
            "sky_sphere { pigment { rgbt <0, 0, 0, 1> } }\n")
    if not light:
        return text
    fade = ("" if fade_distance is None else
            f"\n  fade_distance {float(fade_distance):.17g} fade_power {FADE_POWER:g}")
    return text + (f"light_source {{ {pov_vector(eye)} color rgb {LIGHT_COLOUR:g}\n"
                   f"  shadowless media_interaction off media_attenuation off\n"
                   f"  photons {{ reflection off refraction off }}{fade} }}\n")


def distance_from_fade(b0: np.ndarray, b1: np.ndarray, b2: np.ndarray,
                       fade_distance: float) -> np.ndarray:
    """Distances (H, W) in scene units from the three renders (H, W, C), linear.

    Parameters
    ----------
    b0, b1, b2 : the scene without the light, with the fading light, with the light
        without fade; channels 0-2 are RGB, a fourth (if any) alpha.
    fade_distance : D, scene units.

    Returns
    -------
    np.ndarray
        float64 (H, W): d = D (2/r - 1)^(1/p); ``inf`` for background (alpha at most
        :data:`BACKGROUND_ALPHA`, no response); ``nan`` where the response cannot
        resolve r to :data:`RATIO_TOLERANCE` (no depth of its own).
    """
    b0, b1, b2 = (np.asarray(b, dtype=np.float64) for b in (b0, b1, b2))
    num = (b1[..., :3] - b0[..., :3]).mean(axis=2)
    den = (b2[..., :3] - b0[..., :3]).mean(axis=2)
    s0, s1, s2 = (np.abs(b[..., :3]).mean(axis=2) for b in (b0, b1, b2))
    with np.errstate(divide="ignore", invalid="ignore"):
        r = num / den
        # half-float rounding of the four values, carried to r
        err = _HALF_EPS * (s1 + s0 + np.abs(r) * (s2 + s0)) / den
        ok = (den > 0) & (r > 0) & np.isfinite(r) & (err <= RATIO_TOLERANCE * r)
        rc = np.clip(np.where(ok, r, 1.0), 1e-300, 2.0)      # r > 2: rounding, d ~ 0
        d = float(fade_distance) * (2.0 / rc - 1.0) ** (1.0 / FADE_POWER)
    d = np.maximum(d, 1e-6 * float(fade_distance))           # touching the eye: tiny, > 0
    out = np.where(ok, d, np.nan)
    if b0.shape[-1] > 3:
        out = np.where(~ok & (b0[..., 3] <= BACKGROUND_ALPHA), np.inf, out)
    return out


def ray_directions(view: ProbeView | Plan) -> np.ndarray:
    """Unit world directions (H, W, 3) of the pinhole camera's pixel rays.

    POV-Ray's perspective camera shoots pixel (col i, row j) along
    ``D + (u - 1/2) R + (1/2 - v) U`` with u = (i + 1/2)/W, v = (j + 1/2)/H
    (W x H: ``view.film``'s pixels).
    """
    cam = view.povray_camera
    w, h = view.film.width_px, view.film.height_px
    D, R, U = (np.asarray(v, dtype=np.float64) for v in (cam.direction, cam.right, cam.up))
    u = (np.arange(w) + 0.5) / w - 0.5
    v = 0.5 - (np.arange(h) + 0.5) / h
    d = D + u[None, :, None] * R + v[:, None, None] * U
    return d / np.linalg.norm(d, axis=2, keepdims=True)


def axial_depth(view: ProbeView | Plan, distance: np.ndarray) -> np.ndarray:
    """Distance along the viewing direction (as thin-lens depths are measured) of
    points at ray distance ``distance`` (H, W) from the camera location.  The axis is
    the image plane's normal (R x U toward ``direction``), which a lens shift's tilted
    ``direction`` (:func:`povlens.plan.camera_setup.off_axis_direction`) is not."""
    cam = view.povray_camera
    D, R, U = (np.asarray(v, dtype=np.float64) for v in (cam.direction, cam.right, cam.up))
    fwd = np.cross(R, U)
    fwd = fwd / np.linalg.norm(fwd)
    fwd = fwd if fwd @ D >= 0 else -fwd
    return np.asarray(distance, dtype=np.float64) * (ray_directions(view) @ fwd)


def depth_limits(axial_mm: np.ndarray) -> tuple[float, float, dict]:
    """Near and far axial distances (mm) of what a probe's pixels hit.

    Robust percentiles (:data:`NEAR_PERCENTILE`, :data:`FAR_PERCENTILE`) of the
    finite distances; pixels without a depth (``nan``) are left out.  Far is
    infinity when more than :data:`BACKGROUND_FRACTION` of the pixels see background
    (``inf``); both are infinity when no pixel has a finite depth.

    Returns
    -------
    (near_mm, far_mm, info)
        ``info``: probe_pixels, background_fraction, no_depth_pixels,
        no_depth_fraction, and closest_mm / farthest_finite_mm when something was hit.
    """
    a = np.asarray(axial_mm, dtype=float).ravel()
    finite = a[np.isfinite(a) & (a > 0)]
    n = max(a.size, 1)
    no_depth = int(np.isnan(a).sum())
    bg = float(np.isposinf(a).sum()) / n
    info = {"probe_pixels": int(a.size), "background_fraction": bg,
            "no_depth_pixels": no_depth, "no_depth_fraction": no_depth / n}
    if finite.size == 0:
        return math.inf, math.inf, info
    near = float(np.percentile(finite, NEAR_PERCENTILE))
    far = math.inf if bg > BACKGROUND_FRACTION else float(np.percentile(finite, FAR_PERCENTILE))
    info.update({"closest_mm": float(finite.min()), "farthest_finite_mm": float(finite.max())})
    return near, far, info


# ``fog {`` / ``media {`` outside comments and strings; included files next to the scene.
_ATMOSPHERE = re.compile(r"\b(fog|media)\s*\{")
_INCLUDE = re.compile(r'#\s*include\s+"([^"]+)"')
_COMMENTS = re.compile(r'//[^\n]*|/\*.*?\*/|"(?:[^"\\\n]|\\.)*"', re.S)


def scene_atmosphere(scene: str | os.PathLike, _seen: set | None = None,
                     library_paths=()) -> list[str]:
    """Which of ``fog`` and ``media`` the scene's text (and the files it includes from
    its own folder or ``library_paths``) writes, sorted; a text scan, not an
    evaluation of the scene."""
    path = Path(scene)
    seen = set() if _seen is None else _seen
    if path.resolve() in seen or len(seen) > 200:
        return []
    seen.add(path.resolve())
    try:
        text = path.read_text(errors="replace")
    except OSError:
        return []
    found = set()
    folders = [path.parent, *map(Path, library_paths)]
    for name in _INCLUDE.findall(text):
        inc = next((f / name for f in folders if (f / name).is_file()), None)
        if inc is not None:
            found.update(scene_atmosphere(inc, seen, library_paths))
    code = _COMMENTS.sub(lambda m: "" if m.group(0).startswith("/") else '""', text)
    found.update(m.group(1) for m in _ATMOSPHERE.finditer(code))
    return sorted(found)


def atmosphere_note(scene: str | os.PathLike, library_paths=()) -> str | None:
    """The plan's note that the depth probe does not see the scene's own fog / media
    (only if its text, or a file it includes from its folder or ``library_paths``, has
    them; :func:`scene_atmosphere`), else None."""
    found = scene_atmosphere(scene, library_paths=library_paths)
    if not found:
        return None
    return (f"the scene has {' and '.join(found)}: the depth probe does not see "
            f"{'it' if len(found) == 1 else 'them'} (POV-Ray computes no fog or "
            f"media at +Q6); its distances are to surfaces")


def probe_record(depth_range: dict | None = None, focus: dict | None = None
                 ) -> DepthProbeRecord:
    """The plan.json record of the probes run for a plan: the method, how pixels
    without depth count and the probes' numbers (``depth_range``, ``focus``)."""
    return DepthProbeRecord(METHOD, TREATMENT, depth_range, focus)


def probe_depth(outdir: str | os.PathLike, fade_distance: float | None = None,
                threads: int | None = None) -> np.ndarray:
    """Per-pixel distance (H, W) float64 in scene units of the folder's pinhole view:
    ``inf`` where the ray hits nothing, ``nan`` where it hits something without a
    depth of its own (module docstring).  ``fade_distance`` D defaults to the focus
    distance (scene units); ``threads``: unused by the three renders (single-threaded
    for determinism), kept for the callers."""
    outdir = Path(outdir)
    return start_probe(ProbeView.of_plan(read_plan(outdir)), outdir,
                       fade_distance=fade_distance, threads=threads).result()


def _fade_distance(view: ProbeView, fade_distance: float | None) -> float:
    """D: given, else the view's focus if finite and positive, else a default."""
    if fade_distance is None:
        focus = float(view.focus)
        fade_distance = focus if math.isfinite(focus) and focus > 0 else _DEFAULT_FADE_DISTANCE
    if not (fade_distance > 0 and math.isfinite(fade_distance)):
        raise PovlensError(f"fade distance {fade_distance}: must be positive and finite")
    return float(fade_distance)


def start_probe(view: ProbeView, folder: str | os.PathLike, *,
                fade_distance: float | None = None, threads: int | None = None,
                keep_wrappers: bool = True, prefix: str = ".depth.", label: str | None = None,
                with_image: bool = False) -> "DepthProbe":
    """Start the three renders of ``view`` (W x H: ``view.film``); returns at once.

    Parameters
    ----------
    view : the pinhole view (:class:`ProbeView`).
    folder : where the temporary folder ``prefix*`` (the images) is made, and the
        wrappers ``depth_fade_{b0,b1,b2}.pov`` are written if ``keep_wrappers`` (else
        into the temporary folder).
    fade_distance : D in scene units (default: ``view.focus``, or 10 if it is not
        finite).
    threads : POV-Ray threads of the ``with_image`` render (default half the cores);
        the three depth renders run single-threaded.
    label : names the probe in errors (default ``folder``).
    with_image : also render the view as it is, at full quality, beside them
        (:attr:`DepthProbe.image` once collected).

    Returns
    -------
    DepthProbe
        Running; collect with :meth:`DepthProbe.result`.
    """
    folder = Path(folder)
    fade_distance = _fade_distance(view, fade_distance)
    w, h = view.film.width_px, view.film.height_px
    if threads is None:
        threads = max(1, (os.cpu_count() or 1) // 2)
    scene = Path(view.scene)
    cam = view.povray_camera
    tmp = Path(tempfile.mkdtemp(prefix=prefix, dir=folder))
    wrappers = folder if keep_wrappers else tmp
    probe = DepthProbe(view, fade_distance, tmp, label or str(folder))
    try:
        include = include_text(scene, wrappers, RenderFolder(wrappers).scene_link)
        linear = pinhole_wrapper(include, cam.location, cam.direction, cam.right, cam.up,
                                 assumed_gamma=1.0)
        for name, light, fade in (("b0", False, None), ("b1", True, fade_distance),
                                  ("b2", True, None)):
            pov = write_text(wrappers / f"depth_fade_{name}.pov",
                             probe_wrapper(linear, cam.location, fade, light))
            probe._jobs[name] = start_render(pov, tmp / f"{name}.exr", w, h, threads=1,
                                             library_paths=[scene.parent],
                                             povray_options=view.povray_options,
                                             extra_args=PROBE_SWITCHES)
        if with_image:
            base = pinhole_wrapper(include, cam.location, cam.direction, cam.right, cam.up)
            pov = write_text(wrappers / "depth_view.pov", base)
            probe._jobs["view"] = start_render(pov, tmp / "view.exr", w, h, threads=threads,
                                               library_paths=[scene.parent],
                                               povray_options=view.povray_options)
    except BaseException:
        probe.cancel()
        raise
    return probe


class DepthProbe:
    """The running renders of a depth probe (:func:`start_probe`).

    ``view`` is the :class:`ProbeView` rendered (its film the probe's size), for
    :func:`ray_directions` / :func:`axial_depth`; ``fade_distance`` its D (scene
    units)."""

    def __init__(self, view: ProbeView, fade_distance: float, tmp: Path, label: str):
        self.view, self.fade_distance, self.label = view, fade_distance, label
        self._tmp = tmp
        self._jobs: dict = {}
        #: (H, W, 3) linear image of the view as it is (``with_image``), once collected.
        self.image: np.ndarray | None = None

    @property
    def renders(self) -> tuple[str, ...]:
        """The renders started: ``b0``, ``b1``, ``b2`` (without the light, with it
        fading, with it not fading) and ``view`` (the view as it is)."""
        return tuple(self._jobs)

    def result(self) -> np.ndarray:
        """Wait for the renders; per-pixel distances (H, W) in scene units: ``inf``
        where the ray hits nothing, ``nan`` where it hits something without a depth of
        its own.  Raises POV-Ray's error if a render failed (the others are stopped)."""
        from povlens.util.images import read_image   # (OpenImageIO: imported while POV-Ray runs)
        try:
            images = {name: read_image(job.wait()) for name, job in self._jobs.items()}
        finally:
            self.cancel()
        if "view" in images:
            self.image = np.asarray(images["view"][..., :3], dtype=np.float64)
        return distance_from_fade(images["b0"], images["b1"], images["b2"], self.fade_distance)

    def cancel(self) -> None:
        """Stop the renders still running and remove the temporary folder.  A second
        Ctrl-C or SIGTERM waits until every render is stopped (it would leave the
        rest running)."""
        with interrupts_deferred():
            try:
                for job in self._jobs.values():
                    job.cancel()
            finally:
                shutil.rmtree(self._tmp, ignore_errors=True)
