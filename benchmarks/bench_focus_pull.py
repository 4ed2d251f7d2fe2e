"""Focus pulls: the README strip and what sharing the depth probe between frames saves.

    python benchmarks/bench_focus_pull.py [--strip docs/images/focus_pull.png]
        [--measure] [--size 160x120] [--frames 3]

``--strip``: a 3-frame pull 0.8 m -> 5.5 m of scenes/cards.pov through dgauss.50mm
(mesh, exact lens rays, 32 samples, 320x240), the cards' band of each frame one
above the other (320 px wide).
``--measure``: the same pull with ``--method auto`` at ``--size``, twice, in fresh
folders: with the one depth probe shared by the frames (as povlens does) and with a
probe per frame; prints the wall time of each frame and the total
(docs/decisions/focus-pulls.md); ``--convert-only`` times the conversions alone
(probe, pupil tables, decisions), ``--repeats N`` interleaves N runs of each.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import povlens  # noqa: E402
from povlens.plan import probe_reuse  # noqa: E402
from povlens.util.images import read_image, write_png_srgb  # noqa: E402

SCENE = str(ROOT / "scenes" / "cards.pov")


def strip(out: Path) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        r = povlens.render_frames(SCENE, lens="dgauss.50mm", outdir=tmp, focus=(0.8, 5.5),
                                  frames=3, method="mesh", samples=32, width=320, height=240)
        # the band of the cards (rows 84..156), the frames one above the other
        images = [read_image(p)[84:156, :, :3] for p in r.images_exr]
        gap = np.ones((2, 320, 3))
        row = np.concatenate([x for im in images for x in (im, gap)][:-1], axis=0)
        out.parent.mkdir(parents=True, exist_ok=True)
        write_png_srgb(out, row)
        for f in r.frames:
            print(f"frame {f.frame}: focus {f.focus:.3f} m, film distance "
                  f"{f.film_distance_mm:.3f} mm, hfov {f.hfov_deg:.3f} deg, {f.method} "
                  f"{f.samples}")
    print(f"wrote {out} ({out.stat().st_size} bytes)")


def _pull(outdir: str, width: int, height: int, frames: int, render: bool) -> list:
    if not render:       # the conversions alone: probe, pupil tables, decisions
        from povlens.plan.focus_series import focus_series
        from povlens.plan.options import ConvertOptions
        from povlens.rendering.focus_pull import convert_frames
        values = focus_series((0.8, 5.5), frames)
        return convert_frames(ConvertOptions.of(scene=SCENE, lens="dgauss.50mm", focus=values[0],
                                             outdir=outdir, method="auto", width=width,
                                             height=height), values)
    r = povlens.render_frames(SCENE, lens="dgauss.50mm", outdir=outdir, focus=(0.8, 5.5),
                              frames=frames, method="auto", width=width, height=height)
    return r.frames


def measure(width: int, height: int, frames: int, render: bool = True,
            repeats: int = 1) -> None:
    shared_call = probe_reuse.ProbeReuse.__call__

    def per_frame(self, opts, film, plan):
        self.runs += 1
        return probe_reuse.start_depth_probe(opts, film, plan)

    results = {}
    for label in ("shared probe", "probe per frame") * repeats:   # interleaved
        probe_reuse.ProbeReuse.__call__ = shared_call if label == "shared probe" else per_frame
        try:
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                recs = _pull(tmp, width, height, frames, render)
                total = time.perf_counter() - t0
        finally:
            probe_reuse.ProbeReuse.__call__ = shared_call
        results.setdefault(label, []).append(round(total, 2))
        print(label, json.dumps({"total_s": round(total, 2),
                                 "frames_s": [r.seconds for r in recs],
                                 "methods": [f"{r.method} {r.samples}" for r in recs]}))
    for label, totals in results.items():
        print(f"{label}: fastest {min(totals):.2f} s, median {float(np.median(totals)):.2f} s "
              f"of {len(totals)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--strip", type=Path)
    ap.add_argument("--measure", action="store_true")
    ap.add_argument("--size", default="160x120")
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--convert-only", action="store_true",
                    help="--measure the conversions only (no lens samples rendered)")
    ap.add_argument("--repeats", type=int, default=1)
    a = ap.parse_args()
    if a.strip:
        strip(a.strip)
    if a.measure:
        w, h = (int(v) for v in a.size.split("x"))
        measure(w, h, a.frames, render=not a.convert_only, repeats=a.repeats)


if __name__ == "__main__":
    main()
