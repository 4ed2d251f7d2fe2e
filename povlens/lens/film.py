"""The film: its physical size, its pixels, and where each pixel lies.

Film coordinates are the x, y of the camera frame (:mod:`povlens.lens.frames`), in mm.
The lens inverts the image, so the pixel at image position (u right, v up) lies
at film point (-u, -v): pixel column i, row j (row 0 at the top) with sub-pixel
offset (jx, jy) in [0, 1) has

    u = (i + jx) / W * width_mm - width_mm / 2
    v = height_mm / 2 - (j + jy) / H * height_mm
    film point = (-u, -v).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from povlens.errors import ParameterError

__all__ = ["Film", "parse_film_size"]


@dataclasses.dataclass(frozen=True)
class Film:
    """A film of ``width_mm`` x ``height_mm`` sampled by ``width_px`` x ``height_px`` pixels."""

    width_mm: float
    height_mm: float
    width_px: int
    height_px: int

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
    def pixel_pitch_mm(self) -> float:
        """Horizontal pixel size in mm (pixels are square when the aspect matches)."""
        return self.width_mm / self.width_px

    def image_plane_mm(self, col, row, jitter_x=0.5, jitter_y=0.5):
        """Image-plane (u, v) in mm, u right and v up, of pixel positions."""
        u = (np.asarray(col) + jitter_x) / self.width_px * self.width_mm - 0.5 * self.width_mm
        v = 0.5 * self.height_mm - (np.asarray(row) + jitter_y) / self.height_px * self.height_mm
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
