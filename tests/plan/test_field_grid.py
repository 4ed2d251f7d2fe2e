"""The field meshes of a mesh plan: the grid's certification, what plan.json records,
and the fallbacks to per-pixel meshes."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from povlens.errors import ParameterError
from povlens.plan.field_grid import LIMIT_PX, certification_pupil_points, pixel_subset
from povlens.plan.plan_finish import make_plan_with_lens
from povlens.plan.options import ConvertOptions
from povlens.plan.schema import Plan
from povlens.util.resources import SCENE_DIR


def _opts(**kw):
    base = dict(scene=str(SCENE_DIR / "paper.pov"), lens="dgauss.50mm", focus=4.0,
                outdir="unused", width=160, height=120, method="mesh", samples=8)
    return ConvertOptions.of(**(base | kw))


def test_a_mesh_plan_records_its_certified_field_meshes_and_reads_back():
    plan, _ = make_plan_with_lens(_opts())
    fm = plan.field_mesh
    assert plan.inputs.ray_mesh == "field"
    assert 0 < fm.max_ray_error_px <= LIMIT_PX == fm.limit_px
    assert fm.pupil_points == 17 and fm.pixels_checked > 1000
    assert fm.grid[0] >= 4 and fm.eps in (0.01, 1.0)
    # the m x m tiles are rendered in a row, each ceil(W / m) x ceil(H / m), one pixel larger
    # each way for FS#261; the composite drops row 0 and the last column
    m = fm.interleave
    faces = 2 * fm.grid[0] * fm.grid[1]
    assert m == 3 and m * m * faces <= 6000 and 160 * 120 >= m * m * 2048
    pv = plan.povray
    assert (pv.render_width, pv.render_height, pv.drop_top_rows, pv.drop_right_columns) == (
        m * m * 54 + 1, 41, 1, 1)
    assert fm.domain is not None and 0.8 < fm.domain["efficiency"] <= 1.0
    again = Plan.from_dict(plan.to_dict())
    assert again.field_mesh == fm and again.povray == pv
    assert again.to_dict() == plan.to_dict()


def test_other_methods_and_pixel_meshes_have_no_field_meshes():
    for kw in (dict(method="focal-blur"), dict(ray_mesh="pixel")):
        plan, _ = make_plan_with_lens(_opts(**kw))
        assert plan.field_mesh is None
        assert "field_mesh" not in plan.to_dict()
        assert "drop_right_columns" not in plan.to_dict()["povray"]
    assert make_plan_with_lens(_opts(method="focal-blur"))[0].inputs.ray_mesh is None


def test_a_lens_no_grid_holds_falls_back_to_pixel_meshes_with_a_note():
    """The f/1 singlet's aberrated ray field at 48x36: the coarsest faces allowed (4 px)
    keep 0.2 px, so its samples get a face per pixel, and a note says why."""
    plan, _ = make_plan_with_lens(_opts(lens="singlet.pcx.25mm", focus=2.0, width=48, height=36))
    assert plan.field_mesh is None and plan.inputs.ray_mesh == "pixel"
    assert any("face per pixel" in n and "0.05 px" in n for n in plan.notes)
    assert plan.povray.drop_right_columns == 0


def test_an_unmeasured_povray_version_falls_back_to_pixel_meshes():
    from povlens.plan.plan_finish import PlanReuse, finish_plan
    from povlens.plan.plan_start import start_plan
    o = _opts()
    plan, _ = finish_plan(o, start_plan(o), PlanReuse(version=lambda: "3.8.0-beta.2"))
    assert plan.field_mesh is None and plan.inputs.ray_mesh == "pixel"
    assert any("3.8.0-beta.2" in n for n in plan.notes)


def test_an_unknown_ray_mesh_is_refused_naming_the_parameter():
    with pytest.raises(ParameterError) as e:
        make_plan_with_lens(_opts(ray_mesh="vertex"))
    assert e.value.parameter == "ray_mesh"
    r = subprocess.run([sys.executable, "-m", "povlens", "convert", str(SCENE_DIR / "paper.pov"),
                        "--lens", "dgauss.50mm", "--focus", "4", "--ray-mesh", "vertex",
                        "-o", "unused"], capture_output=True, text=True)
    assert r.returncode == 2 and "--ray-mesh" in r.stderr and "Traceback" not in r.stderr


def test_the_certification_covers_the_frame_and_the_disc():
    rows, cols = pixel_subset(640, 480)
    assert {0, 479} <= set(rows) and {0, 639} <= set(cols)
    assert 8000 < len(rows) < 20000
    r, c = pixel_subset(20, 10)
    assert len(r) == 200                        # small frames: every pixel
    pts = certification_pupil_points(10.0)
    radius = np.hypot(pts[:, 0], pts[:, 1])
    assert len(pts) == 17 and radius.min() == 0.0
    assert np.allclose(sorted(radius)[1:9], 5.0) and np.allclose(sorted(radius)[9:], 9.9)
