"""README picture of the three bundled lenses of issue 26, each rendered on a bundled
scene with povlens's default method (``--method auto``), 320 x 240:

* ``angenieux.100mm`` (catalogue glasses): ``scenes/cards.pov`` focused on the middle
  card (2.1 m) at f/1.14 on a 70 mm film diagonal (the scene's own framing);
* ``aspheric.31mm`` (an even asphere): ``scenes/paper.pov`` focused on the nearest ball
  (4.7 m) on a 24 mm film diagonal;
* ``anamorphic.60mm`` (cylindrical front group, squeeze 1.92): ``scenes/bokeh.pov``
  desqueezed, focused at 0.5 m on a 10 mm film diagonal: oval highlights.

Run from the repository's top folder: ``python3 benchmarks/new_designs_picture.py``
(writes ``docs/images/new_designs.png`` and prints each render's command and time).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from povlens.util.images import read_image, write_png_srgb

ROOT = Path(__file__).resolve().parent.parent
SIZE = ["--width", "320", "--height", "240", "-q"]
RENDERS = [
    ("angenieux.100mm", ["scenes/cards.pov", "--focus", "2.1", "--film-diagonal", "70"]),
    ("aspheric.31mm", ["scenes/paper.pov", "--focus", "4.7", "--film-diagonal", "24"]),
    ("anamorphic.60mm", ["scenes/bokeh.pov", "--focus", "0.5", "--film-diagonal", "10"]),
]


def main() -> None:
    images = []
    with tempfile.TemporaryDirectory() as tmp:
        for lens, args in RENDERS:
            out = Path(tmp) / lens
            cmd = ["povlens", "render", *args, "--lens", lens, *SIZE, "-o", "OUT"]
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", "povlens", *cmd[1:-1], str(out)],
                           check=True, cwd=ROOT)
            print(f"{' '.join(cmd)}: {time.perf_counter() - t0:.1f} s")
            images.append(read_image(out / "image.exr")[..., :3])
    gap = np.ones((240, 4, 3), dtype=np.float32)
    picture = np.concatenate([images[0], gap, images[1], gap, images[2]], axis=1)
    target = ROOT / "docs" / "images" / "new_designs.png"
    write_png_srgb(target, picture)
    print(f"wrote {target}")


if __name__ == "__main__":
    main()
