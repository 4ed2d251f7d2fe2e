"""Rendering a converted folder: lens-sample batches, single views, compositing.

Work units and their outputs (each written under a temporary name, then renamed,
so an interrupted run never leaves a half-written file at a final name):

* batch b of the mesh method -> ``samples/sample_KKKK.exr`` (POV-Ray, linear),
  ``samples/sample_KKKK.weight.exr`` (per-pixel radiometric weights, float32; field
  meshes: ``sample_KKKK.mask.npy``, :mod:`povlens.rendering.field_samples`),
  then the marker ``samples/batch_BBB.done`` (make's target; ``povlens render``
  renders every sample in one process and writes the markers after).  Samples are
  traced one at a time: the ray mesh (``sample_KKKK.inc``) is written and a
  POV-Ray process started for it while the next is traced (several in flight, see
  :data:`POVRAY_IN_FLIGHT`); each mesh is deleted when its render ends.
* a view (``pinhole`` / ``focal-blur``) -> ``view-<name>.exr``.
* composite -> ``image.exr`` (linear float) and ``image.png`` (sRGB preview).

Every POV-Ray run gets the user's POV-Ray options the plan records (library paths,
clock, passthrough options: :func:`povlens.plan.options.povray_options_of`), so
``make`` and ``povlens render-batch`` render as ``povlens render`` does; lens samples
run without anti-aliasing whatever the options say (:data:`MESH_SWITCHES`).

Re-running skips every unit whose outputs exist: that is how an interrupted
render resumes.

Compositing of lens samples (Monte-Carlo estimate of the camera measurement
equation, Pharr, Jakob and Humphreys, *Physically Based Rendering*, 3rd ed.,
§6.4.7): for pixel p and samples k = 1..N with weights
w_k(p) = cos^4(theta) / (z^2 pdf) (0 when blocked),

    image(p) = exposure * (1/N) sum_k w_k(p) I_k(p),

where ``exposure`` = 1 / (E/L at the film centre) makes the frame centre as
bright as the pinhole render, and vignetting shows as it would on film.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from povlens.errors import ParameterError, PovlensError, PovrayError
from povlens.plan.convert import ConvertOptions, convert
from povlens.plan.options import povray_options_of
from povlens.plan.aperture import shape_of_inputs
from povlens.plan.schema import Plan, PovraySettings, read_plan
from povlens.pupil.monte_carlo import exposure_normalisation
from povlens.pupil.storage import cached_pupil_table
from povlens.rendering.composite import accumulate_samples, measurement_image
from povlens.rendering.pixel_sampler import pixel_sampler
from povlens.rendering.spectral import plan_channel_factors
from povlens.util.images import read_image, write_exr, write_png_srgb
from povlens.pupil.rays import sample_points, sample_rays
from povlens.pov.mesh import write_ray_mesh
from povlens.rendering.field_samples import (field_sample_weight, illumination_map,
                                             image_layout as _layout, mask_path, placement_of,
                                             render_rows, sample_lens, write_field_sample)
from povlens.rendering.groups import group_sums, grouped
from povlens.util.files import write_text
from povlens.util.signals import interrupts_deferred
from povlens.lens.aperture_shape import shaped_lens
from povlens.lens.paraxial import stopped_down
from povlens.pov.povray_output import error_in_wrapper, povray_error_text
from povlens.pov.executable import find_povray
from povlens.pov.process import (pixel_range_args, povray_command, povray_finished,
                                 render as povray_render, render_switches, start_povray)
from povlens.lens.prescription import read_lens

__all__ = ["convert_and_render", "render_samples", "render_batch", "sample_rows", "sample_weight",
           "samples_per_pixel", "render_view", "composite_outdir", "render_outdir",
           "pupil_table_for", "lens_for", "exposure_for", "film_row_args", "EarlyRender",
           "POVRAY_IN_FLIGHT", "MESH_SWITCHES", "sample_done", "mark_batches_done",
           "sample_sums"]


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


def pupil_table_for(outdir: Path, plan: Plan, lens):
    """The exit-pupil table of this plan, from ``pupil.npz`` if it is current."""
    film = plan.film
    table, _ = cached_pupil_table(Path(outdir) / "pupil.npz", lens,
                                  plan.focus.film_distance_mm, film.max_field_radius_mm)
    return table


def exposure_for(outdir: Path, plan: Plan, lens, table) -> float:
    """The composite's exposure 1 / (E/L)(0) (film centre as bright as the pinhole
    render), cached in ``exposure.txt`` beside the table."""
    path = Path(outdir) / "exposure.txt"
    if path.exists():
        try:
            return float(path.read_text())
        except ValueError:
            pass
    e = exposure_normalisation(table, lens, plan.focus.film_distance_mm)
    write_text(path, f"{e!r}\n")
    return e


def _sample_paths(outdir: Path, k: int) -> tuple[Path, Path, Path]:
    s = Path(outdir) / "samples"
    return s / f"sample_{k:04d}.exr", s / f"sample_{k:04d}.weight.exr", s / f"sample_{k:04d}.inc"


def _blocked_path(outdir: Path, k: int) -> Path:
    return Path(outdir) / "samples" / f"sample_{k:04d}.blocked"


def _sample_done(outdir: Path, k: int) -> bool:
    """Sample k's weights (or pass mask: field meshes) exist, and its image or the
    marker that it has none (all its rays blocked: it is black with weight 0, never
    rendered)."""
    exr, weight, _ = _sample_paths(outdir, k)
    return ((weight.exists() or mask_path(outdir, k).exists())  # or a group's (groups.py)
            and (exr.exists() or _blocked_path(outdir, k).exists())) or grouped(outdir, k)


def sample_weight(outdir: str | os.PathLike, k: int, plan: Plan | None = None,
                  table=None) -> np.ndarray:
    """(H, W) float32 radiometric weights of rendered lens sample k of a mesh folder
    (0 where its rays are blocked or its rows do not reach): the weight image of
    per-pixel meshes, computed from the pass mask for field meshes.  ``plan`` and
    ``table`` (the pupil table) are read when not given."""
    outdir = Path(outdir)
    plan = read_plan(outdir) if plan is None else plan
    if plan.field_mesh is None:
        return read_image(_sample_paths(outdir, k)[1])[..., 0]
    if table is None:
        table = pupil_table_for(outdir, plan, lens_for(plan))
    return field_sample_weight(plan, table, outdir, k)


def sample_rows(plan: Plan, k: int) -> tuple[int, int]:
    """Film rows [start, end) sample k renders (all rows unless the plan is adaptive)."""
    return plan.rows_of_sample(k)


def samples_per_pixel(plan: Plan) -> np.ndarray:
    """(H,) number of samples whose rows include each film row (N_p of a pixel)."""
    h = plan.film.height_px
    n = np.zeros(h, dtype=np.int64)
    for k in range(plan.inputs.samples):
        r0, r1 = sample_rows(plan, k)
        n[r0:r1] += 1
    return n


def _write_mesh(plan: Plan, lens, table, outdir: Path, k: int,
                points: np.ndarray | None = None) -> bool:
    """Write sample k's ray mesh and weights.

    ``table`` is the lens sampler (the plan's exit-pupil table; any object with
    the ``sample(film_xy, u)`` protocol of :func:`povlens.pupil.rays.sample_rays`
    works).  ``points`` overrides the plan's (H, W, 4) sample points of sample k
    (default: :func:`povlens.pupil.rays.sample_points`); :mod:`povlens.bench`
    uses both to render with the baseline samplers and random points.  A plan
    with field meshes writes its sample with
    :func:`povlens.rendering.field_samples.write_field_sample` (no ``points``).
    """
    exr, weight_path, inc = _sample_paths(outdir, k)
    if plan.field_mesh is not None:
        if points is not None:
            raise PovlensError("field-mesh samples share one pupil point per sample: "
                               "they take no per-pixel sample points",
                               "convert with --ray-mesh pixel")
        if write_field_sample(plan, lens, table, outdir, k, inc):
            return True
        write_text(_blocked_path(outdir, k), "%d %d\n" % plan.rows_of_sample(k))
        return False
    film = plan.film
    placement = placement_of(plan)
    inp = plan.inputs
    if points is None:
        points = sample_points(inp.samples, film.height_px, film.width_px, inp.seed)(k)
    else:
        points = np.array(points, dtype=np.float64)
    if not inp.jitter:
        points[..., :2] = 0.5  # pixel centres, as POV-Ray's perspective camera
    table = pixel_sampler(plan, lens, table)    # the band with --dispersion; an iris's domain
    if inp.dispersion:                           # sample k's wavelength
        lens = sample_lens(plan, lens, k)
    r0, r1 = sample_rows(plan, k)
    rays = sample_rays(lens, plan.focus.film_distance_mm, film, table, placement, points,
                       rows=(r0, r1))  # rows this sample does not render: no rays, weight 0
    valid, weight = rays.valid, rays.weight
    if not np.any(weight[r0:r1] > 0):
        # every ray of its rows blocked: black, weight 0, nothing to render
        write_exr(weight_path, np.zeros(weight.shape + (1,), dtype=np.float32))
        write_text(_blocked_path(outdir, k), f"{r0} {r1}\n")
        return False
    part = inc.with_name(inc.name + ".part")
    t = write_ray_mesh(part, "PovlensRays", rays.origin, rays.direction, valid,
                       sink_centre=plan.sink_centre)
    with open(part, "a") as f:
        f.write(f"#declare PovlensTranslate = <{t[0]:.17g}, {t[1]:.17g}, {t[2]:.17g}>;\n")
    os.replace(part, inc)
    write_exr(weight_path, weight[..., None].astype(np.float32))
    return True


def film_row_args(povray: PovraySettings, rows: tuple[int, int]) -> list[str]:
    """POV-Ray's +SR/+ER switches rendering only the film rows ``rows``.

    Parameters
    ----------
    povray : the plan's POV-Ray settings (``drop_top_rows``, ``render_height``).
    rows : film rows [r0, r1), 0 = top.

    Returns
    -------
    list of str
        Output row = film row + drop_top_rows (:func:`povlens.pov.process.pixel_range_args`);
        the columns before ``drop_right_columns`` when there are such.
    """
    r0, r1 = rows
    drop = povray.drop_top_rows
    cols = []
    if povray.drop_right_columns:       # field meshes: the last column is not traced
        cols = pixel_range_args(0, povray.render_width - povray.drop_right_columns,
                                povray.render_width, "col")
    return cols + pixel_range_args(r0 + drop, r1 + drop, povray.render_height, "row")


#: POV-Ray switches of a lens sample's render after the user's options: no
#: anti-aliasing, which would take rays between pixels from the neighbouring pixels'
#: mesh faces (the plan's notes say so when the user's options turn it on).
MESH_SWITCHES = ("-A",)

#: POV-Ray processes in flight per core (``render_outdir``) or per batch (``povlens
#: render-batch``): each run idles ~0.6 s in start-up, so several overlap on a core
#: (measurements: docs/decisions/planning.md, "POV-Ray processes in flight").
POVRAY_IN_FLIGHT = 4


class _SampleRenders:
    """POV-Ray processes rendering single lens samples of a batch, at most
    ``limit`` at once.  :meth:`start` returns once a slot is free; :meth:`finish`
    waits for all.  Each sample renders into its own temporary folder (stderr to a
    file there, so a chatty scene cannot fill a pipe) and is renamed to
    ``sample_KKKK.exr`` when POV-Ray succeeds; its mesh is deleted then."""

    def __init__(self, plan: Plan, outdir: Path, batch: int, limit: int = POVRAY_IN_FLIGHT,
                 on_done=None):
        self.plan, self.outdir, self.batch = plan, Path(outdir), batch
        self.on_done = on_done
        self.samples = self.outdir / "samples"
        self.limit = max(1, int(limit))
        self.running: dict[int, tuple[subprocess.Popen, Path, float]] = {}
        self.povray_s = 0.0
        self.povray_options = povray_options_of(plan.inputs)   # the user's, checked once

    def start(self, k: int) -> None:
        while len(self.running) >= self.limit:
            self._reap(block=True)
        pv = self.plan.povray
        pov = self.samples / f"batch_{self.batch:03d}.pov"
        tmp = Path(tempfile.mkdtemp(prefix=f".sample_{k:04d}.", dir=self.samples))
        try:        # until the process is tracked, the folder is this call's to remove
            rel = os.path.relpath(tmp, self.samples)
            switches = render_switches(
                "f.exr", pv.render_width, pv.render_height, threads=1,
                library_paths=[Path(self.plan.inputs.scene).parent],
                povray_options=self.povray_options,
                extra_args=[*MESH_SWITCHES, f"Declare=PovlensFrame={k}",
                            *film_row_args(pv, render_rows(self.plan, k))])
            cmd = povray_command(find_povray(), pov.name, f"{rel}/f.exr", switches)
            with interrupts_deferred(), open(tmp / "stderr.txt", "w") as err:
                proc = start_povray(cmd, self.samples, err)
                self.running[k] = (proc, tmp, time.perf_counter())   # abort() sees it
        except BaseException:
            if k in self.running:
                raise           # tracked: abort() stops it and removes the folder
            if "proc" in locals():
                proc.kill()
                proc.wait()
            shutil.rmtree(tmp, ignore_errors=True)
            raise

    def _finished(self, k: int, proc: subprocess.Popen, tmp: Path) -> bool:
        """POV-Ray exited, or wrote and closed its image (it then idles ~0.3 s
        before exiting: :func:`povlens.pov.process.povray_finished`)."""
        return povray_finished(proc, tmp / "f.exr", time.perf_counter() - self.running[k][2])

    def _reap(self, block: bool) -> None:
        while True:
            done = [k for k, (p, tmp, _) in self.running.items() if self._finished(k, p, tmp)]
            if done or not block:
                break
            time.sleep(0.005)
        for k in done:
            proc, tmp, t0 = self.running.pop(k)
            self.povray_s += time.perf_counter() - t0
            try:
                self._collect(k, proc, tmp)
            finally:
                shutil.rmtree(tmp, ignore_errors=True)
                _sample_paths(self.outdir, k)[2].unlink(missing_ok=True)
            if self.on_done is not None:
                self.on_done()

    def _collect(self, k: int, proc: subprocess.Popen, tmp: Path) -> None:
        pov = self.samples / f"batch_{self.batch:03d}.pov"
        if proc.returncode != 0:
            stderr = (tmp / "stderr.txt").read_text(errors="replace")
            in_wrapper = error_in_wrapper(pov, self.samples, povray_error_text(stderr, ""))
            if in_wrapper is not None:
                raise PovrayError(*in_wrapper)
            raise PovrayError(f"POV-Ray failed on {pov}, lens sample {k} (exit status "
                              f"{proc.returncode}):\n" + povray_error_text(stderr, ""),
                              "fix the scene, or run 'make' in the folder to see the command")
        out = tmp / "f.exr"
        if not out.exists():
            raise PovrayError(f"POV-Ray rendered lens sample {k} of {pov} but wrote no image",
                              "check free disk space and POV-Ray's permitted paths")
        os.replace(out, _sample_paths(self.outdir, k)[0])

    def finish(self) -> None:
        while self.running:
            self._reap(block=True)

    def abort(self) -> None:
        """Stop every running process (an error, an interrupt, a cancelled guess).
        SIGKILL: what a sample's POV-Ray holds is its temporary folder, deleted here,
        and SIGTERM would run POV-Ray's slow shutdown (docs/decisions/planning.md)."""
        for p, _, _ in self.running.values():
            p.kill()
        for k, (p, tmp, _) in list(self.running.items()):
            p.wait()
            shutil.rmtree(tmp, ignore_errors=True)
            _sample_paths(self.outdir, k)[2].unlink(missing_ok=True)
        self.running.clear()


