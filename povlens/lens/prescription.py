"""Lens prescriptions: reading, validating and writing Kolb/pbrt lens files.

File format (pbrt / Kolb et al. 1995), one row per surface, object side first:

    radius_mm  thickness_mm  index_after  aperture_diameter_mm  [abbe_vd]

* ``radius`` is signed; R > 0 puts the centre of curvature on the film side.
  R = 0 is a plane: an *aperture* when there is air on both sides, otherwise a
  flat refracting face (pbrt cannot express the latter; povlens can).
* ``thickness`` is the axial distance to the next vertex; the last row's value is
  the distance to the film and is replaced when the lens is focused.
* ``index_after`` is the refractive index (d line) after the surface; 0 means air.
* ``aperture_diameter`` is the clear diameter (for an aperture: its maximum).
  A diameter larger than the surface can physically be (beyond the sphere, or
  past where the faces of an element or across an air gap meet) is read as a
  housing diameter and clipped, with a :class:`~povlens.errors.LensClipWarning`.
* An optional 5th column carries the Abbe number V_d of the medium after the
  surface (kept for dispersion; 0 = unknown).
* ``#`` starts a comment anywhere on a line; tabs or spaces; LF or CRLF.
* A row's comment may hold ``#!glass NAME`` (``#!glass SCHOTT:N-BK7``): the medium
  after the surface is that catalogue glass (:mod:`povlens.lens.glass_catalog`), whose
  formula gives ``--dispersion`` its n(lambda); the row's index stays as stated.
* A row may end with ``#!asphere k=.. a4=..``: the row is an even asphere of base
  radius ``radius`` (:mod:`povlens.lens.asphere`; other Kolb readers see the sphere).
* A row may end with ``#!toric rx=R``: the row is anamorphic (a cylinder or toroid,
  Zemax's TOROIDAL, :mod:`povlens.lens.toric`): ``radius`` is its y-z section and R
  (mm, 0 = flat in x) the radius of its x-z section, so other Kolb readers see the exact
  y-z meridian.  lentil's ``cyl-y`` (curving in x only) is ``0 ... #!toric rx=R``, its
  ``cyl-x`` (curving in y only) ``R ... #!toric rx=0``.  With ``#!asphere`` on the same
  row the terms shape the y-z profile (k, and a2.. on y^2, y^4, ...), as Zemax's
  TOROIDAL does.  ``rx`` equal to ``radius`` is a sphere (refused with asphere terms,
  which would be ambiguous); ``#!toric`` on an aperture row (radius 0, air on both
  sides) is refused.

The old Kolb / CS348B tables (100 mm scale: ``dgauss.dat``, ``wide.dat``) store
in column 2 the distance from the *previous* vertex.  They are recognised by
their first row's column 2 being 0 while the last row's is not, and converted on
reading: ``t[i] = axpos[i+1]``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
import warnings
from pathlib import Path

import numpy as np

from povlens.errors import LensClipWarning, LensFileError
from povlens.lens import glass_catalog as _gc
from povlens.lens import asphere as _asph
from povlens.lens import toric as _toric
from povlens.util.files import decode_text
from povlens.util.resources import LENS_DIR
from povlens.util.files import write_bytes

__all__ = ["LensPrescription", "read_lens", "read_source_bytes", "parse_lens_text", "write_lens", "format_lens",
           "sag_mm", "resolve_lens_path", "clip_to_physical_apertures"]

AIR = 1.0
#: Surfaces may touch (files round data to ~6 digits) but not cross by more than this.
CROSSING_TOLERANCE_MM = 1e-5
#: Supported magnitudes of non-zero radii and aperture diameters, and the largest
#: thickness (mm), and the largest refractive index.
MIN_LENGTH_MM, MAX_LENGTH_MM = 1e-6, 1e20
MAX_INDEX = 10.0
#: Radii at which neighbouring surfaces are checked for crossing.
_CROSSING_GRID = 257


def sag_mm(curvature_per_mm: float | np.ndarray, r_mm: np.ndarray) -> np.ndarray:
    """Sag s(r) = c r^2 / (1 + sqrt(1 - c^2 r^2)) of the vertex branch, in mm.

    Stable for c -> 0 (no cancellation).  Where c^2 r^2 > 1 the surface does not
    exist; the result there is +inf in magnitude's sign of c (callers check).
    """
    c = np.asarray(curvature_per_mm, dtype=np.float64)
    r2 = np.asarray(r_mm, dtype=np.float64) ** 2
    arg = 1.0 - c * c * r2
    with np.errstate(invalid="ignore"):
        root = np.sqrt(np.maximum(arg, 0.0))
    return c * r2 / (1.0 + root)


@dataclasses.dataclass(frozen=True, eq=False)
class LensPrescription:
    """A lens system as read from a prescription file.

    All arrays have shape (n_surfaces,), float64, object side first.

    Attributes
    ----------
    radius_mm : signed radii of curvature; 0 = plane.
    thickness_mm : axial distance to the next vertex (last entry: as in the file).
    index_after : refractive index after each surface; air is stored as 1.0.
    aperture_diameter_mm : clear-aperture diameters (for an aperture stop: its
        current diameter, see :meth:`with_stop_diameter`).
    abbe_vd : Abbe numbers of the medium after each surface, 0 = unknown.
    source : the file it came from (or a label).
    lines : 1-based line number of each row in the source (0 if not from a file).
    file_format : ``"pbrt"`` or ``"kolb-axpos"`` (converted on reading).
    comments : the comment lines of the file header.
    radius_x_mm : (n_surfaces,) radii of the x-z sections (``#!toric``), or None when
        every row is rotationally symmetric (``radius_mm`` is then both sections').
    """

    radius_mm: np.ndarray
    thickness_mm: np.ndarray
    index_after: np.ndarray
    aperture_diameter_mm: np.ndarray
    abbe_vd: np.ndarray
    source: str = "<memory>"
    lines: tuple[int, ...] = ()
    file_format: str = "pbrt"
    comments: tuple[str, ...] = ()
    max_stop_diameter_mm: float | None = None
    #: The stop's shape (:class:`povlens.lens.aperture_shape.ApertureShape`) at row
    #: ``aperture_shape_row``, or None for round apertures; not part of :meth:`sha256`.
    aperture_shape: object | None = None
    aperture_shape_row: int = -1
    #: Catalogue glass per row (``SCHOTT:N-BK7``; ``""`` none), or () when no row
    #: names one (:mod:`povlens.lens.glass_catalog`); not part of :meth:`sha256`.
    glass: tuple[str, ...] = ()
    #: Even-asphere data (n_surfaces, 9): conic k, a2 .. a16 (:mod:`povlens.lens.asphere`),
    #: or None when every row is a sphere; zero rows are spheres.
    asphere: np.ndarray | None = None
    #: Radii (n_surfaces,) of the rows' x-z sections (mm, 0 = flat in x), or None when
    #: every row is rotationally symmetric; a row whose entry differs from ``radius_mm``
    #: (its y-z section) is toric (:mod:`povlens.lens.toric`), on other rows it equals
    #: ``radius_mm``.
    radius_x_mm: np.ndarray | None = None

    # ----- derived geometry ------------------------------------------------
    @property
    def n_surfaces(self) -> int:
        return int(self.radius_mm.shape[0])

    @property
    def curvature_per_mm(self) -> np.ndarray:
        """c = 1/R (1/mm); 0 for planes."""
        r = self.radius_mm
        with np.errstate(divide="ignore"):
            return np.where(r == 0.0, 0.0, 1.0 / np.where(r == 0.0, 1.0, r))

    @property
    def index_before(self) -> np.ndarray:
        """Refractive index in front of each surface (scene side)."""
        return np.concatenate(([AIR], self.index_after[:-1]))

    @property
    def is_aperture(self) -> np.ndarray:
        """True for planar rows with air on both sides: apertures, which clip only.
        (A toric row flat in y but curved in x is not planar.)"""
        flat = self.radius_mm == 0.0
        if self.radius_x_mm is not None:
            flat = flat & (self.radius_x_mm == 0.0)
        return flat & (self.index_before == AIR) & (self.index_after == AIR)

    @property
    def is_anamorphic(self) -> bool:
        """True when some row's x-z radius differs from its y-z radius (a toric row)."""
        return bool(_toric.toric_rows(self).any())

    @property
    def aperture_radius_mm(self) -> np.ndarray:
        return 0.5 * self.aperture_diameter_mm

    @property
    def total_track_mm(self) -> float:
        """Axial distance from the front vertex to the rear vertex."""
        return float(np.sum(self.thickness_mm[:-1]))

    def row_label(self, i: int) -> str:
        line = self.lines[i] if i < len(self.lines) and self.lines[i] else None
        return f"row {i}" + (f" (line {line})" if line else "")

    def sha256(self) -> str:
        """Hash of the optical content (not comments), for caching derived tables."""
        h = hashlib.sha256()
        for a in (self.radius_mm, self.thickness_mm, self.index_after, self.aperture_diameter_mm):
            h.update(np.ascontiguousarray(a, dtype="<f8").tobytes())
        if _asph.aspheric_rows(self).any():     # spherical lenses keep their old hashes
            h.update(b"asphere" + np.ascontiguousarray(self.asphere, dtype="<f8").tobytes())
        if self.is_anamorphic:                  # rotationally symmetric ones too
            h.update(b"toric" + np.ascontiguousarray(self.radius_x_mm, dtype="<f8").tobytes())
        return h.hexdigest()

    # ----- modified copies ----------------------------------------------------
    def replace(self, **changes) -> "LensPrescription":
        return dataclasses.replace(self, **changes)

    def with_aperture_diameter(self, row: int, diameter_mm: float) -> "LensPrescription":
        d = self.aperture_diameter_mm.copy()
        d[row] = diameter_mm
        return self.replace(aperture_diameter_mm=d)

    def sub_lens(self, first: int) -> "LensPrescription":
        """The rows ``first``..end as a lens of their own, seen from inside the full lens.

        For the same film distance the vertices stay where they are in the full
        lens (the rows toward the film are unchanged).  Refractive indices are
        divided by the index in front of row ``first``, so that every index
        *ratio* (all Snell's law sees) is the full lens's and the sub-lens may
        start inside glass.  A ray traced from the film through it leaves at
        surface ``first``.

        Parameters
        ----------
        first : index of the sub-lens's front row, 0 <= first < n_surfaces.

        Returns
        -------
        LensPrescription
            With n_surfaces - first rows (arrays (n_surfaces - first,)).
        """
        if not 0 <= first < self.n_surfaces:
            raise IndexError(f"row {first}: the lens has rows 0..{self.n_surfaces - 1}")
        sl = slice(first, None)
        return self.replace(radius_mm=self.radius_mm[sl], thickness_mm=self.thickness_mm[sl],
                            index_after=self.index_after[sl] / self.index_before[first],
                            aperture_diameter_mm=self.aperture_diameter_mm[sl],
                            abbe_vd=self.abbe_vd[sl], lines=self.lines[sl], glass=self.glass[sl],
                            asphere=None if self.asphere is None else self.asphere[sl],
                            radius_x_mm=(None if self.radius_x_mm is None
                                         else self.radius_x_mm[sl]),
                            **_shape_rows(self, first))

    def __eq__(self, other) -> bool:  # optical equality, used by round-trip tests
        if not isinstance(other, LensPrescription):
            return NotImplemented
        return all(np.array_equal(a, b) for a, b in (
            (self.radius_mm, other.radius_mm), (self.thickness_mm, other.thickness_mm),
            (self.index_after, other.index_after),
            (self.aperture_diameter_mm, other.aperture_diameter_mm),
            (self.abbe_vd, other.abbe_vd),
            (_asphere_or_zeros(self), _asphere_or_zeros(other)),
            (_toric.radius_x_or_y(self), _toric.radius_x_or_y(other))))

    __hash__ = None


def _asphere_or_zeros(lens: LensPrescription) -> np.ndarray:
    """(n_surfaces, 9) asphere data, zeros for a spherical lens."""
    if lens.asphere is None:
        return np.zeros((lens.n_surfaces, _asph.N_ASPHERE))
    return lens.asphere


def _shape_rows(lens: LensPrescription, first: int) -> dict:
    """The aperture shape of ``lens.sub_lens(first)``: its row renumbered, or none when
    the shaped row is not in it."""
    row = lens.aperture_shape_row - first
    if lens.aperture_shape is None or row < 0:
        return {"aperture_shape": None, "aperture_shape_row": -1}
    return {"aperture_shape_row": row}


def resolve_lens_path(name: str | os.PathLike) -> Path:
    """A lens path as given, or a bundled lens by file name or stem (``dgauss.50mm``)."""
    p = Path(name)
    if p.exists():
        return p
    for cand in (LENS_DIR / p.name, LENS_DIR / f"{p.name}.dat"):
        if cand.exists():
            return cand
    return p


def read_source_bytes(path: str | os.PathLike, kind: str, hint: str,
                      shown: str | os.PathLike | None = None) -> bytes:
    """The bytes of a lens source file (a lens file, a lens database, a Zemax file).

    Raises :class:`LensFileError` naming the file (``shown``, default ``path``) when it
    is missing (with ``hint``), a folder, or unreadable; ``kind`` says what it should be.
    """
    shown = path if shown is None else shown
    try:
        return Path(path).read_bytes()
    except FileNotFoundError:
        raise LensFileError(shown, None, f"no such {kind}", hint) from None
    except IsADirectoryError:
        raise LensFileError(shown, None, f"is a directory, not a {kind}") from None
    except OSError as e:
        raise LensFileError(shown, None, f"cannot be read: {e.strerror}") from None


def read_lens(path: str | os.PathLike) -> LensPrescription:
    """Read and validate a lens file.  Raises :class:`LensFileError` on bad input."""
    p = resolve_lens_path(path)
    raw = read_source_bytes(p, "lens file", "give the path of a lens file, or the name of a "
                            "bundled lens (see 'povlens lenses')", shown=path)
    return parse_lens_text(decode_text(raw), str(p))      # UTF-16 (Windows editors) too


def _parse_number(tok: str, source: str, line: int, column: str) -> float:
    try:
        v = float(tok)
    except ValueError:
        raise LensFileError(source, line, f"{column}: '{tok}' is not a number",
                            "each row holds radius, thickness, index and aperture diameter "
                            "(and optionally the Abbe number), separated by spaces or tabs; "
                            "comments start with '#'") from None
    # an infinite Abbe number is a medium known not to disperse (lens/dispersion.py)
    if not math.isfinite(v) and not (column == "Abbe number" and v == math.inf):
        raise LensFileError(source, line, f"{column}: '{tok}' is not a finite number")
    return v


_COLUMNS = ("radius", "thickness", "index", "aperture diameter", "Abbe number")


def parse_lens_text(text: str, source: str = "<string>") -> LensPrescription:
    """Parse the text of a lens file; ``source`` names it in error messages.

    Apertures larger than their surfaces can be are clipped, one
    :class:`~povlens.errors.LensClipWarning` per row (:func:`clip_to_physical_apertures`).
    """
    rows: list[list[float]] = []
    lines: list[int] = []
    comments: list[str] = []
    glass_rows: dict[int, tuple[str, int]] = {}     # row -> (#!glass name, line)
    for lineno, line in enumerate(text.splitlines(), start=1):
        body, sep, comment = line.partition("#")
        toks = body.split()
        glass_name = _gc.glass_directive(comment, toks, source, lineno)
        if glass_name:
            glass_rows[len(rows)] = (glass_name, lineno)
        if not toks:
            if sep and not rows:
                comments.append(comment.strip())
            continue
        if len(toks) not in (4, 5):
            raise LensFileError(source, lineno,
                                f"{len(toks)} columns; a row needs 4 (radius thickness index "
                                f"aperture) or 5 (plus the Abbe number)")
        rows.append([_parse_number(t, source, lineno, _COLUMNS[k]) for k, t in enumerate(toks)])
        if len(toks) == 4:
            rows[-1].append(0.0)
        lines.append(lineno)
    if not rows:
        raise LensFileError(source, None, "contains no lens rows (empty file or only comments)",
                            "a lens file needs one row per surface: radius thickness index aperture")

    a = np.array(rows, dtype=np.float64)
    radius, thick, index, diam, abbe = a.T.copy()
    file_format = "pbrt"
    if len(rows) > 1 and thick[0] == 0.0 and thick[-1] != 0.0:
        # Old Kolb/CS348B table: column 2 is the distance from the previous vertex.
        thick = np.append(thick[1:], 0.0)
        file_format = "kolb-axpos"

    for i, ln in enumerate(lines):
        if diam[i] <= 0.0:
            raise LensFileError(source, ln, f"aperture diameter {diam[i]:g} mm must be positive")
        # Outside these ranges 1/R or the paraxial matrices overflow (e.g. R = 1e-320
        # has an infinite curvature); no real lens comes near them.
        for what, v in (("radius", radius[i]), ("aperture diameter", diam[i])):
            if v != 0.0 and not MIN_LENGTH_MM <= abs(v) <= MAX_LENGTH_MM:
                raise LensFileError(source, ln, f"{what} {v:g} mm is outside the supported "
                                    f"range {MIN_LENGTH_MM:g} .. {MAX_LENGTH_MM:g} mm")
        if abs(thick[i]) > MAX_LENGTH_MM:
            raise LensFileError(source, ln, f"thickness {thick[i]:g} mm is larger than the "
                                f"supported {MAX_LENGTH_MM:g} mm")
        if index[i] > MAX_INDEX:
            raise LensFileError(source, ln, f"index {index[i]:g} is above {MAX_INDEX:g}; no "
                                f"optical medium has it")
        if index[i] != 0.0 and index[i] < 1.0:
            raise LensFileError(source, ln, f"index {index[i]:g} is below 1",
                                "use the refractive index of the medium after the surface "
                                "(0 or 1 for air)")
        if thick[i] < 0.0 and i < len(rows) - 1:
            raise LensFileError(source, ln, f"thickness {thick[i]:g} mm is negative",
                                "column 2 is the axial distance to the next surface")
        if abbe[i] < 0.0:
            raise LensFileError(source, ln, f"Abbe number {abbe[i]:g} is negative")
    index = np.where(index == 0.0, AIR, index)
    if index[-1] != AIR:
        raise LensFileError(source, lines[-1], f"the medium after the last surface has index "
                            f"{index[-1]:g}; the film must be in air (index 0 or 1)")

    asphere = _asphere_rows(text, lines, radius, index, source)
    lens = LensPrescription(radius, thick, index, diam, abbe, source=source, lines=tuple(lines),
                            file_format=file_format, comments=tuple(comments), asphere=asphere,
                            radius_x_mm=_toric_radii(text, lines, radius, index, asphere, source))
    lens = _gc.with_glass_rows(lens, glass_rows)
    lens = clip_to_physical_apertures(lens)
    ap = lens.is_aperture
    if ap.any():
        lens = lens.replace(max_stop_diameter_mm=float(np.max(lens.aperture_diameter_mm[ap])))
    return lens


def _asphere_rows(text: str, lines: list, radius: np.ndarray, index: np.ndarray,
                 source: str) -> np.ndarray | None:
    """(n_rows, 9) asphere data of the rows' ``#!asphere`` comments (``lines``: each
    row's line number; ``index`` with air as 1), None when there are none or all are
    zero.  Errors name the line: a directive on a line without a row, a bad term, an
    asphere on an aperture row (a plane in air, which would bend no light)."""
    row_of_line = {ln: i for i, ln in enumerate(lines)}
    out = np.zeros((len(lines), _asph.N_ASPHERE))
    for lineno, line in enumerate(text.splitlines(), start=1):
        at = line.lower().find("#" + _asph.DIRECTIVE)
        if at < 0:
            continue
        if lineno not in row_of_line:
            raise LensFileError(source, lineno, "'#!asphere' stands on a line without a row",
                                "put it at the end of the row it belongs to")
        i = row_of_line[lineno]
        try:
            out[i] = _asph.parse_directive(line[at + 1:], "#!asphere: ")
        except ValueError as e:
            raise LensFileError(source, lineno, str(e)) from None
        before = index[i - 1] if i > 0 else AIR
        if radius[i] == 0.0 and before == AIR and index[i] == AIR and np.any(out[i] != 0.0):
            raise LensFileError(source, lineno, f"row {i} is an aperture (radius 0, air on "
                                f"both sides) with asphere terms, which would bend no light",
                                "give the row the index of its glass, or remove its '#!asphere'")
    return out if np.any(out != 0.0) else None


def _toric_radii(text: str, lines: list, radius: np.ndarray, index: np.ndarray,
                 asphere: np.ndarray | None, source: str) -> np.ndarray | None:
    """(n_rows,) x-z radii of the rows (their ``#!toric rx=R``, else their radius), None
    when no row is toric.  Errors name the line: a directive on a line without a row or
    given twice, a bad value, a row that cannot be toric (:func:`toric.row_problem`)."""
    row_of_line = {ln: i for i, ln in enumerate(lines)}
    out = radius.copy()
    for lineno, line in enumerate(text.splitlines(), start=1):
        low = line.lower()
        at = low.find("#" + _toric.DIRECTIVE)
        if at < 0:
            continue
        if lineno not in row_of_line:
            raise LensFileError(source, lineno, "'#!toric' stands on a line without a row",
                                "put it at the end of the row it belongs to")
        if low.find("#" + _toric.DIRECTIVE, at + 1) >= 0:
            raise LensFileError(source, lineno, "'#!toric' is given twice on one row")
        i = row_of_line[lineno]
        try:
            rx = _toric.parse_directive(line[at + 1:], "#!toric: ")
        except ValueError as e:
            raise LensFileError(source, lineno, str(e)) from None
        if rx != 0.0 and not MIN_LENGTH_MM <= abs(rx) <= MAX_LENGTH_MM:
            raise LensFileError(source, lineno, f"#!toric: rx {rx:g} mm is outside the "
                                f"supported range {MIN_LENGTH_MM:g} .. {MAX_LENGTH_MM:g} mm "
                                f"(0 = flat in x)")
        before = index[i - 1] if i > 0 else AIR
        why = _toric.row_problem(float(radius[i]), rx, None if asphere is None else asphere[i],
                                 before == AIR and index[i] == AIR)
        if why:
            raise LensFileError(source, lineno, f"row {i}: '#!toric rx={rx:g}': {why}",
                                "give the row the radius of its y-z section and rx that of "
                                "its x-z section, on a surface with glass on a side")
        out[i] = rx
    return out if np.any(out != radius) else None


def clip_to_physical_apertures(lens: LensPrescription) -> LensPrescription:
    """``lens`` with every aperture clipped to where its surface physically ends.

    Published prescriptions often give a housing (mount) radius, not the clear
    aperture.  A row's semi-aperture is limited by

    1. its sphere: a cap exists only out to r = |R| (a hemisphere);
    2. each neighbour: the height where the two faces meet, i.e. the first root of
       the axial gap ``t_i + s_(i+1)(r) - s_i(r)`` (the element's edge thickness, or
       the air gap between two elements).  The gap is monotonic in r for two spheres,
       so the root is bracketed on the crossing check's grid and bisected; both rows
       are clipped to it (the element ends there, or the two elements touch there),
       except an aperture row (the stop, a field stop): its diameter is the design's,
       so only the glass whose rim crosses its plane is clipped (lentil's 1927 Biotar,
       entry 0009: the stop stays 45 mm, f/1.4367 as optical-design programs give it,
       not 44.947 mm and f/1.4384).

    Pairs are taken front to back with the apertures clipped so far.  Gaps that close
    by no more than ``CROSSING_TOLERANCE_MM`` are kept (rounded data); faces that
    cross at the axis itself are refused (no light could pass).

    Parameters
    ----------
    lens : LensPrescription
        As read, apertures as stated in the file.

    Returns
    -------
    LensPrescription
        ``lens`` itself when nothing needs clipping, else a copy with the clipped
        diameters; one :class:`~povlens.errors.LensClipWarning` per clipped row.

    Raises
    ------
    LensFileError
        When neighbouring faces cross at the axis ("physically impossible").
    """
    a, why = _surface_ends(lens)
    for i in range(lens.n_surfaces - 1):
        meet = _meeting_height_mm(_gap_function(lens, i), min(a[i], a[i + 1]))
        if meet is None:
            continue
        glass = lens.index_after[i] != AIR
        for j, other in ((i, i + 1), (i + 1, i)):
            # an aperture (the stop, a field stop) is never clipped: its diameter is the
            # design's (the f-number), and a glass rim crossing its plane is clipped
            # instead, as optical-design programs read the prescription
            if a[j] > meet and not lens.is_aperture[j]:
                a[j] = meet
                why[j] = (f"the faces of the element ({lens.row_label(i)} to "
                          f"{lens.row_label(i + 1)}) meet" if glass else
                          f"it meets {lens.row_label(other)} across the air gap")
    if not why:
        _check_surfaces_do_not_cross(lens)
        return lens
    d = lens.aperture_diameter_mm.copy()
    rows = sorted(why)
    d[rows] = 2.0 * a[rows]
    clipped = lens.replace(aperture_diameter_mm=d)
    _check_surfaces_do_not_cross(clipped)  # before warning: a refused lens gets no notices
    for j in rows[:CLIP_WARNINGS_SHOWN]:
        where = f"{lens.source}:{lens.lines[j]}" if lens.lines and lens.lines[j] else lens.source
        warnings.warn(LensClipWarning(
            f"{where}: row {j}: aperture diameter "
            f"{lens.aperture_diameter_mm[j]:g} mm clipped to {d[j]:.6g} mm, where "
            f"{why[j]} (the stated diameter is taken as a housing diameter)"), stacklevel=3)
    rest = rows[CLIP_WARNINGS_SHOWN:]
    if rest:
        warnings.warn(LensClipWarning(
            f"{lens.source}: {len(rest):,} more rows' aperture diameters clipped the same "
            f"way (rows {rest[0]} to {rest[-1]}; smallest {min(d[rest]):.6g} mm)"),
            stacklevel=3)
    return clipped


def _surface_ends(lens: LensPrescription) -> tuple[np.ndarray, dict]:
    """(n_surfaces,) semi-apertures (mm) clipped where each surface ends (a sphere at
    |R|, an asphere at its conic's rim, a toric row at the edge of its domain,
    :func:`toric.row_domain_radius_mm`), and why, by row."""
    a = lens.aperture_radius_mm.copy()
    why: dict[int, str] = {}
    radius = lens.radius_mm
    toric = _toric.toric_rows(lens)
    aspheric = _asph.aspheric_rows(lens) & ~toric
    for i in np.flatnonzero((radius != 0.0) & ~aspheric & ~toric & (a > np.abs(radius))):
        a[i] = abs(radius[i])
        why[i] = f"the sphere of radius {abs(radius[i]):g} mm ends"
    for i in np.flatnonzero(aspheric):
        rim = _asph.row_domain_radius_mm(lens, i)
        if a[i] > rim:
            a[i] = rim
            why[i] = f"the asphere's conic (base radius {radius[i]:g} mm) ends"
    for i in np.flatnonzero(toric):
        rim = _toric.row_domain_radius_mm(lens, i)
        if a[i] > rim:
            a[i] = rim
            why[i] = (f"the {_toric.describe_row(radius[i], lens.radius_x_mm[i])} ends")
    return a, why


#: Clipped rows a lens's warnings name one by one; the others are counted in one more.
CLIP_WARNINGS_SHOWN = 5


#: Azimuths (over a quarter turn, both meridians included) at which the gap between
#: neighbouring surfaces is taken when one of them is toric (not rotationally symmetric).
_GAP_ANGLES = np.linspace(0.0, 0.5 * math.pi, 17)


def _gap_function(lens: LensPrescription, i: int):
    """Function r_mm (any shape) -> the axial gap (mm) from row ``i`` to row ``i + 1`` at
    height r: ``t_i + s_(i+1)(r) - s_i(r)``; when either row is toric, the smallest over
    the azimuths :data:`_GAP_ANGLES` (the surfaces are even in x and y)."""
    t = lens.thickness_mm[i]
    toric = _toric.toric_rows(lens)
    if not (toric[i] or toric[i + 1]):
        sag0, sag1 = _asph.row_sag(lens, i), _asph.row_sag(lens, i + 1)
        return lambda r: t + sag1(r) - sag0(r)
    sag0, sag1 = _toric.row_sag_xy(lens, i), _toric.row_sag_xy(lens, i + 1)
    cos, sin = np.cos(_GAP_ANGLES), np.sin(_GAP_ANGLES)

    def gap(r):
        r = np.asarray(r, dtype=np.float64)
        x, y = r[..., None] * cos, r[..., None] * sin
        return np.min(t + sag1(x, y) - sag0(x, y), axis=-1)
    return gap


def _meeting_height_mm(gap, r_max_mm: float) -> float | None:
    """Height (mm) in (0, r_max_mm) where the gap between two neighbouring surfaces
    (``gap``: r -> mm, :func:`_gap_function`) closes; None when they do not cross (or
    cross at the axis, which no clipping mends)."""
    r = np.linspace(0.0, r_max_mm, _CROSSING_GRID)
    g = gap(r)
    if g.min() >= -CROSSING_TOLERANCE_MM:
        return None
    k = int(np.argmax(g < 0.0))  # first grid point past the crossing; g[0] = t >= 0
    lo, hi = float(r[k - 1]), float(r[k])
    while True:  # bisect to float resolution; gap(lo) >= 0 throughout
        mid = 0.5 * (lo + hi)
        if not lo < mid < hi:
            break
        if gap(mid) >= 0.0:
            lo = mid
        else:
            hi = mid
    return lo if lo >= 0.5 * MIN_LENGTH_MM else None


def _check_surfaces_do_not_cross(lens: LensPrescription) -> None:
    """Neighbouring surfaces must not cross inside their common clear aperture."""
    for i in range(lens.n_surfaces - 1):
        rmax = min(lens.aperture_radius_mm[i], lens.aperture_radius_mm[i + 1])
        r = np.linspace(0.0, rmax, _CROSSING_GRID)
        gap = _gap_function(lens, i)(r)
        k = int(np.argmin(gap))
        tol = CROSSING_TOLERANCE_MM
        if gap[k] < -tol:
            medium = "glass" if lens.index_after[i] != AIR else "air gap"
            raise LensFileError(
                lens.source, lens.lines[i + 1] if lens.lines else None,
                f"surfaces {lens.row_label(i)} and {lens.row_label(i + 1)} cross inside their "
                f"clear apertures (the {medium} is {gap[k]:.4g} mm thick at height {r[k]:.4g} mm): "
                f"physically impossible",
                f"increase the thickness on {lens.row_label(i)} or reduce the clear apertures")


def format_lens(lens: LensPrescription) -> str:
    """The lens as pbrt-format text (17 significant digits: reading it back is exact)."""
    out = [f"# {c}" if c else "#" for c in lens.comments]
    if lens.file_format != "pbrt":
        out.append(f"# converted from {lens.file_format} format by povlens")
    with_abbe = bool(np.any(lens.abbe_vd != 0.0))
    aspheric = _asph.aspheric_rows(lens)
    toric = _toric.toric_rows(lens)
    out.append("# radius\tthickness\tindex\taperture" + ("\tabbe_vd" if with_abbe else ""))
    for i in range(lens.n_surfaces):
        n = 0.0 if lens.is_aperture[i] else lens.index_after[i]
        cols = [lens.radius_mm[i], lens.thickness_mm[i], n, lens.aperture_diameter_mm[i]]
        if with_abbe:
            cols.append(lens.abbe_vd[i])
        row = "\t".join(f"{v:.17g}" for v in cols)
        if toric[i]:
            row += "\t" + _toric.format_directive(lens.radius_x_mm[i])
        if aspheric[i]:
            row += "\t" + _asph.format_directive(lens.asphere[i])
        out.append(row)
    _gc.add_glass_directives(out, lens)
    return "\n".join(out) + "\n"


def write_lens(lens: LensPrescription, path: str | os.PathLike) -> None:
    """Write ``lens`` to ``path`` (:func:`format_lens`, LF line ends), atomically."""
    write_bytes(path, format_lens(lens).encode("utf-8"))
