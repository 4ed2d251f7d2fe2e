"""What the lens importers (:mod:`~povlens.lens.import_lentil`,
:mod:`~povlens.lens.import_zemax`) share: the imported lens with a note per row, its
validation, scaling to a focal length, and writing it as a Kolb/pbrt file.

An importer turns its format's surfaces into :class:`SourceRow` s (mm, object side
first, the aperture stop as a plane in air), and :func:`build_lens` checks them the
way :func:`~povlens.lens.prescription.parse_lens_text` checks a lens file, but names
the *source's* surface in every message.  The result, an :class:`ImportedLens`,
writes a file that :func:`~povlens.lens.prescription.read_lens` reads back to the
same numbers (17 significant digits), with the source, and per row its surface and
material, as ``#`` comments.
"""

from __future__ import annotations

import dataclasses
import math
import os
import warnings
from pathlib import Path

import numpy as np

from povlens.errors import LensFileError, OpticsError, ParameterError, PovlensWarning
from povlens.lens.asphere import N_ASPHERE, scaled_asphere
from povlens.lens import toric
from povlens.lens.paraxial import anamorphic_data, paraxial_data, primary_meridian
from povlens.lens.prescription import (AIR, MAX_INDEX, MAX_LENGTH_MM, MIN_LENGTH_MM,
                                       LensPrescription, clip_to_physical_apertures,
                                       format_lens, read_lens)
from povlens.util.files import write_text

__all__ = ["LensImportWarning", "SourceRow", "ImportedLens", "build_lens"]


class LensImportWarning(PovlensWarning):
    """Something in an imported design that a spherical lens file cannot hold (a
    coating, an obscuration, a curved image surface, a stop moved off its vertex) was
    dropped or changed; names the source file and surface."""


@dataclasses.dataclass(frozen=True)
class SourceRow:
    """One row of the lens file to write, as the importer read it from its source.

    Attributes
    ----------
    radius_mm : signed radius, 0 = plane (an aperture when in air on both sides).
    thickness_mm : axial distance to the next row (the last: to the film).
    index_after : refractive index after the surface (1 for air).
    aperture_diameter_mm : clear (or housing) diameter.
    abbe_vd : Abbe number of the medium after the surface, 0 = unknown.
    label : the source's name for the surface, for messages
        (``"surface 4 (line 120)"``, ``"row 7"``).
    note : the per-row comment written to the file (material, what the row is).
    line : the row's line in the source file, if known (for error messages).
    glass : the catalogue glass after the surface (``SCHOTT:N-BK7``), or "" (none).
    asphere : None for a sphere, else 9 floats: conic k, a2 .. a16
        (:mod:`povlens.lens.asphere`; on a toric row its y-z profile's).
    radius_x_mm : None for a rotationally symmetric row, else the radius (mm, 0 = flat
        in x) of its x-z section; ``radius_mm`` is then its y-z section
        (:mod:`povlens.lens.toric`).
    """

    radius_mm: float
    thickness_mm: float
    index_after: float
    aperture_diameter_mm: float
    abbe_vd: float
    label: str
    note: str
    line: int | None = None
    asphere: tuple | None = None
    glass: str = ""
    radius_x_mm: float | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class ImportedLens:
    """An imported design: the prescription and a comment per row.

    Attributes
    ----------
    lens : LensPrescription
        As :func:`~povlens.lens.prescription.read_lens` reads the written file back
        (apertures already clipped to the surfaces, see
        :func:`~povlens.lens.prescription.clip_to_physical_apertures`).
    row_notes : tuple of str
        One comment per row of ``lens``.
    """

    lens: LensPrescription
    row_notes: tuple[str, ...]

    def scaled_to_efl(self, efl_mm: float) -> "ImportedLens":
        """The design scaled so that its paraxial EFL is ``efl_mm``.

        Radii, thicknesses and diameters are multiplied by one factor; indices and
        Abbe numbers stay.  f-number and field of view are unchanged.

        Raises
        ------
        ParameterError
            Naming ``efl_mm`` when it is not a positive number, or the design has a
            negative focal length.
        """
        if not (isinstance(efl_mm, (int, float)) and efl_mm > 0 and math.isfinite(efl_mm)):
            raise ParameterError("efl_mm", efl_mm,
                                 f"efl_mm={efl_mm}: must be a positive number of mm")
        efl = paraxial_data(self.lens, primary_meridian(self.lens)).efl
        if efl <= 0:
            raise ParameterError("efl_mm", efl_mm,
                                 f"efl_mm={efl_mm:g}: {self.lens.source} has a negative focal "
                                 f"length ({efl:.6g} mm); it is not a camera lens")
        k = efl_mm / efl
        lens = self.lens
        scaled = lens.replace(
            radius_mm=lens.radius_mm * k, thickness_mm=lens.thickness_mm * k,
            aperture_diameter_mm=lens.aperture_diameter_mm * k,
            asphere=scaled_asphere(lens.asphere, k),
            radius_x_mm=None if lens.radius_x_mm is None else lens.radius_x_mm * k,
            max_stop_diameter_mm=(None if lens.max_stop_diameter_mm is None
                                  else lens.max_stop_diameter_mm * k),
            comments=lens.comments + (f"scaled x{k:.9g} from EFL {efl:.9g} mm to "
                                      f"{efl_mm:.9g} mm (radii, thicknesses, diameters)",))
        return ImportedLens(scaled, self.row_notes)

    def text(self) -> str:
        """The lens file: :func:`~povlens.lens.prescription.format_lens` with each
        row's note appended as a ``#`` comment."""
        lines = format_lens(self.lens).splitlines()
        n = self.lens.n_surfaces
        rows = [f"{row}\t# {note}" if note else row
                for row, note in zip(lines[-n:], self.row_notes)]
        return "\n".join(lines[:-n] + rows) + "\n"

    def write(self, path: str | os.PathLike) -> LensPrescription:
        """Write the lens file to ``path`` atomically and read it back.

        Returns
        -------
        LensPrescription
            The written file as :func:`~povlens.lens.prescription.read_lens` reads it;
            optically equal to :attr:`lens` (checked).
        """
        path = Path(path)
        write_text(path, self.text())
        back = read_lens(path)
        if back != self.lens:  # the format round-trips exactly; anything else is a bug
            raise AssertionError(f"{path}: the written lens does not read back the same")
        return back