def render_samples(plan: Plan, lens, sampler, outdir: str | os.PathLike, batch: int,
                   samples, points=None, in_flight: int = POVRAY_IN_FLIGHT,
                   stop=None, on_done=None, plan_for=None) -> dict:
    """Trace, write and render lens samples ``samples`` of batch ``batch``, pipelined.

    For each sample in turn: trace its rays and write its mesh and weights
    (:func:`_write_mesh`), then start its POV-Ray process and go on to the next
    sample while it runs (at most ``in_flight`` at once).  Samples whose rays are
    all blocked are not rendered.  ``sampler`` is the lens sampler (normally the
    plan's exit-pupil table); ``points(k)`` overrides the plan's sample points
    (:mod:`povlens.bench`).  ``stop``: a :class:`threading.Event`; once set, no
    further sample starts and the running ones are stopped.  ``on_done()`` is called
    as each sample is finished (progress).  ``samples`` may be any iterable of
    sample numbers (a generator that waits for more: :class:`EarlyRender`), and
    ``plan_for(k)`` the plan to trace sample k with (default ``plan``; plans that
    differ only in the sample count give the same sample k).  Returns timings: {samples, blocked,
    rays_and_meshes_s (Python), povray_s (summed over the overlapping processes),
    wall_s}.
    """
    outdir = Path(outdir)
    t0 = time.perf_counter()
    t_mesh = 0.0
    blocked = 0
    queue = _SampleRenders(plan, outdir, batch, in_flight, on_done)
    seen: list[int] = []
    try:
        for k in samples:
            if stop is not None and stop.is_set():
                queue.abort()
                break
            seen.append(k)
            t = time.perf_counter()
            ok = _write_mesh(plan if plan_for is None else plan_for(k), lens, sampler, outdir,
                             k, points=None if points is None else points(k))
            t_mesh += time.perf_counter() - t
            if ok:
                queue.start(k)
            else:
                blocked += 1
                if on_done is not None:
                    on_done()
            queue._reap(block=False)
        if stop is not None and stop.is_set():
            queue.abort()   # stopped while waiting for more samples: do not wait for these
        else:
            queue.finish()
    except BaseException:
        queue.abort()
        raise
    finally:
        for k in seen:
            _sample_paths(outdir, k)[2].unlink(missing_ok=True)
    return {"samples": len(seen), "blocked": blocked, "rays_and_meshes_s": t_mesh,
            "povray_s": queue.povray_s, "wall_s": time.perf_counter() - t0}


