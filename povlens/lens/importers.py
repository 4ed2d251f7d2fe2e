"""One entry for every lens importer: the format of a source file, and its import.

Formats: a lentil lens database (JSON, :mod:`~povlens.lens.import_lentil`) and a
Zemax sequential file (``.zmx``, :mod:`~povlens.lens.import_zemax`).  The format is
told by the file name (``.json``, ``.zmx``), else by the content (a JSON object, or
``SURF`` blocks).
"""

from __future__ import annotations

import os
from pathlib import Path

from povlens.errors import LensFileError, ParameterError
from povlens.lens.import_common import ImportedLens
from povlens.util.files import decode_text
from povlens.lens.import_lentil import import_lentil, list_hint, list_lentil
from povlens.lens.import_zemax import import_zmx

__all__ = ["LENTIL", "ZEMAX", "source_format", "import_lens_file"]

LENTIL, ZEMAX = "lentil", "zemax"


def source_format(path: str | os.PathLike) -> str:
    """:data:`LENTIL` or :data:`ZEMAX` for the file at ``path``.

    Raises
    ------
    povlens.errors.LensFileError
        The file is missing, or is neither format.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".json":
        return LENTIL
    if suffix == ".zmx":
        return ZEMAX
    try:
        head = decode_text(p.read_bytes()[:4096])
    except FileNotFoundError:
        raise LensFileError(p, None, "no such file",
                            "give a lentil lenses.json or a Zemax .zmx file") from None
    except OSError as e:
        raise LensFileError(p, None, f"cannot be read: {e.strerror or e}") from None
    if head.lstrip().startswith("{"):
        return LENTIL
    if any(line.split()[:1] == ["SURF"] for line in head.splitlines()):
        return ZEMAX
    raise LensFileError(p, None, "is neither a lentil lens database (JSON) nor a Zemax "
                        "sequential file (.zmx)",
                        "povlens imports lentil lenses.json and Zemax .zmx files; a Kolb/pbrt "
                        ".dat file needs no import (give it as LENS)")


def import_lens_file(path: str | os.PathLike, *, lens_id: str | None = None,
                     adjusted: bool = False, glasses: dict | None = None,
                     efl_mm: float | None = None) -> ImportedLens:
    """Import the lens design in ``path``, optionally scaled to a focal length.

    Parameters
    ----------
    path : str or path
        A lentil ``lenses.json`` or a Zemax ``.zmx`` file.
    lens_id : str, optional
        The lentil entry; may be left out when the database holds one lens.
    adjusted : bool
        lentil: the entry's adjusted table instead of the patent's.
    glasses : dict, optional
        Zemax: glass name -> (nd, vd) for glasses the file gives no index for.
    efl_mm : float, optional
        Scale the design to this paraxial focal length (mm).

    Returns
    -------
    ImportedLens

    Raises
    ------
    povlens.errors.ParameterError
        An option that does not apply to the format, or a lentil id not in the file.
    povlens.errors.LensFileError
        The file, or what it holds, cannot be imported (names file, line, surface).
    """
    fmt = source_format(path)
    if fmt == LENTIL:
        if glasses:
            raise ParameterError("glasses", glasses, f"'glasses' is for Zemax files; {path} "
                                 f"is a lentil database, which gives every glass's index")
        if lens_id is None:
            entries = list_lentil(path)
            if len(entries) != 1:
                raise ParameterError("lens_id", None, f"'lens_id' is needed: {path} holds "
                                     f"{len(entries)} lenses", list_hint(path))
            lens_id = entries[0].lens_id
        imported = import_lentil(path, lens_id, adjusted)
    else:
        for name, value in (("lens_id", lens_id), ("adjusted", adjusted or None)):
            if value is not None:
                raise ParameterError(name, value, f"'{name}' is for a lentil database; {path} "
                                     f"is a Zemax file, which holds one lens")
        imported = import_zmx(path, glasses)
    return imported if efl_mm is None else imported.scaled_to_efl(efl_mm)
