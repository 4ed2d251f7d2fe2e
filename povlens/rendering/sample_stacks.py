"""Several lens samples in one POV-Ray run: field passes stacked one under another.

Every POV-Ray run of a lens sample redoes what does not depend on the lens: start-up,
the scene's parse, its radiosity pretrace, loading the photon map.  On scenes whose
trace is cheap, or whose radiosity is computed as the image is traced, that dominates
(issue 25; docs/decisions/planning.md, "Several samples per run").  A distribution-3
mesh camera reads one mesh, but its UV map can draw any layout: a render of a field
plan is a *stack* of p bands, pass k drawn in band k mod p of stack k // p
(:func:`povlens.pov.field_mesh.pass_models` with ``band``), one mesh holding the
faces of the passes the run renders
(:func:`povlens.rendering.field_samples.write_field_stack`).  The scene is parsed once
per run, its radiosity samples serve every band (one process on every core shares
them as focal_blur does), and :func:`split_stack` cuts the render into the images the
passes have alone, so the rest of the pipeline (composite, resume, groups) sees
ordinary samples.  When ``povlens render``'s samples of a plan with radiosity need
several stacks, the runs follow one another on every core and hand on their radiosity
samples (:attr:`StackPlan.chained`; POV-Ray's ``+RFI +RFO`` on one file appends).

The layout is the plan's, not the run's: p depends on the plan's field mesh only
(:func:`stack_bands`), a pass always sits in the same band of a render of the same
height, and every pass's mesh is stored relative to the same point
(:func:`povlens.rendering.field_samples.stack_origin_world`).  A band's pixels do not
depend on the other bands, so a sample comes out the same bits whichever samples share
its run: rendered with all of them, alone after an interruption, by ``make``'s
batches or on a cluster worker.  A run renders only the rows from its first band to
its last.

What it costs: POV-Ray finds a pixel's face by walking bitmasks of every face of the
mesh (docs/reference/povray-mesh-camera.md §3.3), so a pixel costs more as the run's
faces grow (about +0.6 us a pixel at 39 k faces, measured on raddem.pov);
:data:`STACK_FACE_BUDGET` bounds a stack.  Plans it does not apply to render one pass
per run, as before: per-pixel meshes (a face per pixel: a stack would multiply a large
mesh), adaptive plans (their samples render different rows) and scenes that compute
something from ``image_width`` / ``image_height`` outside their camera
(``gamma/gamma_showcase.pov``'s one-pixel stripes), which POV-Ray sets to the size it
renders (such a plan renders its passes at the film's size, not interleaved).
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import numpy as np

from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Plan
from povlens.pov.field_mesh import pass_size
from povlens.pov.process import pixel_range_args
from povlens.util.files import write_text
from povlens.util.images import read_image, write_exr

__all__ = ["StackPlan", "stack_bands", "stack_position", "stack_plan", "stack_runs",
           "stack_render_height", "stack_row_args", "split_stack", "pass_faces", "recorded_bands",
           "record_layout", "STACK_FACE_BUDGET",
           "MAX_STACK"]

#: Faces a stack's mesh may hold (every band's passes).
STACK_FACE_BUDGET = 40000
#: The most bands of a stack.
MAX_STACK = 32


def stack_bands(plan: Plan, outdir: str | os.PathLike | None = None) -> int:
    """p: the bands of a stack of the plan's field passes (1: one pass per run).
    ``POVLENS_STACK`` overrides it (measurements); so does the layout the render
    folder ``outdir`` records (:meth:`RenderFolder.sample_layout`)."""
    fm = plan.field_mesh
    H = plan.film.height_px
    if fm is None or plan.povray.image_size_read or any(plan.rows_of_sample(k) != (0, H)
                         for k in range(int(plan.inputs.samples))):
        return 1
    forced = os.environ.get("POVLENS_STACK")
    if forced:
        return max(1, min(int(forced), MAX_STACK))
    recorded = recorded_bands(outdir) if outdir is not None else None
    if recorded is not None:
        return recorded
    return int(max(1, min(MAX_STACK, STACK_FACE_BUDGET // max(pass_faces(plan), 1))))


def pass_faces(plan: Plan) -> int:
    """Faces of one field pass's mesh: two a grid cell, in each of its interleaved tiles."""
    fm = plan.field_mesh
    return 2 * int(fm.grid[0]) * int(fm.grid[1]) * int(fm.interleave) ** 2


def recorded_bands(outdir: str | os.PathLike) -> int | None:
    """The bands the folder's layout record gives (None: no record, or unreadable)."""
    try:
        bands = json.loads(RenderFolder(outdir).sample_layout.read_text()).get("bands")
    except (OSError, ValueError, AttributeError):
        return None
    return bands if isinstance(bands, int) and 1 <= bands <= MAX_STACK else None


