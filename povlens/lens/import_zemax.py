"""Lenses from Zemax OpticStudio sequential files (``.zmx``).

A ``.zmx`` file is text (Zemax writes UTF-16 LE with a byte-order mark, older
versions and converters ASCII): global lines (``UNIT``, ``MODE``, ``NAME``, ``NOTE``,
...) and one block per surface, ``SURF n`` followed by indented lines::

    SURF 4
      STOP
      TYPE STANDARD
      CURV 4.928e-02 0 0 0 0 ""      curvature, 1 / lens unit
      DISZ 4.75041                    thickness to the next surface (INFINITY for the object)
      GLAS SK16 0 0 1.62041 60.32 ... medium after the surface: name, two solve fields, nd, vd
      DIAM 3.8045 0 0 0 1 ""          semi-diameter (clear aperture radius)
      MEMA 3.8045 0 0 0 1 ""          mechanical semi-diameter

Surface 0 is the object, the last the image; the surfaces between are the lens.
Read here: ``UNIT`` (MM, CM, IN, METER), ``MODE`` (SEQ only), ``NAME``, ``NOTE``,
``MNUM``; per surface ``TYPE``, ``STOP``, ``CURV``, ``CONI``, ``PARM``, ``XDAT``, ``DISZ``,
``GLAS``, ``DIAM``, ``MEMA``, ``CLAP``, ``OBSC``/``SQAP``/``ELAP``/``UDAP``, ``COAT``,
``COMM``, ``SCBD``.  Other keywords (drawing, optimisation, tolerancing, solves whose
values the file already holds) do not change the surfaces and are skipped.

Conversion to a Kolb/pbrt file (all lengths to mm):

* radius = 1 / CURV; aperture diameter = 2 x (CLAP maximum radius, else DIAM, else MEMA);
* the medium after a surface: ``GLAS`` absent -> air; ``___BLANK`` (a model glass) or
  a catalogue name with the nd and vd the line gives; a 6-digit glass code
  (``517642`` -> nd 1.517, vd 64.2); ``glasses`` (name -> (nd, vd)) overrides all.
  A catalogue glass whose line holds Zemax's placeholder (nd 1.5, vd 40), or nd 0 (as
  Thorlabs' files do), has no index in the file: nd and vd come from the glass
  catalogue (:mod:`povlens.lens.glass_catalog`, SCHOTT, OHARA, HOYA, CDGM, HIKARI,
  SUMITA); a name no catalogue holds is refused,
  naming the closest, unless ``glasses`` gives it.  A row whose glass the catalogue
  holds (and whose nd, vd match it) is written with ``#!glass MAKER:NAME``, which gives
  ``--dispersion`` the catalogue formula;
* the STOP becomes a plane in air (an aperture row): a flat stop surface in air as it
  is; a stop on a lens face gets a plane in the air beside it, in the vertex plane
  when the face is flat or convex toward that air (paraxially exact), else in the
  plane of the face's rim at the stop radius, with a :class:`LensImportWarning`;
* surfaces in air on both sides other than the stop (Zemax's dummy surfaces) have no
  power and are dropped, their thickness added to the gap before them;
* ``TYPE EVENASPH`` (``PARM 1..8`` the coefficients of r^2 .. r^16) and ``CONI`` (on
  STANDARD or EVENASPH) make an even asphere (:mod:`povlens.lens.asphere`), written as
  the row's ``#!asphere`` comment; the coefficients are converted to mm
  (a_2i x unit^(1 - 2i));
* ``TYPE TOROIDAL`` is a toric row (:mod:`povlens.lens.toric`, written with
  ``#!toric rx=R``): CURV is the curvature of its y-z section, ``PARM 1`` its radius of
  rotation R (the radius of its x-z section; 0 is Zemax's infinity, flat in x), CONI and
  ``PARM 2..8`` (the coefficients of y^2 .. y^14) shape its y-z profile (``#!asphere``);
  Thorlabs' cylindrical lenses (LJ..., LK...) are TOROIDAL.  Its Zernike terms
  (``XDAT 3..``) are refused;
* refused, naming the surface: surface types other than STANDARD, EVENASPH and
  TOROIDAL, other PARMs of an EVENASPH or TOROIDAL, mirrors, tilts and decenters, a stop
  inside glass or on an aspheric face, a file without STOP.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import warnings
from pathlib import Path

import numpy as np

from povlens.errors import LensFileError
from povlens.lens import glass_catalog, toric
from povlens.lens.asphere import N_ASPHERE, scaled_asphere
from povlens.lens.import_common import ImportedLens, LensImportWarning, SourceRow, build_lens
from povlens.lens.prescription import LensPrescription, read_source_bytes, sag_mm
from povlens.util.files import decode_text

__all__ = ["ZmxSurface", "ZmxFile", "parse_zmx_text", "import_zmx", "read_zmx", "UNIT_MM"]

#: ``UNIT`` lens units in mm.
UNIT_MM = {"MM": 1.0, "CM": 10.0, "IN": 25.4, "INCH": 25.4, "M": 1000.0, "METER": 1000.0,
           "METERS": 1000.0}
#: What Zemax writes for nd and vd of a catalogue glass when it does not store them.
PLACEHOLDER_ND_VD = (1.5, 40.0)
#: Keywords that give a surface a non-circular or extra aperture (dropped, with a warning).
OTHER_APERTURES = {"OBSC": "an obscuration", "SQAP": "a rectangular aperture",
                   "ELAP": "an elliptical aperture", "UDAP": "a user-defined aperture",
                   "SQOB": "a rectangular obscuration", "ELOB": "an elliptical obscuration"}
#: Keywords read inside a surface block (a line starting with one belongs to the surface
#: even when it is not indented).
SURFACE_KEYWORDS = {"TYPE", "STOP", "CURV", "CONI", "PARM", "DISZ", "GLAS", "DIAM", "MEMA",
                    "CLAP", "COAT", "COMM", "SCBD", "XDAT", *OTHER_APERTURES}


@dataclasses.dataclass
class ZmxSurface:
    """One ``SURF`` block, as in the file (lens units; ``None``: not given)."""

    number: int
    line: int
    type: str = "STANDARD"
    stop: bool = False
    curvature: float = 0.0
    conic: float = 0.0
    parms: dict = dataclasses.field(default_factory=dict)
    thickness: float | None = None  # math.inf for INFINITY
    glass: list[str] | None = None
    glass_line: int = 0
    semi_diameter: float = 0.0
    mechanical_semi_diameter: float = 0.0
    clear_aperture: tuple[float, float] | None = None  # CLAP (min, max) radius
    dropped: list[tuple[str, int]] = dataclasses.field(default_factory=list)
    xdat: dict = dataclasses.field(default_factory=dict)   # extra data: number -> value
    coating: str = ""
    comment: str = ""
    tilted: int = 0  # line of a non-zero SCBD, 0 if none

    @property
    def label(self) -> str:
        return f"surface {self.number} (line {self.line})"

    @property
    def aperture_radius(self) -> float:
        """Clear semi-diameter: CLAP's maximum radius, else DIAM, else MEMA."""
        if self.clear_aperture is not None:
            return self.clear_aperture[1]
        return self.semi_diameter or self.mechanical_semi_diameter


