"""Anamorphic lenses rendered end to end (real POV-Ray, small images).

lentil 2004 (a 2x cylindrical front attachment on a 60 mm prime: EFL_x 31.5 mm, EFL_y
60.6 mm, squeeze 1.92), imported with povlens's lentil importer, focused at 10 m; a small
emissive sphere 1.5 m away is far out of focus.  Its blur spot's second moments in the
rendered image are compared with an independent prediction: a bundle of rays from points
of the sphere through the lens (the exact tracer alone, no pupil table, mesh or POV-Ray),
landed on the film and converted to the image's pixels; and, more loosely, with the
paraxial marginal ray of each meridian.  The spot is an upright oval (aspect 0.41) where
a spherical lens's is round; without desqueeze it is S times narrower; per-pixel and
field meshes agree.  focal_blur is ruled out by --method auto and warns when asked for;
the pinhole view is framed per meridian."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest

import povlens
from conftest import ROOT
from povlens.lens.import_lentil import import_lentil
from povlens.lens.paraxial import entrance_pupil, system_matrix
from povlens.lens.prescription import read_lens, write_lens
from povlens.lens.tracer import trace_from_scene
from povlens.plan.anamorphic import AnamorphicFocalBlurWarning
from povlens.util.images import read_image

LENTIL = ROOT / "tests" / "data" / "lentil-lenses.json"
FOCUS_M, HIGHLIGHT_M, SPHERE_M = 10.0, 1.5, 0.002
SIZE = dict(width=96, height=72, film_diagonal_mm=4.6)
SCENE = """#version 3.7;
global_settings {{ assumed_gamma 1.0 }}
camera {{ perspective location <0, 0, 0> look_at <0, 0, 1> right x*4/3 up y }}
background {{ rgb 0 }}
sphere {{ <0, 0, {z}>, {r} pigment {{ rgb 1 }} finish {{ emission 1 diffuse 0 ambient 0 }} }}
"""


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    base = tmp_path_factory.mktemp("anamorphic")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")              # the importer's notes on clipped rims
        lens = import_lentil(LENTIL, "2004").lens
    lens_file = base / "schneider2004.dat"
    write_lens(lens, lens_file)
    scene = base / "highlight.pov"
    scene.write_text(SCENE.format(z=HIGHLIGHT_M, r=SPHERE_M))
    return base, lens_file, scene


_RENDERS: dict = {}


def render(setup, name, lens=None, **opts):
    """(image (H, W, 3), plan.json dict) of a mesh render of the highlight, kept per name."""
    if name not in _RENDERS:
        base, lens_file, scene = setup
        out = base / name
        kw = dict(method="mesh", samples=64, **SIZE)
        kw.update(opts)
        povlens.render(scene, lens=lens or lens_file, outdir=out, focus=FOCUS_M, **kw)
        _RENDERS[name] = (read_image(out / "image.exr")[..., :3],
                          json.loads((out / "plan.json").read_text()))
    return _RENDERS[name]


def image_sigmas(img) -> tuple[float, float]:
    """(sigma_x, sigma_y) in pixels: the second moments of the image's light about its
    centroid (the scene is black but for the highlight)."""
    Y = img.mean(axis=2)
    Y = np.where(Y > 1e-4 * Y.max(), Y, 0.0)
    h, w = Y.shape
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    m = Y.sum()
    cx, cy = (Y * xx).sum() / m, (Y * yy).sum() / m
    return (math.sqrt((Y * (xx - cx) ** 2).sum() / m), math.sqrt((Y * (yy - cy) ** 2).sum() / m))


def traced_sigmas(plan: dict, lens, n: int = 200_000) -> tuple[float, float]:
    """The prediction: rays from points spread uniformly over the sphere's disc (as the
    lens sees it) toward points spread uniformly over the front of the lens, traced with
    the exact tracer, landed on the film, weighted cos^3 (a point source's flux per area
    of the plane they start toward), converted to the image's pixels (its pitch in x and
    y, desqueezed or not) and widened by a pixel's box (1/12 px^2)."""
    fd = plan["focus"]["film_distance_mm"]
    z_obj = plan["thin_lens"]["centre_z_mm"] + HIGHLIGHT_M * 1000.0   # from the camera location
    rng = np.random.default_rng(0)
    a, rr = rng.random(n) * 2 * math.pi, SPHERE_M * 1000.0 * np.sqrt(rng.random(n))
    src = np.stack([rr * np.cos(a), rr * np.sin(a), np.full(n, z_obj)], 1)
    A = float(lens.aperture_radius_mm[0]) * 1.2
    P = np.stack([rng.uniform(-A, A, n), rng.uniform(-A, A, n),
                  np.full(n, fd + lens.total_track_mm + 1.0)], 1)
    d = P - src
    t = trace_from_scene(lens, fd, src, d)
    o, dd = t.origin_mm[t.passed], t.direction[t.passed]
    xy = o[:, :2] + (-o[:, 2] / dd[:, 2])[:, None] * dd[:, :2]
    w = (-d[t.passed, 2] / np.linalg.norm(d[t.passed], axis=1)) ** 3
    c = (w[:, None] * xy).sum(0) / w.sum()
    var = (w[:, None] * (xy - c) ** 2).sum(0) / w.sum()
    f = plan["film"]
    px, py = f["width_mm"] / f["width_px"], f["height_mm"] / f["height_px"]
    return math.sqrt(var[0] / px ** 2 + 1 / 12), math.sqrt(var[1] / py ** 2 + 1 / 12)


