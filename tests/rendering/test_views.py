"""A folder's single views (povlens.rendering.views).  With the real POV-Ray."""

import shutil

import numpy as np
import pytest

from povlens.errors import ParameterError
from povlens.plan.convert import convert
from povlens.rendering.driver import render_outdir
from povlens.rendering.views import render_view
from povlens.util.images import read_image

from conftest import paper_options

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")


def test_focal_blur_method_renders_one_image(tmp_path):
    convert(paper_options(tmp_path, method="focal-blur", samples=7))
    out = tmp_path / "out"
    render_outdir(out, quiet=True)
    img = read_image(out / "image.exr")
    assert img.shape[:2] == (36, 48) and np.isfinite(img).all()
    assert "blur_samples 7, 7" in (out / "focal_blur.pov").read_text()


def test_a_view_is_kept_as_povray_rendered_it_and_rendered_once(tmp_path):
    convert(paper_options(tmp_path, method="pinhole"))
    out = tmp_path / "out"
    view = render_view(out, "pinhole")
    assert view == out / "view-pinhole.exr" and (out / "image.exr").exists()
    before = view.stat().st_mtime_ns
    assert render_view(out, "pinhole") == view and view.stat().st_mtime_ns == before
    with pytest.raises(ParameterError) as e:
        render_view(out, "fisheye")
    assert e.value.parameter == "view"
