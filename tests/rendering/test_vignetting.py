"""The lens's vignetting on the pinhole and focal_blur views: image.exr is the view as
POV-Ray rendered it times the relative illumination map, recorded in plan.json."""

import json
import pathlib
import shutil
import subprocess

import numpy as np
import pytest

from povlens.plan.convert import ConvertOptions, convert
from povlens.plan.schema import read_plan
from povlens.pupil.illumination import illumination_profile, relative_illumination_map
from povlens.rendering.driver import render_outdir
from povlens.rendering.folder_inputs import lens_for, pupil_table_for
from povlens.rendering.views import render_view
from povlens.rendering.vignetting import apply_vignetting_map, wants_vignetting_map
from povlens.util.images import read_image

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENE = str(ROOT / "scenes" / "paper.pov")

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")


def _render(tmp_path, name, **kw):
    base = dict(scene=SCENE, lens="dgauss.50mm", focus=4.0, width=64, height=48,
                method="pinhole", outdir=str(tmp_path / name))
    base.update(kw)
    convert(ConvertOptions.of(**base))
    out = tmp_path / name
    render_outdir(out, quiet=True)
    return out


def test_pinhole_image_is_the_view_times_the_map(tmp_path):
    """dgauss.50mm loses two thirds of the light in the corners: image.exr is darker
    there by exactly the map, the centre keeps its brightness, the view stays raw."""
    out = _render(tmp_path, "vig")
    view = read_image(out / "view-pinhole.exr")[..., :3].astype(np.float64)
    image = read_image(out / "image.exr")[..., :3].astype(np.float64)
    plan = read_plan(out)
    table = pupil_table_for(out, plan, lens_for(plan))
    ri = relative_illumination_map(illumination_profile(table, plan.film.half_diagonal_mm),
                                   plan.film.width_mm, plan.film.height_mm, 64, 48)
    np.testing.assert_allclose(image, view * ri[..., None], rtol=2e-6, atol=1e-7)
    lit = view > 0.02
    ratio = np.where(lit, image / np.where(lit, view, 1.0), np.nan)
    assert np.nanmean(ratio[:4, :4]) < 0.4 and np.nanmean(ratio[:4, -4:]) < 0.4
    assert np.nanmin(ratio[22:26, 30:34]) > 0.98                   # the centre: as rendered
    assert float(np.mean(np.abs(image - view))) > 0.02             # the test can fail
    rec = plan.vignetting_map
    assert rec["applied_to"] == ["image.exr", "image.png"] and rec["view"] == "view-pinhole.exr"
    assert rec["corner_relative_illumination"] == pytest.approx(ri[0, 0], abs=1e-6)
    assert rec["min_relative_illumination"] < 0.4 and rec["pixel_average"] is True
    assert rec["lens_sha256"] == plan.inputs.lens_sha256
    # make renders nothing more; a render again gives the same image bit for bit
    r = subprocess.run(["make", "-C", str(out)], capture_output=True, text=True)
    assert r.returncode == 0 and "Nothing to be done" in r.stdout, r.stdout + r.stderr
    (out / "image.exr").unlink()
    render_view(out, "pinhole")
    np.testing.assert_array_equal(read_image(out / "image.exr")[..., :3], image)


def test_no_vignetting_leaves_the_view_as_it_is(tmp_path):
    out = _render(tmp_path, "novig", vignetting=False)
    view = read_image(out / "view-pinhole.exr")[..., :3]
    np.testing.assert_array_equal(read_image(out / "image.exr")[..., :3], view)
    plan = read_plan(out)
    assert plan.vignetting_map is None and not wants_vignetting_map(plan)
    assert "vignetting_map" not in json.loads((out / "plan.json").read_text())
    assert apply_vignetting_map(out, plan, view, None) is view      # nothing to apply


def test_focal_blur_view_gets_the_map_and_a_mesh_plan_does_not(tmp_path):
    out = _render(tmp_path, "fb", method="focal-blur", samples=4)
    view = read_image(out / "view-focal-blur.exr")[..., :3].astype(np.float64)
    image = read_image(out / "image.exr")[..., :3].astype(np.float64)
    plan = read_plan(out)
    assert plan.vignetting_map["view"] == "view-focal-blur.exr"
    ri = np.asarray(plan.vignetting_map["corner_relative_illumination"])
    np.testing.assert_allclose(image[0, 0], view[0, 0] * ri, rtol=2e-6, atol=1e-7)
    mesh = tmp_path / "mesh"
    convert(ConvertOptions.of(scene=SCENE, lens="dgauss.50mm", focus=4.0, width=64, height=48,
                           method="mesh", samples=2, outdir=str(mesh)))
    assert not wants_vignetting_map(read_plan(mesh))            # its composite weighs it
