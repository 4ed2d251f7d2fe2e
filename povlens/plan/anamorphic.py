"""Anamorphic lenses in a plan: the squeeze, the desqueezed film, and what focal_blur cannot do.

An anamorphic lens (toric or cylindrical rows, ``lens.is_anamorphic``) has two focal
lengths, EFL_x in the x-z plane and EFL_y in the y-z plane; their ratio
S = EFL_y / EFL_x is the squeeze (:func:`povlens.lens.paraxial.anamorphic_data`).  A 2x
lens (EFL_x = EFL_y / 2) takes in twice the horizontal field a spherical lens of EFL_y
would and squeezes it onto the film: round things are exposed S times narrower.

**Desqueeze** (``desqueeze``, the default; ``--no-desqueeze``).  The output image is
what a projector with the matching anamorphic lens shows: the film stretched S times
horizontally.  povlens does it exactly, without resampling, by the pixels it puts on
the film: the film of the given diagonal takes the proportions (W / H) / S, so each
output pixel covers a film patch 1 / S times as wide as tall (film pitch x = pitch y /
S), and every lens ray starts from the film point of its pixel as always
(:class:`povlens.lens.film.Film` maps pixels to film points with any pitch).  A film size
given in mm (``film_size_mm``) is the exposed gate as given; the picture is then that
gate stretched to W x H, whose pixels are square when W / H = S w / h (the note says
which proportions that needs).  Without desqueeze the film takes the image's
proportions (square pixels on the film): the image is the film as exposed, squeezed.

**What POV-Ray's own cameras can draw.**  Their projection takes one scale per image
axis (``right`` and ``up``), so the pinhole view is framed per meridian
(:class:`povlens.thinlens.model.EquivalentThinLens` keeps both image distances); but
``focal_blur`` has one focal length and a round pupil, so it cannot draw the two blurs
of an anamorphic lens (its oval bokeh): ``--method auto`` rules it out
(:func:`povlens.plan.decision.decide`, :data:`povlens.plan.decision.ANAMORPHIC_REASON`), and an explicit ``--method focal-blur`` renders
with the y-z meridian's thin lens after a :class:`AnamorphicFocalBlurWarning`.
"""

from __future__ import annotations

import dataclasses
import math
import warnings

from povlens.errors import OpticsError, PovlensWarning
from povlens.lens.film import Film
from povlens.lens.paraxial import AnamorphicData, anamorphic_data

__all__ = ["AnamorphicFocalBlurWarning", "anamorphic_data_of", "describe", "squeezed_film",
           "apply_anamorphic", "anamorphic_text",
           "anamorphic_record", "warn_focal_blur", "FOCAL_BLUR_NOTE"]

#: The note (and warning) of a focal-blur plan of an anamorphic lens.
FOCAL_BLUR_NOTE = (
    "method focal-blur on an anamorphic lens ({what}): POV-Ray's focal_blur has one focal "
    "length and a round pupil, so it renders the y-z meridian's thin lens (focal length "
    "{efl_y:.4g} mm, entrance pupil {pupil:.3g} mm) in both directions: out-of-focus light "
    "is round, not the lens's ovals; the view is framed per meridian; --method mesh renders "
    "the lens exactly")

class AnamorphicFocalBlurWarning(PovlensWarning):
    """An explicit focal-blur render of an anamorphic lens: rendered with the y-z
    meridian's thin lens (:data:`FOCAL_BLUR_NOTE`)."""


def anamorphic_data_of(lens) -> AnamorphicData | None:
    """The two meridians' first-order data of an anamorphic ``lens`` (None for a
    rotationally symmetric one).

    Raises
    ------
    OpticsError
        When the lens has no power in one meridian (a lone cylinder, an afocal
        attachment): it forms no image on film in that meridian.
    """
    if not getattr(lens, "is_anamorphic", False):
        return None
    data = anamorphic_data(lens)
    if data.afocal or not (math.isfinite(data.squeeze) and data.squeeze > 0):
        m = data.afocal or ("x" if not math.isfinite(data.efl_x_mm) else "y")
        raise OpticsError(f"{lens.source}: the lens has no power in its {m}-z plane (an "
                          f"afocal anamorphic attachment or a lone cylinder): it forms no "
                          f"image on film there",
                          "put it in front of (or behind) a lens with power in both "
                          "meridians, as lentil's 2004 and 2003 designs are")
    return data


def describe(data: AnamorphicData) -> str:
    """``EFL_x 31.5 mm, EFL_y 60.6 mm, squeeze 1.92``."""
    return (f"EFL_x {data.efl_x_mm:.4g} mm, EFL_y {data.efl_y_mm:.4g} mm, squeeze "
            f"{data.squeeze:.3g}")


