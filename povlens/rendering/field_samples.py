"""Lens samples of a field-mesh plan: the ray mesh POV-Ray renders, and the weights.

Sample k of a plan with ``field_mesh`` (:mod:`povlens.plan.field_grid`) is one pupil
point and one sub-pixel offset for every pixel (:mod:`povlens.pupil.field`).  Its
outputs, beside the image POV-Ray renders:

* ``samples/sample_KKKK.inc``: the mesh ``PovlensRays`` and the transform
  ``PovlensPlace`` (:mod:`povlens.pov.field_mesh`), deleted after the render;
* ``samples/sample_KKKK.mask.npy``: which pixels the lens passes
  (:func:`povlens.pupil.field_mask.pass_mask`), bits packed by row (``np.packbits``).
  The weights follow from it, the pupil point and the offset
  (:func:`povlens.pupil.field.field_weight`), so no weight image is written.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np

from povlens.errors import PovlensError
from povlens.plan.schema import Plan
from povlens.pov.field_mesh import (build_field_mesh, lens_ray_field, mesh2_text,
                                    placement_text, uv_model)
from povlens.pupil.field import concentric_disc_mm, field_sample_points, field_weight
from povlens.pupil.field_mask import pass_mask
from povlens.pupil.rays import ScenePlacement
from povlens.util.files import write_bytes, write_text

__all__ = ["placement_of", "field_sample", "mask_path", "write_field_sample",
           "field_sample_weight"]


def placement_of(plan: Plan) -> ScenePlacement:
    """The plan's camera frame in the world."""
    pl = plan.placement
    return ScenePlacement(np.array(pl.film_centre), np.array(pl.right), np.array(pl.up),
                          np.array(pl.forward), pl.mm_per_unit)


@functools.lru_cache(maxsize=8)
def _points(n: int, seed: int, jitter: bool) -> np.ndarray:
    return field_sample_points(n, seed, jitter)


def field_sample(plan: Plan, k: int) -> tuple[np.ndarray, tuple[float, float]]:
    """Sample k's pupil point (2,) mm on the table's plane and its sub-pixel offset.
    The same for every sample count (Sobol' prefixes), so a plan that adds samples
    keeps the first ones."""
    inp = plan.inputs
    n = 1 << max(0, int(inp.samples) - 1).bit_length()
    pts = _points(n, int(inp.seed), bool(inp.jitter))[k]
    pupil = concentric_disc_mm(pts[2:], plan.field_mesh.pupil_disc_radius_mm)
    return pupil, (float(pts[0]), float(pts[1]))


def mask_path(outdir: Path, k: int) -> Path:
    return Path(outdir) / "samples" / f"sample_{k:04d}.mask.npy"


def _pack(mask: np.ndarray) -> bytes:
    import io
    buf = io.BytesIO()
    np.save(buf, np.packbits(mask, axis=1), allow_pickle=False)
    return buf.getvalue()


def write_field_sample(plan: Plan, lens, table, outdir: Path, k: int, inc: Path) -> bool:
    """Trace sample k, write its pass mask and, if any pixel of its rows passes, its
    mesh to ``inc``.  Returns False when every ray of its rows is blocked."""
    film, fm = plan.film, plan.field_mesh
    fd = plan.focus.film_distance_mm
    pupil, jitter = field_sample(plan, k)
    model = uv_model(film.width_px, film.height_px, jitter, plan.povray.version)
    placement = placement_of(plan)
    pixel_angle = film.pixel_pitch_mm / abs(plan.lens.efl_mm)
    field = lens_ray_field(lens, fd, film, table.plane_z_mm, pupil)
    mesh = build_field_mesh(field, placement, model, fm.grid, fm.eps, pixel_angle)
    xs, ys, margins = mesh.node_margins()
    px, py = model.pixel_positions()
    passed, _ = pass_mask(xs, ys, margins, px, py, field)
    r0, r1 = plan.rows_of_sample(k)
    passed[:r0] = False
    passed[r1:] = False
    write_bytes(mask_path(outdir, k), _pack(passed))
    if not passed.any():
        return False
    part = inc.with_name(inc.name + ".part")
    with open(part, "w") as f:
        f.write(mesh2_text(mesh))
        f.write(placement_text(mesh))
    os.replace(part, inc)
    return True


def field_sample_weight(plan: Plan, table, outdir: Path, k: int) -> np.ndarray:
    """(H, W) float32 weights of rendered sample k (its mask, pupil point and offset)."""
    film = plan.film
    path = mask_path(outdir, k)
    try:
        packed = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as e:
        raise PovlensError(f"{path}: cannot read the sample's pass mask ({e})",
                           f"delete it and sample_{k:04d}.exr, then render again") from None
    passed = np.unpackbits(packed, axis=1, count=film.width_px).astype(bool)
    if passed.shape != (film.height_px, film.width_px):
        raise PovlensError(f"{path} holds a {passed.shape} mask, not the film's "
                           f"{(film.height_px, film.width_px)}",
                           f"delete it and sample_{k:04d}.exr, then render again")
    pupil, jitter = field_sample(plan, k)
    return field_weight(film, table.plane_z_mm, pupil, plan.field_mesh.pupil_disc_radius_mm,
                        jitter, passed)