def _check_row(row: SourceRow, last: bool, where: str) -> None:
    """The checks of ``parse_lens_text``, worded for the source's surface."""
    def fail(reason: str, hint: str | None = None):
        raise LensFileError(where, row.line, f"{row.label}: {reason}", hint)

    for name, v in (("radius", row.radius_mm), ("thickness", row.thickness_mm),
                    ("index", row.index_after), ("aperture diameter", row.aperture_diameter_mm),
                    ("Abbe number", row.abbe_vd)):
        if not math.isfinite(v):
            fail(f"{name} {v} is not a finite number")
    if row.aperture_diameter_mm <= 0:
        fail(f"aperture diameter {row.aperture_diameter_mm:g} mm must be positive",
             "give the surface a semi-diameter (clear aperture) in the source")
    for name, v in (("radius", row.radius_mm), ("aperture diameter", row.aperture_diameter_mm)):
        if v != 0 and not MIN_LENGTH_MM <= abs(v) <= MAX_LENGTH_MM:
            fail(f"{name} {v:g} mm is outside the supported range {MIN_LENGTH_MM:g} .. "
                 f"{MAX_LENGTH_MM:g} mm")
    if row.radius_x_mm is not None:
        if not math.isfinite(row.radius_x_mm):
            fail(f"x-z radius {row.radius_x_mm} is not a finite number")
        if row.radius_x_mm != 0 and not MIN_LENGTH_MM <= abs(row.radius_x_mm) <= MAX_LENGTH_MM:
            fail(f"x-z radius {row.radius_x_mm:g} mm is outside the supported range "
                 f"{MIN_LENGTH_MM:g} .. {MAX_LENGTH_MM:g} mm")
    if abs(row.thickness_mm) > MAX_LENGTH_MM:
        fail(f"thickness {row.thickness_mm:g} mm is larger than the supported {MAX_LENGTH_MM:g} mm")
    if row.thickness_mm < 0 and not last:
        fail(f"thickness {row.thickness_mm:g} mm is negative (the surfaces after it would lie "
             f"in front of it)", "only a lens whose surfaces follow each other along the axis "
             "can be imported")
    if not 1.0 <= row.index_after <= MAX_INDEX:
        fail(f"refractive index {row.index_after:g} is outside 1 .. {MAX_INDEX:g}")
    if row.abbe_vd < 0:
        fail(f"Abbe number {row.abbe_vd:g} is negative")


