"""The lens's vignetting on a pinhole or focal_blur view: a relative illumination map.

POV-Ray's pinhole and focal_blur cameras have no vignetting.  The real lens's
relative illumination E(pixel) / E(centre) is known exactly from the exit-pupil
table (:func:`povlens.pupil.illumination.illumination_profile`), so when the
plan wants the vignetting (``inputs.vignetting``, the default; ``--no-vignetting``
turns it off) the view's ``image.exr`` / ``image.png`` are the view as POV-Ray
rendered it (``view-<name>.exr``, kept as it is) times that map.  Where the image
is sharp this is what the lens records, exactly (the mesh render's composite
multiplies by the same quantity: its pixels' mean radiometric weight times the
exposure); what it cannot carry -- the cat's-eye shape of out-of-focus light --
is judged by ``--method auto`` (:mod:`povlens.plan.decision`).

What was applied is recorded in plan.json (``vignetting_map``,
:func:`vignetting_record`): the profile over film radius, the frame's smallest and
corner values, and the table it came from.  The profile is computed once per
folder: a later render reuses the recorded one, and a ``--method auto`` plan
brings the one its decision measured (``decision.numbers.illumination_profile``),
both only when made from the same lens, focus and film.
"""

from __future__ import annotations

import dataclasses
import threading
from pathlib import Path
from typing import Callable

import numpy as np

from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Plan, write_plan
from povlens.pupil.illumination import (IlluminationProfile, illumination_profile,
                                        profile_from_record, profile_record,
                                        relative_illumination_map)

__all__ = ["wants_vignetting_map", "vignetting_profile", "vignetting_record",
           "apply_vignetting_map", "start_vignetting_map", "PendingVignettingMap",
           "mesh_illumination_map", "RECORD_METHOD"]

#: ``vignetting_map.method`` of plan.json.
RECORD_METHOD = ("relative illumination E(pixel)/E(centre) from the exit-pupil table "
                 "(povlens.pupil.illumination), times the view as POV-Ray rendered it")


def wants_vignetting_map(plan: Plan) -> bool:
    """Whether ``plan``'s image gets the map: a pinhole or focal-blur plan that wants
    the lens's vignetting (mesh renders composite it from their weights)."""
    return bool(plan.inputs.vignetting) and plan.inputs.method in ("pinhole", "focal-blur")


def vignetting_profile(plan: Plan, table) -> IlluminationProfile:
    """The relative illumination over film radius for ``plan``'s film: the one
    plan.json records (``vignetting_map``, else the decision's
    ``illumination_profile``) when made from ``table``'s lens, focus and film, else
    computed (:func:`~povlens.pupil.illumination.illumination_profile`).  Always the
    recorded (rounded) values, so a re-render gives the same image bit for bit."""
    numbers = plan.decision.numbers if plan.decision is not None else {}
    for rec in (plan.vignetting_map, numbers.get("illumination_profile")):
        got = profile_from_record(rec, table)
        if got is not None:
            return got
    fresh = illumination_profile(table, plan.film.max_field_radius_mm)
    return profile_from_record(profile_record(fresh, table), table)


def vignetting_record(plan: Plan, table, profile: IlluminationProfile,
                      ri_map: np.ndarray) -> dict:
    """plan.json's ``vignetting_map``: what :func:`apply_vignetting_map` applied.

    Keys: ``applied_to`` (the files), ``view`` (the raw render, kept), ``method``,
    ``pixel_average`` (the map is the mean over each pixel, as jittered mesh samples
    see it), ``min_relative_illumination`` and ``corner_relative_illumination`` of the
    map, ``image_size`` and the profile with the table's key
    (:func:`~povlens.pupil.illumination.profile_record`: lens hash, film distance,
    half-diagonal, ``film_radius_mm`` and ``relative_illumination``; the map is linear
    between them)."""
    h, w = ri_map.shape
    rec = profile_record(profile, table)
    rec.pop("min_relative_illumination", None)
    rec.pop("exact_radii", None)
    names = RenderFolder(".")
    return {"applied_to": [names.image_exr.name, names.image_png.name],
            "view": names.view_image(plan.inputs.method).name,
            "method": RECORD_METHOD,
            "pixel_average": bool(plan.inputs.jitter),
            "min_relative_illumination": round(float(ri_map.min()), 7),
            "corner_relative_illumination": round(float(ri_map[0, 0]), 7),
            "image_size": [int(w), int(h)], **rec}


