"""Run time against error: naive, pbrt-box and povlens lens sampling, and focal_blur.

    python benchmarks/bench_time_error.py [--quick] [options of 'povlens bench']

A thin wrapper of ``povlens bench`` (the logic is in povlens/bench.py, whose
docstring describes the methods and the quick and full settings).  Writes
benchmarks/results/time_error.{csv,png,txt} (``--quick``: time_error_quick.*).
"""

import sys

from povlens.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", *sys.argv[1:]]))
