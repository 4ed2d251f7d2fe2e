"""``--dispersion`` in a plan: the lens's chromatic aberration and what is rendered.

A lens with Abbe numbers (:func:`povlens.lens.dispersion.has_abbe_numbers`) gets
``plan.dispersion``: its lateral colour (F against C chief-ray landing, pixels,
across the field) and longitudinal colour (paraxial focus shift, mm), measured by
:func:`povlens.lens.dispersion.chromatic_aberration`.  Mesh plans render the colour
(``inputs.dispersion`` True): each lens sample is traced at its own wavelength
(:mod:`povlens.rendering.spectral`), and what the samples' pupil points are drawn
from is enlarged to hold every wavelength's pass region: the exit-pupil table's
polygons (``pupil_dilation``, one factor per knot: :mod:`povlens.pupil.band_table`),
which per-pixel meshes sample and the field meshes' ellipses hold
(:mod:`povlens.pupil.field_domain`).  Other methods render none,
and a note says so.
"""

from __future__ import annotations

import dataclasses

from povlens.lens.dispersion import (BAND_NM, chromatic_aberration, dispersion_model,
                                     disperses, has_abbe_numbers, lens_at_wavelength)
from povlens.plan.decision import MIN_SAMPLES
from povlens.pupil.band_table import band_dilation

__all__ = ["apply_dispersion", "colour_decision", "COLOUR_MODEL"]

#: How the samples' wavelengths become RGB (plan.json; povlens.rendering.spectral).
COLOUR_MODEL = ("wavelengths importance-sampled over the band from the CIE 1931 2-degree "
                "colour-matching functions in linear sRGB (negative lobes clipped), "
                "normalised per channel")


#: The note of ``--dispersion`` on an anamorphic lens (not rendered yet).
ANAMORPHIC_NOTE = ("--dispersion: not rendered for an anamorphic lens yet (its pupil table over "
                   "the film's x and y has no band of wavelengths), so the image shows no colour "
                   "fringes ({colour})")


def apply_dispersion(opts, plan, lens, table) -> None:
    """Record ``--dispersion`` in ``plan`` (module docstring); nothing without it.

    Parameters
    ----------
    opts : the :class:`~povlens.plan.options.ConvertOptions`.
    plan : the plan being finished (its field meshes already chosen).
    lens : the stopped-down lens; table : its exit-pupil table (None for pinhole).
    """
    if not opts.sampling.dispersion:
        return
    if not has_abbe_numbers(lens):
        plan.add_note(f"--dispersion: the lens file {lens.source} gives no Abbe numbers "
                      f"(5th column V_d) nor catalogue glasses ('#!glass NAME'), so it "
                      f"renders without dispersion")
        return
    film, focus = plan.film, plan.focus
    info = chromatic_aberration(lens, focus.film_distance_mm,
                                focus.object_distance_from_film_mm, film.max_field_radius_mm,
                                film.pixel_pitch_mm)
    info.update(rendered=False, band_nm=list(BAND_NM),
                model=f"{dispersion_model(lens)}; {COLOUR_MODEL}")
    plan.dispersion = info
    plan.add_note(f"--dispersion: {dispersion_model(lens)}")
    colour = (f"lateral colour up to {info['max_lateral_colour_px']:.2g} px, longitudinal "
              f"{info['longitudinal_colour_mm'] or 0.0:.2g} mm")
    if opts.sampling.method != "mesh":
        plan.add_note(f"--dispersion: only the mesh method renders colour fringes; this "
                      f"{opts.sampling.method} render shows none ({colour})")
        return
    if getattr(table, "kind", "radial") == "grid":
        plan.add_note(ANAMORPHIC_NOTE.format(colour=colour))
        return
    # the samples draw from the d-line table grown to hold the band's pass regions: per-pixel
    # meshes from its polygons, field meshes from the ellipses that hold them
    factors = band_dilation(table, [lens_at_wavelength(lens, lam) for lam in BAND_NM])
    info.update(rendered=True, pupil_dilation=[float(f) for f in factors])
    plan.inputs = dataclasses.replace(plan.inputs, dispersion=True)
    fm = plan.field_mesh
    if fm is not None:
        from povlens.pupil.band_table import band_table
        from povlens.pupil.field import bounding_disc_radius_mm
        from povlens.pupil.field_domain import field_domain
        grown = band_table(table, factors)
        info.update(pupil_disc_radius_d_line_mm=fm.pupil_disc_radius_mm)
        plan.field_mesh = dataclasses.replace(
            fm, pupil_disc_radius_mm=bounding_disc_radius_mm(grown),
            domain=field_domain(grown).to_dict())


def colour_decision(opts, lens, plan, decision):
    """``--method auto --dispersion``: the decision, or mesh when it chose a view (which
    renders no colour) and the lens's colour reaches ``--tolerance``.

    Parameters
    ----------
    opts : the options (method auto); lens : the stopped-down lens; plan : auto's
        mesh plan (its focus and film); decision : :func:`povlens.plan.auto.choose_method`'s.

    Returns
    -------
    Decision
        ``decision`` itself, or a mesh decision of at least twice
        :data:`~povlens.plan.decision.MIN_SAMPLES` samples (each colour channel draws on
        about a third of a spectral render's samples) with the reason.
    """
    if not opts.sampling.dispersion or decision.method == "mesh" or not disperses(lens):
        return decision
    film, focus = plan.film, plan.focus
    ca = chromatic_aberration(lens, focus.film_distance_mm, focus.object_distance_from_film_mm,
                              film.max_field_radius_mm, film.pixel_pitch_mm)
    colour_px = max(ca["max_lateral_colour_px"], ca["longitudinal_blur_px"] or 0.0)
    if colour_px < opts.auto.tolerance_px:
        decision.add_remark(f"--dispersion: the lens's colour ({colour_px:.2g} px) is within "
                            f"the tolerance; the {decision.method} view renders none")
        return decision
    samples = max(2 * MIN_SAMPLES, decision.samples if decision.method == "mesh" else 0)
    return dataclasses.replace(
        decision, method="mesh", samples=samples, focal_blur=None,
        reasons=decision.reasons + [
            f"-> mesh: --dispersion, and the lens's colour (lateral {ca['max_lateral_colour_px']:.2g}"
            f" px, longitudinal blur {ca['longitudinal_blur_px'] or 0.0:.2g} px) exceeds the "
            f"tolerance {opts.auto.tolerance_px:g} px, which only lens samples render "
            f"({decision.method} was chosen without colour)"],
        numbers=dict(decision.numbers, colour_px=colour_px))
