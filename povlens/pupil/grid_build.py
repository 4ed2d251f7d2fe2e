"""Building the exit-pupil table over the film's two coordinates (anamorphic lenses).

The table it produces, and how it is sampled, is
:class:`povlens.pupil.grid_table.GridPupilTable`; the exact probing is
:class:`povlens.pupil.grid_prober.GridProber`.  Frames are those of
:mod:`povlens.lens.coordinates` (camera frame, mm, film at z = 0, lens toward +z); the
sampling plane is the radial table's (:func:`povlens.pupil.build.sampling_plane_z_mm`).
The lens must be mirror-symmetric in x and in y (every surface of a lens file is): the
table covers the quadrant f_x, f_y >= 0 of the film's extent (X, Y).

Phases
------
1. **Nodes.**  At the grid's film points the exact boundary of the pass region is traced
   along 2N directions (the N vertex angles t_k = 2 pi k / N and the N mid-angles), from
   a point found inside it (:meth:`GridProber.interior`), in a frame that is moved to the
   region (centre to the middle of its chords along x and y through the old centre,
   s_x and s_y to their half-lengths) and traced again while it moves by more than
   :data:`povlens.pupil.build.RENORMALISE`.  N starts at 32 and doubles (up to
   :data:`MAX_ANGLES`) until the chords leave at most ``tolerance / 2`` of area error at
   the initial nodes.  Nodes where no ray passes are *dark*: they take the region of the
   nearest lit node, so that the interpolation next to them stays a superset.
2. **Refinement.**  The grid starts with :data:`INITIAL_KNOTS` evenly spaced knots per
   axis.  For every cell the exact boundary is traced at its centre and at the midpoints
   of its edges, in the interpolated frame, and compared with the interpolated polygon
   (area error at the vertex angles relative to the film centre's region, so that a
   sliver at a vignetting cut-off hardly counts): an error above ``tolerance`` at the
   midpoint of an edge along x splits the cell's x interval (a new column of nodes), along
   y its y interval, at the centre both; until no check exceeds it, the intervals are
   shorter than ``1e-5`` of the extent, or an axis has :data:`MAX_KNOTS` knots.
3. **Dilation.**  Every vertex is moved out so that the interpolated polygon contains the
   exact boundary points found at the checks: at a node its own mid-angle points, at an
   edge's midpoint twice the shortfall onto the edge's two nodes, at a cell's centre
   twice onto its four corners (twice, as the radial table does: between checks a kink
   is seen at least half), plus :data:`povlens.pupil.build.SAFETY_MARGIN` and twice the
   bisection bracket.  A shortfall d (normalised) of a boundary point between vertices
   k and k + 1 needs d / cos(pi / N) on both: the polygon's extent between two vertices,
   a b sin h / (a sin phi + b sin(h - phi)), is concave and of degree 1 in (a, b), so
   adding delta to both raises it by at least delta cos(h / 2).  Added to every corner of
   a cell, a dilation raises the interpolated vertex by the same amount in the check's
   own normalised units (the plane point is c + s rho (cos t, sin t) with s and rho
   interpolated alike).  A cell whose four corners, centre and edges found no light is
   *dark*: its film points have no ray (``valid`` False).
4. **On-axis irradiance.**  E/L at the film centre by quadrature over the node (0, 0)'s
   exact (undilated) boundary (:func:`povlens.pupil.grid_illumination.star_irradiance`).

Tests check containment against dense brute-force tracing at film points between the
checks, and the irradiance against the radial table and against naive rear-element
sampling.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from povlens.errors import OpticsError, ParameterError
from povlens.lens.prescription import LensPrescription
from povlens.pupil.build import (PLANES, RENORMALISE, SAFETY_MARGIN,
                                 check_build_arguments, check_stop_is_resolvable,
                                 sampling_plane_z_mm)
from povlens.pupil.grid_illumination import star_irradiance
from povlens.pupil.grid_prober import GridProber
from povlens.pupil.grid_table import GridPupilTable

__all__ = ["build_grid_pupil_table", "INITIAL_KNOTS", "MAX_KNOTS", "MAX_ANGLES",
           "GRID_TOLERANCE", "check_extent", "chord_extent", "area_error", "shortfall_dilation"]

#: Default tolerance of a grid table: twice the radial table's relative area error
#: spends a fifth of the build time (dgauss.50mm on a 28 x 21 mm film: 1.4 s against
#: 5.7 s at 0.005) and keeps 97-99 % of the proposed rays passing.
GRID_TOLERANCE = 0.01

#: Evenly spaced knots per axis the refinement starts from.
INITIAL_KNOTS = 5
#: Knots per axis beyond which no interval is split.
MAX_KNOTS = 17
#: The largest vertex count N.
MAX_ANGLES = 256


@dataclasses.dataclass
class _Node:
    c: np.ndarray        # (2,) centre, mm
    s: np.ndarray        # (2,) half-width, half-height, mm
    rho: np.ndarray      # (2N,) exact normalised boundary at vertex and mid-angles
    res: float           # bisection bracket (normalised)
    lit: bool            # rays pass from this film point


def check_extent(film_extent_mm) -> tuple[float, float]:
    """(X, Y) as floats; ParameterError unless both are positive and finite (mm)."""
    try:
        if isinstance(film_extent_mm, (str, bytes)):
            raise TypeError
        X, Y = (float(v) for v in film_extent_mm)
    except (TypeError, ValueError):
        raise ParameterError("film_extent_mm", film_extent_mm,
                             f"film_extent_mm={film_extent_mm!r}: expected (X, Y) in mm") from None
    if not (math.isfinite(X) and math.isfinite(Y) and X > 0 and Y > 0):
        raise ParameterError("film_extent_mm", film_extent_mm,
                             f"film_extent_mm={film_extent_mm!r}: both must be positive mm")
    return X, Y


def build_grid_pupil_table(lens: LensPrescription, film_distance_mm: float, film_extent_mm,
                           *, tolerance: float = GRID_TOLERANCE, plane: str = PLANES[0],
                           n_angles: int | None = None, safety_margin: float = SAFETY_MARGIN,
                           initial_knots: int = INITIAL_KNOTS, max_knots: int = MAX_KNOTS,
                           progress=None, metadata: dict | None = None) -> GridPupilTable:
    """Build the grid table of ``lens`` with the film ``film_distance_mm`` behind the rear
    vertex, for film points with |f_x| <= X, |f_y| <= Y (``film_extent_mm`` = (X, Y)).

    Parameters
    ----------
    lens : the lens, stop included (its aperture shape is ignored: a round stop's regions
        hold a shaped stop's).
    film_distance_mm : rear vertex to film, mm.
    film_extent_mm : (X, Y), mm: the frame's half-width and half-height (shift included,
        :func:`povlens.pupil.grid_table.frame_extent_mm`).
    tolerance : relative area error of the description (module docstring).
    plane : "exit-pupil" (default) or "rear-vertex".
    n_angles : fix N (vertices over the whole circle, a multiple of 4) instead.
    safety_margin : extra outward margin (normalised).
    initial_knots, max_knots : knots per axis to start from and at most.
    progress : optional callable taking the number of boundary evaluations just done.
    metadata : extra JSON-able entries saved with the table.

    Raises
    ------
    ParameterError
        For bad arguments.
    OpticsError
        When the stop is too small to resolve or no ray from the film centre passes.
    """
    t_start = time.perf_counter()
    X, Y = check_extent(film_extent_mm)
    check_build_arguments(film_distance_mm, math.hypot(X, Y), tolerance, None)
    if n_angles is not None and not (8 <= int(n_angles) <= 4096 and int(n_angles) % 4 == 0):
        raise ParameterError("n_angles", n_angles,
                             f"n_angles={n_angles!r}: a multiple of 4 from 8 to 4096")
    lens = lens.replace(aperture_shape=None, aperture_shape_row=-1)
    check_stop_is_resolvable(lens)
    zp, plane_used = sampling_plane_z_mm(lens, float(film_distance_mm), plane)
    tracer = _Tracer(GridProber(lens, film_distance_mm, zp), progress)
    kx = list(np.linspace(0.0, X, max(2, int(initial_knots))))
    ky = list(np.linspace(0.0, Y, max(2, int(initial_knots))))
    N, nodes, angle_error = _initial_nodes(tracer, kx, ky, tolerance, n_angles)
    if not nodes[(0.0, 0.0)].lit:
        raise OpticsError(f"{lens.source}: no ray from the film centre gets through the lens "
                          f"(film distance {film_distance_mm:g} mm)",
                          "check the stop ('f_number' / 'stop_diameter_mm') and the focus")
    grid = _Grid(kx, ky, nodes, N, tracer)
    max_error = grid.refine(tolerance, 1e-5 * max(X, Y), int(max_knots))
    grid.fill_dark_nodes()
    centre, scale, rho, dark, mean_dilation = grid.dilated(safety_margin)
    n0 = nodes[(0.0, 0.0)]
    axial = float(star_irradiance(np.zeros((1, 2)), n0.c[None], n0.s[None],
                                  n0.rho[None], zp)[0])
    stats = {"build_time_s": time.perf_counter() - t_start,
             "rays_traced": int(tracer.prober.rays),
             "boundary_evaluations": int(tracer.evaluations),
             "max_check_area_error": max_error, "angle_area_error": angle_error,
             "mean_dilation": mean_dilation,
             "knot_limit_reached": max(len(grid.kx), len(grid.ky)) >= int(max_knots),
             "dark_nodes": int(sum(not n.lit for n in nodes.values())),
             "non_star_shaped_points": len(tracer.prober.non_star_points)}
    meta = dict(metadata or {})
    meta.setdefault("requested_plane", plane)
    return GridPupilTable(lens, film_distance_mm, (X, Y), zp, plane_used, grid.kx, grid.ky,
                          centre, scale, rho, dark, tolerance, axial, stats, meta)


class _Tracer:
    """The prober's exact boundaries in frames that follow the regions, counted for the
    statistics and reported to the progress callback."""

    def __init__(self, prober: GridProber, progress=None):
        self.prober = prober
        self.tick = progress or (lambda n: None)
        self.evaluations = 0

    def boundary(self, f, c, s, N: int):
        """Exact boundary (B, 2N) at vertex and mid-angles in frames (c, s) (B, 2)."""
        out = self.prober.boundary(f[:, 0], f[:, 1], c[:, 0], c[:, 1], s[:, 0], s[:, 1], 2 * N)
        self.evaluations += len(f)
        self.tick(len(f))
        return out

    def regions(self, f: np.ndarray, N: int, frames=None) -> list[_Node]:
        """Exact regions of film points f (B, 2), each in a frame moved to it (module
        docstring, phase 1).  ``frames``: (c, s) (B, 2) to try first (None: found from a
        point inside)."""
        B = len(f)
        if frames is None:
            c, s, lit = self._start_frames(f)
        else:
            c, s = (np.array(v, dtype=np.float64) for v in frames)
            lit = np.ones(B, bool)
        rho, ok, res = np.zeros((B, 2 * N)), np.zeros(B, bool), np.zeros(B)
        idx = np.nonzero(lit)[0]
        if idx.size:
            rho[idx], ok[idx], res[idx] = self.boundary(f[idx], c[idx], s[idx], N)
        bad = np.nonzero(lit & ~ok)[0]          # the frame's centre is outside: start over
        if bad.size and frames is not None:
            c[bad], s[bad], lit[bad] = self._start_frames(f[bad])
            redo = bad[lit[bad]]
            if redo.size:
                rho[redo], ok[redo], res[redo] = self.boundary(f[redo], c[redo], s[redo], N)
        lit &= ok
        for _ in range(2):
            c_new, s_new, moved = _moved_frames(c, s, rho, N)
            redo = np.nonzero(lit & (moved > RENORMALISE) & np.all(s_new > 0, axis=1))[0]
            if not redo.size:
                break
            r2, ok2, res2 = self.boundary(f[redo], c_new[redo], s_new[redo], N)
            take = redo[ok2]
            c[take], s[take], rho[take], res[take] = (c_new[take], s_new[take], r2[ok2],
                                                      res2[ok2])
        return [_Node(c[i].copy(), s[i].copy(), rho[i] if lit[i] else np.zeros(2 * N),
                      float(res[i]), bool(lit[i])) for i in range(B)]

    def _start_frames(self, f: np.ndarray):
        """(c, s, found) from a point inside each region and the passing grid's box."""
        cx, cy, found, box = self.prober.interior(f[:, 0], f[:, 1])
        c = np.stack([cx, cy], 1)
        half = np.stack([0.5 * (box[:, 1] - box[:, 0]), 0.5 * (box[:, 3] - box[:, 2])], 1)
        return c, np.where(half > 0, half, 1.0), found


