"""The film: its physical size, its pixels, and where each pixel lies.

Film coordinates are the x, y of the camera frame (:mod:`povlens.lens.coordinates`), in mm.
The lens inverts the image, so the pixel at image position (u right, v up) lies
at film point (-u, -v): pixel column i, row j (row 0 at the top) with sub-pixel
offset (jx, jy) in [0, 1) has

    u = (i + jx) / W * width_mm - width_mm / 2 + shift_x_mm
    v = height_mm / 2 - (j + jy) / H * height_mm + shift_y_mm
    film point = (-u, -v).

Lens shift (``shift_x_mm``, ``shift_y_mm``, 0 by default) moves the frame's centre to
(shift_x_mm, shift_y_mm) on the image plane, off the lens axis: +y shifts the *image* up
(more of the scene above the axis in the picture, a view camera's rising front; the
film itself moves down, to film point (-shift_x_mm, -shift_y_mm)), +x shifts it right.
Verticals stay vertical because the camera does not tilt.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from povlens.errors import ParameterError

__all__ = ["Film", "parse_film_size", "parse_shift", "DEFAULT_FILM_DIAGONAL_MM"]

#: The film's diagonal when none is given: 35 mm (a 28 x 21 mm film at 4:3; pbrt's
#: default ``diagonal``), mm.
DEFAULT_FILM_DIAGONAL_MM = 35.0


@dataclasses.dataclass(frozen=True)
class Film:
    """A film of ``width_mm`` x ``height_mm`` sampled by ``width_px`` x ``height_px`` pixels,
    its centre shifted by (``shift_x_mm``, ``shift_y_mm``) on the image plane (module doc)."""

    width_mm: float
    height_mm: float
    width_px: int
    height_px: int
    shift_x_mm: float = 0.0
    shift_y_mm: float = 0.0

    @classmethod
    def from_diagonal(cls, diagonal_mm: float, width_px: int, height_px: int) -> "Film":
        """pbrt's rule: the film's aspect ratio is the image's (pbrt-v4's film ``diagonal``)."""
        if not (diagonal_mm > 0):
            raise ParameterError("diagonal_mm", diagonal_mm,
                                 f"diagonal_mm={diagonal_mm}: must be positive")
        if width_px < 1 or height_px < 1:
            bad, value = ("width_px", width_px) if width_px < 1 else ("height_px", height_px)
            raise ParameterError(bad, value, f"width_px={width_px}, height_px={height_px}: "
                                             f"must be at least 1")
        a = height_px / width_px
        w = math.sqrt(diagonal_mm ** 2 / (1.0 + a * a))
        return cls(w, a * w, int(width_px), int(height_px))

    @property
    def half_diagonal_mm(self) -> float:
        return 0.5 * math.hypot(self.width_mm, self.height_mm)

    @property
    def shift_mm(self) -> tuple[float, float]:
        """(x, y) shift of the frame's centre on the image plane, mm (module doc)."""
        return float(self.shift_x_mm), float(self.shift_y_mm)

    @property
    def shifted(self) -> bool:
        return self.shift_x_mm != 0.0 or self.shift_y_mm != 0.0

    @property
    def max_field_radius_mm(self) -> float:
        """Largest distance from the lens axis a film point reaches, mm: the frame's
        farthest corner (the half-diagonal when not shifted).  What the exit-pupil
        table and the relative illumination must cover."""
        return math.hypot(0.5 * self.width_mm + abs(self.shift_x_mm),
                          0.5 * self.height_mm + abs(self.shift_y_mm))

    @property
    def min_field_radius_mm(self) -> float:
        """Smallest distance from the lens axis a point of the frame reaches, mm (0
        unless a shift takes the whole frame off the axis)."""
        return math.hypot(max(0.0, abs(self.shift_x_mm) - 0.5 * self.width_mm),
                          max(0.0, abs(self.shift_y_mm) - 0.5 * self.height_mm))

    def resized(self, width_mm: float, height_mm: float, width_px: int,
                height_px: int) -> "Film":
        """A film of another size and pixel count with the same shift."""
        return Film(float(width_mm), float(height_mm), int(width_px), int(height_px),
                    self.shift_x_mm, self.shift_y_mm)

    @property
    def pixel_pitch_mm(self) -> float:
        """Horizontal pixel size in mm (pixels are square when the aspect matches)."""
        return self.width_mm / self.width_px

    def image_plane_mm(self, col, row, jitter_x=0.5, jitter_y=0.5):
        """Image-plane (u, v) in mm, u right and v up, of pixel positions (shift included)."""
        u = ((np.asarray(col) + jitter_x) / self.width_px * self.width_mm - 0.5 * self.width_mm
             + self.shift_x_mm)
        v = (0.5 * self.height_mm - (np.asarray(row) + jitter_y) / self.height_px * self.height_mm
             + self.shift_y_mm)
        return u, v

    def film_points_mm(self, jitter: np.ndarray | None = None) -> np.ndarray:
        """Film points of every pixel, shape (H, W, 2), mm.

        jitter : (H, W, 2) sub-pixel offsets in [0, 1) (x right, y down); None = centres.
        """
        rows, cols = np.mgrid[0:self.height_px, 0:self.width_px].astype(np.float64)
        if jitter is None:
            jx = jy = 0.5
        else:
            jx, jy = jitter[..., 0], jitter[..., 1]
        u, v = self.image_plane_mm(cols, rows, jx, jy)
        return np.stack([-u, -v], axis=-1)


def parse_film_size(text: str) -> tuple[float, float]:
    """'W,H' in mm -> (W, H) (``film_size_mm``); a ParameterError otherwise."""
    try:
        w, h = (float(t) for t in text.split(","))
    except ValueError:
        raise ParameterError("film_size_mm", text, f"film_size_mm={text!r}: expected W,H in mm, "
                                                   f"e.g. 36,24") from None
    if not (w > 0 and h > 0 and math.isfinite(w) and math.isfinite(h)):
        raise ParameterError("film_size_mm", text,
                             f"film_size_mm={text!r}: width and height must be positive")
    return w, h


def parse_shift(text) -> tuple[float, float]:
    """'X,Y' in mm (or a pair of numbers) -> (X, Y) (``shift_mm``); a ParameterError
    otherwise.  +Y shifts the image up, +X right (module doc)."""
    try:
        parts = text.split(",") if isinstance(text, str) else list(text)
        x, y = (float(t) for t in parts)
    except (ValueError, TypeError):
        raise ParameterError("shift_mm", text, f"shift_mm={text!r}: expected X,Y in mm, "
                                               f"e.g. 0,6 (rising front: the image 6 mm up)"
                             ) from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ParameterError("shift_mm", text, f"shift_mm={text!r}: must be finite numbers of mm")
    return x, y
