"""povlens.pov.mesh: ray meshes, wrappers, and renders against POV-Ray's own cameras.

The two render tests are the contract of this layer:

* a pinhole ray mesh through ``mesh_camera`` (with the 3.7.0.x row
  workaround) equals POV-Ray's perspective camera pixel for pixel;
* an ideal thin lens encoded in ray meshes (lens diameter aperture/2) and
  averaged over samples equals POV-Ray's ``focal_blur`` within Monte-Carlo
  noise, while the wrong scale (diameter = aperture) is measurably worse.
"""

from __future__ import annotations

import re
import shutil

import numpy as np
import pytest

from povlens.pov import process as povray
from povlens.pov.executable import needs_row_workaround, povray_version
from povlens.errors import PovlensError, UsageError
from povlens.pov.sdl import read_template
from povlens.util.images import read_image
from povlens.pov.mesh import (
    default_sink_centre,
    focal_blur_wrapper,
    mesh_camera_block,
    mesh_wrapper,
    pinhole_wrapper,
    render_size,
    write_ray_mesh,
    write_text,
)

HAVE_POVRAY = shutil.which("povray") is not None
needs_povray = pytest.mark.skipif(not HAVE_POVRAY, reason="POV-Ray is not installed")

# Checker floor and three spheres at depths ~4.6, 7 and 11 (scene units).
SCENE = """#version 3.7;
global_settings { assumed_gamma 1.0 }
camera { location <0, 1.2, -4> look_at <0, 0.7, 3> angle 50 right x*image_width/image_height }
light_source { <-5, 10, -8> rgb 1 }
plane { y, 0 pigment { checker rgb 0.9 rgb 0.1 scale 0.5 } }
sphere { <-1.2, 0.6, 0.6>, 0.6 pigment { rgb <1, 0.2, 0.2> } finish { specular 0.5 } }
sphere { <0.3, 0.6, 3>, 0.6 pigment { rgb <0.2, 1, 0.2> } }
sphere { <1.8, 0.6, 7>, 0.6 pigment { rgb <0.2, 0.2, 1> } }
sky_sphere { pigment { gradient y color_map { [0 rgb <0.6, 0.7, 1>] [1 rgb <0.1, 0.2, 0.6>] } } }
"""

# The same view as an explicit basis: location, direction (unit * |D|), right, up.
LOC = np.array([0.0, 1.2, -4.0])
_F = np.array([0.0, -0.5, 7.0]) / np.linalg.norm([0.0, -0.5, 7.0])
_R = np.cross([0.0, 1.0, 0.0], _F)
_R /= np.linalg.norm(_R)
_U = np.cross(_F, _R)


def basis(width, height, hfov_deg=50.0):
    r = _R * (width / height)
    d = _F * (width / height) / (2 * np.tan(np.radians(hfov_deg) / 2))
    return d, r, _U.copy()


def pinhole_rays(width, height, d, r, u, jitter=None):
    """Perspective rays (§8.2): origin (H, W, 3), direction D + x0 R + y0 U."""
    ju, jv = (0.5, 0.5) if jitter is None else jitter
    x0 = (np.arange(width)[None, :] + ju) / width - 0.5
    y0 = 0.5 - (np.arange(height)[:, None] + jv) / height
    x0, y0 = np.broadcast_arrays(x0, y0)
    dirs = d + x0[..., None] * r + y0[..., None] * u
    return np.broadcast_to(LOC, dirs.shape).copy(), dirs


