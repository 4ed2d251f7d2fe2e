"""The lenses that come with povlens: what they are, where they come from, and the
numbers a user picks a lens by (focal length, f-number, field of view).

The descriptions and origins are read from the summary table of the bundled
folder's ``SOURCES.md`` (one row per file: file, format, lens, origin), so the lens
files stay byte-for-byte the public copies they are.

The field of view is the *diagonal* one on the film, from the real chief ray: the
ray from the film corner (half the diagonal off axis) through the centre of the
aperture stop, the lens focused at infinity (film at the rear focal point), measured
in object space.  Distortion counts (a wide angle's 77.5 degrees where
``2 atan(diagonal / 2 EFL)`` gives 76.9).  A lens whose clear apertures block the
chief ray before the film corner (the fisheye: its image circle is smaller than the
film) gets the angle across its image circle and the circle's diameter.
"""

from __future__ import annotations

import dataclasses
import math
import re
import warnings
from pathlib import Path

import numpy as np

from povlens.lens.chief_ray import chief_rays, chief_rays_2d
from povlens.lens.film import DEFAULT_FILM_DIAGONAL_MM
from povlens.lens.paraxial import anamorphic_data, paraxial_data
from povlens.lens.prescription import LensPrescription, read_lens
from povlens.util.resources import LENS_DIR

__all__ = ["BundledLens", "bundled_lens_folder", "lens_sources", "bundled_lenses",
           "diagonal_field_of_view_deg"]

#: The film the field of view is given for: 35 mm diagonal (povlens's default film).

# A summary row of SOURCES.md: | `file.dat` | format | lens | origin |
_SUMMARY_ROW = re.compile(r"^\|\s*`(?P<file>[^`]+\.dat)`\s*\|(?P<format>[^|]*)\|"
                          r"(?P<lens>[^|]*)\|(?P<origin>.*)\|\s*$")


@dataclasses.dataclass(frozen=True)
class BundledLens:
    """A bundled lens and the numbers to choose it by.

    Attributes
    ----------
    name : str
        What to pass as LENS (the file name without ``.dat``).
    file : str
        The file in the bundled folder.
    efl_mm, f_number : float
        Paraxial focal length and f-number wide open.
    field_of_view_deg : float or None
        Diagonal field of view on a ``film_diagonal_mm`` film, by the real chief ray at
        infinity focus; when the film corner is outside the lens's image, the field
        of view across its image circle.
    image_circle_mm : float or None
        None when the image covers the film; else the image circle's diameter (the
        film corners are dark).
    film_diagonal_mm : float
        The film diagonal the field of view is for.
    description : str
        The lens as ``SOURCES.md`` describes it ("" if it has no row there).
    source : str
        Where the file comes from (repository, path, commit), from ``SOURCES.md``.
    """

    name: str
    file: str
    efl_mm: float
    f_number: float
    field_of_view_deg: float | None
    image_circle_mm: float | None
    film_diagonal_mm: float
    description: str
    source: str

    def to_dict(self) -> dict:
        """The fields as a JSON-ready dict."""
        return dataclasses.asdict(self)


def bundled_lens_folder() -> Path:
    """The folder of the bundled lenses (where ``read_lens`` finds ``dgauss.50mm``)."""
    return LENS_DIR


def _plain(markdown: str) -> str:
    """A table cell without Markdown emphasis and code marks."""
    return re.sub(r"\s+", " ", markdown.replace("`", "").replace("**", "")).strip()


def lens_sources(sources_md: str | Path) -> dict[str, tuple[str, str]]:
    """file name -> (description, origin) from the summary table of a ``SOURCES.md``.

    Parameters
    ----------
    sources_md : str or path
        The file.  A missing file gives an empty dict.

    Returns
    -------
    dict
        For each row ``| `file.dat` | format | lens | origin |``.
    """
    try:
        text = Path(sources_md).read_text(encoding="utf-8")
    except OSError:
        return {}
    out = {}
    for line in text.splitlines():
        m = _SUMMARY_ROW.match(line.strip())
        if m and m["file"] not in out:
            fmt = _plain(m["format"])
            lens = _plain(m["lens"])
            if "converted" in fmt.lower():
                lens += " (converted to pbrt)"
            elif fmt != "pbrt" and fmt.lower() not in lens.lower():
                lens += f" ({fmt})"
            out[m["file"]] = (lens, _plain(m["origin"]))
    return out


#: The image's proportions the field of view is given for (4:3, 640x480's); an
#: anamorphic lens's film takes them over its squeeze, as a desqueezed render's does.
IMAGE_ASPECT = 4.0 / 3.0


