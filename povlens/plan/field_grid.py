"""Choosing and certifying the field ray meshes of a mesh plan.

The interpolation error of a field mesh (:mod:`povlens.pov.field_mesh`) is second
order in the face size, so from an error e0 measured at a trial grid of width g0 the
width for a target e is about g0 sqrt(e0 / e).  Steps:

1. **Trial.**  Measure the largest ray error over the certification's 17 pupil points
   (the centre, 8 at half the disc radius, 8 at 0.99 of it) at a trial grid of width
   g0 with eps = 0.01 (tangent-plane interpolation, rectilinear lenses), on a regular
   subset of :data:`CHECK_PIXELS` pixels that includes the frame's edges, with a
   sub-pixel offset off the pixel centre.  Fisheyes (:data:`WIDE_DEG`) start with
   eps = 1 (POV-Ray's plain normalised lerp) instead; where the error is far above
   :data:`TARGET_PX`, the other encoding is measured too and the smaller kept.
2. **Grid.**  Scale the width to :data:`TARGET_PX` by the square-root rule, finer, or
   coarser by :data:`COARSER` at least (fewer faces make every pass cheaper:
   :func:`interleave_for`).
3. **Certify.**  Measure the grid's error as in step 1; while it exceeds
   :data:`LIMIT_PX` (the issue's 0.05 px), refine and measure again.

The error is the angle between the ray POV-Ray traces (:func:`povlens.pov.field_emulation.emulate`)
and the exact one, times the focal length over the pixel pitch, wherever the lens
passes light.
"""

from __future__ import annotations

import math

import numpy as np

from povlens.plan.schema import FieldMeshSettings
from povlens.pov.field_emulation import ray_error_px
from povlens.pov.field_mesh import build_field_mesh, uv_model
from povlens.pupil.field import PupilMap, concentric_disc_mm, trace_field
from povlens.pupil.grid_field_domain import bounding_disc_for, field_domain_for

__all__ = ["choose_field_mesh", "certification_pupil_points", "pixel_subset", "interleave_for",
           "TARGET_PX", "LIMIT_PX", "EPS_CHOICES", "PASS_FACE_BUDGET", "MAX_INTERLEAVE"]

#: The ray error the grid is sized for, and the most a certified plan may keep.
TARGET_PX = 0.035
LIMIT_PX = 0.05
#: Direction encodings (module docstring, step 1): the first for most lenses, the
#: second first for lenses whose paraxial half-diagonal field exceeds WIDE_DEG; the
#: other one is measured too when the first misses the target by more than
#: OTHER_ENCODING_ABOVE times (fisheye.10mm at 640x480, 24x18 faces: eps = 0.01 keeps
#: 75 px, eps = 1 0.26 px; tessar.50mm: 0.021 px with eps = 0.01).
EPS_CHOICES = (0.01, 1.0)
WIDE_DEG = 55.0
OTHER_ENCODING_ABOVE = 10.0
#: The certification's sub-pixel offset (not a pixel centre).
CHECK_JITTER = (0.37, 0.61)
#: Pixels compared per pupil point (a regular subset with the edges).
CHECK_PIXELS = 10000
MAX_GRID_WIDTH = 400


def certification_pupil_points(radius_mm: float = 1.0) -> np.ndarray:
    """(17, 2) canonical points (of the disc of ``radius_mm``): the centre, 8 at half the
    radius, 8 at 0.99 of it."""
    a = np.arange(8) * math.pi / 4 + math.pi / 8
    ring = np.stack([np.cos(a), np.sin(a)], 1)
    return np.vstack([[0.0, 0.0], 0.5 * radius_mm * ring, 0.99 * radius_mm * ring])


def pixel_subset(width: int, height: int, n: int = CHECK_PIXELS) -> tuple[np.ndarray, np.ndarray]:
    """Row and column indices of at most about ``n`` pixels (and more than n / 4) on a
    regular lattice that includes the first and last rows and columns (every pixel
    when n >= W H)."""
    step = max(1, int(math.ceil(math.sqrt(width * height / n))))
    cols = np.union1d(np.arange(0, width, step), [width - 1])
    rows = np.union1d(np.arange(0, height, step), [height - 1])
    R, C = np.meshgrid(rows, cols, indexing="ij")
    return R.ravel(), C.ravel()


