"""What rendering a converted folder reads again: the plan's lens, its exit-pupil table
and the composite's exposure.

The lens is read from its file, stopped down and shaped as the plan says, and refused
if the file changed since the conversion; the pupil table and the exposure are cached
in the render folder (:class:`~povlens.plan.render_folder.RenderFolder`: ``pupil.npz``,
``exposure.txt``), so every render of the folder uses the same ones.
"""

from __future__ import annotations

import os

from povlens.errors import PovlensError
from povlens.lens.aperture_shape import shaped_lens
from povlens.lens.paraxial import stopped_down
from povlens.lens.prescription import read_lens
from povlens.plan.aperture import shape_of_inputs
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Plan
from povlens.pupil.monte_carlo import exposure_normalisation
from povlens.pupil.grid_table import frame_extent_mm
from povlens.pupil.storage import cached_pupil_table

__all__ = ["lens_for", "pupil_table_for", "exposure_for"]


def lens_for(plan: Plan):
    """The plan's lens, read again and stopped down as the plan says; refused if the
    file changed since the conversion."""
    inp = plan.inputs
    lens = stopped_down(read_lens(inp.lens), stop_diameter_mm=inp.stop_diameter_mm,
                        f_number=inp.f_number)
    if lens.sha256() != inp.lens_sha256:
        raise PovlensError(f"the lens file {inp.lens} changed since 'povlens convert'",
                           "run 'povlens convert' again")
    return shaped_lens(lens, shape_of_inputs(inp))     # iris / mask (plan.aperture)


def pupil_table_for(outdir: str | os.PathLike, plan: Plan, lens):
    """The exit-pupil table of this plan, from ``pupil.npz`` if it is current (over the
    frame's x and y for an anamorphic lens: :func:`povlens.pupil.storage.cached_pupil_table`)."""
    film = plan.film
    table, _ = cached_pupil_table(RenderFolder(outdir).pupil_npz, lens,
                                  plan.focus.film_distance_mm, film.max_field_radius_mm,
                                  film_extent_mm=frame_extent_mm(film))
    return table


def exposure_for(outdir: str | os.PathLike, plan: Plan, lens, table) -> float:
    """The composite's exposure 1 / (E/L)(0) (film centre as bright as the pinhole
    render), cached in ``exposure.txt`` beside the table."""
    folder = RenderFolder(outdir)
    e = folder.read_exposure()
    if e is not None:
        return e
    e = exposure_normalisation(table, lens, plan.focus.film_distance_mm)
    folder.write_exposure(e)
    return e
