"""``--method auto`` against the fixed methods at equal error (same as ``povlens bench --auto``).

    python benchmarks/bench_auto.py [--quick] [--lenses L1,L2] [--scenes paper,chart] ...

See :mod:`povlens.bench_auto` for what is measured; results go to
benchmarks/results/auto.{csv,txt} (``--quick``: auto_quick.*).
"""

import sys

from povlens.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", "--auto", *sys.argv[1:]]))
