"""povlens's own overhead: a pinhole render through povlens against POV-Ray alone.

    python3 benchmarks/bench_overhead.py [--scenes 30] [--repeats 1] [--lens dgauss.50mm]
                                         [--no-vignetting] [--no-bytecode-cache]
    python3 benchmarks/bench_overhead.py --profile [--scene textures/pigments/crack1.pov]

Material nobody here wrote: the fastest stock scenes of Debian's ``povray-examples``
(``apt-get install povray-examples``), the ones ``benchmarks/results/stock_scenes.csv``
lists as rendered by POV-Ray and planned by povlens, fastest first (that sweep's time
per scene is POV-Ray's render plus ``povlens plan``).  Each scene is rendered at 96x72,
interleaved, in the scene's own folder as a user would run it:

* **POV-Ray alone**: the command line povlens gives its pinhole view
  (:func:`povlens.pov.process.render_switches` and :func:`~povlens.pov.process.povray_command`:
  ``povray -D -V -GR -GS +I<scene> +O<image>.exr +FE +W96 +H72 -A +WT<cores> +L<folder>``)
  on the scene as it is, with its own camera, timed until POV-Ray exits;
* **povlens**: ``povlens render SCENE --lens LENS --method pinhole --width 96 --height 72
  -o TMP`` as a subprocess (the ``povlens`` script beside this Python, else
  ``python -m povlens``; the package of this tree), wall time until it exits.

One untimed run of each comes first (file caches, POV-Ray's version cache, and
Python's bytecode of povlens, cached outside the tree as an installed package has it:
this machine sets ``PYTHONDONTWRITEBYTECODE=1``; ``--no-bytecode-cache`` keeps that,
and every run compiles povlens again).  With ``--repeats R`` each scene's time is the
fastest of R.  ``--no-vignetting`` passes that option to povlens (no relative
illumination map on the view).  Prints and writes ``benchmarks/results/overhead.txt``
(``overhead_no_vignetting.txt``, ``overhead_no_bytecode_cache.txt``): per scene both
times and the difference, and the medians over the scenes of both and of the difference.

``--profile`` reports where povlens's time goes on one scene instead: the slowest
imports (``python -X importtime``) and the functions with the most cumulative time
(``cProfile`` of the command-line entry), written to
``benchmarks/results/overhead_profile.txt``.
"""
from __future__ import annotations

import argparse
import csv
import datetime
import os
import platform
import pstats
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
sys.path.insert(0, str(ROOT))

from povlens.pov.executable import find_povray, povray_version  # noqa: E402
from povlens.pov.process import povray_command, render_switches  # noqa: E402

WIDTH, HEIGHT = 96, 72
EXAMPLES = Path("/usr/share/doc/povray/examples")


