"""The user's own POV-Ray options: library paths, the animation clock, and a passthrough.

:class:`PovrayOptions` is what a user may add to every POV-Ray run of a scene;
:func:`povlens.pov.process.render_switches` puts it on the command line after
povlens's own switches (so ``+A0.3`` overrides povlens's ``-A``).

POV-Ray 3.7 reads its command line (``source/frontend/processrenderoptions.cpp``)
as

* switches ``+X...`` / ``-X...``: the name is the *first* entry of its switch table
  that begins the argument, case-insensitive, and that table lists longer names
  first (so ``+WT2`` sets the thread count, ``+W2`` the width);
* INI options ``Name=value`` (case-insensitive names);
* anything else as an INI file (which may set anything) or a scene to render.

povlens sets the scene and image files, the image's size, type, alpha and pixel
range, the display, the fatal-error log it reads, the thread count, and renders one
still frame per run.  An option that sets any of those is refused with a
:class:`~povlens.errors.ParameterError` naming ``povray_options`` and the option.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
from pathlib import Path
from typing import Iterable

from povlens.errors import ParameterError
from povlens.pov.povray_paths import command_line_path, quoted_value

__all__ = ["PovrayOptions", "check_povray_option", "as_povray_options"]

#: POV-Ray 3.7's command-line switch names in the order it matches them (longest
#: first within a letter): an argument is the first name that begins it.
_SWITCH_NAMES = (
    "AC AG AM A BM BS B CC C D EC EF0 EF EP ER F GA GD GF GI GP GR GS GW HI HR H I J "
    "KC KI KFF KFI KF KLA K L MB MI MV O P Q RFI RFO RF RS RP RTR RVP R "
    "SC SF0 SF SP SR SS STP SU TH UA UD UF UL UO UR UV V WL WT W X"
).split()

_ANIMATION = "sets animation frames, but povlens renders one still frame per run"
_USE_CLOCK = "give the frame's clock value as 'clock' instead"


def _controls(what: str) -> str:
    return f"sets {what}, which povlens controls"


#: Switch name -> (why it is refused, hint) for the switches povlens controls.
_REFUSED_SWITCHES = {
    "I": (_controls("the scene file"), "povlens renders its own wrapper around the scene"),
    "O": (_controls("the output file"), None),
    "F": (_controls("the output file type"), "povlens chooses it from the image's suffix"),
    "W": (_controls("the image width"), None),
    "H": (_controls("the image height"), None),
    "SR": (_controls("the first rendered row"), None),
    "ER": (_controls("the last rendered row"), None),
    "SC": (_controls("the first rendered column"), None),
    "EC": (_controls("the last rendered column"), None),
    "UA": (_controls("alpha output"), None),
    "D": (_controls("the display window"), "povlens renders without one (-D)"),
    "P": ("makes POV-Ray wait for a key press when done", None),
    "GF": (_controls("the fatal-error log"), "povlens reads it to report POV-Ray's errors"),
    "GA": (_controls("every message stream, the fatal-error log included"),
           "redirect the debug (+GD), render (+GR), statistics (+GS) or warning (+GW) "
           "stream instead"),
    "WT": (_controls("the render thread count"), None),
    "K": ("sets the animation clock", _USE_CLOCK),
    "L": ("adds a library path that POV-Ray would read from povlens's working folder",
          "give the folder in 'library_paths' (made absolute) instead"),
    **{name: (_ANIMATION, _USE_CLOCK)
       for name in ("KI", "KF", "KFI", "KFF", "KC", "KLA", "SF", "SF0", "EF", "EF0", "STP")},
}

#: INI option name (lower case) -> the switch it equals in :data:`_REFUSED_SWITCHES`
#: (or its own reason and hint).
_REFUSED_INI = {
    "input_file_name": "I", "output_file_name": "O", "output_file_type": "F",
    "output_to_file": "F", "grayscale_output": "F", "greyscale_output": "F",
    "width": "W", "height": "H", "start_row": "SR", "end_row": "ER",
    "start_column": "SC", "end_column": "EC", "output_alpha": "UA", "display": "D",
    "pause_when_done": "P", "fatal_file": "GF", "all_file": "GA", "work_threads": "WT",
    "clock": "K", "library_path": "L", "initial_clock": "KI", "final_clock": "KF",
    "initial_frame": "KFI", "final_frame": "KFF", "cyclic_animation": "KC",
    "clockless_animation": "KLA", "subset_start_frame": "SF", "subset_end_frame": "EF",
    "frame_step": "STP",
    "include_ini": ("reads further options from an INI file", "give its options one by one"),
}

_INI = re.compile(r"^(?P<name>[A-Za-z_][A-Za-z0-9_]*)\s*=")
_DECLARE = re.compile(r"^declare\s*=\s*(?P<ident>[A-Za-z_][A-Za-z0-9_]*)", re.IGNORECASE)


def _switch_name(body: str) -> str | None:
    """POV-Ray's name for the switch ``+body`` (:data:`_SWITCH_NAMES`), or None."""
    upper = body.upper()
    return next((n for n in _SWITCH_NAMES if upper.startswith(n)), None)


