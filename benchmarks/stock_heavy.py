"""Heavy stock scenes (radiosity, photons): mesh N against focal_blur N, with and without
what the lens samples share (issue 25).

    python3 benchmarks/stock_heavy.py [--sizes 320x240,640x480] [--samples 8,32]
        [--lens tessar.50mm] [--limit-s 60] [--only NAME ...] [--skip NAME ...]
        [--timing-only] [--list] [--out benchmarks/results/stock_heavy]

Finds Debian's povray-examples scenes whose ``global_settings`` hold ``radiosity`` or
``photons`` (povlens's scene reader), keeps those POV-Ray renders through their own
camera in under ``--limit-s`` at the first size, and for each size and sample count
times ``povlens render`` with ``--method focal-blur``, ``--method mesh`` (what the
samples share: several samples per POV-Ray run, the radiosity of one pretrace, one
photon map) and ``--method mesh`` with each sample its own POV-Ray run computing its
own radiosity (``POVLENS_STACK=1``, ``--povray-option Radiosity_File_Name=...``, the
uncached way; photons stay shared: their map gives the per-sample image exactly). It
reports the ratio mesh / focal_blur, how the default render ran its samples (``runs``:
one stack or one run each, as its first sample chose), and RMSE and FLIP of the shared render against the
uncached one. ``--timing-only`` leaves the uncached render out (and with it the image
check): on balcony.pov it costs 7 times the focal_blur render, so the larger sizes are
timed without it. One heavy job at a time: run it alone on the machine. Writes
``OUT.csv`` and ``OUT.txt``.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from povlens.pov.sdl import parse_scene_camera  # noqa: E402
from povlens.report.compare import compare_arrays, flip_error  # noqa: E402
from povlens.util.images import read_image  # noqa: E402

EXAMPLES = Path("/usr/share/doc/povray/examples")
UNCACHED = ["--povray-option", "Radiosity_File_Name=povlens-uncached.rca"]


def heavy_scenes(width: int, height: int) -> list[tuple[Path, str]]:
    """(scene, what it uses) for every stock scene with radiosity or photons."""
    found = []
    for scene in sorted(EXAMPLES.rglob("*.pov")):
        try:
            items = parse_scene_camera(scene, width, height,
                                       library_paths=[scene.parent]).global_settings
        except Exception:               # a scene povlens cannot read: not in the sweep
            continue
        uses = [k for k in ("radiosity", "photons") if k in items]
        if uses:
            found.append((scene, "+".join(uses)))
    return found


def _timed(cmd: list[str], cwd: Path, timeout: float, env=None) -> tuple[float | None, str]:
    t0 = time.perf_counter()
    try:
        r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout,
                           env={**os.environ, **(env or {})})
    except subprocess.TimeoutExpired:
        return None, "timeout"
    dt = time.perf_counter() - t0
    return (dt, "") if r.returncode == 0 else (None, r.stderr.strip().splitlines()[-1][:120])


def _own_camera_s(scene: Path, width: int, height: int, work: Path, limit: float):
    cmd = ["povray", "-D", "-V", "-GR", "-GS", f"+I{scene.name}", f"+O{work / 'own.png'}",
           f"+W{width}", f"+H{height}", f"+L{scene.parent}"]
    return _timed(cmd, scene.parent, limit)


def _render(scene: Path, out: Path, method: str, n: int, size, lens: str, extra=()):
    cmd = [sys.executable, "-m", "povlens", "render", scene.name, "--lens", lens,
           "--method", method, "--samples", str(n), "--width", str(size[0]),
           "--height", str(size[1]), "-q", "-o", str(out), *extra]
    env = {"POVLENS_STACK": "1"} if extra == UNCACHED else {"POVLENS_STACK": ""}
    return _timed(cmd, scene.parent, 3600, env)


def measure(scene: Path, uses: str, size, n: int, lens: str, work: Path,
            timing_only: bool = False) -> dict:
    """One row: the three renders' times, the ratios and the shared render's error
    (``timing_only``: the first two renders and their ratio)."""
    row = {"scene": str(scene.relative_to(EXAMPLES)), "uses": uses,
           "size": f"{size[0]}x{size[1]}", "samples": n}
    renders = (("focal_blur_s", "focal-blur", ()), ("mesh_s", "mesh", ()),
               ("mesh_uncached_s", "mesh", UNCACHED))
    for key, method, extra in renders[:2] if timing_only else renders:
        t, err = _render(scene, work / key, method, n, size, lens, extra)
        row[key] = "" if t is None else round(t, 2)
        if err:
            row["error"] = err
    row["runs"] = _runs_chosen(work / "mesh_s")
    if timing_only and row["focal_blur_s"] and row["mesh_s"]:
        row["ratio"] = round(row["mesh_s"] / row["focal_blur_s"], 3)
    elif row["focal_blur_s"] and row["mesh_s"] and row["mesh_uncached_s"]:
        row["ratio"] = round(row["mesh_s"] / row["focal_blur_s"], 3)
        row["ratio_uncached"] = round(row["mesh_uncached_s"] / row["focal_blur_s"], 3)
        a = read_image(work / "mesh_uncached_s" / "image.exr")[..., :3]
        b = read_image(work / "mesh_s" / "image.exr")[..., :3]
        row["rmse"] = round(compare_arrays(a, b, None)["rmse"], 5)
        row["flip"] = round(flip_error(a, b)[0], 4)
    return row


def _runs_chosen(outdir: Path) -> str:
    """How the default mesh render ran its samples: "stack" or "own" (one run each), as
    its first sample chose (docs/decisions/planning.md, "One run or a stack,
    measured"); "" when no choice was made."""
    try:
        choice = json.loads((outdir / "samples" / "render.timing.json").read_text()).get("choice")
    except (OSError, ValueError):
        return ""
    return "" if not choice else ("stack" if choice.get("stack") else "own")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="320x240,640x480")
    ap.add_argument("--samples", default="8,32")
    ap.add_argument("--lens", default="tessar.50mm")
    ap.add_argument("--limit-s", type=float, default=60.0)
    ap.add_argument("--only", nargs="*", default=None, help="scene file names to keep")
    ap.add_argument("--skip", nargs="*", default=(), help="scene file names to leave out")
    ap.add_argument("--timing-only", action="store_true",
                    help="time focal_blur and the default mesh render only")
    ap.add_argument("--list", action="store_true", help="list the scenes and stop")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "stock_heavy")
    args = ap.parse_args(argv)
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    counts = [int(v) for v in args.samples.split(",")]
    scenes = heavy_scenes(*sizes[0])
    if args.only:
        scenes = [(s, u) for s, u in scenes if s.name in args.only]
    scenes = [(s, u) for s, u in scenes if s.name not in args.skip]
    if args.list:
        for s, u in scenes:
            print(f"{s.relative_to(EXAMPLES)}  {u}")
        return 0
    rows = []
    with tempfile.TemporaryDirectory(prefix="povlens-heavy-") as tmp:
        for i, (scene, uses) in enumerate(scenes):
            work = Path(tmp) / f"s{i}"
            work.mkdir()
            own, err = _own_camera_s(scene, *sizes[0], work, args.limit_s)
            if own is None:
                print(f"{scene.name}: skipped ({err or 'over the limit'})", flush=True)
                continue
            for size in sizes:
                for n in counts:
                    sub = work / f"{size[0]}x{size[1]}-{n}"
                    sub.mkdir()
                    row = measure(scene, uses, size, n, args.lens, sub, args.timing_only)
                    row["own_camera_s"] = round(own, 2)
                    rows.append(row)
                    print(row, flush=True)
                    _write(rows, args.out)      # after each row: a long sweep may be cut
    _write(rows, args.out)
    return 0


def _write(rows: list[dict], out: Path) -> None:
    keys = ["scene", "uses", "size", "samples", "own_camera_s", "focal_blur_s", "mesh_s",
            "runs", "mesh_uncached_s", "ratio", "ratio_uncached", "rmse", "flip", "error"]
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out.with_suffix(".csv"), "w", newline="") as f:
        w = csv.DictWriter(f, keys)
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k, "") for k in keys})
    lines = [f"{'scene':<40} {'uses':<16} {'size':>8} {'N':>3} {'fb s':>7} {'mesh s':>7} "
             f"{'runs':>5} {'uncached':>8} {'ratio':>6} {'rmse':>8} {'flip':>6}"]
    for r in rows:
        lines.append(f"{r['scene']:<40} {r['uses']:<16} {r['size']:>8} {r['samples']:>3} "
                     f"{r.get('focal_blur_s', ''):>7} {r.get('mesh_s', ''):>7} "
                     f"{r.get('runs', ''):>5} {r.get('mesh_uncached_s', ''):>8} {r.get('ratio', ''):>6} "
                     f"{r.get('rmse', ''):>8} {r.get('flip', ''):>6}")
    out.with_suffix(".txt").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    sys.exit(main())
