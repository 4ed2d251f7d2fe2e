"""What POV-Ray prints when it fails, cleaned for the user.

POV-Ray 3.7 starts every run with a banner (version, authors, support libraries);
:func:`povray_error_text` keeps its own description of a failure -- the fatal-error
log and the informative lines of stderr -- without it.
"""

from __future__ import annotations

import re

__all__ = ["last_lines", "povray_error_text"]

#: Lines of POV-Ray's start-up banner and progress output that carry no
#: information about a failure.
_NOISE = re.compile(
    r"^(povray: cannot open the user configuration file|==== \[|POV-Ray finished)"
)


def last_lines(text: str, lines: int = 25) -> str:
    """The last ``lines`` non-blank lines of ``text``."""
    kept = [ln for ln in text.splitlines() if ln.strip()]
    return "\n".join(kept[-lines:])


def _strip_banner(lines: list[str]) -> list[str]:
    """Drop POV-Ray's start-up banner (everything up to the library list)."""
    start = next((i for i, ln in enumerate(lines) if ln.startswith("==== [")), None)
    if start is not None:
        return lines[start:]
    hdr = next((i for i, ln in enumerate(lines) if ln.startswith("Support libraries used by")), None)
    if hdr is None:
        return lines
    i = hdr + 1
    while i < len(lines) and (lines[i].startswith(" ") or not lines[i].strip()):
        i += 1
    return lines[i:]


def povray_error_text(stderr: str, log_text: str) -> str:
    """POV-Ray's own description of a failure, without the start-up banner.

    Parameters
    ----------
    stderr : what POV-Ray wrote to its standard error.
    log_text : the contents of its fatal-error log (``+GF``), or ``""``.

    Returns
    -------
    str
        The log and the informative stderr lines (repeated lines once), or the tail
        of stderr if nothing else is left.
    """
    body = _strip_banner(stderr.splitlines())
    body = [ln for ln in body if ln.strip() and not _NOISE.match(ln)]
    parts = []
    if log_text.strip():
        parts.append(log_text.strip())
    if body:
        stderr_text = "\n".join(dict.fromkeys(body[-25:]))  # drop repeated lines
        if stderr_text not in log_text:
            parts.append(stderr_text)
    if not parts:
        parts.append(last_lines(stderr) or "(POV-Ray printed nothing)")
    return "\n".join(parts)
