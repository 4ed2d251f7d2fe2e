"""Focus from the scene: the focus distance when ``--focus`` is not given.

:func:`resolve_focus`, first that applies:

1. ``focus`` given: ``"option"``;
2. ``focus_at`` (X, Y) given: what the depth probe sees at output pixel (X, Y)
   (column X from the left, row Y from the top, 0-based, of the ``width`` x ``height``
   image): ``"depth probe at X,Y"``;
3. the scene camera's ``focal_point`` when it has focal blur (``aperture`` > 0): the
   distance POV-Ray focuses at, |focal_point - location| (``"focal_point"``);
4. the distance to ``look_at`` (the scene camera's, or ``--look-at``'s): ``"look_at"``;
5. what the depth probe sees at the centre of the frame: ``"depth probe at centre"``;
   for method pinhole, which has no blur to focus, no probe runs: the lens is focused
   at a typical 5 m (:data:`PINHOLE_FOCUS_FROM`; the plan's note says so).

The probe (:mod:`povlens.plan.depth_probe`) renders only a :data:`WINDOW` x
:data:`WINDOW` window of output pixels around the point, as a camera of its own whose
rays are those of the plan's pinhole camera at those pixels (:func:`window_camera`):
the point is measured at the output image's resolution for the cost of POV-Ray's
start-up.  The focus is the median axial distance (along the viewing direction, as
``focus`` is measured) of the window pixels on the surface under the point (within
:data:`SAME_SURFACE` of its distance).  The point's own pixel must have a depth:
background (nothing hit) or a surface without a measurable response (black, emissive,
clear) is a :class:`~povlens.errors.ParameterError` saying so.

The field of view depends on the focus (focus breathing), so pixel (X, Y) looks in a
slightly different direction once the plan is focused: the probe is repeated with the
camera of the focus found until the point moves by less than :data:`SHIFT_PX` and the
distance is well inside the probe's fade range (at most :data:`MAX_ROUNDS` rounds;
the frame's centre never moves, one round suffices).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from povlens.errors import ParameterError
from povlens.lens.film import Film
from povlens.lens.focus import UNITS_MM
from povlens.plan.depth_probe import ProbeView, ray_directions, start_probe
from povlens.plan.camera_setup import camera_focus
from povlens.plan.options import ConvertOptions
from povlens.plan.plan_start import PlanStart, start_plan
from povlens.plan.schema import PovrayCamera

__all__ = ["WINDOW", "SAME_SURFACE", "SHIFT_PX", "MAX_ROUNDS", "FADE_RANGE", "resolve_focus",
           "focus_point", "window_camera", "pixel_shift_px", "measure_focus",
           "PINHOLE_FOCUS_FROM", "pinhole_focus_note"]

#: Output pixels on a side of the probed window (odd: the point is its central pixel).
WINDOW = 5
#: Window pixels within this relative distance of the point's are on its surface.
SAME_SURFACE = 0.1
#: The probe is repeated until the point moves less than this with the new focus (px).
SHIFT_PX = 0.5
#: Most probe rounds of one focus measurement.
MAX_ROUNDS = 4
#: The probe's fade distance D resolves d / D in this range to 1 % or better (measured:
#: docs/decisions/planning.md); outside it the probe is repeated with D = d.
FADE_RANGE = (0.05, 100.0)
#: The first round's focus (mm) when the camera gives none: a typical distance.
_FIRST_FOCUS_MM = 5000.0
#: ``focus_from`` of a pinhole plan whose camera gives no focus: no probe measures one
#: (a pinhole render has no blur); the lens is focused at the typical distance, which
#: sets only the field of view (focus breathing).  :func:`pinhole_focus_note` says so.
PINHOLE_FOCUS_FROM = "default distance (method pinhole: no depth probe)"


def focus_point(opts: ConvertOptions) -> tuple[float, float, str]:
    """Where to focus: (x, y) in output pixels (pixel (i, j) covers [i, i+1) x [j, j+1),
    row 0 at the top) and the plan.json ``focus_from`` label.

    ``opts.pose.focus_at`` (X, Y) is the centre of pixel (X, Y); without it, the frame's
    centre.  :class:`ParameterError` for a pixel outside the image.
    """
    w, h = int(opts.film.width), int(opts.film.height)
    if opts.pose.focus_at is None:
        return w / 2.0, h / 2.0, "depth probe at centre"
    try:
        x, y = (int(v) for v in opts.pose.focus_at)
    except (TypeError, ValueError):
        at = opts.pose.focus_at
        raise ParameterError("focus_at", at, f"focus_at={at!r}: not a pixel",
                             "give 'focus_at' as the column and row of an output pixel"
                             ) from None
    if not (0 <= x < w and 0 <= y < h):
        raise ParameterError("focus_at", opts.pose.focus_at,
                             f"focus_at={x},{y}: outside the {w}x{h} image",
                             f"give a column 0..{w - 1} and a row 0..{h - 1}")
    return x + 0.5, y + 0.5, f"depth probe at {x},{y}"


def window_camera(cam: PovrayCamera, film: Film, x: float, y: float,
                  n: int = WINDOW) -> tuple[PovrayCamera, Film]:
    """The camera (and film) whose n x n pixels are the output pixels centred at (x, y).

    POV-Ray's pixel (i, j) of a W x H image looks along D + (u - 1/2) R + (1/2 - v) U,
    u = (i + 1/2)/W, v = (j + 1/2)/H: a camera with direction D + (x/W - 1/2) R +
    (1/2 - y/H) U, right R n/W and up U n/H shoots the same rays at its n x n pixels.
    The film is the window's (mm), for :class:`~povlens.plan.depth_probe.ProbeView`.
    """
    D, R, U = (np.asarray(v, dtype=np.float64) for v in (cam.direction, cam.right, cam.up))
    w, h = film.width_px, film.height_px
    d = D + (x / w - 0.5) * R + (0.5 - y / h) * U
    win = dataclasses.replace(cam, direction=tuple(d.tolist()),
                              right=tuple((R * n / w).tolist()), up=tuple((U * n / h).tolist()))
    return win, Film(film.width_mm * n / w, film.height_mm * n / h, n, n)


def _pixel_direction(cam: PovrayCamera, film: Film, x: float, y: float) -> np.ndarray:
    """Unit world direction (3,) of point (x, y) (output pixels) of ``cam``'s image."""
    D, R, U = (np.asarray(v, dtype=np.float64) for v in (cam.direction, cam.right, cam.up))
    d = D + (x / film.width_px - 0.5) * R + (0.5 - y / film.height_px) * U
    return d / np.linalg.norm(d)


