"""Per-pixel scene distance of a render folder's pinhole view, measured by POV-Ray fog.

POV-Ray has no depth output, but its constant fog (``fog_type 1``) blends every
primary ray with the fog colour by the distance d the ray travels to its first hit:

    pixel = f * C + (1 - f) * F,      f = exp(-d / D)

where C is what the ray would see without fog, F the fog colour and D the fog's
``distance`` (POV-Ray 3.7 documentation, "Fog": at distance D the fog lets
exp(-1) of the object's colour through; rays that hit nothing travel an infinite
distance and show the fog colour only).  Rendering the same view twice, with a
black fog (F = 0) and a white fog (F = 1):

    B = f * C
    W = f * C + (1 - f)
    W - B = 1 - f      ->   f = 1 - (W - B),   d = -D ln f.

The object's colour, its lighting, shadows and texture cancel exactly, per pixel
and per channel (the three channels are averaged).  Secondary rays would not
cancel: a mirror adds ``f * r * (1 - f2)`` of fog seen along the reflected ray to
W - B, so the wrappers set ``max_trace_level 1`` (only primary rays are traced;
reflected and refracted rays contribute black to both renders).  A fog the scene
declares itself would add to ours; scenes with fog or media are not supported.
POV-Ray applies no fog to ray segments inside a solid object that is not ``hollow``:
a camera inside e.g. ``plane { z, 5 }`` (whose inside is z < 5) sees no fog at all,
which :func:`probe_depth` detects and reports.

Precision: POV-Ray writes EXR as half floats (relative step 2^-11), so f is known
to about +-5e-4 and d to about D * 5e-4 / f: best near d ~ D, a few per cent at
d = 5 D.  Pixels with f below :data:`BACKGROUND_F` (d beyond about 8 D) are
reported as ``inf`` (background).  The default D is twice the plan's focus
distance.

The probe renders ``depth_fog_black.pov`` and ``depth_fog_white.pov`` (the
plan's scene include and pinhole camera, plus the fog) as two POV-Ray processes
running at the same time (:func:`start_probe`; they share the cores, ``+WT1``
each on two): a small render spends most of its ~0.7 s wall time idle in
POV-Ray's start-up, so the pair takes about as long as one.  The images go to a temporary folder that is removed
afterwards.  :func:`probe_depth` probes a render folder: its wrappers are written
next to ``pinhole.pov``.  The ``--method auto`` probe
(:func:`povlens.auto_plan.start_depth_probe`) renders the main plan's camera at
a smaller size, wrappers and images in one temporary folder; it runs while
povlens builds the pupil table.  If either render fails, the other is stopped
and POV-Ray's message is raised (:class:`~povlens.errors.PovrayError`).
Distances are along each pixel's ray from the camera location (the entrance
pupil) in scene units; see :func:`axial_depth` for the distance along the
viewing direction.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from povlens.plan.convert import read_plan
from povlens.errors import PovlensError
from povlens.pov.mesh import pinhole_wrapper
from povlens.util.files import write_text
from povlens.pov.process import start_render

__all__ = ["probe_depth", "start_probe", "DepthProbe", "fog_wrapper", "ray_directions",
           "axial_depth", "distance_from_fog", "BACKGROUND_F"]

#: Fog transmittance below which a pixel counts as background (d > ~8.3 D).
BACKGROUND_F = 2.5e-4


def fog_wrapper(pinhole_text: str, fog_distance: float, white: bool) -> str:
    """The pinhole wrapper's text plus primary-rays-only tracing and a constant fog."""
    colour = 1 if white else 0
    return (pinhole_text.rstrip("\n") + "\n"
            "// povlens depth probe: only primary rays, constant fog (see povlens/depth_probe.py)\n"
            "global_settings { max_trace_level 1 }\n"
            f"fog {{ fog_type 1 distance {float(fog_distance):.17g} color rgb {colour} }}\n")


def distance_from_fog(white: np.ndarray, black: np.ndarray, fog_distance: float) -> np.ndarray:
    """Distances (H, W) from a white-fog and a black-fog render (H, W, C), linear.

    d = -D ln(1 - (W - B)), channel-averaged; ``inf`` where f < :data:`BACKGROUND_F`.
    """
    w = np.asarray(white, dtype=np.float64)[..., :3]
    b = np.asarray(black, dtype=np.float64)[..., :3]
    f = 1.0 - (w - b).mean(axis=2)
    f = np.clip(f, 0.0, 1.0)
    with np.errstate(divide="ignore"):
        d = -float(fog_distance) * np.log(np.where(f >= BACKGROUND_F, f, 1.0))
    return np.where(f >= BACKGROUND_F, d, np.inf)


def ray_directions(plan: dict) -> np.ndarray:
    """Unit world directions (H, W, 3) of the pinhole camera's pixel rays.

    POV-Ray's perspective camera shoots pixel (col i, row j) along
    ``D + (u - 1/2) R + (1/2 - v) U`` with u = (i + 1/2)/W, v = (j + 1/2)/H.
    """
    cam = plan["povray_camera"]
    w, h = plan["film"]["width_px"], plan["film"]["height_px"]
    D, R, U = (np.asarray(cam[k], dtype=np.float64) for k in ("direction", "right", "up"))
    u = (np.arange(w) + 0.5) / w - 0.5
    v = 0.5 - (np.arange(h) + 0.5) / h
    d = D + u[None, :, None] * R + v[:, None, None] * U
    return d / np.linalg.norm(d, axis=2, keepdims=True)


