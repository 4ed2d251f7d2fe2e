"""Shaped aperture stops: an iris of N blades, or a grey-level mask over the stop's disc.

Frames: the stop plane's local (x, y) in mm, the camera frame's x and y
(:mod:`povlens.lens.coordinates`) with the origin on the axis.  A highlight far behind the plane in focus shows the shape as
it is in these coordinates, image right = +x, image up = +y (the film inverts the blur spot
and the image inverts the film again).

Iris.  N >= 3 blades make a regular polygon *inscribed* in the stop's circle (corners on it),
so the stop's diameter, and with it the f-number, stays the largest opening.  At rotation 0
one corner points to +y; ``rotation_deg`` turns the polygon counter-clockwise (from +x toward
+y).  ``curvature`` blends each edge's radius toward the circle's, rho = (1 - k) rho_poly + k R:
0 straight blades, 1 the round stop.

Margin.  Like the tracer's r^2 - h^2 at every clear aperture, the shape's verdict comes as a
continuous signed margin in mm^2 (> 0 inside): R^2 (1 - g^2), with g = |p| / rho(theta) the
shape's gauge (g <= 1 inside); for the round stop it is exactly R^2 - |p|^2.  A mask adds
R^2 (t - T_MIN) with t the bilinear transmission, and the smaller margin decides.

Mask.  ``mask`` (H, W) in [0, 1] spans the stop's full diameter (the square [-R, R]^2, row 0 at
+y, column 0 at -x); outside it and outside the stop's circle nothing passes.  Transmission
below :data:`T_MIN` counts as opaque (its light is below 1e-6 of the open mask's).  Reading the
image file is the caller's (``povlens.util.images`` at the plan layer), not this module's.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math

import numpy as np

from povlens.errors import ParameterError

__all__ = ["ApertureShape", "T_MIN", "shape_margin_mm2", "shaped_lens", "area_fraction"]

#: Transmission at or below this counts as opaque (the margin's zero).
T_MIN = 1e-6


@dataclasses.dataclass(frozen=True, eq=False)
class ApertureShape:
    """The shape of the aperture stop.

    blades : number of iris blades (>= 3), or None for the round stop.
    curvature : 0 straight blade edges ... 1 round (ignored without blades).
    rotation_deg : counter-clockwise turn of the polygon, degrees (0: a corner at +y).
    mask : (H, W) float64 transmission in [0, 1] over the stop's disc, or None.
    mask_source : the mask's file name (for messages and plan.json).
    """

    blades: int | None = None
    curvature: float = 0.0
    rotation_deg: float = 0.0
    mask: np.ndarray | None = None
    mask_source: str = ""

    def __post_init__(self):
        if self.blades is not None:
            if int(self.blades) != self.blades or self.blades < 3:
                raise ParameterError("aperture_blades", self.blades,
                                     f"aperture_blades={self.blades}: an iris needs at least "
                                     "3 blades", "give an integer N >= 3")
            object.__setattr__(self, "blades", int(self.blades))
        k = float(self.curvature)
        if not (0.0 <= k <= 1.0):
            raise ParameterError("blade_curvature", self.curvature,
                                 f"blade_curvature={self.curvature}: must be between 0 "
                                 "(straight edges) and 1 (round)", "give a value in [0, 1]")
        if not math.isfinite(float(self.rotation_deg)):
            raise ParameterError("blade_rotation_deg", self.rotation_deg,
                                 f"blade_rotation_deg={self.rotation_deg}: not a finite angle",
                                 "give degrees, e.g. 15")
        object.__setattr__(self, "curvature", k)
        object.__setattr__(self, "rotation_deg", float(self.rotation_deg))
        if self.mask is not None:
            m = np.asarray(self.mask, dtype=np.float64)
            src = f"aperture_image={self.mask_source}" if self.mask_source else "the mask"
            if m.ndim != 2 or min(m.shape) < 2:
                raise ParameterError("aperture_image", self.mask_source,
                                     f"{src}: an aperture mask must be an image of at least "
                                     "2x2 pixels", "give a grey-level PNG")
            if not np.all(np.isfinite(m)):
                raise ParameterError("aperture_image", self.mask_source,
                                     f"{src}: the mask has non-finite values",
                                     "give a grey-level PNG with values 0..1")
            m = np.clip(m, 0.0, 1.0)
            if not np.any(m > T_MIN):
                raise ParameterError("aperture_image", self.mask_source,
                                     f"{src}: the aperture mask transmits no light "
                                     "(every pixel is black)",
                                     "white lets light through, black blocks it")
            m.setflags(write=False)
            object.__setattr__(self, "mask", m)

    @property
    def is_round(self) -> bool:
        """No blades (or round ones) and no mask: the plain circular stop."""
        return self.mask is None and (self.blades is None or self.curvature >= 1.0)

    def describe(self) -> dict:
        """JSON-able summary (plan.json, reports)."""
        d: dict = {}
        if self.blades is not None:
            d.update(blades=self.blades, curvature=self.curvature,
                     rotation_deg=self.rotation_deg)
        if self.mask is not None:
            d.update(mask=self.mask_source, mask_size_px=[int(self.mask.shape[1]),
                                                          int(self.mask.shape[0])])
        return d

    def digest(self) -> str:
        """Hash of the shape (blades, curvature, rotation and mask values)."""
        h = hashlib.sha256(repr((self.blades, self.curvature, self.rotation_deg)).encode())
        if self.mask is not None:
            h.update(np.asarray(self.mask.shape, "<i8").tobytes())
            h.update(np.ascontiguousarray(self.mask, "<f8").tobytes())
        return h.hexdigest()

    # ----- geometry ----------------------------------------------------------
    def boundary_radius_mm(self, theta, radius_mm: float) -> np.ndarray:
        """rho(theta): distance from the axis to the iris edge at polar angle theta
        (radians, any shape), for a stop of radius ``radius_mm``; R without blades."""
        theta = np.asarray(theta, dtype=np.float64)
        if self.blades is None:
            return np.full(theta.shape, float(radius_mm))
        n = self.blades
        sector = 2.0 * math.pi / n
        # Edge normals lie half a sector from the corners (first corner at +y, turned).
        normal0 = math.pi / 2 + math.radians(self.rotation_deg) + sector / 2
        phi = np.mod(theta - normal0 + sector / 2, sector) - sector / 2
        rho_poly = radius_mm * math.cos(math.pi / n) / np.cos(phi)
        return (1.0 - self.curvature) * rho_poly + self.curvature * radius_mm

    def transmission(self, x_mm, y_mm, radius_mm: float) -> np.ndarray:
        """t(x, y) in [0, 1]: the mask's bilinear transmission at stop points (mm, equal
        shapes) of a stop of radius ``radius_mm``; 1 without a mask (the iris and the
        circle are the margin's, not this)."""
        x = np.asarray(x_mm, dtype=np.float64)
        y = np.asarray(y_mm, dtype=np.float64)
        if self.mask is None:
            return np.ones(np.broadcast(x, y).shape)
        h, w = self.mask.shape
        with np.errstate(all="ignore"):
            # Pixel centres at -R + (j + 0.5) 2R / w (columns from -x), rows from +y.
            u = (x / radius_mm + 1.0) * 0.5 * w - 0.5
            v = (1.0 - y / radius_mm) * 0.5 * h - 0.5
        inside = np.isfinite(u) & np.isfinite(v) & (u > -0.5) & (u < w - 0.5) \
            & (v > -0.5) & (v < h - 0.5)
        u = np.clip(np.where(inside, u, 0.0), 0.0, w - 1.0)
        v = np.clip(np.where(inside, v, 0.0), 0.0, h - 1.0)
        j0 = np.minimum(np.floor(u).astype(np.int64), w - 2)
        i0 = np.minimum(np.floor(v).astype(np.int64), h - 2)
        fu, fv = u - j0, v - i0
        m = self.mask
        t = ((1 - fv) * ((1 - fu) * m[i0, j0] + fu * m[i0, j0 + 1])
             + fv * ((1 - fu) * m[i0 + 1, j0] + fu * m[i0 + 1, j0 + 1]))
        return np.where(inside, t, 0.0)

    def margin_mm2(self, x_mm, y_mm, radius_mm: float) -> np.ndarray:
        """The stop's signed margin (mm^2, > 0 inside; module docstring) at stop points,
        circle included: R^2 - |p|^2 for the round stop."""
        x = np.asarray(x_mm, dtype=np.float64)
        y = np.asarray(y_mm, dtype=np.float64)
        r2 = float(radius_mm) ** 2
        with np.errstate(all="ignore"):
            h2 = x * x + y * y
            if self.blades is None or self.curvature >= 1.0:
                m = r2 - h2
            else:
                rho = self.boundary_radius_mm(np.arctan2(y, x), radius_mm)
                m = r2 - h2 * (r2 / (rho * rho))
            if self.mask is not None:
                m = np.minimum(m, r2 * (self.transmission(x, y, radius_mm) - T_MIN))
        return np.where(np.isfinite(m), m, -np.inf)


def area_fraction(shape: ApertureShape, n: int = 512) -> float:
    """Open area of the shape over the stop circle's, transmission-weighted (a grid of
    n x n points over the disc: about 1e-3 accurate at n = 512)."""
    c = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    x, y = np.meshgrid(c, c)
    disc = x * x + y * y <= 1.0
    m = shape.margin_mm2(x, y, 1.0) > 0.0
    t = shape.transmission(x, y, 1.0)
    return float(np.sum(np.where(m & disc, t, 0.0)) / np.sum(disc))


def shape_margin_mm2(lens, row: int, x_mm, y_mm) -> np.ndarray:
    """Margin (mm^2) of hit points at ``row`` of ``lens``: the shape's at its shaped stop
    row, r^2 - h^2 elsewhere (the tracers' aperture test)."""
    shape = getattr(lens, "aperture_shape", None)
    r = float(lens.aperture_radius_mm[row])
    if shape is not None and row == lens.aperture_shape_row:
        return shape.margin_mm2(x_mm, y_mm, r)
    x = np.asarray(x_mm, dtype=np.float64)
    y = np.asarray(y_mm, dtype=np.float64)
    return r * r - (x * x + y * y)


def shaped_lens(lens, shape: ApertureShape | None):
    """The lens with ``shape`` at its aperture stop (``povlens.lens.paraxial.stop_index``),
    or without a shape for None or the plain round stop.  ``lens.sha256()`` is unchanged:
    it stays the file's hash."""
    from povlens.lens.paraxial import stop_index
    if shape is None or shape.is_round:
        return lens.replace(aperture_shape=None, aperture_shape_row=-1)
    return lens.replace(aperture_shape=shape, aperture_shape_row=int(stop_index(lens)))