def render_batch(outdir: str | os.PathLike, batch: int,
                 in_flight: int = POVRAY_IN_FLIGHT) -> list[int]:
    """Render batch ``batch`` of a mesh plan; returns the samples it rendered (resumes)."""
    outdir = Path(outdir)
    plan = read_plan(outdir)
    if plan.inputs.method != "mesh":
        raise PovlensError(f"{outdir} was converted with the {plan.inputs.method} "
                           f"method; it has no sample batches", "use 'povlens render-view'")
    batches = plan.batches
    if not 0 <= batch < len(batches):
        raise PovlensError(f"batch {batch}: {outdir} has batches 0..{len(batches) - 1}")
    done = outdir / "samples" / f"batch_{batch:03d}.done"
    todo = [k for k in batches[batch] if not _sample_done(outdir, k)]
    if todo:
        lens = lens_for(plan)
        table = pupil_table_for(outdir, plan, lens)
        exposure_for(outdir, plan, lens, table)
        timing = render_samples(plan, lens, table, outdir, batch, todo, in_flight=in_flight)
        write_text(outdir / "samples" / f"batch_{batch:03d}.timing.json",
                   json.dumps(timing) + "\n")
    write_text(done, "".join(f"{k}\n" for k in batches[batch]))
    return todo


def render_view(outdir: str | os.PathLike, view: str) -> Path:
    """Render ``pinhole`` or ``focal-blur`` of a converted folder to ``view-<view>.exr``."""
    outdir = Path(outdir)
    plan = read_plan(outdir)
    film = plan.film
    name = {"pinhole": "pinhole.pov", "focal-blur": "focal_blur.pov"}.get(view)
    if name is None:
        raise ParameterError("view", view, f"view={view!r}: unknown view",
                             "use pinhole or focal-blur")
    out = outdir / f"view-{view}.exr"
    final = plan.inputs.method == view.replace("_", "-")
    # the lens's vignetting as a per-pixel map, computed while POV-Ray renders
    # (rendering/vignetting.py); the view itself stays as POV-Ray rendered it
    from povlens.rendering.vignetting import start_vignetting_map
    vignetting = None if not final else start_vignetting_map(
        outdir, plan, lambda: pupil_table_for(outdir, plan, lens_for(plan)))
    if not out.exists():
        povray_render(outdir / name, out, film.width_px, film.height_px,
                      threads=os.cpu_count() or 1,
                      library_paths=[Path(plan.inputs.scene).parent],
                      povray_options=povray_options_of(plan.inputs))
    if final:
        image = read_image(out)[..., :3]
        _finish_image(outdir, image if vignetting is None else vignetting.apply(image))
    return out