def paraxial_aspect(plan: dict, lens) -> float:
    """The blur's aspect from first-order optics alone: each meridian's marginal ray from
    the axial object point through the edge of that meridian's entrance pupil, its height
    on the film (the blur radius), over the image's pitch in that direction."""
    fd = plan["focus"]["film_distance_mm"]
    front_z = fd + lens.total_track_mm
    dist = plan["thin_lens"]["centre_z_mm"] + HIGHLIGHT_M * 1000.0 - front_z
    f = plan["film"]
    pitch = {"x": f["width_mm"] / f["width_px"], "y": f["height_mm"] / f["height_px"]}
    radius = {}
    for m in "xy":
        ep_pos, epd, _ = entrance_pupil(lens, m)
        u = 0.5 * epd / (dist + ep_pos)
        (A, B), (C, D) = system_matrix(lens, meridian=m)
        y, nu = A * u * dist + B * u, C * u * dist + D * u
        radius[m] = abs(y + nu * fd) / pitch[m]
    return radius["x"] / radius["y"]


def test_oval_bokeh_matches_the_traced_bundle_and_a_spherical_lens_is_round(setup):
    img, plan = render(setup, "field")
    lens = read_lens(plan["inputs"]["lens"])
    sx, sy = image_sigmas(img)
    tx, ty = traced_sigmas(plan, lens)
    aspect, predicted = sx / sy, tx / ty
    print(f"anamorphic bokeh: rendered sigma {sx:.3f} x {sy:.3f} px (aspect {aspect:.4f}), "
          f"traced {tx:.3f} x {ty:.3f} px (aspect {predicted:.4f}), paraxial aspect "
          f"{paraxial_aspect(plan, lens):.4f}")
    assert abs(aspect / predicted - 1) < 0.05
    assert abs(sy / ty - 1) < 0.05                       # the size too, not only the shape
    assert aspect < 0.6                                  # clearly oval: upright, 0.41
    assert abs(paraxial_aspect(plan, lens) / aspect - 1) < 0.15
    # the same scene through a spherical lens: round
    img_s, plan_s = render(setup, "spherical", lens="dgauss.50mm")
    sx_s, sy_s = image_sigmas(img_s)
    tx_s, ty_s = traced_sigmas(plan_s, read_lens(plan_s["inputs"]["lens"]))
    print(f"spherical: rendered aspect {sx_s / sy_s:.4f}, traced {tx_s / ty_s:.4f}")
    assert abs(sx_s / sy_s - 1) < 0.06 and abs(tx_s / ty_s - 1) < 0.01


def test_the_plan_records_the_squeeze_and_the_desqueezed_film(setup):
    _, plan = render(setup, "field")
    ana = plan["anamorphic"]
    assert plan["inputs"]["desqueeze"] is True
    assert abs(ana["squeeze"] - ana["efl_y_mm"] / ana["efl_x_mm"]) < 1e-12
    f = plan["film"]
    pitch_x, pitch_y = f["width_mm"] / f["width_px"], f["height_mm"] / f["height_px"]
    assert abs(pitch_y / pitch_x - ana["squeeze"]) < 1e-9          # no resampling: film pitch
    assert abs(math.hypot(f["width_mm"], f["height_mm"]) - SIZE["film_diagonal_mm"]) < 1e-9
    assert plan["thin_lens"]["image_distance_x_mm"] < 0.6 * plan["thin_lens"]["image_distance_mm"]
    assert plan["field_mesh"]["domain"]["kind"] == "grid"
    assert any(n.startswith("anamorphic lens (EFL_x") for n in plan["notes"])