@dataclasses.dataclass
class ZmxFile:
    """What :func:`parse_zmx_text` reads: the surfaces and the global lines."""

    surfaces: list[ZmxSurface]
    unit_mm: float = 1.0
    unit: str = "MM"
    name: str = ""
    notes: list[str] = dataclasses.field(default_factory=list)
    configurations: int = 1


def _float(tok: str, source: str, line: int, what: str) -> float:
    try:
        v = float(tok.replace(",", "."))
    except ValueError:
        raise LensFileError(source, line, f"{what}: '{tok}' is not a number") from None
    if not math.isfinite(v):
        raise LensFileError(source, line, f"{what}: '{tok}' is not a finite number")
    return v


def _surface_line(s: ZmxSurface, key: str, args: list[str], rest: str, source: str,
                  ln: int) -> None:
    """Apply one line of a ``SURF`` block to ``s``."""
    def num(i: int, what: str) -> float:
        if len(args) <= i:
            raise LensFileError(source, ln, f"{s.label}: {key} needs a value ({what})")
        return _float(args[i], source, ln, f"{s.label}: {key} {what}")

    if key == "TYPE":
        s.type = args[0].upper() if args else "STANDARD"
    elif key == "STOP":
        s.stop = True
    elif key == "CURV":
        s.curvature = num(0, "curvature")
    elif key == "CONI":
        s.conic = num(0, "conic constant")
    elif key == "PARM" and len(args) >= 2:
        s.parms[int(num(0, "number"))] = num(1, "value")
    elif key == "XDAT" and len(args) >= 2:
        s.xdat[int(num(0, "number"))] = num(1, "value")
    elif key == "DISZ":
        s.thickness = (math.inf if args and args[0].upper() == "INFINITY"
                       else num(0, "thickness"))
    elif key == "GLAS":
        s.glass, s.glass_line = args, ln
    elif key == "DIAM":
        s.semi_diameter = num(0, "semi-diameter")
    elif key == "MEMA":
        s.mechanical_semi_diameter = num(0, "mechanical semi-diameter")
    elif key == "CLAP":
        s.clear_aperture = (num(0, "minimum radius"), num(1, "maximum radius"))
    elif key in OTHER_APERTURES:
        s.dropped.append((OTHER_APERTURES[key], ln))
    elif key == "COAT" and args:
        s.coating = args[0]
    elif key == "COMM":
        s.comment = rest.strip().strip('"')
    elif key == "SCBD" and any(_float(a, source, ln, "SCBD") != 0 for a in args[3:]):
        s.tilted = ln