def pixel_shift_px(a: PovrayCamera, b: PovrayCamera, film: Film, x: float, y: float) -> float:
    """How far (output pixels, in ``a``'s image) the point (x, y) of camera ``b``
    lies from the point (x, y) of camera ``a`` (same location, same axes)."""
    v = _pixel_direction(b, film, x, y)
    D, R, U = (np.asarray(t, dtype=np.float64) for t in (a.direction, a.right, a.up))
    # v = s (D + u R + w U): solve in a's image plane, whose normal is R x U (D is
    # tilted off it by a lens shift, plan.camera_setup.off_axis_direction)
    n = np.cross(R, U)
    s = (n @ D) / (n @ v)
    p = s * v - D
    u = (p @ R) / (R @ R)
    w = (p @ U) / (U @ U)
    return float(math.hypot((u + 0.5) * film.width_px - x, (0.5 - w) * film.height_px - y))


def _probe_window(opts: ConvertOptions, st: PlanStart, x: float, y: float,
                  fade: float) -> tuple[np.ndarray, ProbeView]:
    """Axial distances (WINDOW, WINDOW) along ``st``'s axis of the window at (x, y)."""
    cam, film = window_camera(st.povray_camera, st.film, x, y)
    view = ProbeView(cam, film, st.mm_per_unit, str(Path(opts.scene).resolve()), fade,
                     st.povray)                    # the user's POV-Ray options
    out = Path(opts.outdir)
    out.mkdir(parents=True, exist_ok=True)
    d = start_probe(view, out, fade_distance=fade, keep_wrappers=False, prefix=".focus.",
                    label=str(opts.scene)).result()
    fwd = np.asarray(st.forward, dtype=np.float64)
    return d * (ray_directions(view) @ (fwd / np.linalg.norm(fwd))), view