def record_layout(outdir: str | os.PathLike, bands: int, why: dict) -> None:
    """Record that the folder's samples render in stacks of ``bands`` (1: one run
    each), and ``why`` (the measurement that chose it)."""
    write_text(RenderFolder(outdir).sample_layout, json.dumps({"bands": int(bands), **why}) + "\n")


def stack_position(plan: Plan, k: int, bands: int | None = None) -> tuple[int, int]:
    """(stack, band) of pass k."""
    p = stack_bands(plan) if bands is None else int(bands)
    return int(k) // p, int(k) % p


@dataclasses.dataclass(frozen=True)
class StackPlan:
    """How lens samples render: stacks of ``bands`` bands; ``runs`` POV-Ray runs (one
    per stack the samples touch), each on ``threads`` threads; ``together``: the
    samples of one stack share a run (else each sample runs alone, in its band)."""

    bands: int
    runs: int
    threads: int
    together: bool = True
    #: The runs follow one another on every core, each reading the radiosity samples
    #: of those before it (:meth:`RenderFolder.radiosity_chain`).
    chained: bool = False


def stack_plan(plan: Plan, todo, cores: int, together: bool = True,
               chain: bool = False, outdir: str | os.PathLike | None = None) -> StackPlan:
    """How the samples ``todo`` (sample numbers) of ``plan`` render on ``cores`` cores:
    one run per stack they touch; when there are fewer runs than cores, each runs on
    several threads, so that one POV-Ray process shares its radiosity samples over
    every core as focal_blur does (``stackerday.pov``: a stack's second band computed
    45 % of its radiosity lookups, the first 69 %).  With ``chain`` (a render that
    holds every sample: ``povlens render``) and a plan that shares radiosity, several
    runs follow one another on every core, each reading the radiosity samples of those
    before it, so that they are shared as in one process.  ``outdir``: the render
    folder, whose layout record counts (:func:`stack_bands`)."""
    p = stack_bands(plan, outdir)
    todo = list(todo)
    runs = len({k // p for k in todo}) if together else len(todo)
    if p == 1:
        return StackPlan(1, len(todo), 1, together)
    if chain and together and runs > 1 and plan.povray.radiosity_cache:
        return StackPlan(p, runs, max(1, int(cores)), together, True)
    return StackPlan(p, runs, max(1, int(cores) // max(runs, 1)), together)


def stack_runs(samples, bands: int, together: bool = True):
    """The sample numbers ``samples`` (any iterable, taken as they come) in runs:
    consecutive samples of one stack (``together``), or one each."""
    run: list[int] = []
    for k in samples:
        k = int(k)
        if run and (not together or k // bands != run[0] // bands):
            yield run
            run = []
        run.append(k)
    if run:
        yield run


def stack_render_height(plan: Plan, bands: int) -> int:
    """H': the rendered rows of a stack of ``bands`` passes (with FS#261's row)."""
    film, fm = plan.film, plan.field_mesh
    return pass_size(film.width_px, film.height_px, fm.interleave, bands)[1]


def stack_row_args(plan: Plan, ks, bands: int) -> tuple[int, list[str]]:
    """(H', POV-Ray's column and row switches) of a run of passes ``ks``: every column
    but FS#261's, the rows from the first band's to the last's."""
    pv = plan.povray
    h = stack_render_height(plan, bands)
    band_rows = pv.render_height - pv.drop_top_rows
    b = [int(k) % bands for k in ks]
    return h, (pixel_range_args(0, pv.render_width - pv.drop_right_columns,
                                pv.render_width, "col")
               + pixel_range_args(pv.drop_top_rows + min(b) * band_rows,
                                  pv.drop_top_rows + (max(b) + 1) * band_rows, h, "row"))


def split_stack(plan: Plan, image: Path, outdir: Path, ks, drawn, bands: int) -> None:
    """Cut a stacked render ``image`` into the images of its passes ``ks`` (pass k in
    band k mod ``bands``), each in the layout of the pass rendered alone (its cut row
    first, black), written as ``sample_KKKK.exr`` (atomically, POV-Ray's half floats);
    passes not ``drawn`` (every ray blocked) get none."""
    folder = RenderFolder(outdir)
    pv = plan.povray
    stacked = read_image(image)
    band_rows = pv.render_height - pv.drop_top_rows
    for k, ok in zip(ks, drawn):
        if not ok:
            continue
        one = np.zeros((pv.render_height,) + stacked.shape[1:], np.float32)
        r0 = pv.drop_top_rows + (int(k) % bands) * band_rows
        one[pv.drop_top_rows:] = stacked[r0:r0 + band_rows]
        write_exr(folder.sample_image(k), one, half=True)