def parse_zmx_text(text: str, source: str = "<string>") -> ZmxFile:
    """The surfaces and global settings of the text of a ``.zmx`` file.

    Parameters
    ----------
    text : str
        The decoded file.
    source : str
        Names the file in error messages.

    Returns
    -------
    ZmxFile
        With ``surfaces`` (list of :class:`ZmxSurface`, in file order), ``unit_mm``,
        ``unit``, ``name``, ``notes`` (paragraphs of the NOTE lines) and
        ``configurations`` (MNUM).

    Raises
    ------
    povlens.errors.LensFileError
        Not a sequential file, an unknown unit, a malformed number (file and line).
    """
    f = ZmxFile([])
    note_run: list[str] = []
    current: ZmxSurface | None = None
    for ln, line in enumerate(text.splitlines(), start=1):
        toks = line.split()
        if not toks:
            continue
        key, args = toks[0].upper(), toks[1:]
        rest = line.strip()[len(toks[0]):]
        if current is not None and (line[:1].isspace() or key in SURFACE_KEYWORDS):
            _surface_line(current, key, args, rest, source, ln)
            continue
        current = None
        if note_run and key != "NOTE":
            f.notes.append("".join(note_run).strip())
            note_run = []
        if key == "SURF":
            n = int(_float(args[0], source, ln, "SURF number")) if args else len(f.surfaces)
            current = ZmxSurface(number=n, line=ln)
            f.surfaces.append(current)
        elif key == "MODE" and args and args[0].upper() != "SEQ":
            raise LensFileError(source, ln, f"MODE {args[0]}: not a sequential design",
                                "povlens imports sequential (MODE SEQ) lens files only")
        elif key == "UNIT" and args:
            if args[0].upper() not in UNIT_MM:
                raise LensFileError(source, ln, f"UNIT {args[0]}: unknown lens unit",
                                    f"known units: {', '.join(sorted(UNIT_MM))}")
            f.unit, f.unit_mm = args[0].upper(), UNIT_MM[args[0].upper()]
        elif key == "NAME":
            f.name = rest.strip().strip('"')
        elif key == "NOTE":
            # "NOTE 0 text" lines continue a paragraph (Zemax breaks them every 200
            # characters); "NOTE 4" ends it.
            if args[:1] == ["0"]:
                note_run.append(re.sub(r"^\s*0 ?", "", rest, count=1))
            elif note_run:
                f.notes.append("".join(note_run).strip())
                note_run = []
        elif key == "MNUM" and args:
            f.configurations = int(_float(args[0], source, ln, "MNUM"))
    if note_run:
        f.notes.append("".join(note_run).strip())
    f.notes = [n for n in f.notes if n]
    return f