def _window_focus(axial: np.ndarray, label: str, strict: bool = True) -> tuple[float, dict]:
    """The focus of a window of axial distances (its centre pixel's surface, median),
    and the numbers behind it; :class:`ParameterError` if the centre has no depth
    (unless not ``strict``: then the pixel with depth nearest to the centre counts)."""
    c = axial.shape[0] // 2
    centre = float(axial[c, c])
    rows, cols = np.nonzero(np.isfinite(axial))
    if not math.isfinite(centre) and not strict and rows.size:
        k = int(np.argmin(np.hypot(rows - c, cols - c)))
        centre = float(axial[rows[k], cols[k]])
    if not math.isfinite(centre):
        what = ("sees background (nothing: infinitely far)" if centre == math.inf else
                "sees a surface whose distance the depth probe cannot measure (black, "
                "emissive or clear: no response to light)")
        name = "focus" if label.endswith("centre") else "focus_at"
        raise ParameterError(name, None, f"focus from the {label}: the pixel {what}",
                             "give 'focus' (scene units), or 'focus_at' on a lit surface")
    same = axial[np.isfinite(axial) & (np.abs(axial - centre) <= SAME_SURFACE * centre)]
    info = {"window_px": int(axial.shape[0]), "centre_distance": centre,
            "surface_pixels": int(same.size),
            "background_pixels": int(np.isposinf(axial).sum()),
            "no_depth_pixels": int(np.isnan(axial).sum())}
    return float(np.median(same)), info


#: Pixels across the frame of the coarse probe that looks for a lit surface.
SEARCH_WIDTH_PX = 48


def nearest_lit_point(opts: ConvertOptions, st: PlanStart, fade: float
                      ) -> tuple[float, float, str] | None:
    """Where to focus when the frame's centre may see background or an unlit surface.

    Probes the whole frame coarsely (:data:`SEARCH_WIDTH_PX` across; only when the
    window at the centre found no depth); returns the centre itself if it has depth
    there, else the point (output pixels) of the pixel with depth nearest to the centre
    and its ``focus_from`` label, or None when nothing in the frame has depth.
    """
    w, h = st.film.width_px, st.film.height_px
    n_x = min(SEARCH_WIDTH_PX, w)
    n_y = max(1, round(n_x * h / w))
    coarse = st.film.resized(st.film.width_mm, st.film.height_mm, n_x, n_y)
    view = ProbeView(st.povray_camera, coarse, st.mm_per_unit,
                     str(Path(opts.scene).resolve()), fade, st.povray)
    out = Path(opts.outdir)
    out.mkdir(parents=True, exist_ok=True)
    d = start_probe(view, out, fade_distance=fade, keep_wrappers=False, prefix=".focus.",
                    label=str(opts.scene)).result()
    rows, cols = np.nonzero(np.isfinite(d))
    if rows.size == 0:
        return None
    # distance to the centre in output pixels
    px, py = (cols + 0.5) * w / n_x, (rows + 0.5) * h / n_y
    k = int(np.argmin(np.hypot(px - w / 2.0, py - h / 2.0)))
    if abs(px[k] - w / 2.0) <= w / n_x and abs(py[k] - h / 2.0) <= h / n_y:
        return w / 2.0, h / 2.0, "depth probe at centre"
    x, y = int(px[k]), int(py[k])
    return x + 0.5, y + 0.5, f"depth probe at {x},{y} (nearest lit surface to the centre)"


