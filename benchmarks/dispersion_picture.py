"""README picture of --dispersion: scenes/chart.pov through singlet.pcx.25mm (N-SF11,
V_d 25.68) at f/8, 640x480, 32 lens samples, without and with --dispersion; the same
80x60 crop near the top-left corner of each (the wall's grid lines at ~0.85 of the
field, ~1 px of lateral colour), enlarged 2x, side by side (left: the d line only;
right: colour), a 320x120 PNG.

    python3 benchmarks/dispersion_picture.py [--keep DIR]

writes docs/images/dispersion.png.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from povlens.util.images import read_image, write_png_srgb  # noqa: E402

#: The crop (rows, columns) of the 640x480 frame: near the top-left corner.
CROP = (slice(20, 80), slice(10, 90))


def main() -> None:
    keep = sys.argv[sys.argv.index("--keep") + 1] if "--keep" in sys.argv else None
    crops = []
    with tempfile.TemporaryDirectory(prefix="dispersion-picture-") as t:
        for extra in ([], ["--dispersion"]):
            out = Path(keep or t) / ("colour" if extra else "plain")
            subprocess.run([sys.executable, "-m", "povlens", "render",
                            str(ROOT / "scenes" / "chart.pov"), "--lens", "singlet.pcx.25mm",
                            "--f-number", "8", "--method", "mesh", "--samples", "32", "-q",
                            "-o", str(out), *extra], check=True, cwd=ROOT)
            crop = read_image(out / "image.exr")[..., :3][CROP]
            crops.append(np.repeat(np.repeat(crop, 2, axis=0), 2, axis=1))
    strip = np.concatenate([crops[0], crops[1]], axis=1)
    dest = ROOT / "docs" / "images" / "dispersion.png"
    write_png_srgb(dest, np.clip(strip, 0.0, None).astype(np.float32))
    print(f"wrote {dest} ({strip.shape[1]}x{strip.shape[0]})")


if __name__ == "__main__":
    main()
