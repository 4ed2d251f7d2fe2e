"""``povlens report``: one self-contained HTML page about one or more render folders.

For each folder made by ``povlens convert`` / ``povlens render`` the page shows

* the lens drawn to scale: element profiles from the sag formula between their
  clear apertures, glass shaded, the aperture stop, the film plane, and ray fans
  from three film points (centre, mid-field, edge) traced through the real lens;
* its paraxial data and the focus (film distance, object distance, plane of focus);
* the exit pupil across the field (the pupil table's polygons at several film radii
  over the exactly traced pass region);
* the focus made visible: the pinhole render with what lies within the thin-lens
  depth of field tinted (distances from :mod:`povlens.plan.depth_probe`);
* the renders side by side (pinhole, ``focal_blur``, and the exact mesh render when
  the folder has one), false-colour differences against the mesh render, an error
  table (RMSE, PSNR, mean and max error in linear light) and the render times;
* what the thin-lens model gets wrong (``plan.json``'s ``model_error``) over the
  field height.

Every image is embedded as a base64 PNG ``data:`` URI, so the page is one file.
Pieces a folder does not have yet (e.g. no mesh render) are shown as "not
rendered" rather than failing.  A small script on the page sets the document
title to ``images-ok N`` once all N images have decoded (``images-missing K``
otherwise), which the tests check in headless Chromium.
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from povlens.errors import PovlensError
from povlens.lens.coordinates import vertex_z_mm
from povlens.lens.paraxial import paraxial_data
from povlens.lens.asphere import row_sag
from povlens.lens.prescription import LensPrescription
from povlens.lens.tracer import trace_from_film
from povlens.plan.depth_probe import axial_depth, probe_depth
from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import Plan, read_plan
from povlens.report import DEFAULT_REPORT
from povlens.pupil.plot import plot_pupil_shapes
from povlens.pupil.grid_table import frame_extent_mm
from povlens.pupil.storage import cached_pupil_table
from povlens.rendering.folder_composite import composite_outdir
from povlens.rendering.folder_inputs import lens_for
from povlens.rendering.views import render_view
from povlens.report.compare import compare_arrays, difference_magnitude, false_colour
from povlens.rendering.focus_pull import read_frames
from povlens.report.focus_pull_strip import frames_section, is_frames_folder
from povlens.util.files import write_text
from povlens.util.images import read_image

__all__ = ["make_report", "surface_hits", "depth_of_field", "COC_PIXELS"]

#: Circle of confusion (in pixels) that defines the depth of field shown.
COC_PIXELS = 1.5


# ----- small helpers -------------------------------------------------------------------

def _esc(x) -> str:
    return html.escape(str(x), quote=True)


def _num(v, fmt: str = ".4g", unit: str = "") -> str:
    if v is None:
        return "—"
    try:
        f = float(v)
    except (TypeError, ValueError):
        return _esc(v)
    if math.isinf(f):
        return "∞"
    if math.isnan(f):
        return "—"
    return f"{f:{fmt}}{(' ' + unit) if unit else ''}"


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _png_uri(data: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def _fig_uri(fig, dpi: int = 100) -> str:
    plt = _plt()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    return _png_uri(buf.getvalue())


def _array_uri(rgb: np.ndarray) -> str:
    """PNG data URI of an (H, W, 3) display image with values in [0, 1]."""
    plt = _plt()
    buf = io.BytesIO()
    a = np.clip(np.nan_to_num(np.asarray(rgb, dtype=np.float64)[..., :3], nan=0.0), 0.0, 1.0)
    plt.imsave(buf, a, format="png")
    return _png_uri(buf.getvalue())


def _srgb(linear: np.ndarray) -> np.ndarray:
    """Linear light -> sRGB display values in [0, 1] (clipped)."""
    x = np.clip(np.nan_to_num(np.asarray(linear, dtype=np.float64), nan=0.0, posinf=1.0),
                0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def _img(uri: str, alt: str, cls: str = "") -> str:
    c = f' class="{cls}"' if cls else ""
    return f'<img{c} src="{uri}" alt="{_esc(alt)}">'


def _missing(what: str, why: str = "not rendered") -> str:
    return f'<div class="missing">{_esc(what)}: {_esc(why)}</div>'


def _colour_line(d: dict | None, rendered: bool) -> str:
    """The lens's chromatic aberration (plan.json ``dispersion``, F against C line):
    one line and a small table of the lateral colour across the field; "" without."""
    if not d:
        return ""
    lat = [["lateral colour (px)"] + [_num(v, ".3g") for v in d["lateral_colour_px"]]]
    return (f"<p>colour (--dispersion, {'rendered' if rendered else 'not rendered'}): "
            f"lateral up to {_num(d['max_lateral_colour_px'], '.3g')} px, longitudinal "
            f"{_num(d['longitudinal_colour_mm'], '.3g')} mm (blur "
            f"{_num(d['longitudinal_blur_px'], '.3g')} px)</p>"
            + _table(["field"] + [f"{f:.2g}" for f in d["field_fraction"]], lat))


def _table(header: list[str], rows: list[list[str]]) -> str:
    h = "".join(f"<th>{_esc(x)}</th>" for x in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><thead><tr>{h}</tr></thead><tbody>{body}</tbody></table>"


# ----- ray paths for the lens drawing ----------------------------------------------------

def surface_hits(lens: LensPrescription, film_distance_mm: float, origin_mm, direction):
    """Where rays from the film meet each surface, for drawing ray paths.

    Returns (hits (n, S, 3) mm, camera frame, NaN where a ray never reaches the
    surface; result of the full trace).  Not a tracer of its own: the hit on
    surface i is the exit point of the sub-lens made of rows i..S-1
    (:meth:`povlens.lens.prescription.LensPrescription.sub_lens`) traced with
    :func:`povlens.lens.tracer.trace_from_film`.
    """
    o = np.asarray(origin_mm, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(direction, dtype=np.float64).reshape(-1, 3)
    full = trace_from_film(lens, film_distance_mm, o, d)
    n_s = lens.n_surfaces
    hits = np.full((len(o), n_s, 3), np.nan)
    for i in range(n_s):
        r = trace_from_film(lens.sub_lens(i), film_distance_mm, o, d)
        # The ray reaches surface i if the full trace blocked it nowhere behind i.
        reached = full.passed | (full.blocked_at < i)
        ok = r.passed & reached
        hits[ok, i] = r.origin_mm[ok]
    return hits, full


def _fan(lens, fd: float, height_mm: float, n_rays: int = 7):
    """A meridional fan (in the x-z plane) from film point (h, 0, 0) through the lens:
    ``n_rays`` evenly spread over the aims that get through."""
    a_rear = float(lens.aperture_radius_mm[-1])
    aims = np.linspace(-1.6 * a_rear, 1.6 * a_rear, 801)
    o = np.tile([height_mm, 0.0, 0.0], (len(aims), 1))
    d = np.column_stack([aims - height_mm, np.zeros_like(aims), np.full_like(aims, fd)])
    ok = trace_from_film(lens, fd, o, d).passed
    if not ok.any():
        return None
    good = aims[ok]
    pick = np.unique(np.round(np.linspace(0, len(good) - 1, n_rays)).astype(int))
    sel = good[pick]
    o = np.tile([height_mm, 0.0, 0.0], (len(sel), 1))
    d = np.column_stack([sel - height_mm, np.zeros_like(sel), np.full_like(sel, fd)])
    return o, surface_hits(lens, fd, o, d)


def lens_figure(lens: LensPrescription, film_distance_mm: float, film_half_diagonal_mm: float,
                title: str = ""):
    """The lens to scale with ray fans from the film centre, mid-field and edge
    (matplotlib figure; light travels from the scene on the left to the film on the right)."""
    plt = _plt()
    from matplotlib.patches import Polygon
    fd = float(film_distance_mm)
    zv = vertex_z_mm(lens.thickness_mm, fd)
    a = lens.aperture_radius_mm
    glass = lens.index_after != 1.0
    fig, ax = plt.subplots(figsize=(9.0, 4.6))

    def profile(i, r):
        return zv[i] - row_sag(lens, i)(r)          # sphere or even asphere

    for i in range(lens.n_surfaces - 1):                   # glass between rows i and i+1
        if glass[i]:
            r0 = np.linspace(-a[i], a[i], 60)
            r1 = np.linspace(a[i + 1], -a[i + 1], 60)
            pts = np.concatenate([np.column_stack([profile(i, r0), r0]),
                                  np.column_stack([profile(i + 1, r1), r1])])
            ax.add_patch(Polygon(pts, closed=True, facecolor="#bcd7f0", edgecolor="none",
                                 alpha=0.8, zorder=1))
    for i in range(lens.n_surfaces):
        if lens.is_aperture[i]:
            top = max(a.max() * 1.05, a[i] * 1.3)
            for s in (1, -1):
                ax.plot([zv[i], zv[i]], [s * a[i], s * top], color="k", lw=2.5, zorder=3)
            ax.annotate("stop", (zv[i], a.max() * 1.08), ha="center", fontsize=8)
            continue
        r = np.linspace(-a[i], a[i], 120)
        ax.plot(profile(i, r), r, color="#1f3b73", lw=1.2, zorder=2)
    h = film_half_diagonal_mm
    ax.plot([0, 0], [-h, h], color="k", lw=2, zorder=3)
    ax.annotate("film", (0, h * 1.04), ha="center", fontsize=8)
    ext = 0.35 * (zv[0] - zv[-1] + fd)
    for height, colour, label in ((0.0, "#d62728", "centre"), (0.5 * h, "#2ca02c", "mid field"),
                                  (h, "#9467bd", "edge")):
        fan = _fan(lens, fd, height)
        if fan is None:
            ax.plot([0], [height], "x", color=colour, label=f"{label}: vignetted")
            continue
        o, (hits, res) = fan
        first = True
        for k in range(len(o)):
            pts = [o[k]] + [hits[k, i] for i in range(lens.n_surfaces - 1, -1, -1)
                            if np.all(np.isfinite(hits[k, i]))]
            if res.passed[k]:
                pts.append(res.origin_mm[k] + ext * res.direction[k])
            p = np.array(pts)
            ax.plot(p[:, 2], p[:, 0], color=colour, lw=0.7, alpha=0.9, zorder=4,
                    label=f"{label} ({height:.1f} mm)" if first else None)
            first = False
    ax.set_aspect("equal")
    ax.invert_xaxis()
    ax.set_xlabel("z (mm from the film; scene to the left)")
    ax.set_ylabel("x (mm)")
    ax.legend(fontsize=7, loc="lower left")
    ax.set_title(title or Path(lens.source).name, fontsize=10)
    fig.tight_layout()
    return fig


# ----- depth of field ----------------------------------------------------------------------

def depth_of_field(plan: Plan, coc_px: float = COC_PIXELS) -> tuple[float, float]:
    """(near, far) limits of the depth of field of the plan's equivalent thin lens,
    in scene units along the view direction from the camera location (= entrance
    pupil); far may be inf.

    The thin-lens blur of a point at distance d (focus s, pupil A, image distance
    v, all from the centre of projection) is b(d) = A v |d - s| / (d s); b = c
    gives near = A v s / (A v + c s) and far = A v s / (A v - c s) (inf when
    A v <= c s, beyond the hyperfocal distance), with c = ``coc_px`` pixels.
    """
    tl = plan.thin_lens
    A, v = tl.pupil_diameter_mm, tl.image_distance_mm
    c = coc_px * plan.film.pixel_pitch_mm
    s = tl.focus_distance_mm
    mpu = plan.mm_per_unit
    if math.isinf(s):                               # focused at infinity
        return A * v / c / mpu, math.inf
    near = A * v * s / (A * v + c * s)
    far = A * v * s / (A * v - c * s) if A * v > c * s else math.inf
    return near / mpu, far / mpu


# ----- the sections of one folder ------------------------------------------------------------

class _Folder:
    def __init__(self, outdir: Path, render_missing: bool):
        self.dir = outdir
        self.plan = read_plan(outdir)
        self.lens = lens_for(self.plan)
        self.film = self.plan.film
        self.p = paraxial_data(self.lens)
        self.render_missing = render_missing
        self.timings: list[tuple[str, float, str]] = []
        self.notes: list[str] = []

    # -- lens and paraxial data --
    def lens_section(self) -> str:
        fd = self.plan.focus.film_distance_mm
        fig = lens_figure(self.lens, fd, self.film.max_field_radius_mm,
                          f"{Path(self.lens.source).name} focused at "
                          f"{self.plan.inputs.focus:g} {self.plan.inputs.units}")
        p = self.p
        rows = [
            ["effective focal length", _num(p.efl, ".4f", "mm")],
            ["back focal length", _num(p.bfl, ".4f", "mm")],
            ["front focal length", _num(p.ffl, ".4f", "mm")],
            ["f-number", _num(p.f_number, ".3f")],
            ["principal plane H (from front vertex)", _num(p.principal_front, ".4f", "mm")],
            ["principal plane H' (from front vertex)", _num(p.principal_rear, ".4f", "mm")],
            ["entrance pupil: position (from front vertex) / diameter",
             f"{_num(p.entrance_pupil_position, '.4f', 'mm')} / "
             f"{_num(p.entrance_pupil_diameter, '.4f', 'mm')}"],
            ["exit pupil: position (from rear vertex) / diameter",
             f"{_num(p.exit_pupil_position, '.4f', 'mm')} / "
             f"{_num(p.exit_pupil_diameter, '.4f', 'mm')}"],
            ["aperture stop: row / diameter",
             f"{p.stop_index} ({'aperture' if p.stop_is_aperture else 'lens rim'}) / "
             f"{_num(p.stop_diameter, '.4f', 'mm')}"],
            ["total track", _num(p.total_track, ".4f", "mm")],
        ]
        f = self.plan.focus
        tl = self.plan.thin_lens
        units = self.plan.inputs.units
        mpu = self.plan.mm_per_unit
        near, far = depth_of_field(self.plan)
        focus_rows = [
            ["focus (from the camera location)",
             f"{_num(self.plan.inputs.focus, '.6g')} {_esc(units)}"],
            ["film distance (rear vertex to film), real rays",
             _num(f.film_distance_mm, ".5f", "mm")],
            ["film distance, thick lens", _num(f.thick_lens_film_distance_mm, ".5f", "mm")],
            ["RMS spot at the focus", _num(f.rms_spot_mm, ".3g", "mm")],
            ["object plane, from the film", _num(f.object_distance_from_film_mm, ".6g", "mm")],
            ["plane of focus of the equivalent thin lens (from the entrance pupil)",
             _num(None if math.isinf(tl.focus_distance_mm) else tl.focus_distance_mm / mpu,
                  ".5g", units)],
            ["equivalent thin lens: image distance / pupil diameter",
             f"{_num(tl.image_distance_mm, '.4f', 'mm')} / "
             f"{_num(tl.pupil_diameter_mm, '.4f', 'mm')}"],
            [f"depth of field (circle of confusion {COC_PIXELS:g} px)",
             f"{_num(near, '.4g')} to {_num(far, '.4g')} {_esc(units)}"],
            ["film", f"{self.film.width_mm:g} x {self.film.height_mm:g} mm, "
                     f"{self.film.width_px} x {self.film.height_px} px"
                     + (f", shifted {self.film.shift_x_mm:g}, {self.film.shift_y_mm:g} mm"
                        if self.film.shifted else "")],
        ]
        return ("<h3>Lens</h3>" + _img(_fig_uri(fig, 110), "lens drawing", "fig")
                + '<div class="row"><div><h4>Paraxial data</h4>'
                + _table(["quantity", "value"], rows)
                + "</div><div><h4>Focus</h4>" + _table(["quantity", "value"], focus_rows)
                + "</div></div>")

    # -- exit pupil --
    def pupil_section(self) -> str:
        fd = self.plan.focus.film_distance_mm
        hd = self.film.max_field_radius_mm            # a shifted frame's farthest corner
        table, reused = cached_pupil_table(RenderFolder(self.dir).pupil_npz, self.lens, fd, hd,
                                           save=False, film_extent_mm=frame_extent_mm(self.film))
        if not reused:
            self.timings.append(("exit-pupil table (built for this report)",
                                 table.stats["build_time_s"], ""))
        with tempfile.TemporaryDirectory(prefix=".report.", dir=self.dir) as tmp:
            png = plot_pupil_shapes(table, Path(tmp) / "pupil.png",
                                    film_radii=np.linspace(0.0, hd, 6), n_grid=96)
            uri = _png_uri(png.read_bytes())
        return ("<h3>Exit pupil across the field</h3><p>Pass region of rays from film points "
                "at six radii (blue: traced; black: the pupil table's polygon).</p>"
                + _img(uri, "exit pupil shapes", "fig"))

    # -- renders --
    def _view(self, view: str) -> np.ndarray | None:
        path = RenderFolder(self.dir).view_image(view)
        if not path.exists() and self.render_missing:
            t0 = time.perf_counter()
            try:
                render_view(self.dir, view)
            except PovlensError as e:
                self.notes.append(f"{view} view: {e.message}")
                return None
            self.timings.append((f"{view} view (rendered for this report)",
                                 time.perf_counter() - t0, "1 POV-Ray run"))
        if not path.exists():
            return None
        return read_image(path)[..., :3].astype(np.float64)

    def _mesh(self) -> np.ndarray | None:
        """The mesh render, composited with its vignetting divided out (POV-Ray's pinhole
        and focal_blur cameras have none, so differences then show geometry and blur)."""
        path = RenderFolder(self.dir).image_exr
        if self.plan.inputs.method != "mesh" or not path.exists():
            return None
        try:
            return composite_outdir(self.dir, vignetting=False, write=False)
        except PovlensError:  # samples gone: fall back to the image as composited
            self.mesh_vignetting = self.plan.inputs.vignetting
            return read_image(path)[..., :3].astype(np.float64)

    def renders_section(self) -> tuple[str, np.ndarray | None]:
        views = {"pinhole": self._view("pinhole"), "focal_blur (equivalent thin lens)":
                 self._view("focal-blur"), "mesh (exact lens rays)": self._mesh()}
        cells = []
        for name, im in views.items():
            body = (_img(_array_uri(_srgb(im)), name, "render") if im is not None
                    else _missing(name))
            cells.append(f"<figure>{body}<figcaption>{_esc(name)}</figcaption></figure>")
        out = "<h3>Renders</h3><div class=\"row\">" + "".join(cells) + "</div>"
        ref = views["mesh (exact lens rays)"]
        if ref is None:
            out += _missing("differences against the mesh render",
                            "no mesh render in this folder (not rendered, or another method)")
        else:
            out += self._differences(ref, {k: v for k, v in views.items() if k[:4] != "mesh"})
        return out, views["pinhole"]

    def _differences(self, ref: np.ndarray, others: dict) -> str:
        rows, cells, errs = [], [], {}
        for name, im in others.items():
            if im is None or im.shape != ref.shape:
                rows.append([_esc(name)] + ["not rendered" if im is None else "size differs"] * 4)
                continue
            r = compare_arrays(ref, im, name_a="mesh", name_b=name)
            rows.append([_esc(name), _num(r["rmse"], ".4g"), _num(r["psnr_db"], ".2f", "dB"),
                         _num(r["mean_abs_error"], ".4g"), _num(r["max_abs_error"], ".4g")])
            errs[name] = difference_magnitude(ref, im)
        finite = [e[np.isfinite(e)].max() for e in errs.values() if np.isfinite(e).any()]
        scale = max(finite) if finite else None
        for name, e in errs.items():
            rgb, used = false_colour(e, scale)
            cells.append(f"<figure>{_img(_array_uri(rgb), 'difference ' + name, 'render')}"
                         f"<figcaption>|mesh − {_esc(name)}| (max over RGB; scale 0 to "
                         f"{used:.3g})</figcaption></figure>")
        vig = ("with the lens's vignetting" if getattr(self, "mesh_vignetting", False)
               else "with the lens's vignetting divided out (POV-Ray's cameras have none)")
        return ("<h4>Errors against the mesh render</h4>"
                f"<p>Linear light, RGB; the mesh render is composited {vig}.</p>"
                + _table(["image", "RMSE", "PSNR (peak 1)", "mean |error|", "max |error|"], rows)
                + '<div class="row">' + "".join(cells) + "</div>")

    def _times(self) -> str:
        rows = []
        t_rays = t_pov = t_wall = 0.0
        n = 0
        for f in RenderFolder(self.dir).timing_files():
            try:
                t = json.loads(f.read_text())
                t_rays += float(t.get("rays_and_meshes_s", 0.0))
                t_pov += float(t.get("povray_s", 0.0))
                t_wall += float(t.get("wall_s", 0.0))
                n += int(t.get("samples", 0))
            except (ValueError, TypeError, OSError):
                self.notes.append(f"{f.name}: unreadable timing file, skipped")
        if n:
            rows.append(["mesh: rays and meshes (Python)", _num(t_rays, ".3g", "s"),
                         f"{n} samples, summed over batches"])
            rows.append(["mesh: POV-Ray processes", _num(t_pov, ".3g", "s"),
                         "summed over processes, which run several at once"])
            if t_wall:
                rows.append(["mesh: batches", _num(t_wall, ".3g", "s"),
                             f"wall time summed over batches (they run in parallel); "
                             f"{t_wall / n:.3g} s per sample"])
        for name, t, what in self.timings:
            rows.append([_esc(name), _num(t, ".3g", "s"), _esc(what)])
        if not rows:
            return _missing("render times", "no timings recorded in this folder")
        return "<h4>Times</h4>" + _table(["step", "time", "notes"], rows)

    # -- focus --
    def focus_section(self, pinhole: np.ndarray | None) -> str:
        if pinhole is None:
            return "<h3>Depth of field</h3>" + _missing("depth of field", "no pinhole render")
        if not self.render_missing:
            return "<h3>Depth of field</h3>" + _missing("depth probe", "not rendered (--no-render)")
        t0 = time.perf_counter()
        try:
            dist = probe_depth(self.dir)
        except PovlensError as e:
            return "<h3>Depth of field</h3>" + _missing("depth probe", e.message)
        self.timings.append(("depth probe", time.perf_counter() - t0, "3 POV-Ray runs"))
        z = axial_depth(self.plan, dist)
        near, far = depth_of_field(self.plan)
        inside = np.isfinite(z) & (z >= near) & (z <= far)
        if math.isinf(far):
            inside |= ~np.isfinite(z)
        base = _srgb(pinhole)
        tint = np.array([0.15, 0.95, 0.25])
        shown = np.where(inside[..., None], 0.45 * base + 0.55 * tint, 0.6 * base)
        finite = z[np.isfinite(z)]
        logz = np.where(np.isfinite(z), np.log10(np.maximum(z, 1e-9)), np.nan)
        if finite.size:
            lo, hi = math.log10(max(finite.min(), 1e-9)), math.log10(max(finite.max(), 1e-9))
            t = (logz - lo) / (hi - lo) if hi > lo else np.zeros_like(logz)
            dm, _ = false_colour(np.nan_to_num(t, nan=1.0), 1.0, "viridis_r")
            dm = np.where(np.isfinite(z)[..., None], dm, 0.0)
            rng = f"{finite.min():.3g} (yellow) to {finite.max():.3g} (purple), log scale; black: nothing hit or no depth"
        else:
            dm, rng = np.zeros(z.shape + (3,)), "nothing hit"
        units = _esc(self.plan.inputs.units)
        frac = 100.0 * inside.mean()
        return ("<h3>Depth of field</h3>"
                f"<p>Thin-lens depth of field for a circle of confusion of {COC_PIXELS:g} pixels: "
                f"{_num(near, '.4g')} to {_num(far, '.4g')} {units} from the camera along the "
                f"view direction; tinted green: {frac:.1f}% of the pixels.  Distances from "
                f"the light-fade depth probe (povlens.plan.depth_probe).</p><div class=\"row\">"
                f"<figure>{_img(_array_uri(shown), 'depth of field', 'render')}"
                f"<figcaption>in focus (green)</figcaption></figure>"
                f"<figure>{_img(_array_uri(dm), 'depth map', 'render')}"
                f"<figcaption>depth {rng} {units}</figcaption></figure></div>")

    # -- model error --
    def model_error_section(self) -> str:
        me = self.plan.model_error
        if me is None:
            return _missing("thin-lens model error", "not in plan.json")
        plt = _plt()
        h = np.asarray(me.film_height_mm, dtype=np.float64)
        zc = self.plan.thin_lens.centre_z_mm
        mpu = self.plan.mm_per_unit
        units = self.plan.inputs.units
        depths = [(z - zc) / mpu for z in me.object_z_mm]
        panels = [("distortion_px", "distortion (px)"),
                  ("blur_size_error_px", "blur size error (px)"),
                  ("elongation", "blur elongation"),
                  ("relative_illumination", "relative illumination")]
        fig, axes = plt.subplots(1, 4, figsize=(13, 3.1))
        for ax, (key, label) in zip(axes, panels):
            arr = np.asarray(getattr(me, key), dtype=np.float64)
            if arr.ndim != 2 or arr.shape[1] != len(h):
                ax.text(0.5, 0.5, "not recorded", ha="center", transform=ax.transAxes)
                continue
            for k, row in enumerate(arr):
                ax.plot(h, row, "o-", ms=3, label=f"{depths[k]:.3g} {units}")
            ax.set_title(label, fontsize=9)
            ax.set_xlabel("film height (mm)", fontsize=8)
            ax.tick_params(labelsize=7)
        axes[0].legend(fontsize=7, title="object distance", title_fontsize=7)
        fig.tight_layout()
        summary = [[_esc(k.replace("_", " ")), _num(getattr(me, k), ".4g")] for k in
                   ("max_distortion_px", "max_blur_size_error_px", "max_elongation",
                    "min_relative_illumination")]
        return ("<h3>What the thin-lens model gets wrong</h3><p>Measured with the exact "
                "tracer (plan.json, model_error), over the field along the film diagonal.</p>"
                + _img(_fig_uri(fig, 100), "model error", "fig")
                + _table(["summary", "value"], summary))

    def html(self, anchor: str) -> str:
        inp = self.plan.inputs
        head = (f'<section id="{anchor}"><h2>{_esc(self.dir)}</h2>'
                f"<p>scene {_esc(inp.scene)}, lens {_esc(inp.lens)}, method "
                f"{_esc(inp.method)}, {inp.samples} samples, {inp.width} x "
                f"{inp.height} px</p>")
        fm = self.plan.field_mesh
        if fm is not None:
            tiles = (f"; {fm.interleave} x {fm.interleave} interleaved tiles per lens sample"
                     if fm.interleave > 1 else "")
            head += (f"<p>ray meshes: {fm.grid[0]} x {fm.grid[1]} faces (POV-Ray mesh_camera "
                     f"distribution 3), rays within {fm.max_ray_error_px:.3f} px of the exact "
                     f"ones (measured over {fm.pupil_points} pupil points; limit "
                     f"{fm.limit_px:g} px){tiles}</p>")
        head += _colour_line(self.plan.dispersion, bool(inp.dispersion))
        parts = [self.lens_section(), self.pupil_section()]
        renders, pinhole = self.renders_section()
        parts += [self.focus_section(pinhole), renders, self._times(),
                  self.model_error_section()]
        notes = "".join(f"<li>{_esc(n)}</li>" for n in self.notes)
        return head + "".join(parts) + (f"<h4>Notes</h4><ul>{notes}</ul>" if notes else "") + \
            "</section>"



class _FramesFolder:
    """A focus pull's folder (``render --frames``): its strip (:mod:`povlens.report.focus_pull_strip`)."""

    def __init__(self, outdir: Path):
        self.dir = outdir
        read_frames(outdir)                   # validate before working

    def html(self, anchor: str) -> str:
        return frames_section(self.dir, anchor)


