"""The render folder's layout (povlens.plan.render_folder): every name as render folders
have always spelled it (folders written before stay readable and resumable), markers,
what a changed plan drops, the small files' readers.  No POV-Ray."""

from __future__ import annotations

import numpy as np
import pytest

from povlens.errors import PovlensError
from povlens.plan.render_folder import VIEWS, FramesFolder, RenderFolder
from povlens.pov.sdl import read_template
from povlens.util.images import write_exr


def test_the_names_are_those_render_folders_have():
    f = RenderFolder("out")
    rel = {name: str(getattr(f, name)) for name in (
        "plan_json", "pupil_npz", "makefile", "exposure_txt", "illumination_json", "image_exr",
        "image_png", "samples", "speculative_wrapper", "speculative_view")}
    assert rel == {"plan_json": "out/plan.json", "pupil_npz": "out/pupil.npz",
                   "makefile": "out/Makefile", "exposure_txt": "out/exposure.txt",
                   "illumination_json": "out/illumination.json", "image_exr": "out/image.exr",
                   "image_png": "out/image.png", "samples": "out/samples",
                   "speculative_wrapper": "out/.speculative-focal-blur.pov",
                   "speculative_view": "out/.speculative-focal-blur.exr"}
    assert [str(f.wrapper(v)) for v in VIEWS] == ["out/pinhole.pov", "out/focal_blur.pov"]
    assert str(f.view_image("focal-blur")) == "out/view-focal-blur.exr"
    k = 7
    assert [f.sample_image(k).name, f.sample_weight(k).name, f.sample_mask(k).name,
            f.sample_transmission(k).name, f.sample_blocked(k).name, f.sample_mesh(k).name] == [
        "sample_0007.exr", "sample_0007.weight.exr", "sample_0007.mask.npy",
        "sample_0007.transmission.npy", "sample_0007.blocked", "sample_0007.inc"]
    assert str(f.sample_image(12345)) == "out/samples/sample_12345.exr"
    assert f.sample_temp_prefix(3) == ".sample_0003."
    assert f.partial(f.sample_mesh(3)).name == "sample_0003.inc.part"
    assert [f.batch_wrapper(2).name, f.batch_done(2).name, f.batch_timing(2).name] == [
        "batch_002.pov", "batch_002.done", "batch_002.timing.json"]
    assert f.timing("cluster").name == "cluster.timing.json"
    assert str(f.group_file(16, 32)) == "out/samples/group_0016_0032.npz"


def test_the_templates_get_the_names(tmp_path):
    names = RenderFolder(".").makefile_names(3)
    assert names["batch_dones"] == ("samples/batch_000.done samples/batch_001.done "
                                    "samples/batch_002.done")
    assert names["batch_done_rule"] == "samples/batch_%.done"
    batch = read_template("mesh_batch.pov.tmpl").substitute(
        RenderFolder.mesh_include_names(), scene_include='"s.pov"', sink_centre="<0, 0, 0>",
        sink_radius="1", photons="")
    assert '#include concat("sample_", str(PovlensFrame, -4, 0), ".inc")' in batch
    ph = RenderFolder.photon_map_names()
    assert RenderFolder(tmp_path).photon_map_partial(123456).name == "photons-123456.tmp"
    assert ph["save"] == 'concat("photons-", str(PovlensPhotonSave, 0, 0), ".tmp")'
    assert ph["load"] == '"../photons.ph"' and RenderFolder(tmp_path).photon_map.name == "photons.ph"


def test_a_sample_is_done_with_its_weights_and_image_or_blocked_marker(tmp_path):
    f = RenderFolder(tmp_path)
    f.samples.mkdir()
    assert not f.sample_done(0)
    f.sample_weight(0).write_bytes(b"")
    assert not f.sample_done(0)                      # weights without an image
    f.sample_blocked(0).write_text("0 4\n")
    assert not f.sample_done(0)                      # a marker its weights cannot confirm
    write_exr(f.sample_weight(0), np.zeros((4, 3, 1), np.float32))
    assert f.sample_done(0) and f.blocked(0)         # weights all 0: blocked indeed
    f.write_pass_mask(1, np.ones((2, 3), bool))      # field meshes: the mask, no weights
    f.sample_image(1).write_bytes(b"")
    assert f.sample_done(1)
    f.sample_mesh(1).write_text("mesh")
    assert [p.name for p in f.sample_outputs(1)] == ["sample_0001.exr", "sample_0001.mask.npy"]
    f.mark_batch_done(0, [0, 1])                     # the files make checks
    assert f.batch_done(0).read_text().split() == [
        "samples/sample_0000.blocked", "samples/sample_0000.weight.exr",
        "samples/sample_0001.exr", "samples/sample_0001.mask.npy"]


