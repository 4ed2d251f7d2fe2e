"""The pupil-table file: one ``.npz`` per table, written atomically.

Two formats: ``povlens-pupil-table`` (the radial table, :mod:`povlens.pupil.table`) and
``povlens-pupil-grid`` (the table over the film's two coordinates of a lens without
rotational symmetry, :mod:`povlens.pupil.grid_table`).  Either holds the table's arrays
(knots, frames, vertex distances), the lens
prescription (so a table can be used without its lens file) and a JSON
metadata string (format and version, lens hash, stop, film distance, focus,
film, tolerance, plane, build statistics).  Reading checks the format, the
version, the lens against its hash and that every number is finite, so a damaged
file is refused (and a render folder's ``pupil.npz`` built again:
:func:`povlens.pupil.storage.load_if_current`).
"""

from __future__ import annotations

import io
import json
import zipfile
import zlib
from pathlib import Path

import numpy as np

from povlens.errors import PovlensError, UsageError, WriteError
from povlens.lens.prescription import LensPrescription
from povlens.util.files import write_bytes

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "GRID_FORMAT_NAME", "GRID_FORMAT_VERSION",
           "write_table_file", "read_table_file",
           "read_grid_table_file", "table_format"]

FORMAT_NAME = "povlens-pupil-table"
FORMAT_VERSION = 1
#: The grid table's format (:class:`povlens.pupil.grid_table.GridPupilTable`).
GRID_FORMAT_NAME = "povlens-pupil-grid"
GRID_FORMAT_VERSION = 1
#: Metadata entries the table is built from; any other entry is the caller's metadata.
_TABLE_KEYS = {"format", "version", "lens", "film_distance_mm", "plane", "plane_z_mm",
               "tolerance", "knots", "angles", "max_film_radius_mm",
               "vignetted_beyond_mm", "axial_irradiance_factor", "stats"}


def write_table_file(path, arrays: dict, lens: LensPrescription, metadata: dict) -> Path:
    """Write a table file atomically (a temporary name, renamed when complete).

    Parameters
    ----------
    path : the ``.npz`` file.
    arrays : the table's arrays by name (``film_radius_mm`` (K,), ``centre_x_mm``,
        ``scale_x_mm``, ``scale_y_mm`` (K,), ``rho`` (K, M + 1)).
    lens : the prescription the table was built for.
    metadata : JSON-able description (:meth:`PupilTable.describe`).

    Returns
    -------
    The path written.
    """
    path = Path(path)
    meta = json.dumps(metadata, allow_nan=False, default=_json_default)
    buf = io.BytesIO()
    if lens.asphere is not None:                       # even aspheres (lens/asphere.py)
        arrays = {**arrays, "lens_asphere": lens.asphere}
    if getattr(lens, "radius_x_mm", None) is not None:   # toric / cylindrical rows
        arrays = {**arrays, "lens_radius_x_mm": lens.radius_x_mm}
    np.savez(buf, **arrays,
             lens_radius_mm=lens.radius_mm, lens_thickness_mm=lens.thickness_mm,
             lens_index_after=lens.index_after,
             lens_aperture_diameter_mm=lens.aperture_diameter_mm, lens_abbe_vd=lens.abbe_vd,
             metadata=np.array(meta))
    try:
        write_bytes(path, buf.getvalue())
    except WriteError:
        raise                        # a full disk, a read-only folder: names it, exit 4
    except OSError as e:
        raise UsageError(f"{path}: cannot write there ({e.strerror})") from None
    return path


