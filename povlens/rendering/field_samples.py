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
from povlens.pupil.field_mask import field_transmission, pass_mask
from povlens.pupil.aperture_domain import iris_point_mm
from povlens.lens.aperture_shape import ApertureShape
from povlens.pupil.rays import ScenePlacement
from povlens.util.files import write_bytes, write_text

__all__ = ["placement_of", "field_sample", "sample_domain_radius_mm", "sample_lens", "mask_path",
           "write_field_sample",
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
    pupil, _ = _pupil_and_domain_radius(plan, pts[2:])
    return pupil, (float(pts[0]), float(pts[1]))


def _pupil_and_domain_radius(plan: Plan, u: np.ndarray) -> tuple[np.ndarray, float]:
    """The pupil point (2,) mm of u (2,) and the domain's radius there (mm; the density is
    1 / (pi r^2)): the disc, or with an iris its polygon (povlens.pupil.aperture_domain)."""
    fm = plan.field_mesh
    if fm.iris_domain_radius_mm is None:
        return concentric_disc_mm(u, fm.pupil_disc_radius_mm), fm.pupil_disc_radius_mm
    inp = plan.inputs
    shape = ApertureShape(blades=inp.aperture_blades, curvature=inp.blade_curvature or 0.0,
                          rotation_deg=inp.blade_rotation_deg or 0.0)
    return iris_point_mm(shape, bool(fm.iris_flip), fm.iris_domain_radius_mm,
                         fm.pupil_disc_radius_mm, concentric_disc_mm(u, 1.0))


def sample_domain_radius_mm(plan: Plan, k: int) -> float:
    """The pupil domain's radius (mm) at sample k's pupil point: the weight's pi r^2."""
    inp = plan.inputs
    n = 1 << max(0, int(inp.samples) - 1).bit_length()
    return _pupil_and_domain_radius(plan, _points(n, int(inp.seed), bool(inp.jitter))[k][2:])[1]


def sample_lens(plan: Plan, lens, k: int):
    """The lens sample k is traced with: ``lens`` itself, or with ``--dispersion`` the
    lens at sample k's wavelength (:mod:`povlens.rendering.spectral`)."""
    if not plan.inputs.dispersion:
        return lens
    from povlens.lens.dispersion import lens_at_wavelength
    from povlens.rendering.spectral import sample_wavelength_nm
    return lens_at_wavelength(lens, float(sample_wavelength_nm(k, plan.inputs.seed)[0]))


def mask_path(outdir: Path, k: int) -> Path:
    return Path(outdir) / "samples" / f"sample_{k:04d}.mask.npy"


def transmission_path(outdir: Path, k: int) -> Path:
    """Sample k's per-pixel transmission of a mask stop (float32 .npy; mask plans only)."""
    return Path(outdir) / "samples" / f"sample_{k:04d}.transmission.npy"


def _npy(a: np.ndarray) -> bytes:
    import io
    buf = io.BytesIO()
    np.save(buf, a, allow_pickle=False)
    return buf.getvalue()


def _pack(mask: np.ndarray) -> bytes:
    return _npy(np.packbits(mask, axis=1))


def write_field_sample(plan: Plan, lens, table, outdir: Path, k: int, inc: Path) -> bool:
    """Trace sample k, write its pass mask and, if any pixel of its rows passes, its
    mesh to ``inc``.  Returns False when every ray of its rows is blocked."""
    film, fm = plan.film, plan.field_mesh
    fd = plan.focus.film_distance_mm
    pupil, jitter = field_sample(plan, k)
    lens = sample_lens(plan, lens, k)
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
    if lens.aperture_shape is not None and lens.aperture_shape.mask is not None:
        # grey mask stop: each passing pixel's transmission, before the mask (done marker)
        t = field_transmission(lens, fd, film, table.plane_z_mm, pupil, px, py, passed)
        write_bytes(transmission_path(outdir, k), _npy(t))
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
    w = field_weight(film, table.plane_z_mm, pupil, sample_domain_radius_mm(plan, k),
                     jitter, passed)
    if plan.inputs.aperture_image:                        # grey mask: w times transmission
        tpath = transmission_path(outdir, k)
        try:
            t = np.load(tpath, allow_pickle=False)
        except (OSError, ValueError) as e:
            raise PovlensError(f"{tpath}: cannot read the sample's mask transmission ({e})",
                               f"delete sample_{k:04d}.mask.npy and sample_{k:04d}.exr, "
                               "then render again") from None
        w = w * t.astype(np.float32)
    return w
