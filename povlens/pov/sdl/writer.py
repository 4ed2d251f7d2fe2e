"""Writing POV-Ray scene description language (SDL) text: literals and templates.

Vectors are written with full double precision (``%.17g``), strings with POV-Ray's
escapes; the wrapper templates (:class:`string.Template`, ``$name`` placeholders)
live in ``templates/`` at the top of the repository.
"""

from __future__ import annotations

import os
import string
from typing import Sequence

import numpy as np

from povlens.errors import PovlensError
from povlens.util.resources import TEMPLATE_DIR as BUNDLED_TEMPLATES

__all__ = ["TEMPLATE_DIR", "pov_vector", "pov_string", "read_template"]

#: Folder holding the ``*.tmpl`` files (wrapper scenes, the output folder's Makefile).
TEMPLATE_DIR = BUNDLED_TEMPLATES


def pov_vector(v: Sequence[float]) -> str:
    """A POV-Ray vector literal ``<x, y, z>`` with full double precision.

    Parameters
    ----------
    v : shape (3,), any units (written as given).

    Returns
    -------
    str
        e.g. ``"<1, 0.5, -2>"``.

    Raises
    ------
    PovlensError
        If a component is not finite.
    """
    a = np.asarray(v, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(a)):
        raise PovlensError(f"cannot write the vector {a.tolist()} to POV-Ray: it is not finite")
    return "<%.17g, %.17g, %.17g>" % tuple(a.tolist())


def pov_string(s: str | os.PathLike) -> str:
    """A POV-Ray string literal, quoted and with ``\\`` and ``"`` escaped (for
    ``#include`` file names).

    Parameters
    ----------
    s : the text or a path.

    Returns
    -------
    str
        The literal, quotes included.
    """
    s = os.fspath(s)
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def read_template(name: str) -> string.Template:
    """The template ``name`` of :data:`TEMPLATE_DIR` (e.g. ``"mesh_wrapper.pov.tmpl"``).

    Raises
    ------
    PovlensError
        If the file cannot be read (a povlens installed without its templates).
    """
    path = TEMPLATE_DIR / name
    try:
        return string.Template(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise PovlensError(
            f"cannot read the povlens template {path}: {exc.strerror or exc}",
            "reinstall povlens from its source tree (the templates folder is missing)",
        ) from None
