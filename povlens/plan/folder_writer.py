"""Writing a render folder from its plan: plan.json, POV-Ray wrappers, the Makefile.

OUTDIR (file names: :class:`povlens.plan.render_folder.RenderFolder`) gets

* ``plan.json`` (:func:`povlens.plan.schema.write_plan`);
* ``pinhole.pov`` and ``focal_blur.pov``: wrappers that ``#include`` the scene and
  declare their own camera last (POV-Ray uses the last camera);
* for the mesh method, ``samples/batch_NNN.pov``: wrappers that render one lens
  sample each per POV-Ray run (the sample's ray mesh is written just before,
  :mod:`povlens.rendering.mesh_samples`);
* ``Makefile``: ``make -C OUTDIR -j2`` renders and composites; a second ``make``
  does nothing.  A batch's marker lists its samples' files
  (:meth:`~povlens.plan.render_folder.RenderFolder.mark_batch_done`) and the Makefile
  reads it: when one of them is gone (a damaged sample deleted) the batch renders
  again.  Its recipes run side by side under the folder's shared lock
  (:mod:`povlens.plan.folder_lock`).

Files whose text is unchanged are left alone (make compares modification
times), and what an earlier plan rendered that the new one cannot use is removed.
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

from povlens.errors import PovlensError
from povlens.plan.render_folder import VIEWS, RenderFolder
from povlens.plan.schema import FocalBlurSettings, Plan, read_plan, write_plan
from povlens.pov.mesh import (SINK_RADIUS, focal_blur_wrapper, photon_map_block, pinhole_wrapper,
                              pretrace_block)
from povlens.pov.povray_paths import include_text
from povlens.pov.sdl import pov_string, pov_vector, read_template
from povlens.util.files import write_text

__all__ = ["write_folder", "write_if_changed", "focal_blur_text", "blur_settings",
           "stale_samples", "invalidate_outputs", "SAMPLE_INDEPENDENT_INPUTS",
           "write_pinhole_wrapper"]

#: Plan inputs that do not change what lens sample k renders: the sample count
#: (scrambled-Sobol point k is the same for any count), how samples are batched,
#: and how the method and count were chosen.  A change of these keeps rendered
#: samples whose row range is unchanged.
SAMPLE_INDEPENDENT_INPUTS = ("samples", "batch_size", "adaptive", "requested_method",
                             "tolerance_px", "auto_samples")


def write_if_changed(path: Path, text: str) -> None:
    """Write atomically, but leave an identical file alone (make compares mtimes)."""
    try:
        if path.read_text() == text:
            return
    except OSError:
        pass
    write_text(path, text)


def _scene_include(plan: Plan, outdir: Path, wrapper_dir: Path | None = None) -> str:
    """How a wrapper in ``wrapper_dir`` (default ``outdir``) includes the scene: its
    relative path, or the folder's ASCII link to it (:func:`include_text`)."""
    return include_text(plan.inputs.scene, wrapper_dir or outdir,
                        RenderFolder(outdir).scene_link)


def write_pinhole_wrapper(outdir: Path, scene: str, camera, photon_settings: str | None
                          ) -> Path:
    """Write the folder's ``pinhole.pov``: ``scene`` through the plan's pinhole
    ``camera`` (a :class:`~povlens.plan.schema.PovrayCamera`), with the photons block
    that saves the map when ``photon_settings`` (the plan's ``povray.photon_settings``)
    are shared.  :func:`write_folder` writes it; a render that makes the radiosity
    samples before the plan is finished writes the same text first."""
    folder = RenderFolder(outdir)
    ph = RenderFolder.photon_map_names()
    path = folder.wrapper("pinhole")
    write_if_changed(path, pinhole_wrapper(
        include_text(scene, outdir, folder.scene_link), camera.location, camera.direction,
        camera.right, camera.up,
        photons=photon_map_block(photon_settings, "save_file", ph["save"], ph["save_flag"])))
    return path


def blur_settings(plan: Plan, settings: FocalBlurSettings | None = None) -> dict:
    """focal_blur sampling of a plan as :func:`povlens.pov.mesh.focal_blur_wrapper`
    takes it: ``blur_samples`` min and max, and the confidence and variance of
    POV-Ray's adaptive sampling.  ``settings`` (default: those --method auto chose,
    unless ``--samples`` was given) replace the fixed ``samples, samples``."""
    if settings is None and plan.decision is not None and plan.inputs.auto_samples is not False:
        settings = plan.decision.focal_blur
    if settings is not None:
        return {"blur_samples": settings.min_samples, "max_blur_samples": settings.max_samples,
                "confidence": settings.confidence, "variance": settings.variance}
    n = int(plan.inputs.samples)
    return {"blur_samples": n, "max_blur_samples": n, "confidence": None, "variance": None}


def focal_blur_text(plan: Plan, outdir: Path, settings: FocalBlurSettings | None = None) -> str:
    """The text of ``focal_blur.pov`` of ``plan`` in ``outdir`` (sampling:
    :func:`blur_settings`)."""
    cam = plan.povray_camera
    return focal_blur_wrapper(
        _scene_include(plan, outdir), cam.location, cam.direction, cam.right, cam.up,
        aperture=cam.aperture, focal_distance=cam.focal_distance,
        **blur_settings(plan, settings))