def _finish_image(outdir: Path, image: np.ndarray) -> None:
    write_exr(outdir / "image.exr", image.astype(np.float32))
    write_png_srgb(outdir / "image.png", np.clip(image, 0.0, None))


def composite_outdir(outdir: str | os.PathLike, vignetting: bool | None = None,
                     write: bool = True, sums=None) -> np.ndarray:
    """Combine the rendered samples of a mesh plan into image.exr and image.png.

    With ``vignetting`` (the plan's setting when None) the image is the camera
    measurement normalised at the frame centre, darker toward the corners as the
    lens makes it.  Without, each pixel is divided by its own mean weight
    (``sum w I / sum w``), which removes natural and mechanical vignetting and
    leaves the lens's geometry and blur: comparable with POV-Ray's cameras.
    Returns the (H, W, 3) float64 image; ``write=False`` only returns it.  ``sums``:
    the sums over the rendered samples, added in sample order by the caller as they
    came (:func:`sample_sums`; :mod:`povlens.cluster`), instead of reading them here.
    """
    outdir = Path(outdir)
    plan = read_plan(outdir)
    if vignetting is None:
        vignetting = plan.inputs.vignetting
    n = plan.inputs.samples
    drop = plan.povray.drop_top_rows
    missing = [k for k in range(n) if not _sample_done(outdir, k)]
    if missing:
        raise PovlensError(f"{outdir}: samples {missing[:8]}{'...' if len(missing) > 8 else ''} "
                           f"are not rendered yet", "run 'povlens render' or 'make' in the folder")
    lens = lens_for(plan)
    table = pupil_table_for(outdir, plan, lens)
    exposure = exposure_for(outdir, plan, lens, table)
    sums = sums if sums is not None else group_sums(outdir, plan, table, sample_sums)  # groups
    # Blocked samples (all rays blocked) are black with weight 0: they add nothing to
    # the sums but count in N_p.  Adaptive plans: sample k covers only its rows
    # (weight 0 elsewhere) and pixel p's N_p counts the samples covering its row.
    rendered = [k for k in range(n) if not _blocked_path(outdir, k).exists()]
    film = plan.film
    n_p = samples_per_pixel(plan).astype(np.float64)
    if not rendered:
        image = np.zeros((film.height_px, film.width_px, 3))
    else:
        paths = [_sample_paths(outdir, k)[0] for k in rendered]
        # sum w I / sum w, in float64, one sample in memory at a time (composite.py);
        # times sum w / N_p for the measurement
        spectral = plan_channel_factors(plan)    # --dispersion: per-channel weights
        total, wsum = sums if sums is not None else accumulate_samples(
            paths, (sample_weight(outdir, k, plan, table) for k in rendered),
            drop_top_rows=drop, drop_right_columns=plan.povray.drop_right_columns,
            channel_weights=None if spectral is None else spectral[rendered],
            transform=_layout(plan))
        ri = illumination_map(outdir, plan, table) if vignetting else None   # field meshes
        image = measurement_image(total, wsum, n_p, exposure if vignetting else None, ri)
    if write:
        _finish_image(outdir, image.astype(np.float32))
    return image


