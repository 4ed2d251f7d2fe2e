"""Coordinate frames used everywhere in povlens.  They are defined here, once.

Camera frame (all lens code; millimetres)
    Origin at the centre of the film.  The film is the plane z = 0.  +z points
    from the film toward the scene.  x and y span the film.  The lens lies at
    z > 0; its rear vertex (the last row of the prescription) is at
    ``z = film_distance_mm`` and its front vertex (the first row) at
    ``z = film_distance_mm + total_track_mm``.  This is pbrt's camera space.
    A ray is a pair (origin_mm, direction) of arrays of shape (n, 3), float64;
    directions are unit vectors.

Surface-local sag coordinate
    Inside the tracers each surface i is described by its vertex position
    ``vertex_z_mm[i]`` (camera frame) and its curvature ``c = 1/R`` (1/mm, 0 for a
    plane).  The local depth ``s = vertex_z_mm[i] - z`` grows from the vertex
    toward the film, i.e. along the direction light travels from scene to film.
    The surface is the set ``c (x^2 + y^2 + s^2) - 2 s = 0`` (the curvature form
    of optical design programs), whose branch through the vertex is
    ``s = sag(r) = c r^2 / (1 + sqrt(1 - c^2 r^2))``.  With the prescription's
    sign convention, R > 0 puts the centre of curvature on the film side
    (the surface is convex toward the scene).

Prescription rows
    Row 0 is the front (scene-side) surface, row n-1 the rear (film-side)
    surface.  ``thickness_mm[i]`` is the axial distance from vertex i to vertex
    i+1; the last row's thickness in the file is ignored and replaced by the
    film distance when the lens is focused.

Film coordinates and the scene
    The lens inverts the image: a film point at +x sees the scene toward -x.
    Conversion to POV-Ray's left-handed world (+x right, +y up, +z forward) is
    done only in the POV-Ray emission modules, which state how they map the
    camera frame onto the scene camera.
"""

from __future__ import annotations

import numpy as np

__all__ = ["vertex_z_mm"]


def vertex_z_mm(thickness_mm: np.ndarray, film_distance_mm: float) -> np.ndarray:
    """Camera-frame z of every surface vertex, shape (n,), in mm.

    ``thickness_mm`` is the prescription's thickness column (its last entry is
    ignored); the rear vertex lies at ``film_distance_mm``.
    """
    t = np.asarray(thickness_mm, dtype=np.float64)
    gaps = np.append(t[:-1], 0.0)
    # z_i = film + sum_{j >= i} gaps_j, accumulated from the rear so that
    # zero gaps give bit-identical vertex positions.
    return film_distance_mm + np.cumsum(gaps[::-1])[::-1]
