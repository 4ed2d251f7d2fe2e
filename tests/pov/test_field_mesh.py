"""Field ray meshes (mesh_camera distribution 3): what POV-Ray traces through them,
against the emulation and the exact tracer, and a thin lens against focal_blur.

* a direction-readout render: every pixel's ray as POV-Ray traces it equals the
  emulation (the FS#261 sampling model) and lies within 0.05 px of the exact ray;
* the certified grids of the bundled lenses hold at every pixel of a 640x480 frame,
  for pupil points and offsets the certification did not use;
* the pass masks equal a full per-pixel trace;
* an ideal thin lens encoded in field meshes equals POV-Ray's focal_blur at 320x240
  within Monte-Carlo noise.
"""

from __future__ import annotations

import dataclasses
import shutil

import numpy as np
import pytest

from povlens.plan.plan_finish import make_plan_with_lens
from povlens.plan.options import ConvertOptions
from povlens.pov import process as povray
from povlens.pov.field_emulation import emulate, ray_error_px
from povlens.pov.field_mesh import (build_field_mesh, lens_ray_field, mesh2_text, placement_text,
                                    uv_model)
from povlens.pov.mesh import focal_blur_wrapper
from povlens.pupil.field import concentric_disc_mm, field_sample_points, trace_field
from povlens.pupil.field_mask import pass_mask
from povlens.pupil.rays import ScenePlacement
from povlens.pupil.storage import cached_pupil_table
from povlens.util.files import write_text
from povlens.util.images import read_image
from povlens.util.resources import SCENE_DIR

needs_povray = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray is not installed")
FIELD_CAMERA = "camera { mesh_camera { 1 3 mesh { PovlensRays transform { PovlensPlace } } smooth } }\n"


@dataclasses.dataclass
class Setup:
    plan: object
    lens: object
    table: object
    placement: ScenePlacement

    @property
    def pixel_angle(self):
        return self.plan.film.pixel_pitch_mm / self.plan.lens.efl_mm

    def field(self, pupil):
        return lens_ray_field(self.lens, self.plan.focus.film_distance_mm, self.plan.film,
                              self.table.plane_z_mm, pupil)

    def pupil(self, u):
        return concentric_disc_mm(np.asarray(u, float), self.plan.field_mesh.pupil_disc_radius_mm)


_SETUPS = {}


def setup_for(lens, width, height) -> Setup:
    key = (lens, width, height)
    if key not in _SETUPS:
        o = ConvertOptions.of(scene=str(SCENE_DIR / "paper.pov"), lens=lens, focus=4.0,
                           outdir="unused", width=width, height=height, method="mesh")
        plan, stopped = make_plan_with_lens(o)
        table, _ = cached_pupil_table("unused/pupil.npz", stopped, plan.focus.film_distance_mm,
                                      plan.film.half_diagonal_mm, save=False)
        pl = plan.placement
        placement = ScenePlacement(np.array(pl.film_centre), np.array(pl.right), np.array(pl.up),
                                   np.array(pl.forward), pl.mm_per_unit)
        _SETUPS[key] = Setup(plan, stopped, table, placement)
    return _SETUPS[key]


# ---------------------------------------------------------------------------
# no POV-Ray needed


