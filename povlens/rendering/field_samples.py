"""Lens samples of a field-mesh plan: the ray mesh POV-Ray renders, and the weights.

Sample k of a plan with ``field_mesh`` (:mod:`povlens.plan.field_grid`) is one pass:
m x m tiles (m = ``field_mesh.interleave``), tile c holding every m-th pixel from
(ox, oy) with its own canonical lens sample (a point of the unit disc, mapped per film
point onto that point's pupil ellipse, and a sub-pixel offset: :mod:`povlens.pupil.field`).
Its outputs, beside the image POV-Ray renders (the tiles side by side;
:func:`povlens.pov.field_mesh.deinterleave` puts each pixel in its place):

* ``samples/sample_KKKK.inc``: the mesh ``PovlensRays`` (every tile's) and the transform
  ``PovlensPlace`` (:mod:`povlens.pov.field_mesh`), deleted after the render;
* ``samples/sample_KKKK.mask.npy``: which pixels the lens passes
  (:func:`povlens.pupil.field_mask.pass_mask`), bits packed by row (``np.packbits``).
  The weights follow from it and the tiles' samples
  (:func:`povlens.pupil.field.field_weight`), so no weight image is written.
"""

from __future__ import annotations

import dataclasses
import functools
import os
from pathlib import Path

import numpy as np

from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Plan
from povlens.pov.field_mesh import (build_field_meshes, combine_meshes, deinterleave,
                                    mesh2_text, pass_models, pass_rows, placement_text, seen_from)
from povlens.pov.mesh import eye_text
from povlens.pupil.field import (PupilMap, concentric_disc_mm, field_sample_points, field_weight,
                                 tile_points, trace_field)
from povlens.pupil.field_domain import FieldDomain, disc_domain
from povlens.pupil.grid_field_domain import domain_from_dict
from povlens.pupil.field_mask import field_transmission, pass_masks
from povlens.pupil.rays import ScenePlacement
from povlens.rendering.vignetting import mesh_illumination_map

__all__ = ["placement_of", "FieldTile", "field_tiles", "field_domain_of", "sample_lens",
           "write_field_sample", "write_field_stack", "stack_origin_world",
           "field_sample_weight", "image_layout",
           "illumination_map", "render_rows"]


def placement_of(plan: Plan) -> ScenePlacement:
    """The plan's camera frame in the world."""
    pl = plan.placement
    return ScenePlacement(np.array(pl.film_centre), np.array(pl.right), np.array(pl.up),
                          np.array(pl.forward), pl.mm_per_unit)


@functools.lru_cache(maxsize=8)
def _points(n: int, seed: int, jitter: bool) -> np.ndarray:
    return field_sample_points(n, seed, jitter)


def field_domain_of(plan: Plan) -> FieldDomain:
    """The plan's pupil domain (the bounding disc for plans made before domains; the
    ellipses over x and y of an anamorphic lens, :mod:`povlens.pupil.grid_field_domain`)."""
    fm = plan.field_mesh
    if fm.domain is None:
        return disc_domain(fm.pupil_disc_radius_mm, plan.film.max_field_radius_mm)
    return domain_from_dict(fm.domain)


@dataclasses.dataclass(frozen=True)
class FieldTile:
    """One tile of a field pass: its UV model (:class:`povlens.pov.field_mesh.UVModel`:
    which pixels, where POV-Ray samples them, the sub-pixel offset) and its pupil map."""

    model: object
    pupil: PupilMap


def field_tiles(plan: Plan, k: int, band: int = 0, bands: int = 1) -> list[FieldTile]:
    """The tiles of pass k.  The same for every sample count (Sobol' prefixes), so a
    plan that adds samples keeps the first ones.  ``band`` of ``bands``: where the pass
    is rendered in a stacked render (:func:`povlens.pov.field_mesh.pass_models`)."""
    inp, fm, film = plan.inputs, plan.field_mesh, plan.film
    n = 1 << max(0, int(inp.samples) - 1).bit_length()
    pts = tile_points(_points(n, int(inp.seed), bool(inp.jitter))[k], fm.interleave,
                      int(inp.seed))
    if not inp.jitter:
        pts[:, :2] = 0.5
    models = pass_models(film.width_px, film.height_px, fm.interleave, pts[:, :2],
                         plan.povray.version, band, bands)
    domain = field_domain_of(plan)
    return [FieldTile(m, PupilMap(domain, tuple(concentric_disc_mm(p[2:], 1.0))))
            for m, p in zip(models, pts)]


