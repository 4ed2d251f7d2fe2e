"""Drawing a pupil table's region over the exact pass region (matplotlib, Agg)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from povlens.pupil.grid_prober import GridProber
from povlens.pupil.prober import PupilProber
from povlens.pupil.table import PupilTable
from povlens.util.files import atomic_output

__all__ = ["plot_pupil_shapes"]


def plot_pupil_shapes(table: PupilTable, path, *, film_radii=None, boxes=None,
                      n_grid: int = 160) -> Path:
    """Draw the table's region at several film radii over the exact pass region.

    Each panel shows, on the sampling plane in the rotated frame (film point on
    +x), the rays that get through (dots, from an n_grid^2 brute-force grid) and
    the table's polygon; ``boxes`` (a :class:`~povlens.pupil.baselines.PbrtBoxes`)
    adds pbrt's box, mapped to this plane.  Written with matplotlib (Agg).

    Parameters
    ----------
    table : the table to draw (a grid table's panels are at film points along the frame's
        diagonal, :func:`_panel`).
    path : the PNG file to write.
    film_radii : film radii of the panels, mm (default: 6 from 0 to the half-diagonal).
    boxes : optional pbrt boxes to draw too.
    n_grid : grid points per side of the brute-force trace.

    Returns
    -------
    The path written.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if film_radii is None:
        film_radii = np.linspace(0.0, table.film_half_diagonal_mm, 6)
    film_radii = [float(r) for r in film_radii]
    n = len(film_radii)
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 4.2 * rows), squeeze=False)
    grid = getattr(table, "kind", "radial") == "grid"
    for ax, r in zip(axes.ravel(), film_radii):
        X, Y, ok, poly, where, state = _panel(table, r, n_grid)
        ext = [X.min(), X.max(), Y.min(), Y.max()]
        ax.imshow(np.where(ok, 1.0, np.nan), origin="lower", extent=ext, cmap="Blues",
                  vmin=0.0, vmax=1.6, interpolation="nearest")
        ax.plot([], [], "s", color="#6fa8dc", label="rays that get through (traced grid)")
        if len(poly):
            pc = np.vstack([poly, poly[:1]])
            ax.plot(pc[:, 0], pc[:, 1], "k-", lw=1, label="povlens table")
        if boxes is not None and not grid:
            b = boxes.box_on_plane(r, table.plane_z_mm)
            if b is not None:
                x0, x1, y0, y1 = b
                ax.plot([x0, x1, x1, x0, x0], [y0, y0, y1, y1, y0], "r--", lw=1,
                        label="pbrt box")
        ax.set_title(f"{where} ({state})", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlabel("x on sampling plane (mm)")
        ax.set_ylabel("y (mm)")
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    handles, labels = axes.ravel()[0].get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=8)
    fig.suptitle(f"{Path(table.lens.source).name}: pass region on the {table.plane} plane "
                 f"(z = {table.plane_z_mm:.2f} mm), "
                 + ("film points along the frame's diagonal" if grid else "film point on +x"),
                 fontsize=10)
    fig.tight_layout(rect=(0, 0.05, 1, 0.96))
    path = Path(path)
    try:
        with atomic_output(path) as tmp:  # the format from the final name, as savefig would
            fig.savefig(tmp, dpi=110,
                        format=path.suffix[1:] or matplotlib.rcParams["savefig.format"])
    finally:
        plt.close(fig)
    return path


def _panel(table, r: float, n_grid: int):
    """One panel's brute-force grid (X, Y, passes), the table's polygon, where the film
    point is and its state: the film point (r, 0) of a radial table (rotated frame), or
    for a grid table (an anamorphic lens) the point at radius r along the frame's
    diagonal (the plane's own frame)."""
    if getattr(table, "kind", "radial") == "grid":
        X0, Y0 = table.film_extent_mm
        f = np.array([X0, Y0]) * (r / max(float(np.hypot(X0, Y0)), 1e-300))
        pr = GridProber(table.lens, table.film_distance_mm, table.plane_z_mm)
        cx, cy, dR = pr.domain(f[0], f[1])
        g = np.linspace(-1, 1, n_grid)
        X, Y = np.meshgrid(cx[0] + dR[0] * g, cy[0] + dR[0] * g)
        ok = pr.passes(f[0], f[1], X, Y)
        area = float(table.area_at(f[None])[0])
        state = "vignetted" if not area > 0 else f"area {area:.1f} mm$^2$"
        return X, Y, ok, table.region_at(f), f"film point ({f[0]:.2f}, {f[1]:.2f}) mm", state
    pr = PupilProber(table.lens, table.film_distance_mm, table.plane_z_mm)
    dcx, dR = pr.domain(np.array([r]))
    g = np.linspace(-1, 1, n_grid)
    X, Y = np.meshgrid(dcx[0] + dR[0] * g, dR[0] * g)
    ok = pr.passes(np.array(r), X, Y)
    state = "vignetted" if table.is_vignetted(r)[0] else (
        f"area {table.area_mm2(r)[0]:.1f} mm$^2$")
    return X, Y, ok, table.region(r), f"film radius {r:.2f} mm", state
