"""Saved pupil tables: read one, check that it is current, or build and save it.

:func:`cached_pupil_table` is the one place that decides whether a saved
``pupil.npz`` can be reused: only when it was built for the same lens (stop
included), film distance and film (:func:`load_if_current`).
"""

from __future__ import annotations

from pathlib import Path

from povlens.errors import PovlensError
from povlens.lens.prescription import LensPrescription
from povlens.pupil.build import DEFAULT_TOLERANCE, build_pupil_table
from povlens.pupil.table import PupilTable

__all__ = ["load", "load_if_current", "cached_pupil_table"]


def load(path) -> PupilTable:
    """Read a saved table (see :meth:`PupilTable.load`)."""
    return PupilTable.load(path)


def load_if_current(path, lens: LensPrescription, film_distance_mm: float,
                    film_half_diagonal_mm: float, *, tolerance: float | None = None,
                    plane: str | None = None) -> PupilTable | None:
    """The table saved at ``path`` if it was built for exactly these inputs, else None.

    Inputs compared: the lens's optical content including its stop (the hash of
    the prescription), the film distance (so the focus), the film half-diagonal
    and, when given, the tolerance and the requested sampling plane.  A missing
    or unreadable file gives None.  The table's lens takes ``lens.source``.
    """
    path = Path(path)
    if not path.is_file():
        return None
    try:
        table = PupilTable.load(path)
    except PovlensError:
        return None

    def same(a, b):
        return abs(float(a) - float(b)) <= 1e-9 * max(1.0, abs(float(b)))

    if (table.lens.sha256() != lens.sha256()
            or not same(table.film_distance_mm, film_distance_mm)
            or not same(table.film_half_diagonal_mm, film_half_diagonal_mm)
            or (tolerance is not None and not same(table.tolerance, tolerance))
            or (plane is not None and table.metadata.get("requested_plane", table.plane)
                != plane)):
        return None
    table.lens = table.lens.replace(source=lens.source)
    return table


def cached_pupil_table(path, lens: LensPrescription, film_distance_mm: float,
                       film_half_diagonal_mm: float, *, save: bool = True,
                       tolerance: float | None = None, plane: str | None = None,
                       progress=None, metadata: dict | None = None
                       ) -> tuple[PupilTable, bool]:
    """The table saved at ``path`` if it is current for these inputs, else a new one.

    Parameters
    ----------
    path : the table file (``pupil.npz``), or None to build without reading or saving.
    lens : the lens, stop included.
    film_distance_mm : rear vertex to film, mm.
    film_half_diagonal_mm : largest film radius the table covers, mm.
    save : write a newly built table to ``path``.
    tolerance, plane : when given, a saved table must have been built with them, and
        a new one is; when None, a saved table of any tolerance or plane is current
        and a new one gets the defaults (``DEFAULT_TOLERANCE``, the exit-pupil plane).
    progress : callable taking the number of boundary evaluations done (build only).
    metadata : extra JSON-able entries saved with a new table (e.g. the focus).

    Returns
    -------
    table : the :class:`PupilTable`.
    reused : True when it was read from ``path``.
    """
    if path is not None:
        table = load_if_current(path, lens, film_distance_mm, film_half_diagonal_mm,
                                tolerance=tolerance, plane=plane)
        if table is not None:
            return table, True
    table = build_pupil_table(
        lens, film_distance_mm, film_half_diagonal_mm,
        tolerance=DEFAULT_TOLERANCE if tolerance is None else tolerance,
        plane="exit-pupil" if plane is None else plane, progress=progress, metadata=metadata)
    if save and path is not None:
        table.save(path)
    return table, False