def _progress(total: int, desc: str, quiet: bool):
    return tqdm(total=total, desc=desc, unit="sample", disable=quiet or not sys.stderr.isatty(),
                file=sys.stderr)


def sample_sums(outdir: str | os.PathLike, k: int, plan: Plan, table):
    """Sample k's terms of :func:`composite_outdir`'s sums (float64 ``w_k I_k``, ``w_k``),
    None if blocked; added in sample order they are its sums bit for bit."""
    outdir = Path(outdir)
    if _blocked_path(outdir, k).exists():
        return None
    spectral = plan_channel_factors(plan)
    return accumulate_samples(
        [_sample_paths(outdir, k)[0]], [sample_weight(outdir, k, plan, table)],
        drop_top_rows=plan.povray.drop_top_rows,
        drop_right_columns=plan.povray.drop_right_columns,
        channel_weights=None if spectral is None else spectral[[k]], transform=_layout(plan))


def _mark_batches_done(outdir: Path, plan: Plan) -> None:
    """Write ``batch_BBB.done`` (make's target) for each batch whose samples are done."""
    for b, ks in enumerate(plan.batches):
        if all(_sample_done(outdir, k) for k in ks):
            write_text(outdir / "samples" / f"batch_{b:03d}.done", "".join(f"{k}\n" for k in ks))


