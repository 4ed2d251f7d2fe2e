"""README picture of an anamorphic lens's bokeh: scenes/bokeh.pov through dgauss.50mm
(left: round discs) and through lentil's Schneider 2x anamorphic design, entry 2004 of
tests/data/lentil-lenses.json (right: ovals), both exact lens rays (mesh, 64 samples,
desqueezed), 160 x 120 each, focus 0.5 m, 10 mm film diagonal.

Run from the repository's top folder: ``python3 benchmarks/anamorphic_picture.py``
(writes ``docs/images/anamorphic_bokeh.png``; ~20 s on 2 cores).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from povlens.util.images import read_image, write_png_srgb

ROOT = Path(__file__).resolve().parent.parent
COMMON = ["render", "scenes/bokeh.pov", "--focus", "0.5", "--film-diagonal", "10",
          "--method", "mesh", "--samples", "64", "--width", "160", "--height", "120", "-q"]


def main() -> None:
    images = []
    with tempfile.TemporaryDirectory() as tmp:
        lens = Path(tmp) / "schneider2004.dat"
        subprocess.run([sys.executable, "-m", "povlens", "import-lens",
                        "tests/data/lentil-lenses.json", "--id", "2004", "-o", str(lens)],
                       check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
        for name, path in (("spherical", "dgauss.50mm"), ("anamorphic", str(lens))):
            out = Path(tmp) / name
            subprocess.run([sys.executable, "-m", "povlens", *COMMON, "--lens", path,
                            "-o", str(out)], check=True, cwd=ROOT)
            images.append(read_image(out / "image.exr")[..., :3])
    picture = np.concatenate(images, axis=1)
    picture[:, 159:161] = 1.0                       # a white line between the two (320 px)
    target = ROOT / "docs" / "images" / "anamorphic_bokeh.png"
    write_png_srgb(target, picture)
    print(f"wrote {target}")


if __name__ == "__main__":
    main()
