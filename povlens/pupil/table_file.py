"""The pupil-table file: one ``.npz`` per table, written atomically.

It holds the table's arrays (knot radii, frames, vertex distances), the lens
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

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "write_table_file", "read_table_file"]

FORMAT_NAME = "povlens-pupil-table"
FORMAT_VERSION = 1
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
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise UsageError(f"{path}: no such pupil table") from None
    except IsADirectoryError:
        raise UsageError(f"{path}: is a directory, not a pupil table") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as e:
        raise PovlensError(f"{path}: not a povlens pupil table ({e})") from None
    try:
        bad = [k for k, a in arrays.items() if a.dtype.kind == "f" and not np.all(np.isfinite(a))]
        if bad:
            raise ValueError(f"NaN or infinite values in {', '.join(bad)}")
        meta = json.loads(str(arrays["metadata"]))
        if meta.get("format") != FORMAT_NAME or meta.get("version") != FORMAT_VERSION:
            raise ValueError("unknown format or version")
        lens = LensPrescription(arrays["lens_radius_mm"], arrays["lens_thickness_mm"],
                                arrays["lens_index_after"],
                                arrays["lens_aperture_diameter_mm"], arrays["lens_abbe_vd"],
                                source=meta["lens"]["source"],
                                asphere=arrays.get("lens_asphere"))
        if lens.sha256() != meta["lens"]["sha256"]:
            raise ValueError("the stored lens does not match its hash")
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


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