def _check_shape(s: ZmxSurface, source: str) -> None:
    """Refuse what a spherical surface cannot be (type, conic, asphere, tilt)."""
    def refuse(reason: str, hint: str = "a Kolb lens file holds spherical surfaces on one "
               "axis only; remove it in the design program or pick another design"):
        raise LensFileError(source, s.line, f"{s.label}: {reason}", hint)

    if s.glass and s.glass[0].upper() == "MIRROR":
        refuse("a mirror (GLAS MIRROR); povlens imports refracting lenses only")
    if s.type == "EVENASPH":
        other = {k: v for k, v in s.parms.items() if v != 0 and not 1 <= k <= N_ASPHERE - 1}
        if other:
            shown = ", ".join(f"PARM {k} = {v:g}" for k, v in sorted(other.items()))
            refuse(f"an even asphere with terms beyond r^16 ({shown}); PARM 1..8 are read")
    elif s.type == "TOROIDAL":
        other = {k: v for k, v in s.parms.items() if v != 0 and not 0 <= k <= N_ASPHERE - 1}
        zernike = {k: v for k, v in s.xdat.items() if v != 0 and k >= 3}
        if other:
            shown = ", ".join(f"PARM {k} = {v:g}" for k, v in sorted(other.items()))
            refuse(f"a toroidal surface with parameters beyond PARM 8 ({shown}); PARM 1 (the "
                   f"radius of rotation) and 2..8 (y^2 .. y^14) are read")
        if zernike:
            refuse(f"a toroidal surface with Zernike terms (XDAT {min(zernike)} = "
                   f"{zernike[min(zernike)]:g}); povlens reads its radius of rotation, conic "
                   f"and y polynomial")
    elif s.type == "COORDBRK":
        refuse("a coordinate break (tilts or decenters the axis)")
    elif s.type == "PARAXIAL":
        refuse("a paraxial (ideal thin) lens surface")
    elif s.type != "STANDARD":
        refuse(f"surface type {s.type}; povlens imports STANDARD, EVENASPH and TOROIDAL "
               f"surfaces")
    if s.tilted:
        refuse(f"tilted or decentered (SCBD, line {s.tilted})")
    if s.thickness is not None and math.isinf(s.thickness):
        refuse("thickness INFINITY inside the lens")


def _medium(s: ZmxSurface, glasses: dict) -> tuple[float, float, str] | None:
    """(nd, vd, name) of the medium after ``s``; (1, 0, "air") for air; None when the
    file gives no index for its glass."""
    if not s.glass or s.glass[0].upper() == "AIR":
        return 1.0, 0.0, "air"
    name = s.glass[0]
    given = glasses.get(name, glasses.get(name.upper()))
    if given is not None:
        nd, vd = (tuple(given) + (0.0,))[:2] if isinstance(given, (tuple, list)) else (given, 0.0)
        return float(nd), float(vd), f"{name} (given)"
    try:
        nd, vd = float(s.glass[3].replace(",", ".")), float(s.glass[4].replace(",", "."))
    except (IndexError, ValueError):
        nd = vd = math.nan
    if nd == 0.0:
        nd = math.nan          # 'GLAS N-BK7 0 0 0 0 ...' (Thorlabs' files): not stored
    code = re.fullmatch(r"(\d{3})(\d{3})(\.\d*)?", name)
    if code and (math.isnan(nd) or (nd, vd) == PLACEHOLDER_ND_VD):
        nd, vd = 1.0 + int(code[1]) / 1000.0, int(code[2]) / 10.0  # glass code: 517642
    elif math.isnan(nd) or (name != "___BLANK" and (nd, vd) == PLACEHOLDER_ND_VD):
        return _catalogue_medium(name)
    label = "model glass" if name == "___BLANK" else name
    return nd, (vd if math.isfinite(vd) and vd > 0 else 0.0), label


def _closest(name: str) -> str:
    """The catalogue's hint for an unknown glass name (closest known names)."""
    try:
        glass_catalog.find_glass(name)
    except glass_catalog.UnknownGlassError as e:
        return (e.hint or "").split("; or ")[0]
    return ""


def _catalogue_medium(name: str) -> tuple[float, float, str] | None:
    """(nd, vd, label) of catalogue glass ``name`` from its formula; None if unknown."""
    try:
        g = glass_catalog.find_glass(name)
    except glass_catalog.UnknownGlassError:
        return None
    return g.n_d, g.v_d, f"{name} (catalogue {g.label})"