def _corner_direction(lens: LensPrescription) -> np.ndarray:
    """Unit film direction (x, y) of the film corner: along x for a rotationally
    symmetric lens (any azimuth is the same), else toward the corner of a film of
    proportions :data:`IMAGE_ASPECT` / squeeze (povlens's desqueezed film)."""
    if not lens.is_anamorphic:
        return np.array([1.0, 0.0])
    aspect = IMAGE_ASPECT / anamorphic_data(lens).squeeze
    return np.array([aspect, 1.0]) / math.hypot(aspect, 1.0)


def _chief_ray_angle_deg(lens: LensPrescription, film_distance_mm: float,
                         r_mm: float) -> float | None:
    """Object-space angle (degrees) of the chief ray from the film point ``r_mm`` from
    the centre toward the corner (:func:`_corner_direction`); None if it does not get
    through the lens's clear apertures."""
    if lens.is_anamorphic:
        rays, found = chief_rays_2d(lens, film_distance_mm,
                                    (r_mm * _corner_direction(lens))[None, :])
    else:
        rays, found = chief_rays(lens, film_distance_mm, np.array([r_mm]))
    d = rays.direction[0]
    if not (found[0] and rays.passed[0] and np.all(np.isfinite(d)) and d[2] > 0):
        return None
    return math.degrees(math.atan2(math.hypot(d[0], d[1]), d[2]))


def diagonal_field_of_view_deg(lens: LensPrescription,
                               film_diagonal_mm: float = DEFAULT_FILM_DIAGONAL_MM
                               ) -> tuple[float | None, float | None]:
    """Diagonal field of view (degrees) of ``lens`` at infinity focus, by the real chief ray.

    Parameters
    ----------
    lens : LensPrescription
        The lens, its stop as in the file.
    film_diagonal_mm : float
        The film's diagonal.

    Returns
    -------
    field_of_view_deg : float or None
        Twice the object-space angle of the chief ray from the film corner; when that
        ray does not get through (the corner is beyond the lens's image), the angle
        across the image circle instead.  None if no chief ray gets through at all.
    image_circle_mm : float or None
        None when the image covers the film corner; else the diameter of the image
        circle (twice the largest film radius whose chief ray gets through the clear
        apertures, to 0.01 %).

    An anamorphic lens's corner is that of a film of the diagonal and of proportions
    4:3 over its squeeze, the film a desqueezed 4:3 render uses (so the angle is the
    picture's diagonal), focused at its y meridian's paraxial focus.
    """
    p = paraxial_data(lens)
    half = 0.5 * film_diagonal_mm
    corner = _chief_ray_angle_deg(lens, p.bfl, half)
    if corner is not None:
        return 2.0 * corner, None
    lo, hi, angle = 0.0, half, None  # bisect for the edge of the image circle
    while hi - lo > 1e-4 * half:
        mid = 0.5 * (lo + hi)
        a = _chief_ray_angle_deg(lens, p.bfl, mid)
        if a is None:
            hi = mid
        else:
            lo, angle = mid, a
    return (None, None) if angle is None else (2.0 * angle, 2.0 * lo)


def bundled_lenses(film_diagonal_mm: float = DEFAULT_FILM_DIAGONAL_MM) -> list[BundledLens]:
    """Every bundled lens, by name, with its focal length, f-number, field of view and source.

    Parameters
    ----------
    film_diagonal_mm : float
        The film the field of view is computed for (default 35 mm).

    Returns
    -------
    list of BundledLens
        In file-name order (``dgauss.50mm.dat`` before ``dgauss.dat``, which
        ``SOURCES.md`` describes as "the same double Gauss, 100 mm scale").
    """
    folder = bundled_lens_folder()
    sources = lens_sources(folder / "SOURCES.md")
    out = []
    for path in sorted(folder.glob("*.dat")):
        with warnings.catch_warnings():  # clipped housings are the files' business here
            warnings.simplefilter("ignore")
            lens = read_lens(path)
            p = paraxial_data(lens)
            fov, circle = diagonal_field_of_view_deg(lens, film_diagonal_mm)
        description, origin = sources.get(path.name, ("", "not listed in SOURCES.md"))
        out.append(BundledLens(name=path.stem, file=path.name, efl_mm=p.efl,
                               f_number=p.f_number, field_of_view_deg=fov,
                               image_circle_mm=circle,
                               film_diagonal_mm=float(film_diagonal_mm),
                               description=description, source=origin))
    return out