def _radius_x(rows: list[SourceRow], source: str):
    """(n,) x-z radii of ``rows`` (their radius where not given), None when no row is
    toric; a row that cannot be toric is refused (:func:`toric.row_problem`)."""
    rx = [r.radius_mm if r.radius_x_mm is None else r.radius_x_mm for r in rows]
    for i, (row, r) in enumerate(zip(rows, rx)):
        if row.radius_x_mm is None:
            continue
        before_air = i == 0 or rows[i - 1].index_after == AIR
        why = toric.row_problem(row.radius_mm, r, row.asphere,
                                before_air and row.index_after == AIR)
        if why:
            raise LensFileError(source, row.line, f"{row.label}: {why}")
    out = np.array(rx, dtype=np.float64)
    return out if any(a != r.radius_mm for a, r in zip(rx, rows)) else None


def _check_power(lens: LensPrescription, source: str) -> None:
    """OpticsError when the lens has no power (in neither meridian of an anamorphic
    lens); a :class:`LensImportWarning` when an anamorphic lens has none in one."""
    if not lens.is_anamorphic:
        paraxial_data(lens)
        return
    m = anamorphic_data(lens).afocal
    if m:
        warnings.warn(LensImportWarning(
            f"{source}: the lens has no power in {m} (afocal in {m}): it images only in the "
            f"{'y' if m == 'x' else 'x'}-z plane (a line focus); EFL_{m} is infinite"),
            stacklevel=4)


def build_lens(rows: list[SourceRow], source: str, comments: list[str]) -> ImportedLens:
    """Check ``rows`` and make the :class:`ImportedLens`.

    Parameters
    ----------
    rows : list of SourceRow
        Object side first; the last row's medium must be air (the film is in air).
    source : str
        The source file (or file and entry), for messages and ``lens.source``.
    comments : list of str
        The header comments of the file to write.

    Returns
    -------
    ImportedLens
        Apertures clipped where surfaces end (one
        :class:`~povlens.errors.LensClipWarning` per clipped row).

    Raises
    ------
    LensFileError
        A row povlens cannot use, naming ``source`` and the row's source label.
    OpticsError
        The design has no power (afocal).
    """
    if not rows:
        raise LensFileError(source, None, "contains no lens surfaces")
    for i, row in enumerate(rows):
        _check_row(row, i == len(rows) - 1, source)
    if len(rows) > 1 and rows[0].thickness_mm == 0 and rows[-1].thickness_mm != 0:
        # read_lens takes a first thickness 0 with a last one not 0 for an old Kolb table
        # (column 2 shifted); the last thickness (to the film) is replaced when focusing.
        last = rows[-1]
        rows = rows[:-1] + [dataclasses.replace(
            last, thickness_mm=0.0, note=f"{last.note}; the design's {last.thickness_mm:.6g} mm "
            f"to the image written as 0 (povlens focuses)")]
    if rows[-1].index_after != AIR:
        raise LensFileError(source, rows[-1].line,
                            f"{rows[-1].label}: the medium after the last surface has index "
                            f"{rows[-1].index_after:g}; the film must be in air")
    a = np.array([[r.radius_mm, r.thickness_mm, r.index_after, r.aperture_diameter_mm,
                   r.abbe_vd] for r in rows], dtype=np.float64)
    radius, thick, index, diam, abbe = a.T.copy()
    # Planes in air on both sides are apertures; their index column is air by definition.
    # ``lines`` point into the source file, so row labels in messages name its lines.
    asph = None
    if any(r.asphere is not None and any(r.asphere) for r in rows):
        asph = np.array([r.asphere if r.asphere is not None else (0.0,) * N_ASPHERE
                         for r in rows], dtype=np.float64)
    lens = LensPrescription(radius, thick, index, diam, abbe, source=source,
                            lines=tuple(r.line or 0 for r in rows), comments=tuple(comments),
                            asphere=asph, radius_x_mm=_radius_x(rows, source))
    if any(r.glass for r in rows):
        lens = lens.replace(glass=tuple(r.glass for r in rows))
    lens = clip_to_physical_apertures(lens)
    ap = lens.is_aperture
    if ap.any():
        lens = lens.replace(max_stop_diameter_mm=float(np.max(lens.aperture_diameter_mm[ap])))
    try:
        _check_power(lens, source)
    except OpticsError as e:
        raise OpticsError(f"{e.message} (imported from {source})") from None
    notes = []
    for i, row in enumerate(rows):
        note = row.note
        if lens.aperture_diameter_mm[i] != row.aperture_diameter_mm:
            note += (f"; stated diameter {row.aperture_diameter_mm:.6g} clipped where the "
                     f"surface ends")
        notes.append(note)
    return ImportedLens(lens, tuple(notes))