def image_layout(plan: Plan):
    """What puts the pixels of a sample's render (after its cut row and column) in
    their places: :func:`povlens.pov.field_mesh.deinterleave` for an interleaved field
    pass, else None."""
    fm, film = plan.field_mesh, plan.film
    if fm is None or fm.interleave == 1:
        return None
    models = pass_models(film.width_px, film.height_px, fm.interleave,
                         np.full((fm.interleave ** 2, 2), 0.5), plan.povray.version)
    return lambda image: deinterleave(image, models)


def render_rows(plan: Plan, k: int) -> tuple[int, int]:
    """The rows [R0, R1) of sample k's render (after the cut row) that hold its film rows:
    the film rows themselves, or in an interleaved field pass the tiles' rows holding them
    (:func:`povlens.pov.field_mesh.pass_rows`)."""
    fm = plan.field_mesh
    rows = plan.rows_of_sample(k)
    return rows if fm is None or fm.interleave == 1 else pass_rows(rows, fm.interleave)


def illumination_map(outdir: Path, plan: Plan, table) -> np.ndarray | None:
    """(H, W) the lens's exact relative illumination a field-mesh composite is scaled by
    (:func:`povlens.rendering.composite.measurement_image`, a ratio estimator), or None
    where the composite keeps the measurement's own estimate: per-pixel meshes (their
    samples follow each pixel's region, so their weights have no steps) and grey
    aperture masks (whose transmission the map does not hold)."""
    if plan.field_mesh is None or plan.inputs.aperture_image:
        return None
    return mesh_illumination_map(outdir, plan, table)


def sample_lens(plan: Plan, lens, k: int):
    """The lens sample k is traced with: ``lens`` itself, or with ``--dispersion`` the
    lens at sample k's wavelength (:mod:`povlens.rendering.spectral`)."""
    if not plan.inputs.dispersion:
        return lens
    from povlens.lens.dispersion import lens_at_wavelength
    from povlens.rendering.spectral import sample_wavelength_nm
    return lens_at_wavelength(lens, float(sample_wavelength_nm(k, plan.inputs.seed)[0]))


def _field_pass(plan: Plan, lens, table, outdir: Path, k: int, band: int, bands: int,
                origin_world):
    """Trace pass k as band ``band`` of ``bands``, write its pass mask (and grey-mask
    transmission); returns its :class:`~povlens.pov.field_mesh.PassMesh`, or None when
    every ray of its rows is blocked."""
    film, fm = plan.film, plan.field_mesh
    fd = plan.focus.film_distance_mm
    lens = sample_lens(plan, lens, k)
    placement = placement_of(plan)
    pixel_angle = film.pixel_pitch_mm / abs(plan.lens.efl_mm)
    tiles = field_tiles(plan, k, band, bands)
    domain = field_domain_of(plan)
    qs = np.array([t.pupil.q for t in tiles])

    def field(x, y, tile):          # the rays of image positions of the tiles ``tile``
        q = qs[tile]
        return trace_field(lens, fd, film, table.plane_z_mm,
                           lambda f: domain.points_mm(f, q), x, y)
    models = [t.model for t in tiles]
    meshes = build_field_meshes(field, placement, models, fm.grid, fm.eps, pixel_angle,
                                origin_world)
    masks = pass_masks([m.node_margins() + t.model.pixel_positions()
                        for m, t in zip(meshes, tiles)], field)
    passed = np.zeros((film.height_px, film.width_px), bool)
    masked = lens.aperture_shape is not None and lens.aperture_shape.mask is not None
    transmission = np.zeros(passed.shape, np.float32) if masked else None
    for tile, (ok, _) in zip(tiles, masks):
        rows, cols = tile.model.rows(), tile.model.columns()
        passed[np.ix_(rows, cols)] = ok
        if masked:      # grey mask stop: each passing pixel's transmission
            px, py = tile.model.pixel_positions()
            transmission[np.ix_(rows, cols)] = field_transmission(
                lens, fd, film, table.plane_z_mm, tile.pupil, px, py, ok)
    r0, r1 = plan.rows_of_sample(k)
    passed[:r0] = False
    passed[r1:] = False
    folder = RenderFolder(outdir)
    if masked:          # before the mask (its done marker)
        folder.write_transmission(k, transmission)
    folder.write_pass_mask(k, passed)
    return combine_meshes(meshes) if passed.any() else None


