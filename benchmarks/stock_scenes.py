"""Sweep of Debian's povray-examples scenes: does POV-Ray render each, does `povlens plan`?

Material nobody here wrote: every ``.pov`` file that ``dpkg -L povray-examples`` lists.
For each scene, POV-Ray renders it as it is (small, no anti-aliasing), then
``povlens plan SCENE --lens LENS`` runs on it (working directory: the scene's folder, as
a user would run it).  Outcomes are grouped by povlens's first message line.

    apt-get install povray-examples
    python3 benchmarks/stock_scenes.py [--jobs 2] [--limit N] [--lens dgauss.50mm]

Writes ``benchmarks/results/stock_scenes.csv`` (one row a scene) and
``stock_scenes.txt`` (the counts by group).  A scene that POV-Ray itself cannot render
counts apart.  Progress goes to stderr; interrupted with Ctrl-C, it writes what it has.
"""
from __future__ import annotations

import argparse
import collections
import concurrent.futures as cf
import csv
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"


def stock_scenes() -> list[Path]:
    """Every .pov file of the povray-examples package, sorted."""
    try:
        out = subprocess.run(["dpkg", "-L", "povray-examples"], capture_output=True,
                             text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        sys.exit("povray-examples is not installed: apt-get install povray-examples")
    return sorted(Path(p) for p in out.split() if p.endswith(".pov"))


def povray_renders(scene: Path, tmp: Path, timeout_s: float) -> tuple[bool, str]:
    """Whether POV-Ray renders ``scene`` as it is (64x48, no anti-aliasing)."""
    cmd = ["povray", f"+I{scene.name}", f"+O{tmp / 'own.png'}", "+W64", "+H48", "-D",
           "-A", "+WT1", "-GA", "+FN"]
    try:
        p = subprocess.run(cmd, cwd=scene.parent, capture_output=True, text=True,
                           timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return False, "timeout"
    ok = p.returncode == 0 and (tmp / "own.png").exists()
    tail = [ln for ln in p.stderr.splitlines() if "Error" in ln or "error" in ln]
    return ok, (tail[0] if tail else "") if not ok else ""


def povlens_plan(scene: Path, tmp: Path, lens: str, extra: list[str],
                 timeout_s: float) -> tuple[int, str, bool]:
    """Exit code, first message line and whether a traceback was printed."""
    cmd = [sys.executable, "-m", "povlens", "plan", scene.name, "--lens", lens,
           "--width", "64", "--height", "48", "-o", str(tmp / "plan"), *extra]
    try:
        p = subprocess.run(cmd, cwd=scene.parent, capture_output=True, text=True,
                           timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return -1, "timeout", False
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    first = next((ln for ln in lines if not ln.startswith(("povlens: note", "warning"))), "")
    return p.returncode, first, "Traceback" in p.stderr


def sweep_one(scene: Path, args) -> dict:
    with tempfile.TemporaryDirectory(prefix="povlens-sweep-") as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        own_ok, own_msg = povray_renders(scene, tmp, args.timeout)
        code, msg, tb = povlens_plan(scene, tmp, args.lens, args.extra, args.timeout)
        return {"scene": str(scene.relative_to(args.base)), "povray_ok": int(own_ok),
                "povray_message": own_msg, "plan_exit": code, "traceback": int(tb),
                "plan_message": "" if code == 0 else msg,
                "seconds": round(time.perf_counter() - t0, 2)}


def group_of(message: str) -> str:
    """A message with its scene-specific parts (paths, numbers, quoted names) removed."""
    text = re.sub(r"^povlens: (error: )?", "", message)
    text = re.sub(r"'[^']*'|\"[^\"]*\"|\S+\.(pov|inc)\b|line \d+|[-+]?\d[\d.e+-]*", "_", text)
    return text[:90]


def summarise(rows: list[dict]) -> str:
    slow = [r for r in rows if r["povray_message"] == "timeout"]
    renders = [r for r in rows if r["povray_ok"]]
    planned = [r for r in renders if r["plan_exit"] == 0]
    lines = [f"{len(rows)} scenes; POV-Ray renders {len(renders)} "
             f"({len(slow)} more not within the time limit, left out); povlens plan succeeds on "
             f"{len(planned)} of those ({100 * len(planned) / max(1, len(renders)):.1f} %); "
             f"tracebacks anywhere: {sum(r['traceback'] for r in rows)}", ""]
    groups = collections.Counter(group_of(r["plan_message"]) for r in renders
                                 if r["plan_exit"] != 0)
    lines.append("refused or failed, of the scenes POV-Ray renders, by message:")
    for text, n in groups.most_common():
        example = next(r["scene"] for r in renders
                       if r["plan_exit"] != 0 and group_of(r["plan_message"]) == text)
        lines.append(f"{n:4d}  {text}   (e.g. {example})")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--lens", default="dgauss.50mm")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--limit", type=int, default=0, help="first N scenes only")
    ap.add_argument("--match", default="", help="only scenes whose path contains this")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds per command")
    ap.add_argument("--name", default="stock_scenes", help="results file name")
    ap.add_argument("extra", nargs="*", help="more options for povlens plan (after --)")
    args = ap.parse_args(argv)
    scenes = [s for s in stock_scenes() if args.match in str(s)]
    scenes = scenes[: args.limit] if args.limit else scenes
    args.base = Path(os.path.commonpath([str(s.parent) for s in scenes])) if scenes else ROOT
    rows = []
    try:
        with cf.ThreadPoolExecutor(args.jobs) as pool:
            futures = [pool.submit(sweep_one, s, args) for s in scenes]
            for i, fut in enumerate(cf.as_completed(futures), 1):
                rows.append(fut.result())
                print(f"\r{i}/{len(scenes)}", end="", file=sys.stderr, flush=True)
    except KeyboardInterrupt:
        print("\ninterrupted: writing what was swept", file=sys.stderr)
    print(file=sys.stderr)
    rows.sort(key=lambda r: r["scene"])
    RESULTS.mkdir(parents=True, exist_ok=True)
    with open(RESULTS / f"{args.name}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]) if rows else ["scene"])
        w.writeheader()
        w.writerows(rows)
    text = summarise(rows)
    (RESULTS / f"{args.name}.txt").write_text(text)
    print(text, end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