def axial_depth(plan: dict, distance: np.ndarray) -> np.ndarray:
    """Distance along the viewing direction (as thin-lens depths are measured) of
    points at ray distance ``distance`` (H, W) from the camera location."""
    fwd = np.asarray(plan["povray_camera"]["direction"], dtype=np.float64)
    fwd = fwd / np.linalg.norm(fwd)
    return np.asarray(distance, dtype=np.float64) * (ray_directions(plan) @ fwd)


def probe_depth(outdir: str | os.PathLike, fog_distance: float | None = None,
                threads: int | None = None) -> np.ndarray:
    """Per-pixel distance (H, W) float64 in scene units of the folder's pinhole view,
    ``inf`` where the ray hits nothing.  ``fog_distance`` D defaults to twice the
    focus distance (scene units); ``threads`` per render (the two run at once;
    default half the cores, at least 1)."""
    outdir = Path(outdir)
    return start_probe(read_plan(outdir), outdir, fog_distance=fog_distance,
                       threads=threads).result()


def start_probe(plan: dict, folder: str | os.PathLike, *, width: int | None = None,
                height: int | None = None, fog_distance: float | None = None,
                threads: int | None = None, keep_wrappers: bool = True,
                prefix: str = ".depth.", label: str | None = None,
                view: bool = False) -> "DepthProbe":
    """Start the two fogged renders of ``plan``'s pinhole view; returns at once.
    With ``view``, a third render of the same view without fog runs beside them
    (:attr:`DepthProbe.image` once collected: what the scene looks like, for
    estimates of image error).

    ``plan`` needs ``povray_camera``, ``inputs.scene`` and ``inputs.focus`` (and
    ``film.width_px`` / ``height_px`` unless ``width`` / ``height`` are given:
    the probe may be smaller than the plan's film; the view is the same).
    A temporary folder ``prefix*`` in ``folder`` holds the images; the wrappers
    ``depth_fog_{black,white}.pov`` are written to ``folder`` if
    ``keep_wrappers``, else into the temporary folder.  ``label`` names the probe
    in errors (default ``folder``).  Collect with :meth:`DepthProbe.result`."""
    folder = Path(folder)
    if fog_distance is None:
        focus = float(plan["inputs"]["focus"])
        fog_distance = 2.0 * focus if math.isfinite(focus) and focus > 0 else 10.0
    if not (fog_distance > 0 and math.isfinite(fog_distance)):
        raise PovlensError(f"fog distance {fog_distance}: must be positive and finite")
    w = int(plan["film"]["width_px"] if width is None else width)
    h = int(plan["film"]["height_px"] if height is None else height)
    if threads is None:
        threads = max(1, (os.cpu_count() or 1) // 2)
    probe_plan = dict(plan, film=dict(plan.get("film", {}), width_px=w, height_px=h))
    scene = Path(plan["inputs"]["scene"])
    cam = plan["povray_camera"]
    tmp = Path(tempfile.mkdtemp(prefix=prefix, dir=folder))
    wrappers = folder if keep_wrappers else tmp
    probe = DepthProbe(probe_plan, float(fog_distance), tmp, label or str(folder))
    try:
        base = pinhole_wrapper(os.path.relpath(scene, wrappers), cam["location"],
                               cam["direction"], cam["right"], cam["up"])
        for name, white in (("black", False), ("white", True)):
            pov = write_text(wrappers / f"depth_fog_{name}.pov",
                             fog_wrapper(base, fog_distance, white))
            probe._jobs[name] = start_render(pov, tmp / f"{name}.exr", w, h, threads=threads,
                                             library_paths=[scene.parent])
        if view:
            pov = write_text(wrappers / "depth_view.pov", base)
            probe._jobs["view"] = start_render(pov, tmp / "view.exr", w, h, threads=threads,
                                               library_paths=[scene.parent])
    except BaseException:
        probe.cancel()
        raise
    return probe


class DepthProbe:
    """The two running renders of a depth probe (:func:`start_probe`).

    ``plan`` is the plan as the probe sees it (``film.width_px`` / ``height_px``
    the probe's size), for :func:`ray_directions` / :func:`axial_depth`."""

    def __init__(self, plan: dict, fog_distance: float, tmp: Path, label: str):
        self.plan, self.fog_distance, self.label = plan, fog_distance, label
        self._tmp = tmp
        self._jobs: dict = {}
        #: (H, W, 3) linear image of the view without fog (``view=True``), once collected.
        self.image: np.ndarray | None = None

    def result(self) -> np.ndarray:
        """Wait for both renders; per-pixel distances (H, W) in scene units, ``inf``
        where the ray hits nothing.  Raises POV-Ray's error if a render failed (the
        other is stopped), :class:`PovlensError` if the fog had no effect."""
        from povlens.util.images import read_image   # (OpenImageIO: imported while POV-Ray runs)
        try:
            images = {name: read_image(job.wait()) for name, job in self._jobs.items()}
        finally:
            self.cancel()
        if "view" in images:
            self.image = np.asarray(images["view"][..., :3], dtype=np.float64)
        d = distance_from_fog(images["white"], images["black"], self.fog_distance)
        if np.all(d[np.isfinite(d)] < 1e-3 * self.fog_distance) and np.isfinite(d).any():
            raise PovlensError(
                f"{self.label}: the depth probe's fog had no effect: the camera seems to be "
                f"inside a solid object (POV-Ray applies no fog inside objects that are not "
                f"'hollow')",
                "make the object around the camera hollow, or flip the plane's normal")
        return d

    def cancel(self) -> None:
        """Stop the renders still running and remove the temporary folder."""
        try:
            for job in self._jobs.values():
                job.cancel()
        finally:
            shutil.rmtree(self._tmp, ignore_errors=True)
