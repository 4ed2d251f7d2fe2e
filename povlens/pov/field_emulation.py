"""What POV-Ray 3.7.0.10 traces through a field ray mesh, and how far that is from
the exact lens rays (the measure :mod:`povlens.plan.field_grid` certifies).

:func:`emulate` reproduces POV-Ray's distribution-3 camera for output pixels
(:mod:`povlens.pov.field_mesh`: FS#261 sampling, first containing face, float32
vertices and normals, the mesh's matrix in double, ``smooth``); the tests check it
against a direction-readout render.  :func:`ray_error_px` compares it with
:func:`povlens.pupil.field.trace_field` (or any ray field) at the same image positions.
"""

from __future__ import annotations

import numpy as np

from povlens.pov.field_mesh import FieldMesh, UVModel, locate_in_grid

__all__ = ["emulate", "ray_error_px"]


def emulate(mesh: FieldMesh, model: UVModel, rows=None, cols=None):
    """World origins (n, 3) and unit directions (n, 3) POV-Ray traces for the tile's
    pixels (``rows``, ``cols``: equal-length index arrays into the tile's (Hc, Wc)
    pixels; default every pixel, row-major)."""
    pu, pv = model.pixel_uv()
    if rows is None:
        pu, pv = pu.ravel(), pv.ravel()
    else:
        pu, pv = pu[rows, cols], pv[rows, cols]
    face, B = locate_in_grid(mesh.grid, mesh.rect, pu, pv)
    tri = mesh.faces[face]
    q = mesh.vertex.astype(np.float32).astype(float)
    n = mesh.normal.astype(np.float32).astype(float)
    M, T = mesh.matrix[:3], mesh.matrix[3]
    origin = np.einsum("nk,nkd->nd", B, q[tri]) @ M + T
    d = np.einsum("nk,nkd->nd", B, n[tri]) @ np.linalg.inv(M).T
    return origin, d / np.linalg.norm(d, axis=1, keepdims=True)


def ray_error_px(mesh: FieldMesh, model: UVModel, ray_field, placement, pixel_angle_rad: float,
                 rows=None, cols=None, exact=None) -> dict:
    """The rays POV-Ray traces against the exact ones (``ray_field``, as for
    :func:`povlens.pov.field_mesh.build_field_mesh`), where the lens passes light.

    ``exact``: ``ray_field`` at those pixels' sample positions, when already traced
    (it depends on the pupil point and offset, not on the mesh).

    Returns
    -------
    dict
        ``direction_px``: largest angle between them in pixels (angle / pixel angle);
        ``origin_mm``: largest distance of POV-Ray's origin from the exact ray's line
        (mm); ``pixels``: how many passing pixels were compared.
    """
    W, H = model.size
    if rows is None:
        rows, cols = (a.ravel() for a in np.mgrid[0:H, 0:W])
    px, py = model.pixel_positions()
    if exact is None:
        exact = ray_field(px[cols], py[rows])
    ok = exact.passed
    if not ok.any():
        return {"direction_px": 0.0, "origin_mm": 0.0, "pixels": 0}
    o, d = emulate(mesh, model, rows[ok], cols[ok])
    ed = placement.directions_to_world(exact.direction[ok])
    eo = placement.points_to_world(exact.origin_mm[ok])
    ang = np.arcsin(np.clip(np.linalg.norm(np.cross(ed, d), axis=1), 0.0, 1.0))
    rel = o - eo
    perp = rel - np.einsum("nd,nd->n", rel, ed)[:, None] * ed
    return {"direction_px": float(ang.max() / pixel_angle_rad),
            "origin_mm": float(np.linalg.norm(perp, axis=1).max() * placement.mm_per_unit),
            "pixels": int(ok.sum())}
