"""API parameter names as command-line options, in error messages.

The core names parameters as the API spells them, ``name=value`` or ``'name'``
(:mod:`povlens.errors`); a command-line user reads the option that sets the
parameter instead.  :data:`FLAG_OF` is the one table of that correspondence.
"""

from __future__ import annotations

import re
from collections.abc import Collection

from povlens.errors import ParameterError, PovlensError
from povlens.plan.options import dask_options, options

__all__ = ["FLAG_OF", "OTHER_FLAGS", "with_flags", "error_text"]

#: Parameters of the core that are no option of a conversion (the lens commands', the
#: importers', a pull's) or that name an option otherwise (``width_px`` of
#: :class:`~povlens.lens.film.Film` is ``--width``) -> the option that sets them.
OTHER_FLAGS = {
    "frames": "--frames",
    "distance_mm": "--distance",
    "tolerance": "--tolerance",
    "plane": "--plane",
    "view": "--view",
    "width_px": "--width",
    "height_px": "--height",
    "diagonal_mm": "--film-diagonal",
    "film_distance_mm": "--film-distance",
    "lens_id": "--id",
    "efl_mm": "--efl",
    "adjusted": "--adjusted",
    "glasses": "--glass",
}

#: API parameter -> the option that sets it: every declared option with a flag
#: (:mod:`povlens.plan.options`), and :data:`OTHER_FLAGS`.
FLAG_OF = ({f.name: spec.flag for _, f, spec in options() if spec.flag is not None}
           | {f.name: spec.flag for f, spec in dask_options()} | OTHER_FLAGS)

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
