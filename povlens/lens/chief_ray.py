"""Real chief rays: rays from film points through the centre of the aperture stop.

Camera frame of :mod:`povlens.lens.coordinates` (mm, film at z = 0, lens toward +z).
Used to place the thin-lens model's field of view and to seed the search for a
tiny exit pupil.
"""

from __future__ import annotations

import numpy as np

from povlens.lens.paraxial import anamorphic_data, paraxial_data, primary_meridian
from povlens.lens.prescription import LensPrescription
from povlens.lens.tracer import TraceResult, trace_from_film

__all__ = ["chief_ray_aim_mm", "chief_rays"]


def chief_ray_aim_mm(lens: LensPrescription, film_distance_mm: float, film_radius_mm,
                     iterations: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Where real chief rays from film points (r, 0, 0) cross the rear-vertex plane.

    The chief ray passes through the centre of the stop.  Its aim x_rear on the
    plane z = film_distance_mm is found by the secant method so that its height at
    the stop plane is 0, starting from the paraxial aim at the exit-pupil centre.
    Clear apertures other than the stop's are ignored while aiming (the chief ray
    is a construction).

    Parameters
    ----------
    lens : the lens; its stop is the paraxial stop (:func:`paraxial_data`; of an
        anamorphic lens the x-z meridian's, in which these chief rays lie).
    film_distance_mm : rear vertex to film, mm.
    film_radius_mm : (n,) film radii r, mm (a scalar is one radius).
    iterations : most secant steps.

    Returns
    -------
    x_rear : (n,) x of the aim on the rear-vertex plane, mm.
    found : (n,) bool, True where the stop height converged to within 1e-9 mm.
    """
    p = paraxial_data(lens, _film_x_meridian(lens))
    s = p.stop_index
    r = np.atleast_1d(np.asarray(film_radius_mm, dtype=np.float64)).ravel()
    n = r.size
    # Open every clear aperture (a clear radius cannot exceed |R|) and stop at the stop.
    wide = lens.replace(aperture_diameter_mm=np.where(
        lens.radius_mm != 0, 2 * np.abs(lens.radius_mm) * (1 - 1e-12), 1e6))
    to_stop = wide.sub_lens(s)
    origin = np.column_stack([r, np.zeros(n), np.zeros(n)])
    z_rear = film_distance_mm

    def stop_height(x_rear):
        d = np.column_stack([x_rear - r, np.zeros(n), np.full(n, z_rear)])
        t = trace_from_film(to_stop, film_distance_mm, origin, d)
        return t.origin_mm[:, 0], t.passed

    z_xp = film_distance_mm - p.exit_pupil_position  # camera-frame z of the exit pupil
    x0 = r * (1.0 - z_rear / z_xp) if z_xp != 0 else np.zeros(n)
    x1 = x0 + 1e-3 * max(1.0, float(np.max(np.abs(r))) if n else 1.0)
    h0, ok0 = stop_height(x0)
    h1, ok1 = stop_height(x1)
    for _ in range(iterations):
        denom = h1 - h0
        step_ok = (denom != 0) & ok0 & ok1
        x2 = np.where(step_ok, x1 - h1 * (x1 - x0) / np.where(denom != 0, denom, 1.0), x1)
        x0, h0, ok0 = x1, h1, ok1
        x1 = x2
        h1, ok1 = stop_height(x1)
        if np.all(~ok1 | (np.abs(h1) < 1e-12)):
            break
    return x1, ok1 & (np.abs(h1) < 1e-9)


def _film_x_meridian(lens: LensPrescription) -> str:
    """The meridian of chief rays from film points (r, 0, 0): the x-z plane's on an
    anamorphic lens with power there, else the lens's primary one ("y": the same data
    on a rotationally symmetric lens)."""
    if lens.is_anamorphic and anamorphic_data(lens).afocal != "x":
        return "x"
    return primary_meridian(lens)


def chief_rays(lens: LensPrescription, film_distance_mm: float,
               film_radius_mm: np.ndarray) -> tuple[TraceResult, np.ndarray]:
    """Real chief rays from film points (r, 0, 0) through the centre of the stop.

    Parameters
    ----------
    lens, film_distance_mm : the lens and its rear-vertex-to-film distance (mm).
    film_radius_mm : (n,) film radii r, mm.

    Returns
    -------
    rays : the trace of the n rays (leaving the front surface); its ``passed`` tells
        whether a chief ray gets through every aperture.
    found : (n,) bool, True where the aim at the stop centre converged.
    """
    r = np.atleast_1d(np.asarray(film_radius_mm, dtype=np.float64)).ravel()
    x_rear, found = chief_ray_aim_mm(lens, film_distance_mm, r)
    n = r.size
    origin = np.column_stack([r, np.zeros(n), np.zeros(n)])
    d = np.column_stack([x_rear - r, np.zeros(n), np.full(n, float(film_distance_mm))])
    return trace_from_film(lens, film_distance_mm, origin, d), found
