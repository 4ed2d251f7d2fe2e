"""Interrupt mesh renders at random moments; count POV-Ray processes left behind.

    python3 benchmarks/stress_interrupts.py [--runs 40] [--signal SIGINT]

Each run starts ``povlens render`` (paper.pov, dgauss.50mm, 48x36, 48 mesh samples),
waits for its first lens sample's mask, sleeps 0-0.3 s (uniform, seeded), sends the
signal, and checks: the exit status (130 for SIGINT, 143 for SIGTERM; 0 would mean
the signal was lost and the render ran to the end) and, 0.5 s later, any process
still working in the render's ``samples/`` folder (a POV-Ray nobody stopped).
The test suite runs one such interrupt (tests/rendering/test_render.py); this is the
sweep that finds a race one run in twenty shows.  Results to stdout.
"""

from __future__ import annotations

import argparse
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def processes_in(folder: Path) -> list[int]:
    """PIDs of processes whose working directory is ``folder`` (POV-Ray runs there)."""
    pids = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                if os.readlink(f"/proc/{d}/cwd") == str(folder):
                    pids.append(int(d))
            except OSError:
                pass
    return pids


def one_run(signum: int, delay_s: float) -> tuple[int | str, list[int]]:
    """(exit status or "timeout", PIDs left in the samples folder) of one interrupted run."""
    tmp = Path(tempfile.mkdtemp(prefix="povlens-stress-"))
    out = tmp / "int"
    cmd = [sys.executable, "-m", "povlens", "render", str(ROOT / "scenes" / "paper.pov"),
           "--lens", "dgauss.50mm", "--focus", "4", "--width", "48", "--height", "36",
           "--method", "mesh", "--samples", "48", "--batch-size", "24", "-o", str(out), "-q"]
    try:
        p = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        while not (out.exists() and list((out / "samples").glob("sample_*.mask.npy"))):
            if p.poll() is not None:
                break
            time.sleep(0.02)
        time.sleep(delay_s)
        p.send_signal(signum)
        try:
            code: int | str = p.wait(timeout=60)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
            code = "timeout"
        time.sleep(0.5)
        left = processes_in(out / "samples")
        for pid in left:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
        return code, left
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=40)
    ap.add_argument("--signal", default="SIGINT", choices=["SIGINT", "SIGTERM"])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    signum = getattr(signal, args.signal)
    want = 130 if signum == signal.SIGINT else 143
    rng = random.Random(args.seed)
    codes: dict = {}
    leaks = 0
    for i in range(args.runs):
        code, left = one_run(signum, rng.uniform(0.0, 0.3))
        codes[code] = codes.get(code, 0) + 1
        if left or code != want:
            print(f"run {i}: exit {code}, left running {left}", flush=True)
        leaks += bool(left)
    print(f"{args.runs} runs, {args.signal}: exit statuses {codes}; runs that left POV-Ray "
          f"running: {leaks}")
    return 0 if leaks == 0 and codes.get(want, 0) == args.runs else 1


if __name__ == "__main__":
    sys.exit(main())