def _concentric(u, v):
    """Shirley's concentric map of [0,1)^2 onto the unit disc."""
    a, b = 2 * u - 1, 2 * v - 1
    use_a = np.abs(a) > np.abs(b)
    rad = np.where(use_a, a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(use_a, np.pi / 4 * b / a, np.pi / 2 - np.pi / 4 * a / b)
    phi = np.where((a == 0) & (b == 0), 0.0, phi)
    return rad * np.cos(phi), rad * np.sin(phi)


def thin_lens_rays(width, height, d, r, u, *, diameter, focal_distance, n, rng):
    """n samples of an ideal thin lens: yields (origin, direction), each (H, W, 3).

    Per pixel the lens disc (``diameter``) and the pixel area are each split
    into n = g*g strata, paired by independent random permutations, with
    jitter inside each stratum.  Every ray of a pixel passes through
    ``LOC + Dpix * F/|D|`` (focal plane perpendicular to D at distance F).
    """
    g = int(round(np.sqrt(n)))
    assert g * g == n
    xp = np.cross(u, d)
    xp /= np.linalg.norm(xp)
    yp = np.cross(d, xp)
    yp /= np.linalg.norm(yp)
    lens_perm = np.argsort(rng.random((height, width, n)), axis=2)
    pix_perm = np.argsort(rng.random((height, width, n)), axis=2)
    for k in range(n):
        ls, ps = lens_perm[..., k], pix_perm[..., k]
        lx, ly = _concentric(
            (ls % g + rng.random((height, width))) / g, (ls // g + rng.random((height, width))) / g
        )
        jitter = ((ps % g + rng.random((height, width))) / g, (ps // g + rng.random((height, width))) / g)
        _, dpix = pinhole_rays(width, height, d, r, u, jitter=jitter)
        focus = LOC + dpix * (focal_distance / np.linalg.norm(d))
        origin = LOC + (0.5 * diameter) * (lx[..., None] * xp + ly[..., None] * yp)
        yield origin, focus - origin


def box_filter(img, k=8):
    h, w = img.shape[0] // k * k, img.shape[1] // k * k
    return img[:h, :w].reshape(h // k, k, w // k, k, -1).mean(axis=(1, 3))


def _read_mesh(path):
    """Vertices (float32 as POV-Ray stores them, times the mesh2's ``scale``) and
    faces of a written mesh2."""
    text = path.read_text()
    vblock = text[text.index("vertex_vectors") : text.index("face_indices")]
    fblock = text[text.index("face_indices") : text.rindex("scale")]
    scale = float(re.search(r"scale ([^\s}]+)", text[text.rindex("scale"):]).group(1))
    nv = int(re.search(r"vertex_vectors \{ (\d+),", vblock).group(1))
    nf = int(re.search(r"face_indices \{ (\d+),", fblock).group(1))
    verts = np.array(re.findall(r"<([^>]*)>", vblock)[:nv], dtype=object)
    verts = np.array([[float(c) for c in v.split(",")] for v in verts], dtype=np.float32)
    faces = np.array([[int(c) for c in f.split(",")] for f in re.findall(r"<([^>]*)>", fblock)])
    assert len(verts) == nv and len(faces) == nf
    return verts.astype(np.float64) * scale, faces


# ---------------------------------------------------------------------------
# no POV-Ray needed


def test_render_size():
    assert render_size(96, 72, "3.7.0.10") == (96, 73, 1)
    assert render_size(96, 72, "3.8.0") == (96, 72, 0)
    assert render_size(96, 72, "3.7.1") == (96, 72, 0)


def test_ray_mesh_encodes_rays_exactly(tmp_path):
    h, w = 5, 7
    rng = np.random.default_rng(3)
    origin = np.array([10.0, 2.0, -30.0]) + rng.normal(scale=0.02, size=(h, w, 3))
    direction = rng.normal(size=(h, w, 3))
    direction[0, 0] = [1.0, 0.0, 0.0]  # axis-aligned rays use the other helper axis
    direction[0, 1] = [0.0, -3.0, 0.0]
    valid = np.ones((h, w), bool)
    valid[2, 3] = valid[4, 6] = False
    direction[2, 3] = np.nan  # ignored: blocked
    sink = [0.0, 0.0, -1e5]
    t = write_ray_mesh(tmp_path / "m.inc", "LensMesh", origin, direction, valid, sink_centre=sink)
    text = (tmp_path / "m.inc").read_text()
    assert "#declare LensMesh = mesh2 {" in text
    verts, faces = _read_mesh(tmp_path / "m.inc")
    assert faces.shape == (h * w, 3)
    tri = verts[faces]  # (n, 3, 3)
    centroid = tri.mean(axis=1) + t
    normal = np.cross(tri[:, 2] - tri[:, 0], tri[:, 1] - tri[:, 0])
    area = np.linalg.norm(normal, axis=1)
    assert area.min() > 0.5 * 1.5 * np.sqrt(3.0)  # never degenerate (s = 1)
    ok = valid.ravel()
    unit = direction.reshape(-1, 3)[ok]
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    np.testing.assert_allclose(centroid[ok], origin.reshape(-1, 3)[ok], atol=1e-5)
    np.testing.assert_allclose(normal[ok] / area[ok, None], unit, atol=1e-6)
    np.testing.assert_allclose(centroid[~ok], [sink, sink], atol=0.02)
    # vertices near the local origin, which is the centre of the valid origins
    assert np.abs(verts[: 3 * ok.sum()]).max() < 1.2


def test_ray_mesh_integer_vertices_keep_float32_precision(tmp_path):
    """Lens-like rays (origins over 2 cm, unit triangles): the integer grid's
    direction error stays at float32's level (max 3e-8 measured on a real lens
    sample, where a 2^23 grid gave 1.9e-7), and the vertex text is integers."""
    h, w = 40, 50
    rng = np.random.default_rng(11)
    origin = np.array([0.3, 1.2, -4.0]) + rng.uniform(-0.01, 0.01, size=(h, w, 3))
    direction = np.array([0.0, 0.0, 1.0]) + rng.uniform(-0.4, 0.4, size=(h, w, 3))
    valid = np.ones((h, w), bool)
    t = write_ray_mesh(tmp_path / "m.inc", "M", origin, direction, valid,
                       sink_centre=[0.3, 1.2, -1e5])
    text = (tmp_path / "m.inc").read_text()
    vblock = text[text.index("vertex_vectors"): text.index("face_indices")]
    ray_vertices = re.findall(r"<([^>]*)>", vblock)[:-3]          # the last 3: the sink
    assert all(re.fullmatch(r"-?\d+,-?\d+,-?\d+", v) for v in ray_vertices)
    verts, faces = _read_mesh(tmp_path / "m.inc")
    tri = verts[faces]
    normal = np.cross(tri[:, 2] - tri[:, 0], tri[:, 1] - tri[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    unit = direction.reshape(-1, 3) / np.linalg.norm(direction.reshape(-1, 3), axis=1,
                                                      keepdims=True)
    err = np.linalg.norm(normal - unit, axis=1)
    assert err.max() < 6e-8 and np.sqrt(np.mean(err ** 2)) < 2e-8
    np.testing.assert_allclose(tri.mean(axis=1) + t, origin.reshape(-1, 3), atol=1e-7)


def test_ray_mesh_rejects_bad_input(tmp_path):
    o = np.zeros((2, 3, 3))
    d = np.tile([0.0, 0.0, 1.0], (2, 3, 1))
    v = np.ones((2, 3), bool)
    with pytest.raises(PovlensError, match="shape"):
        write_ray_mesh(tmp_path / "a.inc", "M", o, d[:, :2], v, sink_centre=[0, 0, -1e5])
    bad = d.copy()
    bad[1, 2] = 0.0
    with pytest.raises(PovlensError, match="row 1, column 2"):
        write_ray_mesh(tmp_path / "a.inc", "M", o, bad, v, sink_centre=[0, 0, -1e5])
    far = o.copy()
    far[0, 0, 0] = 2e8  # float32 cannot hold unit triangles 1e8 units from the local origin
    with pytest.raises(PovlensError, match="degenerate"):
        write_ray_mesh(tmp_path / "a.inc", "M", far, d, v, sink_centre=[0, 0, -1e5])
    with pytest.raises(UsageError, match="identifier"):
        write_ray_mesh(tmp_path / "a.inc", "2bad", o, d, v, sink_centre=[0, 0, -1e5])
    assert not (tmp_path / "a.inc").exists()
    assert [p for p in tmp_path.iterdir()] == []  # no temporary files left


def test_camera_block_and_wrappers():
    block = mesh_camera_block(["A", "B"], [[1, 2, 3], [4, 5, 6]], 2)
    assert "2 0" in block and "mesh { A translate <1, 2, 3> }" in block
    assert "mesh { B translate <4, 5, 6> }" in block
    with pytest.raises(UsageError, match="rays per pixel"):
        mesh_camera_block(["A"], [0, 0, 0], 2)
    text = mesh_wrapper("scene.pov", ["a.inc"], ["A"], [0, 0, 0], 1, sink_centre=[0, 0, -1e5])
    assert "assumed_gamma" not in text.split("#include")[0].replace("assumed_gamma is kept", "")
    assert text.index('#include "scene.pov"') < text.index('#include "a.inc"') < text.index("camera {")
    assert _keeps_scene_version(text, before="sphere {")
    text = mesh_wrapper("s.pov", ["a.inc"], ["A"], [0, 0, 0], 1, sink_centre=[0, 0, -1e5], assumed_gamma=1.0)
    assert text.index("global_settings { assumed_gamma 1 }") < text.index('#include "s.pov"')
    fb = focal_blur_wrapper("s.pov", LOC, [0, 0, 2], [1.33, 0, 0], [0, 1, 0],
                            aperture=0.4, focal_distance=7, blur_samples=37)  # fmt: skip
    assert "aperture 0.40000000000000002" in fb and "blur_samples 37, 37" in fb
    assert "focal_point <0, 1.2, 3>" in fb
    pin = pinhole_wrapper("s.pov", LOC, [0, 0, 2], [1.33, 0, 0], [0, 1, 0])
    assert "aperture " not in pin.split("camera {")[1] and "direction <0, 0, 2>" in pin
    assert _keeps_scene_version(fb) and _keeps_scene_version(pin)
    from povlens.plan.render_folder import RenderFolder
    batch = read_template("mesh_batch.pov.tmpl").substitute(
        RenderFolder.mesh_include_names(), scene_include='"s.pov"',
        sink_centre="<0, 0, -1e5>", sink_radius="1", photons="")
    assert _keeps_scene_version(batch, before="sphere {")


def _keeps_scene_version(text, before="camera {"):
    """No ``#version`` before the scene; after it, 3.7 only if the scene ended below
    3.7, from ``before`` (povlens's first statement) to the end, where the scene's
    version is restored (tests/pov/test_scene_version.py renders why)."""
    head, tail = text.split("#include", 1)
    save = "#declare PovlensSceneVersion = version;\n#if (PovlensSceneVersion < 3.7) #version 3.7; #end\n"
    restore = "#if (PovlensSceneVersion < 3.7) #version PovlensSceneVersion; #end\n"
    code = [ln for ln in tail.splitlines() if not ln.lstrip().startswith("//")]
    return ("#version" not in "".join(ln for ln in head.splitlines() if not ln.startswith("//"))
            and tail.index(save) < tail.index(before)
            and tail.endswith(restore)
            and sum("#version" in ln for ln in code) == 2)


# ---------------------------------------------------------------------------
# against POV-Ray


@pytest.fixture
def scene(tmp_path):
    p = tmp_path / "scene.pov"
    p.write_text(SCENE)
    return p


def _render_meshes(tmp_path, tag, rays, width, height, sink, rays_per_pixel=None, **kw):
    """Write one mesh per (origin, direction[, valid]) and render them in one process."""
    names, incs, shifts = [], [], []
    for k, ray in enumerate(rays):
        o, dvec = ray[:2]
        valid = ray[2] if len(ray) > 2 else np.ones((height, width), bool)
        name = f"{tag}{k}"
        shifts.append(write_ray_mesh(tmp_path / f"{name}.inc", name, o, dvec, valid, sink_centre=sink))
        names.append(name)
        incs.append(f"{name}.inc")
    rpp = len(names) if rays_per_pixel is None else rays_per_pixel
    wrapper = write_text(
        tmp_path / f"{tag}.pov",
        mesh_wrapper("scene.pov", incs, names, shifts, rpp, sink_centre=sink, **kw),
    )
    rw, rh, drop = render_size(width, height)
    out = povray.render(wrapper, tmp_path / f"{tag}.exr", rw, rh, start_row=drop or None, threads=2)
    img = read_image(out)
    assert img.shape[:2] == (rh, rw)
    if drop:
        assert np.all(img[:drop] == 0)  # skipped with +SR
    return img[drop:]


@needs_povray
def test_pinhole_mesh_matches_perspective(scene, tmp_path):
    w, h = 96, 72
    d, r, u = basis(w, h)
    sink = default_sink_centre(LOC, d)
    own = povray.render(scene, tmp_path / "own.exr", w, h)
    write_text(tmp_path / "pin.pov", pinhole_wrapper("scene.pov", LOC, d, r, u))
    pin = read_image(povray.render(tmp_path / "pin.pov", tmp_path / "pin.exr", w, h))
    # the explicit basis is the scene's own camera
    assert np.abs(pin - read_image(own)).max() < 1e-3

    o, dirs = pinhole_rays(w, h, d, r, u)
    blocked = np.zeros((h, w), bool)
    blocked[::7, ::5] = True  # vignetted rays go into the sink
    mesh = _render_meshes(tmp_path, "Pin", [(o, dirs), (o, dirs, ~blocked)], w, h, sink, rays_per_pixel=1)
    diff = np.abs(mesh - pin).max(axis=2)
    assert np.median(diff) == 0.0
    assert np.mean(diff > 1e-3) < 0.01  # only grazing rays near the horizon may differ

    sunk = _render_meshes(tmp_path, "Sink", [(o, dirs, ~blocked)], w, h, sink)
    assert np.all(sunk[blocked] == 0.0)
    diff = np.abs(sunk - pin).max(axis=2)[~blocked]
    assert np.median(diff) == 0.0 and np.mean(diff > 1e-3) < 0.01

    if needs_row_workaround(povray_version()):
        # Without the workaround, 3.7.0.x shows face row j-1 in pixel row j.
        naive = read_image(povray.render(tmp_path / "Pin.pov", tmp_path / "naive.exr", w, h))
        assert np.abs(naive[1:] - mesh[:-1]).max() == 0.0
        assert np.abs(naive - mesh).max() > 0.1


@needs_povray
def test_thin_lens_meshes_match_focal_blur(scene, tmp_path):
    w, h = 96, 72
    aperture, focal = 1.2, 7.0  # POV-Ray aperture = 2 x lens diameter
    d, r, u = basis(w, h)
    sink = default_sink_centre(LOC, d)
    rng = np.random.default_rng(2012)

    write_text(
        tmp_path / "fb.pov",
        focal_blur_wrapper("scene.pov", LOC, d, r, u, aperture=aperture, focal_distance=focal,
                           blur_samples=100),
    )  # fmt: skip
    fb = read_image(povray.render(tmp_path / "fb.pov", tmp_path / "fb.exr", w, h, threads=2))

    def lens(tag, diameter):
        rays = thin_lens_rays(w, h, d, r, u, diameter=diameter, focal_distance=focal, n=16, rng=rng)
        return _render_meshes(tmp_path, tag, list(rays), w, h, sink, assumed_gamma=1.0)

    good = [lens("GoodA", aperture / 2), lens("GoodB", aperture / 2)]  # 2 x 16 samples
    wrong = lens("Wrong", aperture)  # lens diameter = aperture: the classic mistake

    def err(a, b):
        return float(np.abs(box_filter(a) - box_filter(b)).mean())

    e_good = err(np.mean(good, axis=0), fb)
    e_wrong = err(wrong, fb)
    noise = err(good[0], good[1])  # two independent 16-sample estimates
    blur_signal = err(
        read_image(
            povray.render(
                write_text(tmp_path / "pin.pov", pinhole_wrapper("scene.pov", LOC, d, r, u)),
                tmp_path / "pin.exr", w, h,
            )
        ),
        fb,
    )  # fmt: skip
    assert blur_signal > 0.01  # the test scene is visibly blurred
    assert e_good < noise * 1.5  # within Monte-Carlo noise
    assert e_good < 0.006
    assert e_wrong > 3 * e_good


def test_focal_blur_wrapper_adaptive_sampling_text():
    from povlens.pov.mesh import focal_blur_wrapper
    kw = dict(aperture=0.05, focal_distance=4.0)
    fixed = focal_blur_wrapper("s.pov", [0, 0, 0], [0, 0, 1], [1.33, 0, 0], [0, 1, 0],
                               blur_samples=16, **kw)
    assert "blur_samples 16, 16" in fixed and "confidence" not in fixed
    ad = focal_blur_wrapper("s.pov", [0, 0, 0], [0, 0, 1], [1.33, 0, 0], [0, 1, 0],
                            blur_samples=8, max_blur_samples=256, confidence=0.95,
                            variance=0.001, **kw)
    assert "blur_samples 8, 256" in ad and "confidence 0.95" in ad and "variance 0.001" in ad
    with pytest.raises(UsageError):
        focal_blur_wrapper("s.pov", [0, 0, 0], [0, 0, 1], [1, 0, 0], [0, 1, 0],
                           blur_samples=16, max_blur_samples=8, **kw)
    with pytest.raises(UsageError):
        focal_blur_wrapper("s.pov", [0, 0, 0], [0, 0, 1], [1, 0, 0], [0, 1, 0],
                           blur_samples=8, max_blur_samples=16, confidence=1.5, **kw)
