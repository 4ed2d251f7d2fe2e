"""Lenses from the lentil lens database (zpelgrims/lentil, ``polynomial-optics/database/lenses.json``).

The database is one JSON object: lens id (``"0001"``) -> entry.  An entry holds
``company``, ``product-name``, ``year``, ``patent-number``, ``focal-length-mm-patent``
and the prescription ``optical-elements-patent`` (some also
``optical-elements-adjusted``, lentil's corrected copy): a list of surfaces, object
side first, each with ``radius``, ``thickness`` (to the next surface; the last: to
the image), ``ior`` and ``abbe`` of the medium after it, ``housing-radius``,
``material`` (``"air"``, ``"iris"`` or a glass name) and ``lens-geometry``
(``"spherical"``, ``"aspherical"``, ``"cyl-x"``, ``"cyl-y"``) with
``aspherical-equation``.

Conversion to a Kolb/pbrt file:

* the iris row becomes the aperture stop (radius 0, in air), its diameter 2 x its
  housing radius;
* |radius| >= :data:`FLAT_RADIUS_MM` (the patents' infinity, stored as 9999, 99999,
  100000 ...) is a flat face, radius 0 (povlens reads a plane with glass on a side
  as a flat refracting face);
* aperture = 2 x housing radius (clipped where a surface ends, see
  :func:`~povlens.lens.prescription.clip_to_physical_apertures`);
* ior null or material ``air`` -> air; the glass index and Abbe number go to the 4th
  and 5th columns;
* ``lens-geometry: "aspherical"`` with ``aspherical-equation`` [A4, A6, A8, A10] (the
  coefficients of r^4 .. r^10, conic 0, the patents' convention: sag positive toward
  the image) is an even asphere (:mod:`povlens.lens.asphere`), written as the row's
  ``#!asphere`` comment.  (lentil's own loader reads only A4 and A8 and traces with a
  conic constant of 1; povlens takes the table as the patent states it.)
* ``lens-geometry: "cyl-y"`` (lentil's cylinder with its axis along y: the surface
  curves in x only, power in the x-z meridian) is a toric row ``0 ... #!toric rx=R``,
  ``"cyl-x"`` (axis along x, curving in y only) ``R ... #!toric rx=0``
  (:mod:`povlens.lens.toric`); an ``aspherical-equation`` on a ``cyl-x`` row shapes its
  y-z profile, on a ``cyl-y`` row it is refused.
* zoom thickness lists are refused, naming the row.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import warnings
from pathlib import Path

from povlens.errors import LensFileError, ParameterError
from povlens.lens import glass_catalog
from povlens.lens.asphere import N_ASPHERE
from povlens.lens.import_common import ImportedLens, LensImportWarning, SourceRow, build_lens
from povlens.util.files import decode_text
from povlens.lens.prescription import LensPrescription, read_source_bytes

__all__ = ["FLAT_RADIUS_MM", "LentilEntry", "list_lentil", "import_lentil", "read_lentil",
           "list_hint"]

#: Radii of this magnitude or more are flat faces (lentil stores the patents' "infinity"
#: as 9999, 99999, 100000 or 1e6).
FLAT_RADIUS_MM = 9999.0

PATENT_TABLE = "optical-elements-patent"
ADJUSTED_TABLE = "optical-elements-adjusted"


def list_hint(path) -> str:
    """How to see the ids of the database at ``path``."""
    return f"list the ids with: povlens import-lens {path} --list"


@dataclasses.dataclass(frozen=True)
class LentilEntry:
    """One entry of the database, as :func:`list_lentil` lists it."""

    lens_id: str
    company: str
    name: str
    year: int | None
    focal_length_mm: float | None  # the patent's (``focal-length-mm-patent``)
    surfaces: int
    has_adjusted: bool

    def to_dict(self) -> dict:
        """The fields as a JSON-ready dict."""
        return dataclasses.asdict(self)


def _load(path: str | os.PathLike) -> dict:
    """The database as a dict; LensFileError naming the file (and line) otherwise."""
    p = Path(path)
    raw = read_source_bytes(p, "file", "give the path of a lentil lenses.json")
    try:
        data = json.loads(decode_text(raw))
    except json.JSONDecodeError as e:
        raise LensFileError(p, e.lineno, f"not valid JSON: {e.msg} (column {e.colno})",
                            "the file is damaged or truncated; download lenses.json again "
                            "(zpelgrims/lentil polynomial-optics/database/lenses.json)") from None
    if not isinstance(data, dict) or not all(isinstance(v, dict) for v in data.values()):
        raise LensFileError(p, None, "is JSON but not a lentil database (an object of lens "
                            "entries by id)")
    return data


def _text(v) -> str:
    return "" if v is None else str(v)


def list_lentil(path: str | os.PathLike) -> list[LentilEntry]:
    """The entries of a lentil database, in the file's order.

    Parameters
    ----------
    path : str or path
        A lentil ``lenses.json`` (or a subset of it).

    Returns
    -------
    list of LentilEntry
        Id, company, product name, year, the patent's focal length, number of
        surfaces, and whether an adjusted table exists.

    Raises
    ------
    povlens.errors.LensFileError
        The file is missing, not JSON (names the line), or not a lentil database.
    """
    out = []
    for lens_id, e in _load(path).items():
        table = e.get(PATENT_TABLE)
        fl = e.get("focal-length-mm-patent")
        out.append(LentilEntry(
            lens_id=lens_id, company=_text(e.get("company")), name=_text(e.get("product-name")),
            year=e.get("year") if isinstance(e.get("year"), int) else None,
            focal_length_mm=float(fl) if isinstance(fl, (int, float)) else None,
            surfaces=len(table) if isinstance(table, list) else 0,
            has_adjusted=isinstance(e.get(ADJUSTED_TABLE), list)))
    return out


def _number(v, what: str, fail) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        fail(f"{what} is {json.dumps(v)}, not a number")
    return float(v)


def _source_row(s: dict, k: int, before_is_air: bool, fail) -> SourceRow:
    """Row ``k`` of the table as a :class:`SourceRow` (``fail(reason)`` raises)."""
    material = _text(s.get("material")).strip() or "?"
    geometry = s.get("lens-geometry", "spherical")
    if geometry not in (None, "spherical", "aspherical", "cyl-x", "cyl-y"):
        fail(f"lens-geometry '{geometry}' (material {material}): povlens reads spherical, "
             f"aspherical, cyl-x and cyl-y surfaces")
    asph = _lentil_asphere(s.get("aspherical-equation"), fail)
    if geometry == "cyl-y" and asph is not None:
        fail("an aspherical-equation on a cyl-y row (a cylinder curving in x): povlens's "
             "toric rows take aspheric terms on their y-z profile only (cyl-x)")
    if isinstance(s.get("thickness"), list):
        fail("thickness is a list (a zoom lens: it changes with the zoom position); povlens "
             "imports fixed focal lengths only")
    radius = _number(s.get("radius"), "radius", fail)
    thickness = _number(s.get("thickness"), "thickness", fail)
    housing = _number(s.get("housing-radius", s.get("housing_radius")), "housing-radius", fail)
    flat = radius == 0 or abs(radius) >= FLAT_RADIUS_MM
    if material.lower() == "iris":
        if not before_is_air:
            fail("the iris lies inside glass; the aperture stop must be in air")
        return SourceRow(0.0, thickness, 1.0, 2 * housing, 0.0, f"row {k}",
                         "iris: aperture stop")
    ior = s.get("ior")
    if material.lower() == "air" or ior is None or ior == 1:
        index, abbe, what = 1.0, 0.0, "air"
    else:
        index = _number(ior, "ior", fail)
        abbe_v = s.get("abbe")
        abbe = 0.0 if abbe_v is None else _number(abbe_v, "abbe", fail)
        shown = "glass" if material.lower() == "abbe" else material
        what = f"{shown} nd {index:g}" + (f" vd {abbe:g}" if abbe else "")
    note = what + (f"; flat (radius {radius:g} in the source)" if flat and radius else "")
    if asph is not None:
        note += "; asphere"
    r = 0.0 if flat else radius
    if geometry in ("cyl-x", "cyl-y") and r != 0.0:
        # cyl-y: cylinder axis along y, curving in x only; cyl-x: curving in y only
        note += f"; {geometry}: " + ("curves in x only" if geometry == "cyl-y"
                                      else "curves in y only")
        ry, rx = (0.0, r) if geometry == "cyl-y" else (r, 0.0)
        return SourceRow(ry, thickness, index, 2 * housing, abbe, f"row {k}", note,
                         asphere=asph, radius_x_mm=rx)
    return SourceRow(r, thickness, index, 2 * housing, abbe,
                     f"row {k}", note, asphere=asph)


def _lentil_asphere(eq, fail) -> tuple | None:
    """(k, a2 .. a16) of an ``aspherical-equation`` [A4, A6, A8, A10] (fewer: the rest 0),
    None for null or all zeros."""
    if eq is None:
        return None
    if not (isinstance(eq, list) and len(eq) <= N_ASPHERE - 2):
        fail(f"aspherical-equation {json.dumps(eq)} is not a list of at most "
             f"{N_ASPHERE - 2} numbers (the coefficients of r^4, r^6, ...)")
    coef = [_number(a, f"aspherical-equation[{j}]", fail) for j, a in enumerate(eq)]
    if not any(coef):
        return None
    return (0.0, 0.0) + tuple(coef) + (0.0,) * (N_ASPHERE - 2 - len(coef))


def _with_glass(row: SourceRow, s: dict, where: str) -> SourceRow:
    """``row`` with its catalogue glass (:mod:`povlens.lens.glass_catalog`) when the
    table's ``material`` names one (``SF5``, ``SLAH59`` for OHARA's S-LAH59) whose n_d
    and V_d match the row's ior and abbe: those stay as stated, the glass gives
    ``--dispersion`` its formula.  An unknown name keeps the Cauchy model (noted in the
    row); a glass the stated values do not match is not kept, with a warning."""
    material = _text(s.get("material")).strip()
    if row.index_after == 1.0 or material.lower() in ("", "air", "iris", "abbe"):
        return row
    try:
        g = glass_catalog.find_glass(material)
    except glass_catalog.UnknownGlassError:
        return dataclasses.replace(row, note=f"{row.note} (not in the glass catalogues)")
    off = glass_catalog.mismatch(g, row.index_after, row.abbe_vd)
    if off:
        warnings.warn(LensImportWarning(
            f"{where}: {row.label}: material {material}: the table states {off}, not "
            f"catalogue glass {g.label}; its dispersion is the Cauchy model of the stated "
            f"values"), stacklevel=3)
        return row
    return dataclasses.replace(row, glass=g.label)


def import_lentil(path: str | os.PathLike, lens_id: str, adjusted: bool = False) -> ImportedLens:
    """Entry ``lens_id`` of a lentil database as an :class:`ImportedLens`.

    Parameters
    ----------
    path : str or path
        A lentil ``lenses.json``.
    lens_id : str
        The entry's id (``"0001"``; :func:`list_lentil` lists them).
    adjusted : bool
        Use the entry's ``optical-elements-adjusted`` table instead of the patent's.

    Returns
    -------
    ImportedLens
        In the patent's units (mm, most designs normalised to 100 mm), with header
        comments naming the file, entry, design and table, and the material per row.

    Raises
    ------
    povlens.errors.ParameterError
        ``lens_id`` is not in the file, or ``adjusted`` is asked of an entry without
        an adjusted table.
    povlens.errors.LensFileError
        The file cannot be read, or a row cannot be held by a Kolb file (an asphere,
        a cylinder, a zoom), naming the entry and row.
    """
    data = _load(path)
    lens_id = str(lens_id)
    if lens_id not in data:
        some = ", ".join(list(data)[:8]) + (", ..." if len(data) > 8 else "")
        raise ParameterError("lens_id", lens_id,
                             f"lens_id={lens_id!r}: {path} has no entry {lens_id!r} "
                             f"(its ids: {some})", list_hint(path))
    e = data[lens_id]
    table_name = ADJUSTED_TABLE if adjusted else PATENT_TABLE
    table = e.get(table_name)
    if adjusted and not isinstance(table, list):
        raise ParameterError("adjusted", adjusted,
                             f"'adjusted': entry {lens_id} of {path} has no {ADJUSTED_TABLE} "
                             f"table", f"leave out 'adjusted' to import {PATENT_TABLE}")
    where = f"{path} [entry {lens_id}, {table_name}]"
    if not isinstance(table, list) or not table:
        raise LensFileError(where, None, "has no surfaces")
    rows: list[SourceRow] = []
    for k, s in enumerate(table):
        def fail(reason, hint=None, k=k):
            raise LensFileError(where, None, f"row {k}: {reason}", hint)
        if not isinstance(s, dict):
            fail("is not an object of surface data")
        before_is_air = not rows or rows[-1].index_after == 1.0
        rows.append(_with_glass(_source_row(s, k, before_is_air, fail), s, where))
    if not any(_text(s.get("material")).strip().lower() == "iris" for s in table):
        # the optical-design convention: the surface that limits the axial beam is the
        # stop (povlens.lens.paraxial finds it; its note says which)
        warnings.warn(LensImportWarning(
            f"{where}: no iris row: the surface that limits the axial beam is taken as "
            f"the aperture stop"), stacklevel=2)
    return build_lens(rows, where, _header(path, lens_id, e, table_name))


def _header(path, lens_id: str, e: dict, table_name: str) -> list[str]:
    design = " ".join(x for x in (_text(e.get("company")), _text(e.get("product-name"))) if x)
    year = f" ({e['year']})" if e.get("year") else ""
    patent = f", patent {e['patent-number']}" if e.get("patent-number") else ""
    fl = e.get("focal-length-mm-patent")
    return [f"{design}{year}{patent}",
            f"source: lentil lens database {Path(path).name}, entry {lens_id}, {table_name}"
            + (f" (patent focal length {fl:g} mm)" if isinstance(fl, (int, float)) else ""),
            "imported by povlens import-lens: the iris is the aperture stop (without one, "
            "the surface that limits the axial beam); |radius| >= "
            f"{FLAT_RADIUS_MM:g} is flat (radius 0); aperture = 2 x housing radius; one row "
            "per row of the table"]


def read_lentil(path: str | os.PathLike, lens_id: str, adjusted: bool = False
                ) -> LensPrescription:
    """Entry ``lens_id`` of a lentil database as a lens prescription.

    :func:`import_lentil` without the per-row notes; the parameters, result and
    errors are its.
    """
    return import_lentil(path, lens_id, adjusted).lens