def _row_glass(s: ZmxSurface, nd: float, vd: float, glasses: dict, source: str) -> str:
    """The catalogue label (``SCHOTT:N-BK7``) of the glass after ``s``, or "" (air, a
    model glass, a glass code, one ``glasses`` gives, or not in the catalogues); a
    glass whose nd, vd differ from the catalogue's is not kept, with a warning."""
    name = s.glass[0] if s.glass else "AIR"
    if (name.upper() in ("AIR", "___BLANK") or re.fullmatch(r"[\d.]+", name)
            or name in glasses or name.upper() in glasses):
        return ""
    try:
        g = glass_catalog.find_glass(name)
    except glass_catalog.UnknownGlassError:
        return ""
    off = glass_catalog.mismatch(g, nd, vd)
    if off:
        _warn(source, s, f"glass {name}: the file states {off}, not catalogue glass "
                         f"{g.label}; its dispersion is the Cauchy model of the stated values")
        return ""
    return g.label


def _media(lens: list[ZmxSurface], glasses: dict, source: str) -> list[tuple[float, float, str]]:
    """The medium after each lens surface; one error listing every glass without index."""
    media = [_medium(s, glasses) for s in lens]
    missing = [s for s, m in zip(lens, media) if m is None]
    if missing:
        names = sorted({s.glass[0] for s in missing})
        where = ", ".join(f"{s.number}" for s in missing)
        raise LensFileError(
            source, missing[0].glass_line,
            f"surface{'s' if len(missing) > 1 else ''} {where}: glass "
            f"{', '.join(names)} has no refractive index in the file (only Zemax's "
            f"placeholder nd 1.5, vd 40) and is in no glass catalogue povlens has",
            f"{_closest(names[0])}; or give its nd (and vd) with 'glasses': {names[0]}=ND,VD")
    for s, m in zip(lens, media):
        if not 1.0 <= m[0] <= 10.0:
            raise LensFileError(source, s.glass_line,
                                f"{s.label}: glass {s.glass[0]} has index {m[0]:g}")
    return media


def _warn(source: str, s: ZmxSurface, what: str) -> None:
    warnings.warn(LensImportWarning(f"{source}:{s.line}: surface {s.number}: {what}"),
                  stacklevel=4)


def _stop_rows(s: ZmxSurface, k: float, before_air: bool, after_air: bool, row: SourceRow,
               source: str) -> tuple[list[SourceRow], float]:
    """Rows for stop surface ``s`` (``row`` is its own row, mm) and how much the gap in
    front of it shrinks (mm) when the stop plane goes in front of its vertex."""
    a = s.aperture_radius * k
    if a <= 0:
        raise LensFileError(source, s.line, f"{s.label}: the stop has no semi-diameter (DIAM 0)",
                            "set the stop's semi-diameter in the design program")
    stop = SourceRow(0.0, row.thickness_mm, 1.0, 2 * a, 0.0, row.label,
                     f"aperture stop (surface {s.number})", s.line)
    if before_air and after_air:
        if s.curvature != 0:
            _warn(source, s, "the stop surface is curved but in air on both sides; written as "
                             "a plane in its vertex plane")
        return [stop], 0.0
    if not (before_air or after_air):
        raise LensFileError(source, s.line, f"{s.label}: the stop lies between two glasses",
                            "povlens needs the aperture stop in air; move the STOP to an air "
                            "space in the design program")
    shift = 0.0
    rx = _radius_of_rotation_mm(s, k)
    for c in (s.curvature / k,) + (() if not rx else (1.0 / rx,)):   # 1/mm, each section
        if abs(c) * a > 1:
            raise LensFileError(source, s.line, f"{s.label}: stop semi-diameter {a:g} mm "
                                f"exceeds the radius of the surface")
        # Toward the air the face bulges (no room lost) when c >= 0 in front, c <= 0 behind.
        if not (c >= 0 if before_air else c <= 0):
            shift = max(shift, abs(float(sag_mm(c, a))))
    if shift:
        _warn(source, s, f"the stop lies on a face that is concave toward the air; the aperture "
                         f"is placed in the plane of the face's rim, {shift:.6g} mm "
                         f"{'in front of' if before_air else 'behind'} its vertex (pupils "
                         f"move by about that much)")
    if before_air:  # plane, then the face
        return [dataclasses.replace(stop, thickness_mm=shift), row], shift
    if row.thickness_mm < shift:
        raise LensFileError(source, s.line, f"{s.label}: no room for the stop plane behind it "
                            f"({row.thickness_mm:g} mm of air, the rim is {shift:g} mm deep)")
    face = dataclasses.replace(row, thickness_mm=shift)
    return [face, dataclasses.replace(stop, thickness_mm=row.thickness_mm - shift)], 0.0


