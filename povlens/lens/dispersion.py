"""Dispersion: refractive indices at any wavelength from n_d and the Abbe number V_d.

A glass with a known Abbe number (5th column of a lens file,
:class:`~povlens.lens.prescription.LensPrescription.abbe_vd`) gets the two-term
Cauchy model

    n(lambda) = A + B / lambda^2,

through n_d at the helium d line (587.5618 nm) and with n_F - n_C = (n_d - 1) / V_d
between the hydrogen F (486.1327 nm) and C (656.2725 nm) lines.  V_d = 0 (unknown)
or V_d = inf gives B = 0: that medium does not disperse.  Air (index 1) never does.

A medium that is a catalogue glass (``lens.glass``, :mod:`povlens.lens.glass_catalog`)
follows its maker's formula instead, with its secondary spectrum:
n(lambda) = n_d + n_cat(lambda) - n_cat(d), the row's stated n_d plus the catalogue's
change from the d line (stated n_d and catalogue n_d agree to
:data:`~povlens.lens.glass_catalog.ND_TOLERANCE`, or the name is not kept).
:func:`dispersion_model` says which rows follow which model.

The lens at a wavelength has the same geometry (radii, thicknesses, apertures):
the film stays where the d-line focus put it, which is what makes longitudinal
colour visible.  Chromatic aberration of a focused lens (lateral colour of the real
chief rays, longitudinal colour of the paraxial focus) is :func:`chromatic_aberration`.
Camera frame and units of :mod:`povlens.lens.coordinates` (mm).
"""

from __future__ import annotations

import math

import numpy as np

from povlens.lens.chief_ray import chief_rays
from povlens.lens.glass_catalog import find_glass
from povlens.lens.paraxial import image_of_object, paraxial_data, primary_meridian
from povlens.lens.prescription import AIR, LensPrescription
from povlens.lens.tracer import trace_from_film

__all__ = ["LINE_F_NM", "LINE_D_NM", "LINE_C_NM", "BAND_NM", "cauchy_coefficients", "index_at",
           "has_abbe_numbers", "disperses", "lens_at_wavelength", "chief_landing_mm", "chromatic_aberration",
           "pass_radius_mm", "dispersion_model"]

#: Fraunhofer lines (nm): hydrogen F, helium d, hydrogen C.
LINE_F_NM, LINE_D_NM, LINE_C_NM = 486.1327, 587.5618, 656.2725
#: The visible band lens samples are spread over with --dispersion (nm): where the
#: CIE 1931 colour-matching functions are above ~1e-4 of their peak.
BAND_NM = (380.0, 730.0)


def cauchy_coefficients(n_d, v_d) -> tuple[np.ndarray, np.ndarray]:
    """A and B (nm^2) of n = A + B / lambda^2 through n_d with n_F - n_C = (n_d - 1) / V_d.

    Parameters
    ----------
    n_d : (n,) indices at the d line (>= 1).
    v_d : (n,) Abbe numbers; 0 (unknown) or inf: no dispersion (B = 0).

    Returns
    -------
    A : (n,) float64, B : (n,) float64 in nm^2.
    """
    n_d = np.asarray(n_d, dtype=np.float64)
    v_d = np.asarray(v_d, dtype=np.float64)
    known = (v_d > 0) & np.isfinite(v_d) & (n_d != AIR)
    spread = np.where(known, (n_d - 1.0) / np.where(known, v_d, 1.0), 0.0)   # n_F - n_C
    b = spread / (LINE_F_NM ** -2 - LINE_C_NM ** -2)
    return n_d - b / LINE_D_NM ** 2, b


def index_at(n_d, v_d, wavelength_nm: float) -> np.ndarray:
    """(n,) refractive indices at ``wavelength_nm`` (:func:`cauchy_coefficients`)."""
    a, b = cauchy_coefficients(n_d, v_d)
    return a + b / float(wavelength_nm) ** 2


def has_abbe_numbers(lens: LensPrescription) -> bool:
    """True when some glass of ``lens`` has a known Abbe number (V_d != 0; inf counts:
    known not to disperse)."""
    glass = lens.index_after != AIR
    return bool(np.any(glass & (lens.abbe_vd != 0.0))) or any(lens.glass)


def disperses(lens: LensPrescription) -> bool:
    """True when some glass has a finite, non-zero V_d (its index depends on lambda)."""
    v = lens.abbe_vd
    return bool(np.any((lens.index_after != AIR) & (v > 0) & np.isfinite(v))) or any(lens.glass)


