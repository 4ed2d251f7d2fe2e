"""Saved pupil tables: read one, check that it is current, or build and save it.

:func:`cached_pupil_table` is the one place that decides whether a saved
``pupil.npz`` can be reused: only when it was built for the same lens (stop
included), film distance and film (:func:`load_if_current`), and which table a lens
gets: the radial table (:mod:`povlens.pupil.table`) for a rotationally symmetric lens,
the table over the film's two coordinates (:mod:`povlens.pupil.grid_table`) for an
anamorphic one (:func:`needs_grid_table`).
"""

from __future__ import annotations

from pathlib import Path

from povlens.errors import PovlensError
from povlens.lens.prescription import LensPrescription
from povlens.pupil.build import DEFAULT_TOLERANCE, build_pupil_table
from povlens.pupil.grid_build import GRID_TOLERANCE, build_grid_pupil_table
from povlens.pupil.grid_table import GridPupilTable
from povlens.pupil.table import PupilTable
from povlens.pupil.table_file import GRID_FORMAT_NAME, table_format

__all__ = ["load", "load_if_current", "cached_pupil_table", "needs_grid_table"]


def needs_grid_table(lens: LensPrescription) -> bool:
    """Whether ``lens`` needs the grid table: it is not rotationally symmetric
    (``lens.is_anamorphic``: cylindrical or toric rows)."""
    return bool(getattr(lens, "is_anamorphic", False))


def load(path):
    """Read a saved table, radial or grid (:meth:`PupilTable.load`,
    :meth:`GridPupilTable.load`)."""
    if table_format(path) == GRID_FORMAT_NAME:
        return GridPupilTable.load(path)
    return PupilTable.load(path)


def _same(a, b) -> bool:
    return abs(float(a) - float(b)) <= 1e-9 * max(1.0, abs(float(b)))


def _extent(lens, film_half_diagonal_mm: float, film_extent_mm):
    """The quadrant a grid table of ``lens`` covers (None: the radial table's lens)."""
    if not needs_grid_table(lens):
        return None
    if film_extent_mm is None:          # the square holding the disc of the half-diagonal
        return (float(film_half_diagonal_mm), float(film_half_diagonal_mm))
    return tuple(float(v) for v in film_extent_mm)


def load_if_current(path, lens: LensPrescription, film_distance_mm: float,
                    film_half_diagonal_mm: float, *, tolerance: float | None = None,
                    plane: str | None = None, film_extent_mm=None):
    """The table saved at ``path`` if it was built for exactly these inputs, else None.

    Inputs compared: the kind of table the lens needs (:func:`needs_grid_table`), the
    lens's optical content including its stop (the hash of the prescription), the film
    distance (so the focus), the film half-diagonal (radial table) or the frame's extent
    ``film_extent_mm`` (X, Y) (grid table; default (hd, hd)) and, when given, the
    tolerance and the requested sampling plane.  A missing or unreadable file gives
    None.  The table's lens takes ``lens.source``.
    """
    path = Path(path)
    if not path.is_file():
        return None
    extent = _extent(lens, film_half_diagonal_mm, film_extent_mm)
    try:
        if (table_format(path) == GRID_FORMAT_NAME) != (extent is not None):
            return None
        table = GridPupilTable.load(path) if extent is not None else PupilTable.load(path)
    except PovlensError:
        return None
    film_ok = (all(_same(a, b) for a, b in zip(table.film_extent_mm, extent))
               if extent is not None else _same(table.film_half_diagonal_mm,
                                                film_half_diagonal_mm))
    if (table.lens.sha256() != lens.sha256() or not film_ok
            or not _same(table.film_distance_mm, film_distance_mm)
            or (tolerance is not None and not _same(table.tolerance, tolerance))
            or (plane is not None and table.metadata.get("requested_plane", table.plane)
                != plane)):
        return None
    table.lens = table.lens.replace(source=lens.source)
    return table


def cached_pupil_table(path, lens: LensPrescription, film_distance_mm: float,
                       film_half_diagonal_mm: float, *, save: bool = True,
                       tolerance: float | None = None, plane: str | None = None,
                       progress=None, metadata: dict | None = None, film_extent_mm=None):
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
        and a new one gets the defaults (``DEFAULT_TOLERANCE`` radial,
        ``GRID_TOLERANCE`` grid; the exit-pupil plane).
    progress : callable taking the number of boundary evaluations done (build only).
    metadata : extra JSON-able entries saved with a new table (e.g. the focus).
    film_extent_mm : (X, Y), the frame's largest |f_x|, |f_y| (mm,
        :func:`povlens.pupil.grid_table.frame_extent_mm`): what a grid table covers
        (default (hd, hd)); the radial table ignores it.

    Returns
    -------
    table : the :class:`PupilTable`, or a :class:`GridPupilTable` for an anamorphic lens.
    reused : True when it was read from ``path``.
    """
    if path is not None:
        table = load_if_current(path, lens, film_distance_mm, film_half_diagonal_mm,
                                tolerance=tolerance, plane=plane, film_extent_mm=film_extent_mm)
        if table is not None:
            return table, True
    extent = _extent(lens, film_half_diagonal_mm, film_extent_mm)
    plane = "exit-pupil" if plane is None else plane
    if extent is not None:
        table = build_grid_pupil_table(
            lens, film_distance_mm, extent,
            tolerance=GRID_TOLERANCE if tolerance is None else tolerance, plane=plane,
            progress=progress, metadata=metadata)
    else:
        table = build_pupil_table(
            lens, film_distance_mm, film_half_diagonal_mm,
            tolerance=DEFAULT_TOLERANCE if tolerance is None else tolerance, plane=plane,
            progress=progress, metadata=metadata)
    if save and path is not None:
        table.save(path)
    return table, False