def _zmx_asphere(s: ZmxSurface, k: float) -> tuple | None:
    """(conic, a2 .. a16) in mm of ``s`` (lens unit ``k`` mm), None for a sphere; of a
    TOROIDAL surface its y-z profile's (PARM 2..8 are a2 .. a14)."""
    if s.curvature == 0 and s.type not in ("EVENASPH", "TOROIDAL"):
        return None                       # a conic of a plane is a plane
    if s.type == "EVENASPH":
        poly = [s.parms.get(j, 0.0) for j in range(1, N_ASPHERE)]
    elif s.type == "TOROIDAL":
        poly = [s.parms.get(j, 0.0) for j in range(2, N_ASPHERE)] + [0.0]
    else:
        poly = [0.0] * (N_ASPHERE - 1)
    terms = [s.conic] + poly
    if not any(terms):
        return None
    return tuple(float(v) for v in scaled_asphere(np.array(terms, dtype=np.float64), k))


def _radius_of_rotation_mm(s: ZmxSurface, k: float) -> float | None:
    """The x-z radius (mm, 0 = flat in x) of a TOROIDAL surface (its PARM 1, lens unit
    ``k`` mm), None for other surfaces."""
    return s.parms.get(1, 0.0) * k if s.type == "TOROIDAL" else None


def _lens_rows(f: ZmxFile, glasses: dict, source: str) -> tuple[list[SourceRow], list[int]]:
    """The rows to write, and the numbers of the dummy surfaces dropped."""
    lens = f.surfaces[1:-1]
    for s in lens:
        _check_shape(s, source)
    media = _media(lens, glasses, source)
    k = f.unit_mm
    rows: list[SourceRow] = []
    dummies: list[int] = []
    before_air = _medium(f.surfaces[0], {}) == (1.0, 0.0, "air")
    if not before_air:
        raise LensFileError(source, f.surfaces[0].line, "the object is in glass (GLAS on the "
                            "object surface)", "povlens imports lenses that look into air")
    for s, (nd, vd, name) in zip(lens, media):
        after_air = name == "air"
        t = 0.0 if s.thickness is None else s.thickness * k
        if before_air and after_air and not s.stop:
            # A dummy surface: no power, and a semi-diameter Zemax does not clip at.
            dummies.append(s.number)
            for what, _ in s.dropped + ([("its clear aperture", 0)] if s.clear_aperture else []):
                _warn(source, s, f"{what} on a dummy surface in air is dropped with it")
            if rows:
                rows[-1] = dataclasses.replace(rows[-1],
                                               thickness_mm=rows[-1].thickness_mm + t)
            before_air = after_air
            continue
        for what, ln in s.dropped:
            _warn(source, s, f"{what} (line {ln}) is dropped; the clear semi-diameter is kept")
        if s.coating:
            _warn(source, s, f"coating {s.coating} is dropped (povlens has no coatings)")
        if s.clear_aperture is not None and s.clear_aperture[0] > 0:
            _warn(source, s, f"the central obscuration of CLAP (radius "
                             f"{s.clear_aperture[0]:g}) is dropped")
        radius = 1.0 / s.curvature * k if s.curvature != 0 else 0.0
        what = "air" if after_air else f"{name} nd {nd:g}" + (f" vd {vd:g}" if vd else "")
        note = f"surface {s.number}: {what}" + (f"; {s.comment}" if s.comment else "")
        asph = _zmx_asphere(s, k)
        rx = _radius_of_rotation_mm(s, k)
        note += "; " + toric.describe_row(radius, rx) if rx not in (None, radius) else ""
        row = SourceRow(radius, t, nd, 2 * s.aperture_radius * k, vd, s.label,
                        note + ("; asphere" if asph else ""), s.line, asph, radius_x_mm=rx)
        if s.stop and asph and not (before_air and after_air):
            raise LensFileError(source, s.line, f"{s.label}: the stop lies on an aspheric "
                                f"face", "move the STOP to a plane in the air beside it in the "
                                "design program")
        row = dataclasses.replace(row, glass=_row_glass(s, nd, vd, glasses, source))
        if s.stop:
            new, shrink = _stop_rows(s, k, before_air, after_air, row, source)
            if shrink and rows:
                if rows[-1].thickness_mm < shrink:
                    raise LensFileError(source, s.line, f"{s.label}: no room for the stop "
                                        f"plane in front of it (the rim is {shrink:g} mm deep)")
                rows[-1] = dataclasses.replace(rows[-1],
                                               thickness_mm=rows[-1].thickness_mm - shrink)
            rows.extend(new)
        else:
            rows.append(row)
        before_air = after_air
    return rows, dummies