def _quoted_option(option: str) -> str:
    """``option`` with a value holding spaces quoted (POV-Ray splits its command line
    again at spaces): ``Name=a b`` -> ``Name="a b"``, ``+HIa b`` -> ``+HI"a b"``."""
    if not any(c.isspace() for c in option):
        return option
    m = _INI.match(option)
    if m is not None:
        return option[:m.end()] + quoted_value(option[m.end():].strip())
    name = _switch_name(option[1:]) if option[:1] in "+-" else None
    if name is not None:
        cut = 1 + len(name)
        return option[:cut] + quoted_value(option[cut:])
    return option


def _refuse(option: str, why: str, hint: str | None = None) -> ParameterError:
    return ParameterError("povray_options", option, f"povray_options={option!r}: {why}", hint)


def check_povray_option(option: str) -> str:
    """Check one passthrough option for POV-Ray; return it unchanged.

    Parameters
    ----------
    option : a switch (``"+A0.3"``, ``"-J"``) or an INI option (``"Antialias=on"``).

    Returns
    -------
    str

    Raises
    ------
    ParameterError
        (parameter ``povray_options``) for an option povlens controls
        (:data:`_REFUSED_SWITCHES`, :data:`_REFUSED_INI`), a ``Declare`` of a name
        starting with ``Povlens``, an unknown switch, several options in one
        string, or an argument POV-Ray would read as an INI file or scene.
    """
    if not isinstance(option, str) or not option.strip():
        raise _refuse(option, "expected a POV-Ray option text")
    if re.search(r"\s[+-]\S", option.strip()):
        raise _refuse(option, "holds several options", "give one option per entry")
    if option[0] in "+-":
        name = _switch_name(option[1:])
        if name is None:
            raise _refuse(option, "not a POV-Ray 3.7 switch")
        if name in _REFUSED_SWITCHES:
            raise _refuse(option, *_REFUSED_SWITCHES[name])
        return option
    m = _INI.match(option)
    if m is None:
        raise _refuse(option, "neither a switch (+X, -X) nor an INI option (Name=value); "
                      "POV-Ray would read it as an INI file or a scene",
                      "give the INI file's options one by one")
    refused = _REFUSED_INI.get(m.group("name").lower())
    if refused is not None:
        raise _refuse(option, *(_REFUSED_SWITCHES[refused] if isinstance(refused, str)
                                else refused))
    d = _DECLARE.match(option)
    if d is not None and d.group("ident").lower().startswith("povlens"):
        raise _refuse(option, _controls(f"{d.group('ident')}, an identifier of its wrappers"),
                      "choose a name that does not start with 'Povlens'")
    return option