_CSS = """
body { font-family: sans-serif; margin: 1.5em; color: #222; max-width: 1400px; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 0.9em; }
td, th { border: 1px solid #bbb; padding: 2px 8px; text-align: left; }
th { background: #eef; }
.row { display: flex; flex-wrap: wrap; gap: 1.2em; align-items: flex-start; }
figure { margin: 0; }
figcaption { font-size: 0.8em; max-width: 320px; }
img.render { width: 320px; image-rendering: pixelated; border: 1px solid #999; }
img.fig { max-width: 100%; }
.missing { border: 1px dashed #c00; color: #900; padding: 1em; width: 290px; }
section { border-top: 3px solid #446; margin-top: 2em; }
"""

_SCRIPT = """
window.addEventListener('load', function () {
  var imgs = Array.prototype.slice.call(document.images);
  var bad = imgs.filter(function (i) { return !(i.complete && i.naturalWidth > 0); });
  document.title = bad.length ? 'images-missing ' + bad.length : 'images-ok ' + imgs.length;
  document.getElementById('imgcheck').textContent = document.title;
});
"""


def make_report(outdirs, output=DEFAULT_REPORT, render_missing: bool = True) -> Path:
    """Write the HTML report of the render folders ``outdirs`` to ``output`` (atomically).

    ``render_missing`` lets the report run POV-Ray for what it needs and the folder
    lacks: the pinhole and focal-blur views and the depth probe.
    """
    dirs = [Path(d) for d in outdirs]
    if not dirs:
        raise PovlensError("no render folder given", "povlens report OUTDIR... -o report.html")
    for d in dirs:
        if not d.is_dir():
            raise PovlensError(f"{d} is not a folder",
                               "give folders made by 'povlens convert' or 'povlens render'")
    out = Path(output)
    if not out.parent.is_dir():
        raise PovlensError(f"-o {out}: the folder {out.parent} does not exist")
    folders = [_FramesFolder(d) if is_frames_folder(d) else _Folder(d, render_missing)
               for d in dirs]                         # validate all before working
    sections, toc = [], []
    for k, f in enumerate(folders):
        anchor = f"folder{k}"
        toc.append(f'<li><a href="#{anchor}">{_esc(f.dir)}</a></li>')
        sections.append(f.html(anchor))
    page = ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<title>povlens report</title>"
            f"<style>{_CSS}</style><script>{_SCRIPT}</script></head><body>"
            "<h1>povlens report</h1>"
            f"<p>{time.strftime('%Y-%m-%d %H:%M:%S')}; image check: "
            "<span id=\"imgcheck\">pending</span></p>"
            f"<ul>{''.join(toc)}</ul>" + "".join(sections) + "</body></html>\n")
    return write_text(out, page)