sample_done, mark_batches_done = _sample_done, _mark_batches_done  # public (cluster)


def render_outdir(outdir: str | os.PathLike, jobs: int | None = None, quiet: bool = False,
                  in_flight: int | None = None) -> Path:
    """Render everything a converted folder needs and composite.

    Mesh plans: every lens sample not yet rendered, in this process
    (:func:`render_samples`: trace, write the mesh, start its POV-Ray process, go
    on), with up to ``in_flight`` POV-Ray processes at once (default
    :data:`POVRAY_IN_FLIGHT` per core, ``jobs`` cores, default all).  One process
    with the lens and pupil table in memory is faster than a worker process per
    batch: a worker's Python start-up costs more than the tracing it would share
    (docs/decisions/planning.md).  ``make -jN`` in the folder renders its batches
    in parallel processes (``povlens render-batch``)."""
    outdir = Path(outdir)
    plan = read_plan(outdir)
    method = plan.inputs.method
    if method != "mesh":
        render_view(outdir, method)
        return outdir / "image.exr"
    jobs = jobs or os.cpu_count() or 1
    in_flight = in_flight or POVRAY_IN_FLIGHT * jobs
    todo = [k for k in range(plan.inputs.samples) if not _sample_done(outdir, k)]
    if todo:
        lens = lens_for(plan)
        table = pupil_table_for(outdir, plan, lens)

        def samples():
            yield from todo
            # every sample is written and its POV-Ray started: the composite's
            # exposure is computed while they run (not after)
            exposure_for(outdir, plan, lens, table)

        with _progress(len(todo), "lens samples", quiet) as bar:
            timing = render_samples(plan, lens, table, outdir, 0, samples(),
                                    in_flight=in_flight, on_done=lambda: bar.update(1))
        write_text(outdir / "samples" / "render.timing.json", json.dumps(timing) + "\n")
    _mark_batches_done(outdir, plan)
    composite_outdir(outdir)
    return outdir / "image.exr"