def _strings(value, parameter: str) -> tuple:
    """``value`` as a tuple: one str or path is one entry, not its characters."""
    if isinstance(value, (str, os.PathLike)):
        return (value,)
    try:
        return tuple(value)
    except TypeError:
        raise ParameterError(parameter, value,
                             f"{parameter}={value!r}: expected a list") from None


@dataclasses.dataclass(frozen=True)
class PovrayOptions:
    """POV-Ray options a user adds to every render of a scene.

    Parameters
    ----------
    library_paths : folders where POV-Ray looks for ``#include`` files and image
        maps (``+L``), searched after the scene's own folder; stored as absolute
        paths (relative ones are taken from the current directory).
    clock : POV-Ray's ``clock`` for the frame (``+K``): a still of an animation at
        that clock value; None leaves POV-Ray's default (0).
    extra_options : further switches or INI options passed as they are, e.g.
        ``("+A0.3", "Jitter=off")``, checked by :func:`check_povray_option`.

    Raises
    ------
    ParameterError
        ``library_paths`` naming no folder, a ``clock`` that is not a finite number,
        or a refused option (parameter ``povray_options``).
    """

    library_paths: tuple[str, ...] = ()
    clock: float | None = None
    extra_options: tuple[str, ...] = ()

    def __post_init__(self):
        paths = []
        for p in _strings(self.library_paths, "library_paths"):
            if not Path(p).is_dir():
                raise ParameterError("library_paths", p,
                                     f"library_paths={os.fspath(p)!r}: no such folder")
            paths.append(str(Path(p).absolute()))
        object.__setattr__(self, "library_paths", tuple(paths))
        if self.clock is not None:
            try:
                clock = float(self.clock)
            except (TypeError, ValueError):
                clock = math.nan
            if not math.isfinite(clock):
                raise ParameterError("clock", self.clock,
                                     f"clock={self.clock!r}: expected a finite number")
            object.__setattr__(self, "clock", clock)
        extra = tuple(check_povray_option(o)
                      for o in _strings(self.extra_options, "povray_options"))
        object.__setattr__(self, "extra_options", extra)

    def switches(self) -> list[str]:
        """The command-line arguments: ``+L<folder>`` each, ``+K<clock>``, then the
        extra options in their order; paths and values as POV-Ray reads them
        (:mod:`povlens.pov.povray_paths`: quoted, or an ASCII link)."""
        clock = [] if self.clock is None else [f"+K{self.clock!r}"]
        return [*(f"+L{command_line_path(p)}" for p in self.library_paths), *clock,
                *map(_quoted_option, self.extra_options)]

    def antialiasing(self) -> bool | None:
        """Whether the extra options turn POV-Ray's anti-aliasing on (``+A``,
        ``Antialias=on``) or off (``-A``, ``Antialias=off``): the last one that sets it
        decides, as on POV-Ray's command line; None when none sets it."""
        state = None
        for option in self.extra_options:
            if option[0] in "+-":
                if _switch_name(option[1:]) == "A":
                    state = option[0] == "+"
                continue
            m = _INI.match(option)
            if m is not None and m.group("name").lower() == "antialias":
                value = option[m.end():].strip().lower()
                if value in _INI_BOOLEANS:
                    state = _INI_BOOLEANS[value]
        return state


#: POV-Ray's words for an INI option's true and false.
_INI_BOOLEANS = {"on": True, "true": True, "yes": True, "1": True,
                 "off": False, "false": False, "no": False, "0": False}


def as_povray_options(value: "PovrayOptions | None | Iterable") -> PovrayOptions:
    """``value`` as :class:`PovrayOptions` (None: none)."""
    if value is None:
        return PovrayOptions()
    if isinstance(value, PovrayOptions):
        return value
    raise ParameterError("povray_options", value,
                         f"povray_options={value!r}: expected a PovrayOptions")