def _map_of(plan: Plan, table):
    """(profile, map (H, W)) of ``plan``'s film."""
    film = plan.film
    profile = vignetting_profile(plan, table)
    ri = relative_illumination_map(profile, film.width_mm, film.height_mm, film.width_px,
                                   film.height_px, pixel_average=bool(plan.inputs.jitter),
                                   shift_mm=film.shift_mm)
    return profile, ri


def _apply(outdir, plan: Plan, image: np.ndarray, table, profile, ri) -> np.ndarray:
    film = plan.film
    img = np.asarray(image, dtype=np.float64)
    if img.shape[:2] != (film.height_px, film.width_px):
        raise ValueError(f"image {img.shape[1]}x{img.shape[0]} is not the film's "
                         f"{film.width_px}x{film.height_px} pixels")
    record = vignetting_record(plan, table, profile, ri)
    if plan.vignetting_map != record:
        write_plan(dataclasses.replace(plan, vignetting_map=record), Path(outdir))
    return img * ri[..., None]


def apply_vignetting_map(outdir, plan: Plan, image: np.ndarray, table) -> np.ndarray:
    """``image`` (H, W, C) times the lens's relative illumination map, when the plan
    wants it (:func:`wants_vignetting_map`; otherwise ``image`` is returned as it
    is), and the record of it written to OUTDIR/plan.json (left alone when it is
    already there).

    Parameters
    ----------
    outdir : the render folder.
    plan : its plan (read from ``outdir``).
    image : (H, W, C) linear, the view as POV-Ray rendered it (H, W the film's pixels).
    table : the plan's exit-pupil table
        (:func:`povlens.rendering.folder_inputs.pupil_table_for`).

    Returns
    -------
    ndarray
        (H, W, C) float64; the map is the mean over each pixel's area
        (``inputs.jitter``, as the mesh render's jittered film points) or the value
        at its centre.
    """
    if not wants_vignetting_map(plan):
        return image
    profile, ri = _map_of(plan, table)
    return _apply(outdir, plan, image, table, profile, ri)


def mesh_illumination_map(outdir, plan: Plan, table) -> np.ndarray:
    """(H, W) the relative illumination a field-mesh composite is scaled by
    (:func:`povlens.rendering.composite.measurement_image`).  Its profile over film
    radius is the plan's (auto's decision measured it) or computed once and kept in
    OUTDIR/illumination.json (plan.json is left alone: make compares its time
    with the samples'), so a later composite gives the same image bit for bit."""
    import json
    from povlens.util.files import write_text
    path = RenderFolder(outdir).illumination_json
    try:
        profile = profile_from_record(json.loads(path.read_text()), table)
    except (OSError, ValueError):
        profile = None
    if profile is None:
        profile = vignetting_profile(plan, table)
        write_text(path, json.dumps(profile_record(profile, table)))
    film = plan.film
    return relative_illumination_map(profile, film.width_mm, film.height_mm, film.width_px,
                                     film.height_px, pixel_average=bool(plan.inputs.jitter),
                                     shift_mm=film.shift_mm)


class PendingVignettingMap:
    """The map of a plan computed in a thread while POV-Ray renders the view
    (:func:`start_vignetting_map`); :meth:`apply` waits for it."""

    def __init__(self, outdir, plan: Plan, table_for: Callable):
        self._outdir, self._plan = Path(outdir), plan
        self._result: tuple | None = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(table_for,), daemon=True)
        self._thread.start()

    def _run(self, table_for) -> None:
        try:
            table = table_for()
            self._result = (table, *_map_of(self._plan, table))
        except BaseException as e:          # handed to apply()
            self._error = e

    def apply(self, image: np.ndarray) -> np.ndarray:
        """:func:`apply_vignetting_map` of ``image`` with the map computed meanwhile."""
        self._thread.join()
        if self._error is not None:
            raise self._error
        table, profile, ri = self._result
        return _apply(self._outdir, self._plan, image, table, profile, ri)


def start_vignetting_map(outdir, plan: Plan, table_for: Callable
                         ) -> PendingVignettingMap | None:
    """Start computing ``plan``'s map in a thread (None when the plan does not want
    it: :func:`wants_vignetting_map`).  ``table_for()`` returns the plan's exit-pupil
    table (it may build it: a pinhole plan has none yet).  The tracing is numpy work
    that releases the GIL, so it runs while POV-Ray starts and renders."""
    if not wants_vignetting_map(plan):
        return None
    return PendingVignettingMap(outdir, plan, table_for)
