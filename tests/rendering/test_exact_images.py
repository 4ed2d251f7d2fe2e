"""The default exact path renders right pictures (issue 22), on real POV-Ray renders:

* stopped down (f/64, f/16) its exposure is the pinhole view's, with no dark crescent
  or ring, at 4 samples;
* wide open its vignetting over a smooth sky has no steps (the ratio estimator and each
  film point's own pupil ellipse);
* a far highlight through a 6-blade iris is a filled hexagon at ``--method auto``'s
  sample count;
* the interleaved tiles of one pass take different lens samples: blurred edges show
  noise, not ghost copies of the edge.

The field meshes' rays and masks are checked in tests/pov/test_field_mesh.py, the
ellipses' containment in tests/pupil/test_field_domain.py.
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from povlens.cli import main
from povlens.plan.schema import read_plan
from povlens.util.images import read_image

from conftest import ROOT
from test_aperture_render import _outline_corner_angles

needs_povray = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray is not installed")
PAPER = ROOT / "scenes" / "paper.pov"


def render(out, scene, *args) -> np.ndarray:
    assert main(["render", str(scene), "--lens", "dgauss.50mm", "-q", "-o", str(out),
                 *map(str, args)]) == 0
    return read_image(out / "image.exr")[..., :3].astype(np.float64)


def block_means(img: np.ndarray, k: int) -> np.ndarray:
    h, w = (img.shape[0] // k) * k, (img.shape[1] // k) * k
    return img[:h, :w].mean(axis=2).reshape(h // k, k, w // k, k).mean(axis=(1, 3))


@needs_povray
@pytest.mark.parametrize("f_number", [64, 16])
def test_stopped_down_mesh_keeps_the_pinhole_exposure_everywhere(tmp_path, f_number):
    """Before: at f/64 a black crescent and parts 1.7x too bright, at f/16 a dark ring and
    the mean 14 % low (samples drawn from one disc that held every film point's region)."""
    size = ["--width", 96, "--height", 72, "--focus", 5, "--f-number", f_number]
    mesh = render(tmp_path / "mesh", PAPER, *size, "--method", "mesh", "--samples", 4,
                  "--no-jitter")
    pin = render(tmp_path / "pin", PAPER, *size, "--method", "pinhole")
    assert read_plan(tmp_path / "mesh").field_mesh is not None
    assert mesh.mean() == pytest.approx(pin.mean(), rel=0.01)
    ratio = block_means(mesh, 12) / block_means(pin, 12)
    assert ratio.min() > 0.9 and ratio.max() < 1.1, ratio


@needs_povray
def test_wide_open_vignetting_has_no_steps(tmp_path):
    """The sky of paper.pov is smooth: the mesh render there is the pinhole view times the
    relative illumination at every pixel, not in steps of 1/N (each sample passing or
    blocked over whole regions, as before)."""
    size = ["--width", 160, "--height", 120, "--focus", 4]
    mesh = render(tmp_path / "mesh", PAPER, *size, "--method", "mesh", "--samples", 16)
    pin = render(tmp_path / "pin", PAPER, *size, "--method", "pinhole")
    sky = (slice(0, 24), slice(None))                 # above the horizon (row ~30)
    ratio = mesh[sky].mean(axis=2) / pin[sky].mean(axis=2)
    plan = read_plan(tmp_path / "mesh")
    assert plan.field_mesh.interleave >= 2
    assert np.abs(ratio - 1).max() < 0.01, np.abs(ratio - 1).max()
    # the vignetting is there: the corners are darker than the centre by the lens's map
    assert mesh[:4, :4].mean() < 0.9 * mesh[:4, 76:84].mean()


HIGHLIGHT = """#version 3.7;
global_settings { assumed_gamma 1.0 }
camera { perspective location <0, 0, 0> look_at <0, 0, 1> right x*image_width/image_height
         angle 12 }
background { rgb 0 }
sphere { <0, 0, 30>, 0.14 pigment { rgb 1 } finish { emission 4 diffuse 0 ambient 0 } }
"""


@needs_povray
def test_far_highlight_through_an_iris_is_a_filled_hexagon_at_auto_samples(tmp_path):
    """A small bright sphere far behind the focus, 6 blades at 10 deg: ``--method auto``
    renders exact lens samples (focal_blur cannot draw an iris) and the highlight is the
    iris's hexagon, filled -- not a cloud of separate dots."""
    scene = tmp_path / "highlight.pov"
    scene.write_text(HIGHLIGHT)
    img = render(tmp_path / "auto", scene, "--focus", 0.5, "--f-number", 2.8,
                 "--film-diagonal", 6, "--aperture-blades", 6, "--blade-rotation", 10,
                 "--width", 128, "--height", 96).mean(axis=2)
    plan = read_plan(tmp_path / "auto")
    assert plan.inputs.method == "mesh" and plan.field_mesh is not None
    n = plan.inputs.samples
    # the hexagon: where a 5x5 box of the image is above a quarter of the disc's level
    from scipy import ndimage
    box = ndimage.uniform_filter(img, 5)
    disc = box > 0.25 * np.percentile(box[box > 0], 90)
    lit = (img > 0)[ndimage.binary_erosion(disc, iterations=3)]
    print(f"{n} samples, interleave {plan.field_mesh.interleave}: disc {disc.sum()} px, "
          f"lit {lit.mean():.3f} inside")
    assert disc.sum() > 200                          # far out of focus: a wide blur
    assert lit.mean() > 0.9                          # filled, not separate dots
    corners = _outline_corner_angles(img)
    assert len(corners) == 6, corners
    want = (100.0 + 60.0 * np.arange(6)) % 360
    err = np.abs((corners[:, None] - want[None, :] + 180) % 360 - 180).min(axis=1)
    assert err.max() < 10.0, corners


@needs_povray
def test_interleaved_tiles_turn_ghost_copies_into_noise(tmp_path, monkeypatch):
    """Blurred image, few samples: neighbouring pixels of one pass take different lens
    samples, so the error against a converged render is uncorrelated between
    neighbours (noise) -- one tile per pass shares every sample over the frame, and its
    error is a few displaced copies of the scene, correlated over many pixels."""
    size = ["--width", 160, "--height", 120, "--focus", 1.5, "--method", "mesh"]
    ref = render(tmp_path / "ref", PAPER, *size, "--samples", 64, "--seed", 5)
    errs = {}
    for m in (1, 3):
        monkeypatch.setenv("POVLENS_INTERLEAVE", str(m))
        img = render(tmp_path / f"m{m}", PAPER, *size, "--samples", 4)
        assert read_plan(tmp_path / f"m{m}").field_mesh.interleave == m
        e = (img - ref).mean(axis=2)[40:, :]                 # the blurred floor
        e = e - e.mean()
        # correlation of the error with its neighbour one pixel to the right
        errs[m] = float((e[:, :-1] * e[:, 1:]).mean() / (e * e).mean())
    print(f"neighbour correlation of the error: one tile {errs[1]:.2f}, 3x3 tiles {errs[3]:.2f}")
    assert errs[1] > 0.5
    assert errs[3] < 0.5 * errs[1]
