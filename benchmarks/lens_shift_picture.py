"""README picture of lens shift: chart.pov through dgauss.50mm, camera tilted up (left,
verticals converge) against camera level with the film shifted 6.3 mm (right, verticals
stay vertical), both exact lens rays (mesh, 16 samples), 160 x 120 each.

Run from the repository's top folder: ``python3 benchmarks/lens_shift_picture.py``
(writes ``docs/images/lens_shift.png``; ~15 s on 2 cores).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from povlens.util.images import read_image, write_png_srgb

ROOT = Path(__file__).resolve().parent.parent
COMMON = ["render", "scenes/chart.pov", "--lens", "dgauss.50mm", "--focus", "8",
          "--method", "mesh", "--samples", "16", "--width", "160", "--height", "120", "-q"]
VIEWS = {
    # look_at raised by atan(6.3 / 50.6 mm) = 7.1 degrees: the same view by tilting
    "tilted": ["--location", "0,1.5,0", "--look-at", "0,2.4949,8"],
    "shifted": ["--shift-mm", "0,6.3"],
}


def main() -> None:
    images = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, extra in VIEWS.items():
            out = Path(tmp) / name
            subprocess.run([sys.executable, "-m", "povlens", *COMMON, *extra, "-o", str(out)],
                           check=True, cwd=ROOT)
            images.append(read_image(out / "image.exr")[..., :3])
    picture = np.concatenate(images, axis=1)
    picture[:, 159:161] = 1.0                       # a white line between the two (320 px)
    target = ROOT / "docs" / "images" / "lens_shift.png"
    target.parent.mkdir(parents=True, exist_ok=True)
    write_png_srgb(target, picture)
    print(target, picture.shape[1], "x", picture.shape[0])


if __name__ == "__main__":
    main()