def lens_at_wavelength(lens: LensPrescription, wavelength_nm: float) -> LensPrescription:
    """``lens`` with every index at ``wavelength_nm`` (geometry unchanged).

    Parameters
    ----------
    lens : the lens (indices at the d line, Abbe numbers in ``abbe_vd``, catalogue
        glasses in ``glass``: those rows follow their formulas, the others Cauchy).
    wavelength_nm : vacuum wavelength, nm (> 0).

    Returns
    -------
    LensPrescription
        The same object when no medium disperses.
    """
    if not (wavelength_nm > 0 and math.isfinite(wavelength_nm)):
        raise ValueError(f"wavelength {wavelength_nm!r} nm must be a positive number")
    if not disperses(lens):
        return lens
    n = index_at(lens.index_after, lens.abbe_vd, wavelength_nm)
    for i, label in enumerate(lens.glass):
        if label:
            g = find_glass(label)
            n[i] = lens.index_after[i] + (float(g.index_at(wavelength_nm)) - g.n_d)
    return lens.replace(index_after=n)


def dispersion_model(lens: LensPrescription) -> str:
    """Which dispersion model each glass of ``lens`` follows, in words: the catalogue
    formulas (rows and glasses named) and Cauchy (rows with a V_d, or none)."""
    glass_rows = np.flatnonzero(lens.index_after != AIR)
    named = [f"row {i} {lens.glass[i]}" for i in glass_rows if lens.glass and lens.glass[i]]
    cauchy = [str(i) for i in glass_rows if not (lens.glass and lens.glass[i])]
    parts = []
    if named:
        parts.append("catalogue formulas (secondary spectrum): " + ", ".join(named))
    if cauchy:
        parts.append(f"Cauchy n = A + B/lambda^2 through n_d and n_F - n_C = (n_d - 1)/V_d: "
                     f"row{'s' if len(cauchy) > 1 else ''} " + ", ".join(cauchy))
    return "; ".join(parts) or "no glass"


def _chief_heights(lens, film_distance_mm, object_distance_mm, radii_mm):
    """Heights (mm) where chief rays from film radii (r, 0) meet the object plane
    (z = object_distance_mm from the film), or their slopes dx/dz for an object at
    infinity; NaN where a chief ray is not found or blocked (kept inside this module)."""
    rays, found = chief_rays(lens, film_distance_mm, radii_mm)
    o, d = rays.origin_mm, rays.direction
    ok = found & rays.passed & (d[:, 2] > 0)
    dz = np.where(ok, d[:, 2], 1.0)
    if math.isinf(object_distance_mm):
        h = d[:, 0] / dz
    else:
        h = o[:, 0] + (object_distance_mm - o[:, 2]) / dz * d[:, 0]
    return np.where(ok, h, np.nan)


def chief_landing_mm(lens: LensPrescription, film_distance_mm: float,
                     object_distance_mm: float, film_radius_mm, wavelengths_nm) -> np.ndarray:
    """Where the object points seen by d-line chief rays land at other wavelengths.

    The d-line chief ray from film radius r (r, 0, 0) meets the object plane
    (``object_distance_mm`` from the film; inf: its direction) at height h; the
    chief ray of wavelength lambda meeting it at h lands at film radius r(lambda),
    found on a grid of 241 film radii up to 1.2 max(r), interpolated.

    Parameters
    ----------
    film_radius_mm : (n,) d-line film radii, mm; wavelengths_nm : (m,) nm.

    Returns
    -------
    (m, n) float64 film radii, mm; NaN where a chief ray is blocked or leaves the grid.
    """
    r_d = np.atleast_1d(np.asarray(film_radius_mm, dtype=np.float64))
    h = _chief_heights(lens, film_distance_mm, object_distance_mm, r_d)
    grid = np.linspace(0.0, 1.2 * max(float(np.max(r_d)), 1e-6), 241)
    out = np.full((len(wavelengths_nm), r_d.size), np.nan)
    for i, lam in enumerate(wavelengths_nm):
        hg = _chief_heights(lens_at_wavelength(lens, float(lam)), film_distance_mm,
                            object_distance_mm, grid)
        ok = np.isfinite(hg)
        if ok.sum() < 2:
            continue
        g, hv = grid[ok], hg[ok]
        order = np.argsort(hv)
        inside = np.isfinite(h) & (h >= hv.min()) & (h <= hv.max())
        r = np.interp(np.where(inside, h, hv.min()), hv[order], g[order])
        out[i] = np.where(inside, r, np.nan)
    return out