def examples_folder() -> Path:
    """Where povray-examples put its scenes (``dpkg -L povray-examples``)."""
    try:
        out = subprocess.run(["dpkg", "-L", "povray-examples"], capture_output=True,
                             text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        sys.exit("povray-examples is not installed: apt-get install povray-examples")
    scenes = [Path(p) for p in out.split() if p.endswith(".pov")]
    if not scenes:
        sys.exit("povray-examples lists no .pov files")
    return Path(os.path.commonpath([str(s.parent) for s in scenes]))


def fast_scenes(n: int, base: Path) -> list[Path]:
    """The ``n`` fastest scenes of the stock sweep that POV-Ray renders and povlens plans."""
    with open(RESULTS / "stock_scenes.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["povray_ok"] == "1" and r["plan_exit"] == "0"]
    rows.sort(key=lambda r: (float(r["seconds"]), r["scene"]))
    scenes = [base / r["scene"] for r in rows]
    return [s for s in scenes if s.is_file()][:n]


def povlens_command() -> list[str]:
    """``povlens`` as a user runs it: the entry script beside this Python, else
    ``python -m povlens`` (no pyenv-style shim in front)."""
    script = Path(sys.executable).parent / "povlens"
    return [str(script)] if script.is_file() else [sys.executable, "-m", "povlens"]


def environment(pycache: Path | None) -> dict:
    """This tree's povlens first on the path (an editable install may point elsewhere).

    ``pycache``: Python's bytecode is cached there (``PYTHONPYCACHEPREFIX``), outside the
    tree, as an installed package has its ``.pyc`` files (pip compiles them); this
    machine sets ``PYTHONDONTWRITEBYTECODE=1``, which makes every run compile every
    povlens module again (~0.1 s).  None: the environment as it is."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + ([env["PYTHONPATH"]]
                                                       if env.get("PYTHONPATH") else []))
    if pycache is not None:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(pycache)
    return env


def time_povray(scene: Path, tmp: Path) -> float:
    """Wall time of POV-Ray alone on ``scene`` with povlens's pinhole-view switches."""
    image = tmp / "own.exr"
    switches = render_switches(image, WIDTH, HEIGHT, threads=os.cpu_count() or 1,
                               library_paths=[scene.parent])
    cmd = povray_command(find_povray(), scene.name, str(image), switches)
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=scene.parent, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if p.returncode != 0 or not image.exists():
        raise RuntimeError(f"POV-Ray failed on {scene}: {p.stderr[-500:]}")
    image.unlink()
    return dt


def render_args(scene: Path, out: Path, lens: str, extra: tuple[str, ...] = ()) -> list[str]:
    return ["render", scene.name, "--lens", lens, "--method", "pinhole",
            "--width", str(WIDTH), "--height", str(HEIGHT), *extra, "-o", str(out)]


def time_povlens(scene: Path, tmp: Path, lens: str, env: dict, extra=()) -> float:
    """Wall time of ``povlens render SCENE --method pinhole`` in the scene's folder."""
    out = tmp / "out"
    cmd = povlens_command() + render_args(scene, out, lens, extra)
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=scene.parent, capture_output=True, text=True, env=env)
    dt = time.perf_counter() - t0
    if p.returncode != 0 or not (out / "image.exr").exists():
        raise RuntimeError(f"povlens failed on {scene} (exit {p.returncode}): "
                           f"{p.stderr[-800:]}")
    shutil.rmtree(out)
    return dt


def measure(scenes: list[Path], base: Path, args) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory(prefix="povlens-overhead-") as tmp:
        tmp = Path(tmp)
        env = environment(None if args.no_bytecode_cache else tmp / "pycache")
        time_povray(scenes[0], tmp)                       # untimed: caches
        time_povlens(scenes[0], tmp, args.lens, env, args.extra)
        for i, scene in enumerate(scenes, 1):
            own, ours = [], []
            for _ in range(args.repeats):                 # interleaved
                own.append(time_povray(scene, tmp))
                ours.append(time_povlens(scene, tmp, args.lens, env, args.extra))
            rows.append({"scene": str(scene.relative_to(base)), "povray_s": min(own),
                         "povlens_s": min(ours), "difference_s": min(ours) - min(own)})
            print(f"\r{i}/{len(scenes)}", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    return rows


def summary(rows: list[dict], args, command: str) -> str:
    med = {k: statistics.median(r[k] for r in rows)
           for k in ("povray_s", "povlens_s", "difference_s")}
    lines = [
        f"povlens overhead: pinhole render of {len(rows)} fast povray-examples scenes at "
        f"{WIDTH}x{HEIGHT}, lens {args.lens}, fastest of {args.repeats} run(s) each",
        f"{datetime.date.today()}, {os.cpu_count()} cores, POV-Ray {povray_version()}, "
        f"Python {platform.python_version()}",
        f"command: python3 benchmarks/bench_overhead.py --scenes {args.scenes} "
        f"--repeats {args.repeats} --lens {args.lens}"
        + (" --no-vignetting" if args.no_vignetting else "")
        + (" --no-bytecode-cache" if args.no_bytecode_cache else ""),
        f"povlens: {command} SCENE --lens {args.lens} --method pinhole --width {WIDTH} "
        f"--height {HEIGHT} {' '.join(args.extra) + ' ' if args.extra else ''}-o TMP "
        f"(in the scene's folder)",
        "bytecode: " + ("as this environment has it (PYTHONDONTWRITEBYTECODE="
                        f"{os.environ.get('PYTHONDONTWRITEBYTECODE', '')!r})"
                        if args.no_bytecode_cache else
                        "cached after the untimed first run (PYTHONPYCACHEPREFIX), as an "
                        "installed package has it"),
        "",
        f"{'scene':50s} {'POV-Ray s':>10s} {'povlens s':>10s} {'diff s':>8s}",
    ]
    lines += [f"{r['scene']:50s} {r['povray_s']:10.3f} {r['povlens_s']:10.3f} "
              f"{r['difference_s']:8.3f}" for r in rows]
    lines += ["", f"median: POV-Ray alone {med['povray_s']:.3f} s, povlens "
              f"{med['povlens_s']:.3f} s, difference {med['difference_s']:.3f} s"]
    return "\n".join(lines) + "\n"


def profile(scene: Path, lens: str, bytecode_cache: bool = True) -> str:
    """Where povlens's time goes on ``scene``: slowest imports, most cumulative time."""
    out = []
    with tempfile.TemporaryDirectory(prefix="povlens-profile-") as tmp:
        tmp = Path(tmp)
        env = environment(tmp / "pycache" if bytecode_cache else None)
        subprocess.run(povlens_command() + render_args(scene, tmp / "warm", lens),
                       cwd=scene.parent, capture_output=True, env=env)
        p = subprocess.run([sys.executable, "-X", "importtime", "-m", "povlens",
                            *render_args(scene, tmp / "imp", lens), "-q"],
                           cwd=scene.parent, capture_output=True, text=True, env=env)
        imports = []
        for line in p.stderr.splitlines():
            if line.startswith("import time:") and "|" in line:
                _, cum, name = line[len("import time:"):].split("|")
                if cum.strip().isdigit():
                    imports.append((int(cum), name.rstrip()))
        top = [(c, n) for c, n in imports if not n.startswith("  ")]   # top-level only
        out.append(f"python -X importtime -m povlens render {scene.name} ... "
                   f"(top-level imports, cumulative ms):")
        out += [f"{c / 1000:9.1f}  {n.strip()}" for c, n in sorted(top, reverse=True)[:25]]
        prof = tmp / "cli.prof"
        subprocess.run([sys.executable, "-m", "cProfile", "-o", str(prof), "-m", "povlens",
                        *render_args(scene, tmp / "prof", lens), "-q"],
                       cwd=scene.parent, capture_output=True, env=env)
        out += ["", "cProfile of the command-line entry (cumulative):"]
        text = tmp / "stats.txt"
        with open(text, "w") as f:
            pstats.Stats(str(prof), stream=f).sort_stats("cumulative").print_stats(40)
        out.append(text.read_text())
    return "\n".join(out) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", type=int, default=30, help="how many scenes (default 30)")
    ap.add_argument("--repeats", type=int, default=1, help="runs per scene, fastest counts")
    ap.add_argument("--lens", default="dgauss.50mm")
    ap.add_argument("--no-vignetting", action="store_true",
                    help="pass --no-vignetting to povlens (no relative illumination map)")
    ap.add_argument("--no-bytecode-cache", action="store_true",
                    help="run povlens with the environment's bytecode setting as it is "
                         "(default: cache the bytecode outside the tree)")
    ap.add_argument("--profile", action="store_true",
                    help="profile povlens on one scene (--scene) instead")
    ap.add_argument("--scene", default="textures/pigments/crack1.pov",
                    help="the scene of --profile, relative to the examples folder")
    args = ap.parse_args(argv)
    args.extra = ("--no-vignetting",) if args.no_vignetting else ()
    base = examples_folder()
    RESULTS.mkdir(parents=True, exist_ok=True)
    if args.profile:
        text = profile(base / args.scene, args.lens, not args.no_bytecode_cache)
        (RESULTS / "overhead_profile.txt").write_text(text)
        print(text, end="")
        return 0
    scenes = fast_scenes(args.scenes, base)
    rows = measure(scenes, base, args)
    command = " ".join(Path(c).name if i == 0 else c
                       for i, c in enumerate(povlens_command()))
    text = summary(rows, args, command)
    name = "overhead" + ("_no_vignetting" if args.no_vignetting else "") + \
        ("_no_bytecode_cache" if args.no_bytecode_cache else "")
    (RESULTS / f"{name}.txt").write_text(text)
    print(text, end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
