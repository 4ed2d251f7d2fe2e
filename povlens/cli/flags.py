"""API parameter names as command-line options, in error messages.

The core names parameters as the API spells them, ``name=value`` or ``'name'``
(:mod:`povlens.errors`); a command-line user reads the option that sets the
parameter instead.  :data:`FLAG_OF` is the one table of that correspondence.
"""

from __future__ import annotations

import re
from collections.abc import Collection

from povlens.errors import ParameterError, PovlensError

__all__ = ["FLAG_OF", "with_flags", "error_text"]

#: API parameter (function argument or :class:`~povlens.plan.convert.ConvertOptions`
#: field) -> the option that sets it.
FLAG_OF = {
    "f_number": "--f-number",
    "stop_diameter_mm": "--stop-diameter",
    "focus": "--focus",
    "focus_at": "--focus-at",
    "frames": "--frames",
    "distance_mm": "--distance",
    "units": "--units",
    "method": "--method",
    "samples": "--samples",
    "batch_size": "--batch-size",
    "tolerance": "--tolerance",
    "tolerance_px": "--tolerance",
    "location": "--location",
    "look_at": "--look-at",
    "sky": "--sky",
    "plane": "--plane",
    "view": "--view",
    "width": "--width",
    "ray_mesh": "--ray-mesh",
    "width_px": "--width",
    "height": "--height",
    "height_px": "--height",
    "diagonal_mm": "--film-diagonal",
    "film_diagonal_mm": "--film-diagonal",
    "film_size_mm": "--film-size",
    "shift_mm": "--shift-mm",
    "scheduler": "--scheduler",
    "shared_dir": "--shared-dir",
    "group_size": "--group-size",
    "aperture_blades": "--aperture-blades",
    "blade_curvature": "--blade-curvature",
    "blade_rotation_deg": "--blade-rotation",
    "aperture_image": "--aperture-image",
    "dispersion": "--dispersion",
    "film_distance_mm": "--film-distance",
    "library_paths": "--library-path",
    "clock": "--clock",
    "povray_options": "--povray-option",
    "lens_id": "--id",
    "efl_mm": "--efl",
    "adjusted": "--adjusted",
    "glasses": "--glass",
}

_NAMES = "|".join(sorted(map(re.escape, FLAG_OF), key=len, reverse=True))
# 'name' alone, or name=value (not name==, not part of a longer identifier).
_PARAMETER = re.compile(rf"'(?P<quoted>{_NAMES})'|(?<![\w.'-])(?P<keyword>{_NAMES})=(?!=)")


def with_flags(text: str, options: Collection[str] | None = None) -> str:
    """``text`` with each API parameter written as its command-line option.

    Parameters
    ----------
    text : str
        A message naming parameters as ``'name'`` or ``name=value``.
    options : collection of str, optional
        The options the command has; a parameter whose option is not among
        them keeps its API name.  None: every parameter of :data:`FLAG_OF`.

    Returns
    -------
    str
        ``'f_number'`` -> ``--f-number``, ``f_number=1.2`` -> ``--f-number 1.2``.
    """
    def flag(m: re.Match) -> str:
        name = m.group("quoted") or m.group("keyword")
        option = FLAG_OF[name]
        if options is not None and option not in options:
            return m.group(0)
        return option if m.group("quoted") else f"{option} "
    return _PARAMETER.sub(flag, text)


def error_text(error: PovlensError, options: Collection[str] | None = None) -> str:
    """The message (and hint) of ``error`` as the command line prints it.

    Parameters are rewritten as options (:func:`with_flags`) in the hint and in
    the message of a :class:`~povlens.errors.ParameterError`; other messages can
    quote the user's text (a scene identifier ``'width'``, POV-Ray's output) and
    stay as they are.
    """
    message = error.message
    if isinstance(error, ParameterError):
        message = with_flags(message, options)
    if error.hint is None:
        return message
    return f"{message}\n  hint: {with_flags(error.hint, options)}"
