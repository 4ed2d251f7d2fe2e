"""Compositing a folder's lens samples (povlens.rendering.folder_composite): the same view
as the pinhole render through a tiny stop, damaged pass masks named.  With the real
POV-Ray."""

import shutil

import numpy as np
import pytest

from povlens.plan.convert import convert
from povlens.plan.schema import read_plan
from povlens.rendering.driver import render_outdir
from povlens.rendering.folder_composite import composite_outdir
from povlens.rendering.views import render_view
from povlens.util.images import read_image

from conftest import paper_options

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")


def test_tiny_stop_mesh_render_matches_the_pinhole_render(tmp_path):
    o = paper_options(tmp_path, width=640, height=480, samples=8, batch_size=8, stop_diameter_mm=2.0,
             jitter=False)
    convert(o)
    out = tmp_path / "out"
    render_outdir(out, jobs=2, quiet=True)
    # without vignetting (cos^4 falloff is physical, and a pinhole has none)
    mesh = composite_outdir(out, vignetting=False, write=False)
    pin = read_image(render_view(out, "pinhole"))[..., :3]
    diff = np.abs(mesh - pin).mean(axis=2)
    # Same view pixel for pixel, up to the real lens's residual geometry against the
    # fitted perspective (its distortion, up to 2 px at the frame's corners at this
    # size, under 0.05 px in the central quarter used here, and rays spread over a
    # 2 mm stop), which flips pixels only where a hard checker edge crosses the pixel
    # centre, and the aliased checker floor near the horizon.
    c = diff[180:300, 240:400]
    assert np.median(c) < 0.01
    assert (c > 0.2).mean() < 0.05
    # the field meshes were certified to 0.05 px
    assert read_plan(out).field_mesh.max_ray_error_px <= 0.05
    # a view shifted by one pixel is clearly worse, so the test can fail (vertically:
    # the floor's checker rows near the horizon show it; per-pixel meshes give the same
    # numbers, 3.1 % against 22-25 % of the pixels)
    for shifted in (mesh[1:] - pin[:-1], mesh[:-1] - pin[1:]):
        assert (np.abs(shifted).mean(axis=2)[180:300, 240:400] > 0.2).mean() > 4.0 * (c > 0.2).mean()


def test_a_damaged_pass_mask_is_a_clear_error_naming_the_file(tmp_path):
    """Field-mesh samples keep their pass mask (the weights follow from it); a
    damaged one stops the composite with the file's name, not a traceback or a
    silently wrong image."""
    from povlens.errors import PovlensError
    convert(paper_options(tmp_path, samples=2, batch_size=2))
    out = tmp_path / "out"
    render_outdir(out, jobs=2, quiet=True)
    masks = sorted((out / "samples").glob("sample_*.mask.npy"))
    assert len(masks) == 2 and not list((out / "samples").glob("*.weight.exr"))
    good = composite_outdir(out, write=False)
    assert np.isfinite(good).all() and good.max() > 0
    masks[0].write_bytes(b"not a mask")
    with pytest.raises(PovlensError, match=masks[0].name):
        composite_outdir(out, write=False)
    np.save(masks[0], np.zeros((3, 1), np.uint8))       # the wrong size
    with pytest.raises(PovlensError, match="mask"):
        composite_outdir(out, write=False)


@pytest.mark.parametrize("text", ["nan", "inf", "-1", "0", "", "1e400"])
def test_a_damaged_exposure_is_computed_again(tmp_path, text):
    """exposure.txt holding no positive finite number (issue 24 item 5: 'nan', 'inf' or
    '-1' made the image NaN, inf or wrong with exit 0) is computed again: the image
    equals the first composite's, and the file is rewritten."""
    convert(paper_options(tmp_path, samples=2, batch_size=2))
    out = tmp_path / "out"
    render_outdir(out, jobs=2, quiet=True)
    good = read_image(out / "image.exr")
    saved = (out / "exposure.txt").read_text()
    (out / "exposure.txt").write_text(text)
    again = composite_outdir(out)
    assert np.isfinite(again).all()
    np.testing.assert_array_equal(read_image(out / "image.exr"), good)
    assert (out / "exposure.txt").read_text() == saved