class EarlyRender:
    """Lens samples rendered in a thread of this process while
    :func:`povlens.plan.convert.convert` goes on (its ``render_early``): those of a
    provisional plan at first, then, after :meth:`extend`, those the final plan
    adds, without draining the POV-Ray pipeline in between.  The lens and pupil
    table are already in memory.  :meth:`wait` waits for the samples given so far
    and raises what the render raised; :meth:`cancel` stops it (what it finished
    stays)."""

    def __init__(self, outdir: Path, plan: Plan, lens, table, in_flight: int, quiet: bool):
        self._outdir = Path(outdir)
        self._stop = threading.Event()
        self._more = threading.Condition()
        self._closed = False
        self._error: BaseException | None = None
        self._plans = {k: plan for k in range(plan.inputs.samples)}
        self._todo = [k for k in range(plan.inputs.samples)
                      if not _sample_done(self._outdir, k)]
        self._final = plan
        self._lens, self._table = lens, table
        self._bar = _progress(len(self._todo), "lens samples", quiet)
        self._thread = threading.Thread(target=self._run, args=(lens, table, in_flight),
                                        daemon=True)
        self._thread.start()

    def _samples(self):
        i = 0
        exposure_known = False
        while True:
            if i >= len(self._todo) and not exposure_known and not self._stop.is_set():
                # nothing to write until the decision adds samples: the composite's
                # exposure is computed now, while POV-Ray runs, instead of after
                exposure_for(self._outdir, self._final, self._lens, self._table)
                exposure_known = True
            with self._more:
                while i >= len(self._todo) and not self._closed and not self._stop.is_set():
                    self._more.wait(0.05)
                if i >= len(self._todo) or self._stop.is_set():
                    return
                k = self._todo[i]
            i += 1
            yield k

    def _run(self, lens, table, in_flight):
        try:
            timing = render_samples(self._final, lens, table, self._outdir, 0, self._samples(),
                                    in_flight=in_flight, stop=self._stop,
                                    on_done=lambda: self._bar.update(1),
                                    plan_for=lambda k: self._plans[k])
            if timing["samples"]:
                write_text(self._outdir / "samples" / "early.timing.json",
                           json.dumps(timing) + "\n")
            if not self._stop.is_set():
                _mark_batches_done(self._outdir, self._final)
        except BaseException as e:      # handed to wait()
            self._error = e
        finally:
            self._bar.close()

    def extend(self, plan: Plan) -> None:
        """Render also the samples ``plan`` (the final plan, more samples than the
        provisional one) adds."""
        with self._more:
            new = [k for k in range(plan.inputs.samples) if k not in self._plans]
            self._plans.update({k: plan for k in new})
            self._todo += [k for k in new if not _sample_done(self._outdir, k)]
            self._final = plan
            self._bar.total = len(self._todo)
            self._bar.refresh()
            self._more.notify_all()

    def wait(self) -> None:
        with self._more:
            self._closed = True
            self._more.notify_all()
        self._thread.join()
        if self._error is not None:
            raise self._error

    def cancel(self) -> None:
        self._stop.set()
        with self._more:
            self._more.notify_all()
        self._thread.join()


def convert_and_render(opts: ConvertOptions, jobs: int | None = None, quiet: bool = False,
                       on_plan=None, depth_probe=None) -> tuple[Plan, Path]:
    """What ``povlens render`` does: convert ``opts`` and render the folder
    (:func:`render_outdir`).

    With --method auto, the render auto is likely to choose starts while its depth
    probe runs (``speculate`` of :func:`povlens.plan.convert.convert`): the adaptive
    focal_blur view, or, when the lens alone rules out the views, the first lens
    samples of the mesh render (``render_early``).  ``on_plan(plan)`` is called
    between conversion and rendering; ``depth_probe`` goes to ``convert`` (a focus
    pull's frames share one probe).  Returns (plan, path of image.exr)."""
    jobs = jobs or os.cpu_count() or 1

    def render_early(plan, lens, table):
        return EarlyRender(Path(opts.outdir), plan, lens, table, POVRAY_IN_FLIGHT * jobs,
                           quiet)

    plan = convert(dataclasses.replace(opts, speculate=True), render_early=render_early,
                   depth_probe=depth_probe)
    if on_plan is not None:
        on_plan(plan)
    return plan, render_outdir(opts.outdir, jobs=jobs, quiet=quiet)