def import_zmx(path: str | os.PathLike, glasses: dict | None = None) -> ImportedLens:
    """A Zemax sequential ``.zmx`` file as an :class:`ImportedLens`.

    Parameters
    ----------
    path : str or path
        The ``.zmx`` file (UTF-16 with or without byte-order mark, UTF-8 or Latin-1).
    glasses : dict, optional
        Glass name -> (nd, vd) (or nd alone): indices for catalogue glasses the file
        gives no index for, or to override the file's.

    Returns
    -------
    ImportedLens
        In mm, object side first; the stop as an aperture row; header comments name
        the file, design, notes and what was dropped; each row names its surface.

    Raises
    ------
    povlens.errors.LensFileError
        A surface a Kolb file cannot hold, a glass without index, no STOP, a
        malformed line: the message names the file, line and surface.
    """
    p = Path(path)
    raw = read_source_bytes(p, "file", "give the path of a Zemax .zmx file")
    source = str(p)
    f = parse_zmx_text(decode_text(raw), source)
    if len(f.surfaces) < 3:
        raise LensFileError(source, None, f"has {len(f.surfaces)} SURF blocks; a lens needs an "
                            "object surface, at least one lens surface and the image surface",
                            "is this a Zemax sequential .zmx file?")
    stops = [s for s in f.surfaces if s.stop]
    if not stops:
        raise LensFileError(source, None, "no surface is marked STOP (the aperture stop)",
                            "mark the aperture stop in the design program and export again")
    if len(stops) > 1 or stops[0] is f.surfaces[0] or stops[0] is f.surfaces[-1]:
        raise LensFileError(source, stops[-1].line, "the STOP must be one lens surface, not the "
                            "object or image surface, and only one")
    if f.configurations > 1:
        warnings.warn(LensImportWarning(
            f"{source}: a multi-configuration design ({f.configurations} configurations); "
            f"the surfaces as stored in the file are imported"), stacklevel=2)
    image = f.surfaces[-1]
    if image.curvature != 0:
        _warn(source, image, "the image surface is curved; the film is flat")
    rows, dummies = _lens_rows(f, glasses or {}, source)
    return build_lens(rows, source, _header(p, f, dummies))


def _header(p: Path, f: ZmxFile, dummies: list[int]) -> list[str]:
    obj = f.surfaces[0].thickness
    out = [f.name] if f.name else []
    out.append(f"source: Zemax sequential file {p.name}, surfaces 0..{len(f.surfaces) - 1}, "
               f"lens units {f.unit}" + (f" (x{f.unit_mm:g} to mm)" if f.unit_mm != 1 else ""))
    out.append("imported by povlens import-lens: object and image surfaces dropped"
               + (f"; dummy surfaces {', '.join(map(str, dummies))} (in air, no power) dropped"
                  if dummies else ""))
    if obj is not None and math.isfinite(obj):
        out.append(f"designed for an object {obj * f.unit_mm:g} mm in front of surface 1; "
                   f"povlens focuses at any distance")
    out.extend(f"note: {n}" for n in f.notes)
    return out


def read_zmx(path: str | os.PathLike, glasses: dict | None = None) -> LensPrescription:
    """A Zemax sequential ``.zmx`` file as a lens prescription.

    :func:`import_zmx` without the per-row notes; the parameters, result and errors
    are its.
    """
    return import_zmx(path, glasses).lens