def test_without_desqueeze_the_spot_is_squeeze_times_narrower(setup):
    img_d, plan = render(setup, "field")
    img_n, plan_n = render(setup, "squeezed", desqueeze=False)
    assert plan_n["inputs"]["desqueeze"] is False
    f = plan_n["film"]
    assert abs(f["width_mm"] / f["height_mm"] - 96 / 72) < 1e-9   # square pixels on the film
    (sx, sy), (nx, ny) = image_sigmas(img_d), image_sigmas(img_n)
    ratio = (sx / sy) / (nx / ny)
    print(f"aspect desqueezed / squeezed {ratio:.4f}, squeeze {plan['anamorphic']['squeeze']:.4f}")
    assert abs(ratio / plan["anamorphic"]["squeeze"] - 1) < 0.05
    tx, ty = traced_sigmas(plan_n, read_lens(plan_n["inputs"]["lens"]))
    assert abs((nx / ny) / (tx / ty) - 1) < 0.05


def test_per_pixel_meshes_render_the_same_oval(setup):
    img_f, _ = render(setup, "field")
    img_p, plan = render(setup, "pixel", ray_mesh="pixel", samples=64)
    assert plan["inputs"]["ray_mesh"] == "pixel" and plan.get("field_mesh") is None
    (fx, fy), (px, py) = image_sigmas(img_f), image_sigmas(img_p)
    assert abs((px / py) / (fx / fy) - 1) < 0.05 and abs(py / fy - 1) < 0.05
    # the same exposure: the frame's light within sampling noise (each pixel's few hits
    # of the small sphere: a few % at 64 samples)
    assert abs(img_p.sum() / img_f.sum() - 1) < 0.1


def test_explicit_focal_blur_warns_renders_and_says_so(setup):
    base, lens_file, scene = setup
    out = base / "fb"
    with pytest.warns(AnamorphicFocalBlurWarning, match="y-z meridian"):
        povlens.render(scene, lens=lens_file, outdir=out, focus=FOCUS_M, method="focal-blur",
                       samples=8, width=48, height=36, film_diagonal_mm=4.6)
    plan = json.loads((out / "plan.json").read_text())
    assert plan["inputs"]["method"] == "focal-blur"
    assert any("method focal-blur on an anamorphic lens" in n for n in plan["notes"])
    assert read_image(out / "image.exr").max() > 0


def test_auto_rules_focal_blur_out_with_a_reason(setup):
    base, lens_file, scene = setup
    plan = povlens.convert(scene, lens=lens_file, outdir=base / "auto", focus=FOCUS_M,
                           width=48, height=36, film_diagonal_mm=4.6)
    d = plan.decision
    assert plan.inputs.method == "mesh"
    assert any(r.startswith("focal-blur: cannot draw an anamorphic lens (EFL_x") for r in d.reasons)
    assert d.reasons[-1].startswith("-> mesh: the lens is anamorphic")
    saved = json.loads((base / "auto" / "plan.json").read_text())
    assert saved["decision"]["reasons"] == d.reasons


def test_pinhole_view_is_framed_per_meridian(setup):
    """A sphere at the focus distance is round in the desqueezed pinhole view (POV-Ray's
    right and up scaled by each meridian's image distance) and squeeze times narrower in
    the squeezed one."""
    base, lens_file, _ = setup
    scene = base / "ball.pov"
    scene.write_text(SCENE.format(z=FOCUS_M, r=0.08))
    out = {}
    for name, dq in (("pin", True), ("pin_squeezed", False)):
        povlens.render(scene, lens=lens_file, outdir=base / name, focus=FOCUS_M,
                       method="pinhole", desqueeze=dq, **SIZE)
        out[name] = image_sigmas(read_image(base / name / "image.exr")[..., :3])
    (sx, sy), (qx, qy) = out["pin"], out["pin_squeezed"]
    S = json.loads((base / "pin" / "plan.json").read_text())["anamorphic"]["squeeze"]
    assert abs(sx / sy - 1) < 0.05, (sx, sy)
    assert abs((sx / sy) / (qx / qy) / S - 1) < 0.05