def test_a_blocked_marker_is_trusted_only_when_its_files_agree(tmp_path):
    f = RenderFolder(tmp_path)
    f.samples.mkdir()
    f.write_pass_mask(0, np.zeros((2, 3), bool))
    f.sample_blocked(0).write_text("0 2\n")
    assert f.blocked(0) and f.sample_done(0) and f.sample_damage(0) is None
    f.write_pass_mask(0, np.ones((2, 3), bool))      # the mask passes light
    assert not f.blocked(0) and not f.sample_done(0)
    path, why = f.sample_damage(0)
    assert path == f.sample_blocked(0) and "passes 6 pixels" in why
    f.sample_image(0).write_bytes(b"")               # a stray marker beside an image
    assert not f.blocked(0) and f.sample_done(0)
    f.sample_mask(0).write_bytes(b"")                # an empty mask: damaged, named
    assert not f.sample_done(0)
    path, why = f.sample_damage(0)
    assert path == f.sample_mask(0) and "cannot read the sample's pass mask" in why


def test_a_changed_plan_drops_its_outputs(tmp_path):
    f = RenderFolder(tmp_path)
    f.samples.mkdir()
    for p in (f.image_exr, f.image_png, f.view_image("pinhole"), f.exposure_txt,
              f.illumination_json, f.pupil_npz, f.batch_done(0), f.timing("render"),
              f.sample_image(0), f.sample_weight(0), f.sample_mask(1), f.sample_blocked(2),
              f.batch_wrapper(0)):
        p.write_bytes(b"")
    kept_samples = set(f.outputs_to_drop([2]))
    assert f.sample_blocked(2) in kept_samples and f.sample_image(0) not in kept_samples
    assert f.exposure_txt not in kept_samples
    every = set(f.outputs_to_drop(None))
    assert {f.sample_image(0), f.sample_weight(0), f.sample_mask(1), f.exposure_txt,
            f.illumination_json, f.image_exr, f.view_image("pinhole"), f.batch_done(0)} <= every
    assert f.pupil_npz not in every and f.batch_wrapper(0) not in every


def test_the_small_files_read_back_and_damage_is_named(tmp_path):
    f = RenderFolder(tmp_path)
    f.samples.mkdir()
    assert f.read_exposure() is None
    f.write_exposure(0.1 + 0.2)
    assert f.read_exposure() == 0.1 + 0.2                      # repr: bit for bit
    f.exposure_txt.write_text("garbage")
    assert f.read_exposure() is None
    mask = np.random.default_rng(0).random((5, 11)) > 0.5
    f.write_pass_mask(3, mask)
    np.testing.assert_array_equal(f.read_pass_mask(3, 5, 11), mask)
    with pytest.raises(PovlensError, match="mask"):
        f.read_pass_mask(3, 6, 11)
    f.sample_mask(3).write_bytes(b"not a mask")
    with pytest.raises(PovlensError, match="sample_0003.mask.npy"):
        f.read_pass_mask(3, 5, 11)
    f.write_transmission(3, np.full((5, 11), 0.5, np.float32))
    assert f.read_transmission(3).dtype == np.float32
    with pytest.raises(PovlensError, match="sample_0004.transmission.npy"):
        f.read_transmission(4)


def test_a_focus_pulls_folder(tmp_path):
    frames = FramesFolder(tmp_path)
    assert frames.frame_name(2) == "frame-0002"
    assert frames.image_name(2, "png") == "image.0002.png"
    assert frames.frame("frame-0002").plan_json == tmp_path / "frame-0002" / "plan.json"
    assert not frames.is_frames_folder()
    frames.frames_json.write_text("{}")
    assert frames.is_frames_folder()
    RenderFolder(tmp_path).plan_json.write_text("{}")      # a render folder is not one
    assert not frames.is_frames_folder()