def measure_focus(opts: ConvertOptions) -> tuple[float, str, dict]:
    """Focus on what the depth probe sees at the focus point (:func:`focus_point`).

    Returns
    -------
    (focus, focus_from, info)
        Axial distance in scene units, the label, and plan.json's
        ``depth_probe.focus`` numbers (point, rounds, fade distance, window counts).
    """
    x, y, label = focus_point(opts)
    got = camera_focus(opts)
    from_mm = _FIRST_FOCUS_MM / _mm_per_unit(opts)
    focus = got[0] if got is not None else from_mm
    fade = focus
    st = start_plan(opts.replace(focus=focus, focus_from=label))
    for rounds in range(1, MAX_ROUNDS + 1):
        axial, _ = _probe_window(opts, st, x, y, fade)
        if rounds == 1 and opts.pose.focus_at is None and not np.isfinite(axial).any():
            # nothing with depth around the frame's centre: the lit surface nearest to it
            near = nearest_lit_point(opts, st, fade)
            if near is None:
                return from_mm, "default distance (no depth anywhere in the frame)", {
                    "point_px": None, "rounds": 0, "focus": from_mm}
            x, y, label = near
            axial, _ = _probe_window(opts, st, x, y, fade)
        new, info = _window_focus(axial, label, strict=opts.pose.focus_at is not None)
        # the point under the new focus's camera: moved by breathing?
        new_st = start_plan(opts.replace(focus=new, focus_from=label))
        shift = pixel_shift_px(st.povray_camera, new_st.povray_camera, st.film, x, y)
        info.update({"fade_distance": fade, "last_shift_px": shift})
        in_range = FADE_RANGE[0] <= new / fade <= FADE_RANGE[1]
        st, focus, fade = new_st, new, new
        if shift <= SHIFT_PX and in_range:
            break
    info.update({"point_px": [x, y], "rounds": rounds, "focus": focus})
    return focus, label, info


def _mm_per_unit(opts: ConvertOptions) -> float:
    return UNITS_MM[opts.pose.units]


def pinhole_focus_note(opts: ConvertOptions) -> str | None:
    """The plan's note when :func:`resolve_focus` gave a pinhole plan the default
    focus (``focus_from`` :data:`PINHOLE_FOCUS_FROM`), else None."""
    if opts.pose.focus_from != PINHOLE_FOCUS_FROM:
        return None
    return (f"the camera gives no focus (no focal_point with focal blur, no look_at) and "
            f"method pinhole needs none: no depth probe ran and the lens is focused at "
            f"focus={opts.pose.focus:g} ({_FIRST_FOCUS_MM / 1000:g} m), which sets only the "
            f"field of view (it changes a little with the focus); give 'focus' for the "
            f"framing at another distance")


def resolve_focus(opts: ConvertOptions) -> tuple[ConvertOptions, dict | None]:
    """``opts`` with ``focus`` and ``focus_from`` set (the module docstring's order).

    Returns
    -------
    (ConvertOptions, dict or None)
        The options, and the focus probe's numbers (None when no probe ran).  A pinhole
        plan runs no probe for step 5: it is focused at the typical distance
        (:data:`PINHOLE_FOCUS_FROM`, :func:`pinhole_focus_note`).

    Raises :class:`ParameterError` for ``focus`` with ``focus_at``, a pixel outside the
    image, or a point the probe finds no depth at.
    """
    if opts.pose.focus is not None:
        if opts.pose.focus_at is not None:
            raise ParameterError("focus_at", opts.pose.focus_at,
                                 "'focus' and 'focus_at' both given",
                                 "give one of them")
        return opts.replace(focus_from=opts.pose.focus_from or "option"), None
    if opts.pose.focus_at is None:
        got = camera_focus(opts)
        if got is not None:
            return opts.replace(focus=got[0], focus_from=got[1]), None
        if opts.sampling.method == "pinhole":       # no blur to focus: no depth probe either
            return opts.replace(focus=_FIRST_FOCUS_MM / _mm_per_unit(opts),
                                       focus_from=PINHOLE_FOCUS_FROM), None
    focus, label, info = measure_focus(opts)
    return opts.replace(focus=focus, focus_from=label), info
