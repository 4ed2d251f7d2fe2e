"""The exact ray field of a real lens for ONE fixed pupil point (accumulation-buffer
sampling), as a function of the image position, for the distribution-3 prototype.

Frames: camera frame of povlens.lens.frames (mm, film z = 0, lens toward +z); world
= POV-Ray scene units via the plan's ScenePlacement.  Image coordinates (x, y) are in
pixels: x right from the left edge, y down from the top edge; pixel (i, j) covers
[i, i+1) x [j, j+1) and its centre is (i + 0.5, j + 0.5) -- povlens.lens.film's
convention (film point = (-u, -v)).

A lens sample here is one point P on the pupil table's sampling plane (the paraxial
exit-pupil plane, z = table.plane_z_mm), shared by every pixel.  The film-side ray of
film point f is f -> P; it is traced to the scene:

* ``ghost``: traced with every clear aperture (rims and stop) ignored.  This is the
  analytic continuation of the ray field across the vignetting cut: smooth wherever
  the spheres are hit and no ray is totally reflected.  It is what the mesh carries.
* ``passed``: the exact verdict (same trace, apertures checked): margins
  r_i^2 - h_i^2 > 0 at every surface i.  Identical to povlens.lens.tracer's verdict
  (checked in check_tracer()).

P is uniform on a disc of radius R_B that contains the table's region for every film
point (all azimuths), so the radiometric weight of a passed ray is
cos^4(theta) / z_p^2 * pi R_B^2 (povlens.pupil.sampler.finish_sample with area
pi R_B^2).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from povlens.lens.film import Film
from povlens.lens.frames import vertex_z_mm
from povlens.lens.paraxial import stopped_down
from povlens.lens.prescription import read_lens
from povlens.lens.tracer import trace_from_film
from povlens.pupil.rays import ScenePlacement
from povlens.pupil.storage import cached_pupil_table


@dataclasses.dataclass
class Setup:
    lens: object
    film: Film
    film_distance_mm: float
    placement: ScenePlacement
    table: object
    efl_mm: float
    plan: dict
    outdir: Path

    @property
    def plane_z_mm(self) -> float:
        return self.table.plane_z_mm

    @property
    def pixel_angle(self) -> float:
        """rad per pixel at the centre: pitch / efl (the issue's px measure)."""
        return self.film.pixel_pitch_mm / self.efl_mm

    def with_size(self, w: int, h: int) -> "Setup":
        f = self.film
        return dataclasses.replace(self, film=Film(f.width_mm, f.height_mm, int(w), int(h)))


def load_setup(outdir) -> Setup:
    """Everything from a folder written by povlens.api.convert(..., method='mesh')."""
    outdir = Path(outdir)
    plan = json.loads((outdir / "plan.json").read_text())
    inp = plan["inputs"]
    lens = stopped_down(read_lens(inp["lens"]), stop_diameter_mm=inp["stop_diameter_mm"],
                        f_number=inp["f_number"])
    fl = plan["film"]
    film = Film(fl["width_mm"], fl["height_mm"], fl["width_px"], fl["height_px"])
    fd = plan["focus"]["film_distance_mm"]
    pl = plan["placement"]
    placement = ScenePlacement(np.array(pl["film_centre"]), np.array(pl["right"]),
                               np.array(pl["up"]), np.array(pl["forward"]), pl["mm_per_unit"])
    table, _ = cached_pupil_table(outdir / "pupil.npz", lens, fd, film.half_diagonal_mm,
                                  save=False)
    return Setup(lens, film, fd, placement, table, plan["lens"]["efl_mm"], plan, outdir)


def image_to_film_mm(film: Film, x, y) -> np.ndarray:
    """Image positions (pixels) -> film points (..., 2) mm (povlens.lens.film)."""
    u = np.asarray(x, float) / film.width_px * film.width_mm - 0.5 * film.width_mm
    v = 0.5 * film.height_mm - np.asarray(y, float) / film.height_px * film.height_mm
    return np.stack([-u, -v], axis=-1)


def bounding_disc_radius_mm(table) -> float:
    """R_B: the largest distance from the axis of any vertex of the table's (dilated)
    region at any knot, i.e. a disc containing the region for every film point."""
    r = 0.0
    for fr in table.film_radius_mm:
        poly = table.region(float(fr))
        if len(poly):
            r = max(r, float(np.hypot(poly[:, 0], poly[:, 1]).max()))
    return r * (1.0 + 1e-6)


def pupil_point(u, radius_mm: float) -> np.ndarray:
    """Shirley-Chiu concentric map of u in [0,1)^2 to the disc of radius_mm (2,)."""
    a, b = 2.0 * u[0] - 1.0, 2.0 * u[1] - 1.0
    if a == 0 and b == 0:
        return np.zeros(2)
    if abs(a) > abs(b):
        r, phi = a, math.pi / 4 * (b / a)
    else:
        r, phi = b, math.pi / 2 - math.pi / 4 * (a / b)
    return radius_mm * r * np.array([math.cos(phi), math.sin(phi)])


@dataclasses.dataclass
class Field:
    """Rays for n image points (camera frame and world)."""
    origin_mm: np.ndarray      # (n, 3) exit point on the front surface (ghost trace)
    direction: np.ndarray      # (n, 3) unit, camera frame
    geom_ok: np.ndarray        # (n,) the ghost trace exists (spheres hit, no TIR)
    margin: np.ndarray         # (n, S) r_i^2 - h_i^2 (mm^2) at each surface; -inf where unknown
    passed: np.ndarray         # (n,) the exact verdict
    weight: np.ndarray         # (n,) cos^4 / z_p^2 * area_B, times passed
    world_origin: np.ndarray   # (n, 3) scene units
    world_direction: np.ndarray  # (n, 3)


def ghost_trace(lens, film_distance_mm, o, d):
    """Trace from the film (like povlens.lens.tracer._trace, toward the scene) but
    without clipping at clear apertures; record r_i^2 - h_i^2 at each surface.

    Returns origin (n,3), direction (n,3), geom_ok (n,), margin (n, S)."""
    o = np.array(o, float).reshape(-1, 3)
    d = np.array(d, float).reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    n = len(o)
    S = lens.n_surfaces
    zv = vertex_z_mm(lens.thickness_mm, float(film_distance_mm))
    curv = lens.curvature_per_mm
    r2max = lens.aperture_radius_mm ** 2
    aperture = lens.is_aperture
    n_before, n_after = lens.index_before, lens.index_after
    margin = np.full((n, S), -np.inf)
    ok = np.ones(n, bool)
    x, y, z = o[:, 0].copy(), o[:, 1].copy(), o[:, 2].copy()
    dx, dy, dz = d[:, 0].copy(), d[:, 1].copy(), d[:, 2].copy()
    sense = -1.0
    with np.errstate(all="ignore"):
        for i in range(S - 1, -1, -1):
            c = curv[i]
            ps = zv[i] - z
            ds = -dz
            B = c * (x * dx + y * dy + ps * ds) - ds
            C = c * (x * x + y * y + ps * ps) - 2.0 * ps
            D = B * B - c * C
            sqrtD = np.sqrt(np.maximum(D, 0.0))
            sigma = -np.sign(ds)
            same = (np.sign(B) == sigma) | (B == 0.0)
            t = np.where(same, -C / (B + sigma * sqrtD), (sigma * sqrtD - B) / (c if c != 0 else 1.0))
            hx, hy = x + t * dx, y + t * dy
            hs = ps + t * ds
            bad = ((D < 0.0) | ~np.isfinite(t) | (t < -1e-9) | (np.sign(ds) != sense)
                   | (1.0 - c * hs <= 0.0))
            margin[:, i] = np.where(ok & ~bad, r2max[i] - (hx * hx + hy * hy), -np.inf)
            if not aperture[i]:
                n1, n2 = n_after[i], n_before[i]
                mu = n1 / n2
                nx, ny, ns = -c * hx, -c * hy, 1.0 - c * hs
                cos_i = nx * dx + ny * dy + ns * ds
                k2 = 1.0 - mu * mu * (1.0 - cos_i * cos_i)
                g = np.sign(cos_i) * np.sqrt(np.maximum(k2, 0.0)) - mu * cos_i
                ex, ey, es = mu * dx + g * nx, mu * dy + g * ny, mu * ds + g * ns
                en = np.sqrt(ex * ex + ey * ey + es * es)
                ex, ey, es = ex / en, ey / en, es / en
                bad |= (k2 < 0.0) | (np.sign(es) != sense) | ~np.isfinite(en) | (en == 0.0)
                dx, dy, dz = np.where(bad, dx, ex), np.where(bad, dy, ey), np.where(bad, dz, -es)
            x, y, z = np.where(bad, x, hx), np.where(bad, y, hy), np.where(bad, z, zv[i] - hs)
            ok &= ~bad
    return np.stack([x, y, z], 1), np.stack([dx, dy, dz], 1), ok, margin


def trace_field(setup: Setup, P_xy, x, y, area_mm2: float) -> Field:
    """The exact rays of image positions (x, y) (any equal shapes, flattened) for the
    pupil point P_xy (2,) on the sampling plane."""
    f = image_to_film_mm(setup.film, x, y).reshape(-1, 2)
    n = len(f)
    org = np.zeros((n, 3))
    org[:, :2] = f
    zp = setup.plane_z_mm
    d = np.empty((n, 3))
    d[:, 0] = P_xy[0] - f[:, 0]
    d[:, 1] = P_xy[1] - f[:, 1]
    d[:, 2] = zp
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o2, d2, ok, margin = ghost_trace(setup.lens, setup.film_distance_mm, org, d)
    passed = ok & np.all(margin > 0, axis=1)
    w = np.where(passed, d[:, 2] ** 4 / zp ** 2 * area_mm2, 0.0)
    pl = setup.placement
    return Field(o2, d2, ok, margin, passed, w, pl.points_to_world(o2), pl.directions_to_world(d2))


def check_tracer(setup: Setup, P_xy, n=20000, seed=1):
    """The ghost trace's verdict and rays equal povlens.lens.tracer's on random points."""
    rng = np.random.default_rng(seed)
    W, H = setup.film.width_px, setup.film.height_px
    x, y = rng.random(n) * W, rng.random(n) * H
    fld = trace_field(setup, P_xy, x, y, 1.0)
    f = image_to_film_mm(setup.film, x, y)
    org = np.zeros((n, 3)); org[:, :2] = f
    d = np.c_[P_xy[0] - f[:, 0], P_xy[1] - f[:, 1], np.full(n, setup.plane_z_mm)]
    t = trace_from_film(setup.lens, setup.film_distance_mm, org, d)
    same = np.array_equal(t.passed, fld.passed)
    p = t.passed
    err = (np.abs(t.direction[p] - fld.direction[p]).max() if p.any() else 0.0,
           np.abs(t.origin_mm[p] - fld.origin_mm[p]).max() if p.any() else 0.0)
    return same, int(p.sum()), err