@pytest.mark.parametrize("lens", ["dgauss.50mm", "wide.22mm", "fisheye.10mm"])
def test_certified_grid_holds_at_every_pixel_for_other_samples(lens):
    s = setup_for(lens, 640, 480)
    fm = s.plan.field_mesh
    assert fm is not None and fm.max_ray_error_px <= 0.05
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(3):
        u, jitter = rng.random(2), rng.random(2)
        model = uv_model(640, 480, jitter)
        field = s.field(s.pupil(u))
        mesh = build_field_mesh(field, s.placement, model, fm.grid, fm.eps, s.pixel_angle)
        e = ray_error_px(mesh, model, field, s.placement, s.pixel_angle)   # every pixel
        assert e["pixels"] > 10000
        worst = max(worst, e["direction_px"])
    assert worst <= 0.05
    # the error is real: a grid of half the width is clearly worse
    coarse = build_field_mesh(field, s.placement, model, (fm.grid[0] // 2, fm.grid[1] // 2),
                              fm.eps, s.pixel_angle)
    assert ray_error_px(coarse, model, field, s.placement, s.pixel_angle)["direction_px"] > 2 * worst


def test_dense_fit_equals_the_sparse_factorisation(monkeypatch):
    """Small fits are solved densely (no scipy.sparse import): the same normals as
    the sparse factorisation larger grids use, to rounding."""
    from povlens.pov import field_mesh
    s = setup_for("dgauss.50mm", 640, 480)
    fm = s.plan.field_mesh
    model = uv_model(640, 480, (0.3, 0.8))
    field = s.field(s.pupil((0.8, 0.3)))
    assert (fm.grid[0] + 1) * (fm.grid[1] + 1) <= field_mesh.DENSE_FIT_VERTICES
    field_mesh._FIT_SOLVERS.clear()
    dense = build_field_mesh(field, s.placement, model, fm.grid, fm.eps, s.pixel_angle)
    field_mesh._FIT_SOLVERS.clear()
    monkeypatch.setattr(field_mesh, "DENSE_FIT_VERTICES", 0)
    sparse = build_field_mesh(field, s.placement, model, fm.grid, fm.eps, s.pixel_angle)
    field_mesh._FIT_SOLVERS.clear()
    assert dense.normal.shape == sparse.normal.shape
    assert np.abs(dense.normal - sparse.normal).max() < 1e-12
    assert np.array_equal(dense.vertex, sparse.vertex)


@pytest.mark.parametrize("lens", ["dgauss.50mm", "wide.22mm", "fisheye.10mm"])
def test_pass_mask_equals_a_full_trace(lens):
    s = setup_for(lens, 640, 480)
    fm = s.plan.field_mesh
    film = s.plan.film
    traced = 0.0
    for u in [(0.5, 0.5), (0.97, 0.5), (0.2, 0.03), (0.71, 0.88)]:
        model = uv_model(640, 480, (0.3, 0.8))
        field = s.field(s.pupil(u))
        mesh = build_field_mesh(field, s.placement, model, fm.grid, fm.eps, s.pixel_angle)
        xs, ys, margins = mesh.node_margins()
        px, py = model.pixel_positions()
        got, stats = pass_mask(xs, ys, margins, px, py, field)
        X, Y = np.meshgrid(px, py)
        full = field(X.ravel(), Y.ravel()).passed.reshape(film.height_px, film.width_px)
        assert np.array_equal(got, full), f"{np.sum(got != full)} pixels differ"
        traced = max(traced, stats["traced_fraction"])
    assert traced < 0.2            # the point: most pixels are not traced


def test_a_pupil_point_outside_the_disc_passes_nowhere():
    """The disc contains every ray the lens passes (unbiased weights): points just
    outside it are blocked at every film point."""
    s = setup_for("dgauss.50mm", 160, 120)
    R = s.plan.field_mesh.pupil_disc_radius_mm
    film = s.plan.film
    X, Y = np.meshgrid(np.linspace(0, 160, 81), np.linspace(0, 120, 61))
    for a in np.linspace(0, 2 * np.pi, 24, endpoint=False):
        P = 1.002 * R * np.array([np.cos(a), np.sin(a)])
        rays = trace_field(s.lens, s.plan.focus.film_distance_mm, film, s.table.plane_z_mm, P,
                           X.ravel(), Y.ravel())
        assert not rays.passed.any()


def _camera(d, r, u) -> ScenePlacement:
    """The camera frame of the basis (d, r, u) at the world origin, 1 mm a unit."""
    return ScenePlacement(np.zeros(3), r / np.linalg.norm(r), u / np.linalg.norm(u),
                          d / np.linalg.norm(d), 1.0)


def _thin_lens_field(width, height, location, d, r, u, lens_xy, focal_distance):
    """An ideal thin lens's rays for one lens point, in the camera frame of
    :func:`_camera`: from the lens point through the focal-plane point of each
    image position."""
    R = _camera(d, r, u).basis
    xp = np.cross(u, d) / np.linalg.norm(np.cross(u, d))
    yp = np.cross(d, xp) / np.linalg.norm(np.cross(d, xp))
    origin = location + lens_xy[0] * xp + lens_xy[1] * yp

    class Rays:
        pass

    def field(x, y):
        x0 = np.asarray(x, float) / width - 0.5
        y0 = 0.5 - np.asarray(y, float) / height
        dpix = d + x0[:, None] * r + y0[:, None] * u
        focus = location + dpix * focal_distance / np.linalg.norm(d)
        out = Rays()
        direction = focus - origin
        out.direction = (direction / np.linalg.norm(direction, axis=1, keepdims=True)) @ R.T
        # start the rays 1e-3 units along: coincident vertices would make every face
        # degenerate, and POV-Ray drops degenerate faces
        out.origin_mm = origin @ R.T + 1e-3 * out.direction
        n = len(x0)
        out.exists = out.passed = np.ones(n, bool)
        out.margin_mm2 = np.ones((n, 1))
        return out

    return field


def test_a_thin_lens_field_is_reproduced_exactly_with_a_small_eps():
    from tests.pov.test_mesh import LOC, basis
    W, H = 640, 480
    d, r, u = basis(W, H)
    world = _camera(d, r, u)
    field = _thin_lens_field(W, H, LOC, d, r, u, (0.25, -0.1), 7.0)
    model = uv_model(W, H, (0.4, 0.6))
    pixel_angle = np.linalg.norm(r) / W / np.linalg.norm(d)
    exact = build_field_mesh(field, world, model, (4, 3), 1e-4, pixel_angle)
    assert ray_error_px(exact, model, field, world, pixel_angle)["direction_px"] < 1e-3
    lerp = build_field_mesh(field, world, model, (4, 3), 1.0, pixel_angle)
    assert ray_error_px(lerp, model, field, world, pixel_angle)["direction_px"] > 0.05


# ---------------------------------------------------------------------------
# against POV-Ray

READOUT_RADIUS = 1.0e4


def _readout_scene(centre, axis, K):
    """A sphere of radius R about ``centre`` whose colour is frac(K a.(p - C)/R + 0.5):
    the hit direction's component along ``axis``, at two scales K."""
    f = (f"({axis[0]:.17g}*x + {axis[1]:.17g}*y + {axis[2]:.17g}*z)/{READOUT_RADIUS:g}*{K:g}"
         " + 0.5")
    return (f"#declare F = function(x, y, z) {{ {f} - floor({f}) }};\n"
            f"sphere {{ 0, {READOUT_RADIUS:g} pigment {{ function {{ F(x, y, z) }} "
            f"color_map {{ [0 rgb 0] [1 rgb 1] }} }} finish {{ ambient 1 diffuse 0 }}\n"
            f"  translate <{centre[0]:.17g}, {centre[1]:.17g}, {centre[2]:.17g}> }}\n")


def _readout(centre, axes, origin, d):
    oc = origin - centre
    b = np.einsum("nd,nd->n", oc, d)
    c = np.einsum("nd,nd->n", oc, oc) - READOUT_RADIUS ** 2
    p = oc + (-b + np.sqrt(b * b - c))[:, None] * d
    return np.stack([p @ axes[0], p @ axes[1]], -1) / READOUT_RADIUS


@needs_povray
def test_povray_traces_the_emulated_rays(tmp_path):
    """Every pixel's ray, read back from a render, equals the emulation to 0.002 px
    (so the FS#261 sampling model is right: half a pixel off would show as ~0.5 px)
    and the exact lens ray to 0.05 px wherever the lens passes light."""
    W, H = 160, 120
    s = setup_for("dgauss.50mm", W, H)
    fm = s.plan.field_mesh
    model = uv_model(W, H, (0.9, 0.1))
    field = s.field(s.pupil((0.8, 0.3)))
    mesh = build_field_mesh(field, s.placement, model, fm.grid, fm.eps, s.pixel_angle)
    write_text(tmp_path / "m.inc", mesh2_text(mesh) + placement_text(mesh))
    o, d = emulate(mesh, model)
    X, Y = np.meshgrid(*model.pixel_positions())
    exact = field(X.ravel(), Y.ravel())
    centre = s.placement.film_centre + s.placement.forward * (
        s.plan.thin_lens.centre_z_mm / s.placement.mm_per_unit)
    axes = s.placement.basis
    predicted = _readout(centre, axes, o, d)
    truth = _readout(centre, axes, s.placement.points_to_world(exact.origin_mm),
                     s.placement.directions_to_world(exact.direction))
    got = []
    for comp in (0, 1):
        imgs = []
        for K in (0.5, 64.0):
            pov = write_text(tmp_path / f"v{comp}_{K:g}.pov",
                             "#version 3.7;\nglobal_settings { assumed_gamma 1.0 }\n"
                             + _readout_scene(centre, axes[comp], K) + '#include "m.inc"\n'
                             + FIELD_CAMERA)
            out = povray.render(pov, tmp_path / f"v{comp}_{K:g}.png", W + 1, H + 1,
                                start_row=1, end_col=W, threads=2,
                                extra_args=["+FN16", "File_Gamma=1.0"])
            imgs.append(read_image(out)[1:, :W, 0].astype(np.float64).ravel())
        coarse, fine = 2.0 * (imgs[0] - 0.5), imgs[1]
        n = np.round(64 * coarse + 0.5 - fine)
        got.append((n + fine - 0.5) / 64)
    got = np.stack(got, -1)
    p = exact.passed
    assert p.mean() > 0.5
    vs_emulation = np.abs(got - predicted).max(-1)[p] / s.pixel_angle
    vs_exact = np.abs(got - truth).max(-1)[p] / s.pixel_angle
    assert vs_emulation.max() < 0.002
    assert vs_exact.max() < 0.05
    # half a pixel of sampling error would be visible
    shifted = field(X.ravel() + 0.5, Y.ravel())
    off = _readout(centre, axes, s.placement.points_to_world(shifted.origin_mm),
                   s.placement.directions_to_world(shifted.direction))
    assert np.abs(got - off).max(-1)[p].max() / s.pixel_angle > 0.3


@needs_povray
def test_thin_lens_field_meshes_match_focal_blur_at_240x180(tmp_path):
    from tests.pov.test_mesh import LOC, SCENE, basis, box_filter
    W, H = 240, 180
    aperture, focal = 1.2, 7.0          # POV-Ray aperture = 2 x lens diameter
    d, r, u = basis(W, H)
    (tmp_path / "scene.pov").write_text(SCENE)
    world = _camera(d, r, u)
    write_text(tmp_path / "fb.pov", focal_blur_wrapper(
        "scene.pov", LOC, d, r, u, aperture=aperture, focal_distance=focal, blur_samples=64))
    fb = read_image(povray.render(tmp_path / "fb.pov", tmp_path / "fb.exr", W, H,
                                  threads=2))[..., :3]
    write_text(tmp_path / "f.pov", "global_settings { assumed_gamma 1.0 }\n"
               '#include "scene.pov"\n#include "m.inc"\n' + FIELD_CAMERA)

    def lens(tag, radius, n, seed):
        total = np.zeros((H, W, 3))
        for k, pt in enumerate(field_sample_points(n, seed=seed)):
            model = uv_model(W, H, pt[:2])
            field = _thin_lens_field(W, H, LOC, d, r, u, concentric_disc_mm(pt[2:], radius),
                                     focal)
            mesh = build_field_mesh(field, world, model, (4, 3), 1e-4, 1e-3)
            write_text(tmp_path / "m.inc", mesh2_text(mesh) + placement_text(mesh))
            out = povray.render(tmp_path / "f.pov", tmp_path / f"{tag}{k}.exr", W + 1, H + 1,
                                start_row=1, end_col=W, threads=2)
            total += read_image(out)[1:, :W, :3]
        return total / n

    good = [lens("a", aperture / 4, 12, 1), lens("b", aperture / 4, 12, 2)]
    wrong = lens("w", aperture / 2, 12, 3)       # diameter = aperture: the classic mistake

    def err(a, b):
        return float(np.abs(box_filter(a) - box_filter(b)).mean())

    e_good, e_wrong = err(np.mean(good, axis=0), fb), err(wrong, fb)
    noise = err(good[0], good[1])
    assert e_good < 1.5 * noise + 1e-3
    assert e_good < 0.006
    assert e_wrong > 3 * e_good


def test_rays_from_one_point_are_refused_not_dropped():
    """Coincident ray origins make degenerate faces, which POV-Ray would drop (their
    pixels get no ray): a clear error instead."""
    from tests.pov.test_mesh import LOC, basis
    from povlens.errors import PovlensError
    W, H = 64, 48
    d, r, u = basis(W, H)
    inner = _thin_lens_field(W, H, LOC, d, r, u, (0.0, 0.0), 7.0)

    def from_one_point(x, y):
        rays = inner(x, y)
        rays.origin_mm = np.broadcast_to(rays.origin_mm[0], rays.origin_mm.shape).copy()
        return rays

    with pytest.raises(PovlensError, match="degenerate faces"):
        build_field_mesh(from_one_point, _camera(d, r, u), uv_model(W, H), (4, 3), 0.01, 1e-3)


def test_fit_systems_are_shared_safely_between_threads(monkeypatch):
    """The lead sample's thread and its companions' build meshes at once: the cache of
    factorised fits, evicting as it fills, must not break under them (without its lock
    this raised "dictionary changed size during iteration" in 2-4 of 8 threads)."""
    import sys
    import threading
    from povlens.pov import field_mesh
    n_v, n_s = 12, 30
    rng = np.random.default_rng(0)
    faces = rng.integers(0, n_v, (20, 3))
    face = rng.integers(0, 20, n_s)
    B = rng.random((n_s, 3))
    B /= B.sum(1, keepdims=True)
    errors = []

    def build(seed):
        r = np.random.default_rng(seed)
        try:
            for _ in range(300):
                use = r.random(64) < 0.5        # a new cache key nearly every time
                assert field_mesh._fit_solver((3, 2), use, face, B, faces, n_v).n_v == n_v
        except Exception as e:                  # noqa: BLE001 - reported below
            errors.append(repr(e))
    monkeypatch.setattr(field_mesh, "_FIT_SOLVERS", {})
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)                 # threads switch as often as they can
    try:
        threads = [threading.Thread(target=build, args=(i,)) for i in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    finally:
        sys.setswitchinterval(interval)
    assert errors == []