def _grid_limit(width: int) -> int:
    """The widest grid tried: :data:`MAX_GRID_WIDTH`, and faces at least 4 pixels wide
    (finer, a per-pixel mesh costs little more)."""
    return max(4, min(MAX_GRID_WIDTH, width // 4))


def _grid_for_width(gx: int, width: int, height: int) -> tuple[int, int]:
    gx = int(min(max(gx, 4), _grid_limit(width)))
    return gx, max(2, int(math.ceil(gx * height / width)))


def _max_error(ctx, grid, eps, points, rows, cols, exact_cache) -> tuple[float, float]:
    lens, fd, film, plane_z, placement, pa, model, domain = ctx
    px, py = model.pixel_positions()
    worst, worst_origin = 0.0, 0.0
    for q in points:
        pupil = PupilMap(domain, (float(q[0]), float(q[1])))

        def field(x, y, pupil=pupil):
            return trace_field(lens, fd, film, plane_z, pupil, x, y)
        key = (float(q[0]), float(q[1]))
        if key not in exact_cache:      # the exact rays do not depend on the grid
            exact_cache[key] = field(px[cols], py[rows])
        mesh = build_field_mesh(field, placement, model, grid, eps, pa)
        e = ray_error_px(mesh, model, field, placement, pa, rows, cols, exact=exact_cache[key])
        worst, worst_origin = max(worst, e["direction_px"]), max(worst_origin, e["origin_mm"])
    return worst, worst_origin


#: A certified grid is coarsened (and measured again) only to this share of its width
#: or less: a face column or two fewer does not pay for another measurement.
COARSER = 0.9
#: Faces a pass may hold in all (m^2 tiles of the grid's): POV-Ray 3.7 finds a pixel's
#: face by testing, in order, the faces that share its cell of a fixed 10 x 10 UV grid,
#: so a pass costs more with more faces (docs/decisions/exact-lens-distribution3.md).
PASS_FACE_BUDGET = 6000
#: Pixels a tile keeps at least: each tile costs povlens a mesh of its own (5-15 ms),
#: which a small tile's share of POV-Ray's work would not pay for.
MIN_TILE_PIXELS = 2048
#: The largest interleave tried.
MAX_INTERLEAVE = 4


def interleave_for(grid: tuple[int, int], width: int, height: int) -> int:
    """m: the largest m <= :data:`MAX_INTERLEAVE` whose m^2 tiles of ``grid`` (2 gx gy
    faces each) stay within :data:`PASS_FACE_BUDGET` faces, and whose tiles keep
    :data:`MIN_TILE_PIXELS` pixels.  ``POVLENS_INTERLEAVE`` overrides it (measurements)."""
    import os
    forced = os.environ.get("POVLENS_INTERLEAVE")
    if forced:
        return max(1, int(forced))
    faces = 2 * int(grid[0]) * int(grid[1])
    m = 1
    while (m < MAX_INTERLEAVE and (m + 1) ** 2 * faces <= PASS_FACE_BUDGET
           and width * height >= MIN_TILE_PIXELS * (m + 1) ** 2):
        m += 1
    return m


def choose_field_mesh(lens, film_distance_mm: float, film, table, placement, efl_mm: float,
                      povray_version: str) -> tuple[FieldMeshSettings | None, str]:
    """The grid and encoding of a plan's field meshes, certified (module docstring).

    Parameters
    ----------
    lens, film_distance_mm, film : the stopped-down lens, its film distance (mm) and
        the film.
    table : the plan's :class:`povlens.pupil.table.PupilTable` (or
        :class:`povlens.pupil.grid_table.GridPupilTable` of an anamorphic lens).
    placement : :class:`povlens.pupil.rays.ScenePlacement`.
    efl_mm : the focal length (the pixel angle is pitch / efl).
    povray_version : POV-Ray's version (its sampling model).

    Returns
    -------
    (FieldMeshSettings or None, str)
        The settings, or None with the reason when no grid up to :func:`_grid_limit`
        faces across meets :data:`LIMIT_PX` (the lens's ray field is not smooth
        enough: the plan then renders per-pixel meshes).
    """
    W, H = film.width_px, film.height_px
    if not str(povray_version).startswith("3.7.0"):
        return None, (f"POV-Ray {povray_version}'s mesh-camera sampling was not measured "
                      f"(only 3.7.0.x's), so lens samples are rendered with a face per pixel")
    model = uv_model(W, H, CHECK_JITTER, povray_version)
    radius = bounding_disc_for(table)          # radial table, or the grid of an anamorphic lens
    domain = field_domain_for(table)
    pa = film.pixel_pitch_mm / abs(efl_mm)
    ctx = (lens, film_distance_mm, film, table.plane_z_mm, placement, pa, model, domain)
    rows, cols = pixel_subset(W, H)
    points = certification_pupil_points()
    g0 = _grid_for_width(int(math.ceil(24 * math.sqrt(W / 640.0))), W, H)
    cache: dict = {}
    measured = {}                       # (grid, eps) -> (error px, origin error mm)
    wide = math.degrees(math.atan(film.max_field_radius_mm / abs(efl_mm))) > WIDE_DEG
    for eps in (EPS_CHOICES[::-1] if wide else EPS_CHOICES):
        measured[g0, eps] = _max_error(ctx, g0, eps, points, rows, cols, cache)
        if measured[g0, eps][0] <= OTHER_ENCODING_ABOVE * TARGET_PX:
            break
    (grid, eps), (err, origin) = min(measured.items(), key=lambda item: item[1][0])
    for _ in range(5):
        # the square-root rule from the last measurement, with a 5 % margin
        nxt = _grid_for_width(int(math.ceil(grid[0] * math.sqrt(err / TARGET_PX) * 1.05)), W, H)
        certified = err <= LIMIT_PX
        if (nxt[0] > COARSER * grid[0]) if certified else (nxt[0] <= grid[0]):
            break       # certified and not much coarser asked, or no finer allowed
        e2 = _max_error(ctx, nxt, eps, points, rows, cols, cache)
        if certified and e2[0] > LIMIT_PX:
            break                   # coarser no longer certifies: keep the last
        grid, (err, origin) = nxt, e2
    if err > LIMIT_PX:
        return None, (f"interpolated ray meshes of this lens keep a ray error of {err:.3g} px "
                      f"at {grid[0]}x{grid[1]} faces (limit {LIMIT_PX} px), so its lens samples "
                      f"are rendered with a face per pixel (exact, slower)")
    return FieldMeshSettings(grid=grid, eps=float(eps), pupil_disc_radius_mm=float(radius),
                             max_ray_error_px=float(err), max_origin_error_mm=float(origin),
                             pupil_points=len(points), pixels_checked=int(len(rows)),
                             limit_px=LIMIT_PX, domain=domain.to_dict(),
                             interleave=interleave_for(grid, W, H)), ""
