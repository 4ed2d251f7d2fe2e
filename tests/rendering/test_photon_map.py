"""Photons shot once for all lens samples (issue 25): a mesh plan of a scene with photons
repeats the scene's own photons items in a block that saves the map (one small pinhole
render) and in one that loads it (every lens sample); the image is the one each sample
shooting its own photons gives."""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest

from povlens.pov.sdl import parse_scene_camera
from povlens.util.images import read_image
from tests.rendering.test_radiosity_cache import SIZE, _povlens

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")

# A glass ball focusing a light's photons onto the floor (a caustic); the photons
# block's spacing is a declared name, and one item sits in an #if.
PHOTON_SCENE = """#version 3.7;
#declare PhotonSpacing = 0.02;
global_settings { assumed_gamma 1 max_trace_level 10
  photons { spacing PhotonSpacing autostop 0 #if (1) jitter 0 #end } }
camera { location <0, 2, -3> look_at <0, 0.3, 0> }
light_source { <2, 4, -1> rgb 1.5 photons { refraction on reflection on } }
plane { y, 0 pigment { rgb 0.8 } }
sphere { <0, 0.6, 0>, 0.5 pigment { rgbf <1, 1, 1, 0.95> }
  interior { ior 1.5 } photons { target refraction on reflection on } }
"""


def test_the_scene_reader_repeats_the_photons_block_with_values(tmp_path):
    scene = tmp_path / "p.pov"
    scene.write_text(PHOTON_SCENE)
    cam = parse_scene_camera(scene, 48, 36)
    assert "photons" in cam.global_settings
    assert cam.photon_settings == "spacing 0.02 autostop 0 jitter 0"
    scene.write_text(PHOTON_SCENE.replace("jitter 0 #end", 'jitter 0 #end save_file "x.ph"'))
    assert parse_scene_camera(scene, 48, 36).photon_settings == ""     # the scene's own file
    scene.write_text(PHOTON_SCENE.replace("photons { spacing", "radiosity { count 9 } photons "
                                          "{ expand_thresholds 0.2, 40 spacing"))
    assert parse_scene_camera(scene, 48, 36).photon_settings.startswith(
        "expand_thresholds 0.2 , 40 spacing 0.02")


def test_one_photon_map_gives_the_image_each_sample_shooting_its_own_gives(tmp_path):
    scene = tmp_path / "p.pov"
    scene.write_text(PHOTON_SCENE)
    shared = tmp_path / "shared"
    _povlens("render", scene, *SIZE, "-o", shared)
    plan = json.loads((shared / "plan.json").read_text())
    assert plan["povray"]["photon_settings"] == "spacing 0.02 autostop 0 jitter 0"
    assert any(n.startswith("photons: they are shot once") for n in plan["notes"])
    assert (shared / "photons.ph").stat().st_size > 0
    assert not list(shared.glob("photons-*"))                 # the partial map renamed
    # the same folder with the photons settings taken out of its plan: make renders
    # every sample shooting its own photons
    own = tmp_path / "own"
    shutil.copytree(shared, own)
    plan["povray"].pop("photon_settings")
    (own / "plan.json").write_text(json.dumps(plan))
    for f in [own / "photons.ph", own / "image.exr", own / "image.png",
              *own.glob("samples/*.exr"), *own.glob("samples/*.npy"),
              *own.glob("samples/*.done")]:
        f.unlink()
    r = subprocess.run(["make", "-s", "-C", str(own), "-j2"], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    assert not (own / "photons.ph").exists()
    a = read_image(shared / "image.exr")[..., :3]
    b = read_image(own / "image.exr")[..., :3]
    assert a.mean() > 0.05
    # the scene's own photons settings matter: POV-Ray's pinhole render of this scene
    # with 'photons { spacing 0.5 }' (what a bare block of povlens's own would have
    # kept of them) is RMSE 0.040 from its own at 96x72
    assert np.sqrt(np.mean((a - b) ** 2)) < 1e-3 * a.max()


def test_a_photons_block_povlens_cannot_repeat_leaves_each_sample_its_own(tmp_path):
    scene = tmp_path / "p.pov"
    scene.write_text(PHOTON_SCENE.replace("jitter 0 #end", 'jitter 0 #end save_file "own.ph"'))
    out = tmp_path / "o"
    _povlens("convert", scene, *SIZE[:-1], "-o", out)
    plan = json.loads((out / "plan.json").read_text())
    assert "photon_settings" not in plan["povray"]
    assert any(n.startswith("photons: povlens cannot repeat") for n in plan["notes"])
    assert "PovlensPhoton" not in (out / "pinhole.pov").read_text()


def test_a_scene_that_writes_files_shares_nothing(tmp_path):
    """A scene that opens a file to write while it is parsed may not be the same scene
    from run to run: no photon map, no shared radiosity, a note naming the #fopen."""
    scene = tmp_path / "p.pov"
    scene.write_text('#fopen Log "log.txt" write\n#write (Log, "run\\n")\n#fclose Log\n'
                     + PHOTON_SCENE.replace("photons { spacing", "radiosity { count 9 } "
                                            "photons { spacing"))
    out = tmp_path / "o"
    _povlens("convert", scene, *SIZE[:-1], "-o", out)
    plan = json.loads((out / "plan.json").read_text())
    assert "photon_settings" not in plan["povray"] and "radiosity_cache" not in plan["povray"]
    notes = [n for n in plan["notes"] if "writes a file while it is parsed" in n]
    assert len(notes) == 2 and all(f"{scene}:1" in n for n in notes)
    assert {n.split(":")[0] for n in notes} == {"radiosity", "photons"}


def test_a_photon_scene_is_led_by_its_first_sample_and_keeps_its_image(tmp_path):
    """A plan with photons only chooses stacks or one run each on its first sample, as
    one with radiosity does (a stack's face lookup can outweigh a parse that costs
    nothing: phot_met_glass.pov at 640x480 took 24.8 s stacked, 14.7 s one run each);
    the image is the one of one run per sample."""
    scene = tmp_path / "p.pov"
    scene.write_text(PHOTON_SCENE)
    _povlens("render", scene, *SIZE, "-o", tmp_path / "led")
    timing = json.loads((tmp_path / "led" / "samples" / "render.timing.json").read_text())
    assert timing["lead"]["samples"] == 1 and timing["choice"] is not None
    assert timing["samples"] == 4
    _povlens("render", scene, *SIZE, "-o", tmp_path / "own", env={"POVLENS_STACK": "1"})
    a = read_image(tmp_path / "own" / "image.exr")[..., :3]
    b = read_image(tmp_path / "led" / "image.exr")[..., :3]
    assert a.mean() > 0.05
    assert np.sqrt(np.mean((a - b) ** 2)) < 1e-3 * a.max()
