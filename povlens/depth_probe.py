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

The probe renders ``depth_fog_black.pov`` and ``depth_fog_white.pov``, written
next to ``pinhole.pov`` (same scene include, same camera, plus the fog), into a
temporary folder that is removed afterwards.  Distances are along each pixel's
ray from the camera location (the entrance pupil) in scene units; see
:func:`axial_depth` for the distance along the viewing direction.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import numpy as np

from .convert import read_plan
from .errors import PovlensError
from .images import read_image
from .mesh_camera import pinhole_wrapper, write_text
from .povray import render as povray_render

__all__ = ["probe_depth", "fog_wrapper", "ray_directions", "axial_depth", "distance_from_fog",
           "BACKGROUND_F"]

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
    focus distance (scene units)."""
    outdir = Path(outdir)
    plan = read_plan(outdir)
    if fog_distance is None:
        focus = float(plan["inputs"]["focus"])
        fog_distance = 2.0 * focus if math.isfinite(focus) and focus > 0 else 10.0
    if not (fog_distance > 0 and math.isfinite(fog_distance)):
        raise PovlensError(f"fog distance {fog_distance}: must be positive and finite")
    cam = plan["povray_camera"]
    scene_inc = os.path.relpath(plan["inputs"]["scene"], outdir)
    base = pinhole_wrapper(scene_inc, cam["location"], cam["direction"], cam["right"], cam["up"])
    w, h = plan["film"]["width_px"], plan["film"]["height_px"]
    images = {}
    with tempfile.TemporaryDirectory(prefix=".depth.", dir=outdir) as tmp:
        for name, white in (("black", False), ("white", True)):
            pov = write_text(outdir / f"depth_fog_{name}.pov",
                             fog_wrapper(base, fog_distance, white))
            out = Path(tmp) / f"{name}.exr"
            povray_render(pov, out, w, h, threads=threads or os.cpu_count() or 1,
                          library_paths=[Path(plan["inputs"]["scene"]).parent])
            images[name] = read_image(out)
    d = distance_from_fog(images["white"], images["black"], fog_distance)
    if np.all(d[np.isfinite(d)] < 1e-3 * fog_distance) and np.isfinite(d).any():
        raise PovlensError(
            f"{outdir}: the depth probe's fog had no effect: the camera seems to be inside a "
            f"solid object (POV-Ray applies no fog inside objects that are not 'hollow')",
            "make the object around the camera hollow, or flip the plane's normal")
    return d