def _read_arrays(path) -> dict:
    """The arrays of a table file by name; UsageError / PovlensError as
    :func:`read_table_file` says."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise UsageError(f"{path}: no such pupil table") from None
    except IsADirectoryError:
        raise UsageError(f"{path}: is a directory, not a pupil table") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as e:
        raise PovlensError(f"{path}: not a povlens pupil table ({e})") from None


def _checked(arrays: dict, name: str, version: int) -> tuple[dict, LensPrescription]:
    """The metadata and the lens of a file's ``arrays`` when they are of format ``name``
    and ``version``, every number finite and the lens its hash; ValueError otherwise."""
    bad = [k for k, a in arrays.items() if a.dtype.kind == "f" and not np.all(np.isfinite(a))]
    if bad:
        raise ValueError(f"NaN or infinite values in {', '.join(bad)}")
    meta = json.loads(str(arrays["metadata"]))
    if meta.get("format") != name or meta.get("version") != version:
        raise ValueError("unknown format or version")
    extra = {}
    if "lens_radius_x_mm" in arrays:                  # toric / cylindrical rows
        extra["radius_x_mm"] = arrays["lens_radius_x_mm"]
    lens = LensPrescription(arrays["lens_radius_mm"], arrays["lens_thickness_mm"],
                            arrays["lens_index_after"], arrays["lens_aperture_diameter_mm"],
                            arrays["lens_abbe_vd"], source=meta["lens"]["source"],
                            asphere=arrays.get("lens_asphere"), **extra)
    if lens.sha256() != meta["lens"]["sha256"]:
        raise ValueError("the stored lens does not match its hash")
    return meta, lens


def table_format(path) -> str | None:
    """The ``format`` a table file names (``povlens-pupil-table`` or
    ``povlens-pupil-grid``), or None when the file cannot be read as a table."""
    try:
        arrays = _read_arrays(path)
        return json.loads(str(arrays["metadata"])).get("format")
    except (PovlensError, KeyError, ValueError, TypeError, AttributeError):
        return None


def read_table_file(path, make):
    """Read a file written by :func:`write_table_file` and build the table from it.

    Parameters
    ----------
    path : the ``.npz`` file.
    make : called with the table's fields as keywords (those of
        :class:`povlens.pupil.table.PupilTable`); a KeyError, ValueError or
        TypeError it raises also means the file is not a table.

    Returns
    -------
    What ``make`` returns.

    Raises
    ------
    UsageError
        If the file is missing or a directory.
    PovlensError
        If it is not a povlens pupil table of this version, or is damaged (truncated,
        or a NaN or infinite value in an array).
    """
    arrays = _read_arrays(path)
    try:
        meta, lens = _checked(arrays, FORMAT_NAME, FORMAT_VERSION)
        return make(
            lens=lens, film_distance_mm=meta["film_distance_mm"],
            film_half_diagonal_mm=meta["film"]["half_diagonal_mm"],
            plane_z_mm=meta["plane_z_mm"], plane=meta["plane"],
            film_radius_mm=arrays["film_radius_mm"], centre_x_mm=arrays["centre_x_mm"],
            scale_x_mm=arrays["scale_x_mm"], scale_y_mm=arrays["scale_y_mm"],
            rho=arrays["rho"], max_film_radius_mm=meta["max_film_radius_mm"],
            vignetted_beyond_mm=meta["vignetted_beyond_mm"], tolerance=meta["tolerance"],
            axial_irradiance_factor=meta["axial_irradiance_factor"],
            stats=meta.get("stats"),
            metadata={k: v for k, v in meta.items() if k not in _TABLE_KEYS})
    except (KeyError, ValueError, TypeError, AttributeError) as e:
        raise PovlensError(f"{path}: not a povlens pupil table ({e})") from None


#: Metadata entries a grid table is built from (:mod:`povlens.pupil.grid_table`).
_GRID_KEYS = {"format", "version", "lens", "film_distance_mm", "plane", "plane_z_mm",
              "tolerance", "grid", "angles", "dark_cells", "axial_irradiance_factor", "stats"}


def read_grid_table_file(path, make):
    """Read a grid table (:class:`povlens.pupil.grid_table.GridPupilTable`, format
    ``povlens-pupil-grid``) written by :func:`write_table_file`; ``make`` is called with
    its fields as keywords.  Errors as :func:`read_table_file`."""
    arrays = _read_arrays(path)
    try:
        meta, lens = _checked(arrays, GRID_FORMAT_NAME, GRID_FORMAT_VERSION)
        return make(
            lens=lens, film_distance_mm=meta["film_distance_mm"],
            film_extent_mm=tuple(meta["film"]["extent_mm"]), plane_z_mm=meta["plane_z_mm"],
            plane=meta["plane"], knots_x_mm=arrays["knots_x_mm"],
            knots_y_mm=arrays["knots_y_mm"], centre_mm=arrays["centre_mm"],
            scale_mm=arrays["scale_mm"], rho=arrays["rho"], cell_dark=arrays["cell_dark"],
            tolerance=meta["tolerance"],
            axial_irradiance_factor=meta["axial_irradiance_factor"], stats=meta.get("stats"),
            metadata={k: v for k, v in meta.items() if k not in _GRID_KEYS})
    except (KeyError, ValueError, TypeError, AttributeError) as e:
        raise PovlensError(f"{path}: not a povlens pupil table ({e})") from None


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