def stack_origin_world(plan: Plan, lens, table) -> np.ndarray:
    """(3,) the world point every field pass's mesh of the plan is stored relative to:
    the middle of the rays from the film's centre to five pupil points (the film
    centre itself when none exists), so a pass's float32 vertices do not depend on
    which passes share its run (:mod:`povlens.rendering.sample_stacks`)."""
    film = plan.film
    q = np.array([[0.0, 0.0], [0.5, 0.0], [-0.5, 0.0], [0.0, 0.5], [0.0, -0.5]])
    domain = field_domain_of(plan)
    x = np.full(len(q), 0.5 * film.width_px)
    y = np.full(len(q), 0.5 * film.height_px)
    rays = trace_field(lens, plan.focus.film_distance_mm, film, table.plane_z_mm,
                       lambda f: domain.points_mm(f, q), x, y)
    if not rays.exists.any():
        return np.array(plan.placement.film_centre, dtype=np.float64)
    p = placement_of(plan).points_to_world(rays.origin_mm[rays.exists])
    return 0.5 * (p.min(0) + p.max(0))


def write_field_stack(plan: Plan, lens, table, outdir: Path, ks, inc: Path,
                      bands: int = 1) -> list[bool]:
    """Trace passes ``ks``, write their pass masks and, if any pixel of their rows
    passes, one mesh to ``inc`` drawing pass k in band k mod ``bands`` of a stack
    (:mod:`povlens.rendering.sample_stacks`; 1: the pass's own render).  Returns for
    each pass whether it has a band to render (False: every ray of its rows is
    blocked)."""
    origin = stack_origin_world(plan, lens, table)
    meshes = [_field_pass(plan, lens, table, outdir, int(k), int(k) % bands, bands, origin)
              for k in ks]
    drawn = [m for m in meshes if m is not None]
    if drawn:
        eye = plan.povray_camera.location       # the scene camera's: radiosity's eye
        one = seen_from(combine_meshes(drawn), eye)
        part = RenderFolder(outdir).partial(inc)
        with open(part, "w") as f:
            f.write(mesh2_text(one))
            f.write(placement_text(one))
            f.write(eye_text(eye))
        os.replace(part, inc)
    return [m is not None for m in meshes]


def write_field_sample(plan: Plan, lens, table, outdir: Path, k: int, inc: Path) -> bool:
    """Trace pass k, write its pass mask and, if any pixel of its rows passes, its
    mesh to ``inc``.  Returns False when every ray of its rows is blocked."""
    return write_field_stack(plan, lens, table, outdir, [k], inc)[0]


def field_sample_weight(plan: Plan, table, outdir: Path, k: int) -> np.ndarray:
    """(H, W) float32 weights of rendered sample k (its mask and its tiles' samples)."""
    film = plan.film
    folder = RenderFolder(outdir)
    passed = folder.read_pass_mask(k, film.height_px, film.width_px)
    w = np.zeros(passed.shape, np.float32)
    for tile in field_tiles(plan, k):
        rows, cols = tile.model.rows(), tile.model.columns()
        w[np.ix_(rows, cols)] = field_weight(film, table.plane_z_mm, tile.pupil,
                                             tile.model.jitter_px, passed[np.ix_(rows, cols)],
                                             cols, rows)
    if plan.inputs.aperture_image:                        # grey mask: w times transmission
        w = w * folder.read_transmission(k).astype(np.float32)
    return w
