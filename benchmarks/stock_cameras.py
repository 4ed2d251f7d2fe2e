"""Does povlens read each stock scene's camera as POV-Ray does?

For every scene of Debian's povray-examples that POV-Ray renders, render it (48x36) with
its own camera, and with a camera statement built from what povlens read (location,
direction, right, up and the camera type), appended after the scene; compare the pixels.
Identical images mean povlens places and orients the camera exactly as POV-Ray does.

    python3 benchmarks/stock_cameras.py [--jobs 2] [--match TEXT]

Writes benchmarks/results/stock_cameras.txt (one line a scene, and a summary).
"""
from __future__ import annotations

import argparse
import concurrent.futures as cf
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from povlens.pov.sdl import parse_scene_camera, pov_vector
from povlens.util.images import read_image

sys.path.insert(0, str(Path(__file__).resolve().parent))
from stock_scenes import RESULTS, stock_scenes  # noqa: E402

W, H = 48, 36


def _render(pov: str, out: Path, cwd: Path, library: Path, timeout_s: float) -> np.ndarray:
    cmd = ["povray", f"+I{pov}", f"+O{out}", f"+W{W}", f"+H{H}", "-D", "-A", "+WT1", "-GA",
           "+FN", f"+L{library}"]
    p = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout_s)
    if p.returncode != 0:
        raise RuntimeError(p.stderr[-200:])
    return read_image(out)[..., :3].astype(np.float64)


def check(scene: Path, timeout_s: float) -> str:
    try:
        cam = parse_scene_camera(scene, W, H)
    except Exception as e:                     # refused (mesh_camera) or unreadable
        return f"refused: {str(e).splitlines()[0][:120]}"
    vecs = (f"location {pov_vector(cam.location)} direction {pov_vector(cam.direction_vector)} "
            f"right {pov_vector(cam.right_vector)} up {pov_vector(cam.up_vector)}")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "own.pov").write_text(f'#include "{scene}"\n')
        (tmp / "read.pov").write_text(
            f'#include "{scene}"\n#declare PV = version;\n#if (PV < 3.7) #version 3.7; #end\n'
            f"camera {{ {cam.projection} {vecs} }}\n#if (PV < 3.7) #version PV; #end\n")
        try:
            own = _render("own.pov", tmp / "own.png", tmp, scene.parent, timeout_s)
        except (RuntimeError, subprocess.TimeoutExpired):
            return "POV-Ray does not render it here"
        try:
            read = _render("read.pov", tmp / "read.png", tmp, scene.parent, timeout_s)
        except (RuntimeError, subprocess.TimeoutExpired) as e:
            return f"camera read, render failed: {str(e)[:100]}"
    d = np.abs(own - read)
    return f"{cam.projection} max {d.max():.3f} mean {d.mean():.4f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--match", default="")
    ap.add_argument("--timeout", type=float, default=40.0)
    args = ap.parse_args(argv)
    scenes = [s for s in stock_scenes() if args.match in str(s)]
    with cf.ThreadPoolExecutor(args.jobs) as pool:
        results = list(pool.map(lambda s: check(s, args.timeout), scenes))
    lines = [f"{s.relative_to('/usr/share/doc/povray/examples')}: {r}"
             for s, r in zip(scenes, results)]
    compared = [r for r in results if " max " in r]
    identical = [r for r in compared if float(r.split(" max ")[1].split()[0]) == 0.0]
    close = [r for r in compared if float(r.split(" mean ")[1]) < 0.01]
    summary = (f"{len(scenes)} scenes; cameras compared {len(compared)}; identical images "
               f"{len(identical)}; mean difference < 0.01: {len(close)}; refused "
               f"{sum(r.startswith('refused') for r in results)}; POV-Ray does not render "
               f"{sum(r.startswith('POV-Ray does not') for r in results)}")
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "stock_cameras.txt").write_text(summary + "\n\n" + "\n".join(lines) + "\n")
    print(summary)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