def _moved_frames(c, s, rho, N: int):
    """The frames moved to the regions: centre to the middle of the chords along x and y
    through the old centre, scales to their half-lengths; and how far each moved
    (relative).  The film centre's region stays centred (mirror symmetry)."""
    r0, r90, r180, r270 = rho[:, 0], rho[:, N // 2], rho[:, N], rho[:, 3 * N // 2]
    c_new = np.stack([c[:, 0] + 0.5 * s[:, 0] * (r0 - r180),
                      c[:, 1] + 0.5 * s[:, 1] * (r90 - r270)], 1)
    s_new = np.stack([0.5 * s[:, 0] * (r0 + r180), 0.5 * s[:, 1] * (r90 + r270)], 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        moved = np.maximum.reduce([np.abs(c_new[:, 0] - c[:, 0]) / s_new[:, 0],
                                   np.abs(c_new[:, 1] - c[:, 1]) / s_new[:, 1],
                                   np.abs(s_new[:, 0] / s[:, 0] - 1),
                                   np.abs(s_new[:, 1] / s[:, 1] - 1)])
    return c_new, s_new, np.where(np.isfinite(moved), moved, np.inf)


def chord_extent(rho_v: np.ndarray) -> np.ndarray:
    """(..., 2N) the polygon's normalised extent at the vertex and mid-angles, from its
    vertex distances (..., N) (closed: vertex N is vertex 0)."""
    N = rho_v.shape[-1]
    a, b = rho_v, np.roll(rho_v, -1, axis=-1)
    s = a + b
    with np.errstate(invalid="ignore", divide="ignore"):
        mid = np.where(s > 0, 2.0 * a * b * math.cos(math.pi / N) / np.where(s > 0, s, 1.0), 0.0)
    out = np.empty(rho_v.shape[:-1] + (2 * N,))
    out[..., 0::2], out[..., 1::2] = rho_v, mid
    return out


def area_error(exact: np.ndarray, approx: np.ndarray) -> float:
    """Area between two star curves at the same evenly spaced angles over the whole
    circle, relative to the area inside ``exact``."""
    ref = float(np.sum(exact * exact))
    diff = float(np.sum(np.abs(exact * exact - approx * approx)))
    if ref <= 0:
        return 0.0 if diff <= 0 else math.inf
    return diff / ref


def _initial_nodes(tracer: _Tracer, kx, ky, tolerance: float, n_angles):
    """N and the initial grid's nodes: N doubled from 32 until the chords' area error at
    the lit nodes is at most tolerance / 2 (or ``n_angles``).  Returns (N, {(x, y):
    _Node}, the chords' largest area error)."""
    pts = np.array([(x, y) for x in kx for y in ky], dtype=np.float64)
    choices = [int(n_angles)] if n_angles else [32, 64, 128, MAX_ANGLES]
    frames = None
    for N in choices:
        found = tracer.regions(pts, N, frames)
        lit = [n for n in found if n.lit]
        err = max((area_error(n.rho, chord_extent(n.rho[0::2])) for n in lit), default=0.0)
        if err <= 0.5 * tolerance or not lit:
            break
        frames = (np.array([n.c if n.lit else [0.0, 0.0] for n in found]),
                  np.array([n.s if n.lit else [1.0, 1.0] for n in found]))
    return N, {(float(x), float(y)): n for (x, y), n in zip(pts, found)}, err


def shortfall_dilation(points: np.ndarray, c: np.ndarray, s: np.ndarray,
                       rho_v: np.ndarray) -> np.ndarray:
    """(N,) what the polygon (centre c (2,), scales s (2,), vertex distances rho_v (N,))
    needs added to its vertex distances to contain the plane points (m, 2): for a point
    at normalised distance D beyond the polygon's extent E at its angle, (D - E) /
    cos(pi / N) on the two vertices about it (module docstring, phase 3)."""
    N = rho_v.size
    h = 2.0 * math.pi / N
    out = np.zeros(N)
    if not len(points) or not np.all(s > 0):
        return out
    d = (np.asarray(points, dtype=np.float64) - c) / s
    theta = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2.0 * math.pi)
    j = np.clip(np.floor(theta / h).astype(np.int64), 0, N - 1)
    phi = theta - j * h
    a, b = rho_v[j], rho_v[(j + 1) % N]
    den = a * np.sin(phi) + b * np.sin(h - phi)
    with np.errstate(invalid="ignore", divide="ignore"):
        extent = np.where(den > 0, a * b * math.sin(h) / np.where(den > 0, den, 1.0), 0.0)
    need = np.maximum(np.hypot(d[:, 0], d[:, 1]) - extent, 0.0) / math.cos(0.5 * h)
    np.maximum.at(out, j, need)
    np.maximum.at(out, (j + 1) % N, need)
    return out


def _boundary_points(node: _Node) -> np.ndarray:
    """(2N, 2) the node's exact boundary points on the plane (empty when dark)."""
    if not node.lit:
        return np.zeros((0, 2))
    t = np.arange(node.rho.size) * (math.pi / (node.rho.size // 2))
    return np.stack([node.c[0] + node.rho * node.s[0] * np.cos(t),
                     node.c[1] + node.rho * node.s[1] * np.sin(t)], 1)


@dataclasses.dataclass
class _Check:
    corners: tuple       # node keys (2 for an edge, 4 for a cell)
    weights: np.ndarray  # their interpolation weights at the check point
    gens: tuple          # the corners' generations when checked
    points: np.ndarray   # (m, 2) exact boundary points found there (empty: no light)
    error: float         # relative area error of the interpolation (inf: not measured)


class _Grid:
    """The tensor grid of nodes during refinement and dilation (module docstring)."""

    def __init__(self, kx, ky, nodes: dict, N: int, tracer: _Tracer):
        self.kx, self.ky = sorted(kx), sorted(ky)
        self.nodes, self.N, self.tracer = nodes, N, tracer
        self.gen = {k: 0 for k in nodes}
        self.checks: dict[tuple, _Check] = {}
        self.fill_dark_nodes()

    def fill_dark_nodes(self) -> None:
        """Give every dark node the region of the nearest lit node (grid index distance),
        bumping its generation when that changes."""
        lit = [(i, j) for i, x in enumerate(self.kx) for j, y in enumerate(self.ky)
               if self.nodes[(x, y)].lit]
        for i, x in enumerate(self.kx):
            for j, y in enumerate(self.ky):
                node = self.nodes[(x, y)]
                if node.lit or not lit:
                    continue
                a, b = min(lit, key=lambda q: (abs(q[0] - i) + abs(q[1] - j),
                                               (self.kx[q[0]] - x) ** 2 + (self.ky[q[1]] - y) ** 2))
                src = self.nodes[(self.kx[a], self.ky[b])]
                if not (np.array_equal(node.rho, src.rho) and np.array_equal(node.c, src.c)):
                    node.c, node.s, node.rho, node.res = (src.c.copy(), src.s.copy(),
                                                          src.rho.copy(), src.res)
                    self.gen[(x, y)] = self.gen.get((x, y), 0) + 1

    def _check_sites(self) -> dict:
        """{key: (film point, corner keys, weights)} of every cell centre and edge midpoint."""
        sites = {}
        for i in range(len(self.kx) - 1):
            x0, x1 = self.kx[i], self.kx[i + 1]
            for j in range(len(self.ky) - 1):
                y0, y1 = self.ky[j], self.ky[j + 1]
                sites[("c", x0, x1, y0, y1)] = ((0.5 * (x0 + x1), 0.5 * (y0 + y1)),
                                                ((x0, y0), (x1, y0), (x0, y1), (x1, y1)),
                                                np.full(4, 0.25))
        for x0, x1 in zip(self.kx[:-1], self.kx[1:]):
            for y in self.ky:
                sites[("x", x0, x1, y)] = ((0.5 * (x0 + x1), y), ((x0, y), (x1, y)),
                                           np.full(2, 0.5))
        for y0, y1 in zip(self.ky[:-1], self.ky[1:]):
            for x in self.kx:
                sites[("y", x, y0, y1)] = ((x, 0.5 * (y0 + y1)), ((x, y0), (x, y1)),
                                           np.full(2, 0.5))
        return sites

    def interpolated(self, corners, weights):
        """(c, s, rho at the vertex angles) interpolated from the corner nodes."""
        ns = [self.nodes[k] for k in corners]
        c = sum(w * n.c for w, n in zip(weights, ns))
        s = sum(w * n.s for w, n in zip(weights, ns))
        return c, s, sum(w * n.rho[0::2] for w, n in zip(weights, ns))

    def run_checks(self) -> None:
        """Trace every check site whose cached check is missing or stale."""
        sites = self._check_sites()
        self.checks = {k: v for k, v in self.checks.items() if k in sites and v.gens == tuple(
            self.gen[c] for c in v.corners)}
        todo = [k for k in sites if k not in self.checks]
        if not todo:
            return
        f = np.array([sites[k][0] for k in todo], dtype=np.float64)
        frames = [self.interpolated(sites[k][1], sites[k][2]) for k in todo]
        c = np.array([fr[0] for fr in frames])
        s = np.array([fr[1] for fr in frames])
        rho, ok, _ = self.tracer.boundary(f, c, s, self.N)
        found = {}
        bad = np.nonzero(~ok)[0]        # the interpolated centre is outside: start over
        if bad.size:
            found = dict(zip(bad.tolist(), self.tracer.regions(f[bad], self.N)))
        for i, k in enumerate(todo):
            _, corners, w = sites[k]
            # errors in units of the axial region's area: a sliver at a vignetting
            # cut-off hardly counts (dilation makes it conservative all the same)
            if ok[i]:
                node = _Node(c[i], s[i], rho[i], 0.0, True)
                err = area_error(rho[i, 0::2], frames[i][2]) * self._area_share(node)
            else:
                node = found[i]
                err = self._area_share(node) if node.lit else 0.0
            self.checks[k] = _Check(corners, w, tuple(self.gen[q] for q in corners),
                                    _boundary_points(node), err)

    def _area_share(self, node: _Node) -> float:
        """The area of ``node``'s exact region over the film centre's (0 when dark)."""
        def area(n):
            r = n.rho[0::2]
            return float(n.s[0] * n.s[1] * np.sum(r * np.roll(r, -1))) if n.lit else 0.0
        a0 = area(self.nodes[(0.0, 0.0)])
        return area(node) / a0 if a0 > 0 else 1.0

    def refine(self, tolerance: float, min_w: float, max_knots: int) -> float:
        """Split intervals until every check's error is within ``tolerance`` (module
        docstring, phase 2); returns the largest error accepted."""
        while True:
            self.run_checks()
            split_x, split_y = set(), set()
            for key, chk in self.checks.items():
                if chk.error <= tolerance:
                    continue
                if key[0] in ("c", "x"):
                    split_x.add((key[1], key[2]))
                if key[0] in ("c", "y"):
                    split_y.add((key[-2], key[-1]))
            new_x = sorted(0.5 * (a + b) for a, b in split_x if b - a > 2 * min_w)
            new_y = sorted(0.5 * (a + b) for a, b in split_y if b - a > 2 * min_w)
            new_x = new_x[:max(0, max_knots - len(self.kx))]
            new_y = new_y[:max(0, max_knots - len(self.ky))]
            if not new_x and not new_y:
                break
            kx, ky = sorted(self.kx + new_x), sorted(self.ky + new_y)
            pts = [(x, y) for x in kx for y in ky if (x, y) not in self.nodes]
            for key, node in zip(pts, self.tracer.regions(np.array(pts), self.N)):
                self.nodes[key], self.gen[key] = node, 0
            self.kx, self.ky = kx, ky
            self.fill_dark_nodes()
        errs = [c.error for c in self.checks.values() if math.isfinite(c.error)]
        return max(errs, default=0.0)

    def dilated(self, safety_margin: float):
        """(centre (Kx, Ky, 2), scale (Kx, Ky, 2), rho (Kx, Ky, N), cell_dark
        (Kx - 1, Ky - 1), mean dilation): the nodes' vertex distances moved out to hold
        every boundary point found (module docstring, phase 3)."""
        self.run_checks()
        dil = {k: np.zeros(self.N) for k in self.nodes}
        for key, node in self.nodes.items():
            if node.lit:
                dil[key] = shortfall_dilation(_boundary_points(node), node.c, node.s,
                                              node.rho[0::2])
        for chk in self.checks.values():
            c, s, rho_v = self.interpolated(chk.corners, chk.weights)
            need = 2.0 * shortfall_dilation(chk.points, c, s, rho_v)
            for q in chk.corners:
                dil[q] = np.maximum(dil[q], need)
        Kx, Ky = len(self.kx), len(self.ky)
        centre, scale = np.zeros((Kx, Ky, 2)), np.zeros((Kx, Ky, 2))
        rho, added = np.zeros((Kx, Ky, self.N)), np.zeros((Kx, Ky, self.N))
        for i, x in enumerate(self.kx):
            for j, y in enumerate(self.ky):
                n = self.nodes[(x, y)]
                added[i, j] = dil[(x, y)] + safety_margin + 2.0 * n.res
                centre[i, j], scale[i, j] = n.c, n.s
                rho[i, j] = np.where(n.rho[0::2] > 0, n.rho[0::2] + added[i, j], 0.0)
        return centre, scale, rho, self._dark_cells(), float(np.mean(added))

    def _dark_cells(self) -> np.ndarray:
        """(Kx - 1, Ky - 1) True where no corner, centre or edge of a cell found light."""
        lit_edge = {}
        for key, chk in self.checks.items():
            lit_edge[key] = len(chk.points) > 0
        dark = np.zeros((len(self.kx) - 1, len(self.ky) - 1), bool)
        for i, (x0, x1) in enumerate(zip(self.kx[:-1], self.kx[1:])):
            for j, (y0, y1) in enumerate(zip(self.ky[:-1], self.ky[1:])):
                keys = [("c", x0, x1, y0, y1), ("x", x0, x1, y0), ("x", x0, x1, y1),
                        ("y", x0, y0, y1), ("y", x1, y0, y1)]
                corners = [(x0, y0), (x1, y0), (x0, y1), (x1, y1)]
                dark[i, j] = (not any(self.nodes[q].lit for q in corners)
                              and not any(lit_edge.get(k, True) for k in keys))
        return dark
