"""The report of a focus pull's folder (``povlens render --frames``): a strip of the
frames with their focus, film distance and field of view (the lens moves to focus,
so the field of view breathes) and a link of each frame's own section."""

from __future__ import annotations

import base64
import html
from pathlib import Path

from povlens.plan.render_folder import FramesFolder
from povlens.rendering.focus_pull import read_frames

__all__ = ["is_frames_folder", "frames_section"]


def is_frames_folder(outdir: str | Path) -> bool:
    """A folder written by ``povlens render/convert --frames`` (frames.json, no plan)."""
    return FramesFolder(outdir).is_frames_folder()


def _png(path: Path, alt: str) -> str:
    if not path.is_file():
        return f'<div class="missing">{html.escape(alt)}: not rendered</div>'
    uri = "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode("ascii")
    return f'<img class="render" src="{uri}" alt="{html.escape(alt)}">'


def _fmt(v, fmt: str, unit: str = "") -> str:
    return "-" if v is None else f"{v:{fmt}}{unit}"


def frames_section(outdir: str | Path, anchor: str) -> str:
    """HTML section of a frames folder: the strip (each frame's PNG, focus, film
    distance, horizontal field of view) and a table with the breathing of every frame
    against the first (field of view change, per cent)."""
    outdir = Path(outdir)
    data, frames = read_frames(outdir)
    units = data.get("units", "")
    figs, rows = [], []
    hfov0 = next((f.hfov_deg for f in frames if f.hfov_deg is not None), None)
    for f in frames:
        cap = (f"frame {f.frame}: focus {f.focus:.4g} {units}, film distance "
               f"{_fmt(f.film_distance_mm, '.3f', ' mm')}, hfov {_fmt(f.hfov_deg, '.2f', '°')}")
        figs.append(f"<figure>{_png(outdir / f.image_png, f'frame {f.frame}')}"
                    f"<figcaption>{html.escape(cap)}</figcaption></figure>")
        breath = (None if f.hfov_deg is None or not hfov0 else
                  100.0 * (f.hfov_deg / hfov0 - 1.0))
        rows.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in [
            str(f.frame), f"{f.focus:.6g} {units}", f"{1.0 / f.focus:.4g}",
            _fmt(f.film_distance_mm, ".4f", " mm"), _fmt(f.hfov_deg, ".3f", "°"),
            _fmt(breath, "+.2f", " %"), f"{f.method or '-'} {f.samples or ''}",
            _fmt(f.seconds, ".2f", " s"), f.folder]) + "</tr>")
    head = "".join(f"<th>{h}</th>" for h in [
        "frame", "focus", "dioptres (1/unit)", "film distance", "hfov",
        "hfov vs frame 1 (breathing)", "method", "time", "folder"])
    return (f'<section id="{anchor}"><h2>{html.escape(str(outdir))}: focus pull, '
            f"{len(frames)} frames</h2>"
            f"<p>The focus moves in even steps of 1/distance; the lens moves to focus, so "
            f"the film distance and the field of view change (breathing).  Each frame is "
            f"an ordinary render folder (report it on its own for its lens and "
            f"errors).</p><div class=\"row\">{''.join(figs)}</div>"
            f"<table><tr>{head}</tr>{''.join(rows)}</table></section>")