def _batch_wrapper(plan: Plan, outdir: Path) -> str:
    """Animation wrapper (templates/mesh_batch.pov.tmpl): frame k renders sample k."""
    scene = _scene_include(plan, outdir, RenderFolder(outdir).samples)
    names = RenderFolder.mesh_include_names()
    ph = RenderFolder.photon_map_names()
    photons = photon_map_block(plan.povray.photon_settings, "load_file", ph["load"],
                               ph["load_flag"])
    if plan.field_mesh is not None:
        film = plan.film
        pretrace = pretrace_block(plan.povray.radiosity_pretrace,
                                  (film.width_px, film.height_px), plan.field_mesh.interleave)
        return read_template("field_batch.pov.tmpl").substitute(
            names, scene_include=pov_string(scene), photons=photons,
            pretrace=pretrace or "// (the scene's own radiosity pretrace, if any, is kept)")
    return read_template("mesh_batch.pov.tmpl").substitute(
        names, scene_include=pov_string(scene), sink_centre=pov_vector(plan.sink_centre),
        sink_radius=f"{SINK_RADIUS:.9g}", photons=photons)


def _makefile(plan: Plan) -> str:
    """The folder's Makefile (templates/Makefile.tmpl)."""
    method = plan.inputs.method
    names = RenderFolder(".").makefile_names(len(plan.batches))
    image, plan_json = names["image_png"], names["plan_json"]
    if method == "mesh":
        rules = (f"{image}: {names['batch_dones']}\n\t$(POVLENS) composite .\n\n"
                 f"{names['batch_done_rule']}: {plan_json}\n\t$(POVLENS) render-batch . $*\n\n"
                 + "".join(f"{done}: $(if $(call povlens_gone,{done}),FORCE)\n"
                           for done in names["batch_dones"].split()))
    else:
        wrapper = VIEWS["pinhole" if method == "pinhole" else "focal-blur"]
        rules = (f"{image}: {plan_json} {wrapper}\n"
                 f"\t$(POVLENS) render-view . --view {method}\n")
    return read_template("Makefile.tmpl").substitute(
        names, povlens=f"{shlex.quote(sys.executable)} -m povlens", rules=rules)


def _sample_layout(plan: Plan):
    """The field samples' pupil domain and interleave (they move every sample's rays)."""
    fm = plan.field_mesh
    return None if fm is None else (fm.domain, fm.interleave)


def stale_samples(old: Plan, new: Plan) -> list[int] | None:
    """Samples of the old plan that the new plan cannot reuse: ``None`` = all (an
    input that changes every sample differs), else those whose rows changed or
    that the new plan no longer has."""
    oi = {k: v for k, v in old.inputs.to_dict().items() if k not in SAMPLE_INDEPENDENT_INPUTS}
    ni = {k: v for k, v in new.inputs.to_dict().items() if k not in SAMPLE_INDEPENDENT_INPUTS}
    if oi != ni or _sample_layout(old) != _sample_layout(new):
        return None
    n_old, n_new = int(old.inputs.samples), int(new.inputs.samples)
    return [k for k in range(n_old)
            if k >= n_new or old.rows_of_sample(k) != new.rows_of_sample(k)]


def invalidate_outputs(outdir: Path, stale: list[int] | None = None) -> None:
    """Inputs changed: drop what no longer belongs to the plan.  ``stale`` lists the
    lens samples to drop (None = every sample, and exposure.txt, which depends on
    the lens, focus and film); images, views and batch markers always go."""
    # pupil.npz stays: load_if_current checks its inputs.  A sample's mesh (.inc)
    # goes with the sample: one still wanted may be in use by a running render.
    for f in RenderFolder(outdir).outputs_to_drop(stale):
        f.unlink(missing_ok=True)


def write_folder(outdir: Path, plan: Plan) -> None:
    """Write a plan's files into ``outdir``: plan.json, the wrappers, the Makefile.

    What an earlier plan in the folder rendered that this one cannot use is
    removed first (:func:`stale_samples`, :func:`invalidate_outputs`)."""
    outdir = Path(outdir)
    folder = RenderFolder(outdir)
    old = None
    if folder.plan_json.exists():
        try:
            old = read_plan(outdir)
        except PovlensError:
            old = None
    if old is not None and (old.inputs.to_dict() != plan.inputs.to_dict()
                            or _sample_layout(old) != _sample_layout(plan)):
        invalidate_outputs(outdir, stale_samples(old, plan))
    write_pinhole_wrapper(outdir, plan.inputs.scene, plan.povray_camera,
                          plan.povray.photon_settings)
    write_if_changed(folder.wrapper("focal-blur"), focal_blur_text(plan, outdir))
    if plan.inputs.method == "mesh":
        folder.samples.mkdir(exist_ok=True)
        text = _batch_wrapper(plan, outdir)
        for b, _ in enumerate(plan.batches):
            write_if_changed(folder.batch_wrapper(b), text)
    write_if_changed(folder.makefile, _makefile(plan))
    write_plan(plan, outdir)
