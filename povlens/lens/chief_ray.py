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

__all__ = ["chief_ray_aim_mm", "chief_rays", "chief_rays_2d"]


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


def chief_rays_2d(lens: LensPrescription, film_distance_mm: float, film_xy):
    """Real chief rays from film points anywhere on the film (f_x, f_y, 0) through the
    centre of the (y-z meridian's) stop, for lenses that are not rotationally symmetric.

    The aim (a_x, a_y) on the rear-vertex plane is found by the secant method in each
    coordinate so that the ray's height at the stop is (0, 0) (a mirror-symmetric lens's
    two meridians decouple to first order, so each coordinate of the aim drives its
    own coordinate of the stop height); every clear aperture is opened while aiming, as
    :func:`povlens.lens.chief_ray.chief_ray_aim_mm` does along x.  Then the ray is traced
    through the whole lens.

    Parameters
    ----------
    lens, film_distance_mm : the lens and its rear-vertex-to-film distance (mm).
    film_xy : (n, 2) film points, mm.

    Returns
    -------
    rays : the :class:`~povlens.lens.tracer.TraceResult` of the n rays (leaving the front
        surface); ``passed`` tells whether the chief ray gets through every aperture.
    found : (n,) bool, True where the aim converged to within 1e-9 mm at the stop.
    """
    p = paraxial_data(lens)
    f = np.asarray(film_xy, dtype=np.float64).reshape(-1, 2)
    n = len(f)
    wide = lens.replace(aperture_diameter_mm=np.full(lens.n_surfaces, 1e6),
                        aperture_shape=None, aperture_shape_row=-1)
    to_stop = wide.sub_lens(p.stop_index)
    origin = np.column_stack([f, np.zeros(n)])

    def rays(aim, through):
        d = np.column_stack([aim - f, np.full(n, float(film_distance_mm))])
        return trace_from_film(through, film_distance_mm, origin, d)

    z_xp = film_distance_mm - p.exit_pupil_position
    a0 = f * (1.0 - film_distance_mm / z_xp) if z_xp != 0 else np.zeros_like(f)
    a1 = a0 + 1e-3 * max(1.0, float(np.abs(f).max()) if n else 1.0)
    t0, t1 = rays(a0, to_stop), rays(a1, to_stop)
    for _ in range(40):
        h0, h1 = t0.origin_mm[:, :2], t1.origin_mm[:, :2]
        ok = (t0.passed & t1.passed)[:, None] & (h1 != h0)
        a2 = np.where(ok, a1 - h1 * (a1 - a0) / np.where(h1 != h0, h1 - h0, 1.0), a1)
        a0, t0, a1 = a1, t1, a2
        t1 = rays(a1, to_stop)
        if np.all(~t1.passed | np.all(np.abs(t1.origin_mm[:, :2]) < 1e-12, axis=1)):
            break
    found = t1.passed & np.all(np.abs(t1.origin_mm[:, :2]) < 1e-9, axis=1)
    return rays(a1, lens), found
