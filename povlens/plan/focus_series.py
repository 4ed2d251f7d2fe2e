"""The focus distances of a focus pull: ``A:B`` over N frames, or an explicit list.

A pull from A to B is interpolated in dioptres (1/distance linear from 1/A to 1/B),
as a focus ring moves: equal turns of the ring are roughly equal steps in 1/d, and
the blur of a fixed object changes at an even rate.  Distances are scene units from
the camera location, as ``--focus``; each must be positive and finite (a pull to
infinity: give a far distance, e.g. 1e6).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from povlens.errors import ParameterError

__all__ = ["FocusPull", "parse_focus", "focus_series"]


@dataclass(frozen=True)
class FocusPull:
    """A focus pull as given: ``start``/``end`` (``A:B``) or ``values`` (a list).

    Distances in scene units from the camera location.
    """

    start: float | None = None
    end: float | None = None
    values: tuple[float, ...] | None = None

    def text(self) -> str:
        """The pull as ``--focus`` spells it."""
        if self.values is not None:
            return ",".join(f"{v:g}" for v in self.values)
        return f"{self.start:g}:{self.end:g}"


def _distance(text: str, whole: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise ParameterError("focus", whole, f"focus={whole}: '{text}' is not a number",
                             "give DIST, A:B (a pull, with --frames N) or D1,D2,... "
                             "(scene units)") from None
    if not v > 0:
        raise ParameterError("focus", whole, f"focus={whole}: '{text}' must be a positive "
                             f"distance", "distances are scene units from the camera; "
                             "inf focuses at infinity")
    return v


def parse_focus(text: str) -> float | FocusPull:
    """``--focus`` text: ``D`` (one distance), ``A:B`` (a pull) or ``D1,D2,...`` (a list).

    Returns
    -------
    float or FocusPull
        One distance (scene units), or the pull.

    Raises
    ------
    ParameterError
        Not numbers, a distance <= 0 or not finite, or both ``:`` and ``,``.
    """
    text = str(text).strip()
    if ":" in text and "," in text:
        raise ParameterError("focus", text, f"focus={text}: give either A:B or a list "
                             f"D1,D2,..., not both")
    if ":" in text:
        parts = text.split(":")
        if len(parts) != 2:
            raise ParameterError("focus", text, f"focus={text}: a pull is A:B (two "
                                 f"distances)")
        return FocusPull(start=_distance(parts[0], text), end=_distance(parts[1], text))
    if "," in text:
        return FocusPull(values=tuple(_distance(p, text) for p in text.split(",")))
    return _distance(text, text)


def focus_series(focus, frames: int | None) -> list[float] | None:
    """The focus distance of every frame, or None for a still.

    Parameters
    ----------
    focus : float, None, FocusPull, (A, B) tuple or list of floats
        A tuple of two is a pull A:B, a list is an explicit list of distances
        (scene units); a :class:`FocusPull` is either.
    frames : int or None
        Frames of the pull (a pull needs it; a list may give it, then it must match).

    Returns
    -------
    list of float or None
        N distances, 1/d linear from 1/A to 1/B for a pull; None: one focus, no frames.

    Raises
    ------
    ParameterError
        ``frames`` < 1, a pull without ``frames`` or with fewer than 2, a list whose
        length differs from ``frames``, ``frames`` with a single focus, distances
        not positive and finite.
    """
    if frames is not None and (isinstance(frames, bool) or int(frames) != frames
                               or frames < 1):
        raise ParameterError("frames", frames, f"frames={frames}: must be a whole number "
                             f">= 1")
    if isinstance(focus, tuple) and not isinstance(focus, FocusPull):
        if len(focus) != 2:
            raise ParameterError("focus", focus, f"focus={focus}: a pull is (A, B)")
        focus = FocusPull(start=float(focus[0]), end=float(focus[1]))
    elif isinstance(focus, list):
        focus = FocusPull(values=tuple(float(v) for v in focus))
    if not isinstance(focus, FocusPull):
        if frames is not None:
            raise ParameterError("frames", frames, f"frames={frames} needs a focus pull",
                                 "give focus=A:B (or a list D1,D2,...) with frames=N")
        return None
    text = focus.text()
    for v in (focus.values or (focus.start, focus.end)):
        if not (v > 0 and math.isfinite(v)):
            raise ParameterError("focus", text, f"focus={text}: a pull's distances must be "
                                 f"positive and finite", "for infinity end the pull at a far "
                                 "distance (1e6 m focuses within 0.1 % of infinity's spot); "
                                 "a still takes inf")
    if focus.values is not None:
        if not focus.values:
            raise ParameterError("focus", text, "focus: the list of distances is empty")
        if frames is not None and frames != len(focus.values):
            raise ParameterError("frames", frames, f"frames={frames} but focus={text} lists "
                                 f"{len(focus.values)} distances", "drop frames= or make "
                                 "them match")
        return [float(v) for v in focus.values]
    if frames is None or frames < 2:
        raise ParameterError("frames", frames, f"focus={text} is a pull: it needs frames=N "
                             f"with N >= 2", "for one frame give one focus distance")
    a, b = 1.0 / focus.start, 1.0 / focus.end
    out = [1.0 / (a + (b - a) * i / (frames - 1)) for i in range(frames)]
    out[0], out[-1] = float(focus.start), float(focus.end)    # exact ends, no round-off
    return out