def chromatic_aberration(lens: LensPrescription, film_distance_mm: float,
                         object_distance_mm: float, film_half_diagonal_mm: float,
                         pixel_pitch_mm: float, n_field: int = 6) -> dict:
    """Lateral and longitudinal colour of a focused lens, F line against C line.

    Lateral colour: for film radii r_d = f * half diagonal (f = 0 .. 1, ``n_field``
    values) the real d-line chief ray meets the object plane (the plane in focus) at
    height h; the F-line and C-line chief rays meeting it at h land at film radii
    r_F and r_C; lateral colour = (r_F - r_C) in pixels (+: blue lands farther out).
    Longitudinal colour: paraxial image distances (rear vertex to focus) of the
    object, z_F - z_C in mm (+: blue focuses behind red), and the blur diameter
    that shift makes on the film, |z_F - z_C| / N in pixels (N the f-number).

    Parameters
    ----------
    lens : the stopped-down lens.
    film_distance_mm : rear vertex to film (the d-line focus), mm.
    object_distance_mm : the plane in focus, from the film, mm (inf allowed).
    film_half_diagonal_mm, pixel_pitch_mm : the film, mm.
    n_field : number of field fractions.

    Returns
    -------
    dict
        ``field_fraction`` (n_field,), ``lateral_colour_px`` (n_field,; None where a
        chief ray is blocked), ``max_lateral_colour_px``, ``longitudinal_colour_mm``,
        ``longitudinal_blur_px``, ``lines_nm`` {F, d, C}.
    """
    frac = np.linspace(0.0, 1.0, int(n_field))
    r_f, r_c = chief_landing_mm(lens, film_distance_mm, object_distance_mm,
                                frac * film_half_diagonal_mm, (LINE_F_NM, LINE_C_NM))
    landing = {"F": r_f, "C": r_c}
    lateral_px = (landing["F"] - landing["C"]) / pixel_pitch_mm
    front = object_distance_mm - film_distance_mm - lens.total_track_mm   # from front vertex
    z = {name: image_of_object(lens_at_wavelength(lens, lam), front)[0]
         for name, lam in (("F", LINE_F_NM), ("C", LINE_C_NM))}
    shift = z["F"] - z["C"] if math.isfinite(z["F"]) and math.isfinite(z["C"]) else math.nan
    n_f = paraxial_data(lens, primary_meridian(lens)).f_number   # y unless afocal there
    finite = np.isfinite(lateral_px)
    return {
        "lines_nm": {"F": LINE_F_NM, "d": LINE_D_NM, "C": LINE_C_NM},
        "field_fraction": [float(f) for f in frac],
        "lateral_colour_px": [float(v) if ok else None for v, ok in zip(lateral_px, finite)],
        "max_lateral_colour_px": float(np.max(np.abs(lateral_px[finite]))) if finite.any()
        else 0.0,
        "longitudinal_colour_mm": float(shift) if math.isfinite(shift) else None,
        "longitudinal_blur_px": (float(abs(shift) / n_f / pixel_pitch_mm)
                                 if math.isfinite(shift) and n_f > 0 else None),
    }


def pass_radius_mm(lens: LensPrescription, film_distance_mm: float, film_radius_mm: float,
                   plane_z_mm: float, search_radius_mm: float, n_film: int = 33,
                   n_angles: int = 48, n_rho: int = 192) -> float:
    """Largest radius on the plane z = ``plane_z_mm`` through which a ray from a film
    point within ``film_radius_mm`` of the centre passes the lens.

    Rays from film points (r, 0, 0), r on ``n_film`` radii 0..film_radius_mm (the
    lens is rotationally symmetric), toward plane points at ``n_angles`` directions
    over [0, pi] and ``n_rho`` radii 0..search_radius_mm; vectorised, one trace.

    Returns
    -------
    float
        The largest passing radius plus one radial step (so the true maximum between
        grid radii is covered), mm; 0 if no ray passes.  Equal to
        ``search_radius_mm`` + step means the search radius was too small.
    """
    r = np.linspace(0.0, float(film_radius_mm), int(n_film))
    th = np.linspace(0.0, math.pi, int(n_angles))
    step = float(search_radius_mm) / (int(n_rho) - 1)
    rho = np.arange(int(n_rho)) * step
    R, T, P = np.meshgrid(r, th, rho, indexing="ij")
    R, T, P = R.ravel(), T.ravel(), P.ravel()
    origin = np.column_stack([R, np.zeros_like(R), np.zeros_like(R)])
    d = np.column_stack([P * np.cos(T) - R, P * np.sin(T), np.full(R.shape, float(plane_z_mm))])
    passed = trace_from_film(lens, film_distance_mm, origin, d).passed
    return float(P[passed].max() + step) if passed.any() else 0.0