def anamorphic_text(record: dict) -> str:
    """:func:`describe` of a plan's ``anamorphic`` record."""
    return (f"EFL_x {record['efl_x_mm']:.4g} mm, EFL_y {record['efl_y_mm']:.4g} mm, squeeze "
            f"{record['squeeze']:.3g}")


def squeezed_film(film: Film, data: AnamorphicData, desqueeze: bool,
                  film_size_given: bool) -> tuple[Film, str]:
    """The film of an anamorphic plan and the note saying what the image shows.

    Parameters
    ----------
    film : the film as :func:`povlens.plan.camera_setup.film_of` made it (the given
        diagonal in the image's proportions, or the given size), its shift included.
    data : the lens's :class:`~povlens.lens.paraxial.AnamorphicData`.
    desqueeze : the option: the image as projected (True) or the film as exposed.
    film_size_given : a film size in mm was given (it is kept as given).

    Returns
    -------
    (Film, str)
        Desqueezed and no size given: the film of the same diagonal whose proportions
        are the image's divided by the squeeze (film pitch x = pitch y / S, module
        docstring); otherwise ``film`` itself.
    """
    S = float(data.squeeze)
    W, H = film.width_px, film.height_px
    what = describe(data)
    if not desqueeze:
        return film, (f"anamorphic lens ({what}), not desqueezed (--no-desqueeze): the image "
                      f"is the film as exposed, the scene squeezed {S:.3g} x horizontally")
    if film_size_given:
        aspect = (film.height_mm / H) / (film.width_mm / W)
        square = S * film.width_mm / film.height_mm
        return film, (f"anamorphic lens ({what}), desqueezed: the {film.width_mm:g} x "
                      f"{film.height_mm:g} mm film (film_size_mm) is stretched to the "
                      f"{W}x{H} image, its pixels {aspect:.4g} times as tall as wide on the "
                      f"film; they show square when the image's proportions are "
                      f"{square:.4g} (the squeeze times the film's)")
    diagonal = math.hypot(film.width_mm, film.height_mm)
    a = (film.width_mm / film.height_mm) / S
    w = diagonal / math.sqrt(1.0 + 1.0 / (a * a))
    out = dataclasses.replace(film, width_mm=w, height_mm=w / a)
    return out, (f"anamorphic lens ({what}), desqueezed: the image shows what a projector "
                 f"with the matching anamorphic lens would; the film ({out.width_mm:.4g} x "
                 f"{out.height_mm:.4g} mm, the {diagonal:.4g} mm diagonal) is sampled with "
                 f"pixels {S:.4g} times as tall as wide, so no resampling is needed "
                 f"(--no-desqueeze: the film as exposed)")


def anamorphic_record(data: AnamorphicData, model, film: Film, desqueeze: bool) -> dict:
    """plan.json's ``anamorphic``: both meridians' first-order data (EFL, f-number,
    paraxial focus, entrance pupil; :meth:`AnamorphicData.to_dict`), the squeeze, whether
    the image is desqueezed, the film's pixel aspect (pitch y / pitch x) and the thin-lens
    model's image distances per meridian (the views' framing)."""
    vx, vy = model.image_distances_mm
    return {**data.to_dict(), "desqueeze": bool(desqueeze),
            "film_pixel_aspect": (film.height_mm / film.height_px)
            / (film.width_mm / film.width_px),
            "image_distance_x_mm": float(vx), "image_distance_y_mm": float(vy)}


def warn_focal_blur(data: AnamorphicData, model) -> str:
    """Warn that an explicit focal-blur render of an anamorphic lens uses the y-z
    meridian's thin lens; returns the note the plan keeps."""
    note = FOCAL_BLUR_NOTE.format(what=describe(data), efl_y=data.efl_y_mm,
                                  pupil=model.pupil_diameter_mm)
    warnings.warn(AnamorphicFocalBlurWarning(note), stacklevel=3)
    return note


def apply_anamorphic(opts, plan, start) -> None:
    """What an anamorphic lens adds to a finished plan: ``plan.anamorphic`` (the
    start's record) and, for an explicit focal-blur render, :data:`FOCAL_BLUR_NOTE` as a
    note and a warning.  Nothing for a rotationally symmetric lens."""
    if start.anamorphic is None:
        return
    plan.anamorphic = start.anamorphic
    if opts.sampling.method == "focal-blur":
        plan.add_note(warn_focal_blur(anamorphic_data_of(start.lens), start.thin_lens))
