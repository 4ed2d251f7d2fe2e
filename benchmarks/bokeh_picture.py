"""Issue 22's picture: a far highlight through a 6-blade iris, the default exact path beside
the per-pixel one at the same sample count.

    python3 benchmarks/bokeh_picture.py [--out docs/images/bokeh-field-vs-pixel.png]

The issue's setting: a small bright sphere far away (emissive, radius 0.14 m at 30 m),
focus 0.3 m, f/2.8, 6 blades turned 10 deg, 256x192, dgauss.50mm.  Renders ``--method auto``
(which picks exact lens samples: focal_blur cannot draw an iris) and ``--method mesh
--ray-mesh pixel`` with the samples auto chose, and writes the 64x64 around the
highlight of each side by side, enlarged 3x (sRGB), with their times and FLIP against
each other.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from povlens.plan.schema import read_plan  # noqa: E402
from povlens.report.compare import flip_error  # noqa: E402
from povlens.util.images import read_image, write_png_srgb  # noqa: E402

SCENE = """#version 3.7;
global_settings { assumed_gamma 1.0 }
camera { perspective location <0, 0, 0> look_at <0, 0, 1> }
background { rgb 0 }
sphere { <0, 0, 30>, 0.14 pigment { rgb 1 } finish { emission 4 diffuse 0 ambient 0 } }
"""


def render(scene: Path, out: Path, *extra) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "povlens", "render", str(scene), "--lens",
                    "dgauss.50mm", "--focus", "0.3", "--f-number", "2.8", "--aperture-blades",
                    "6", "--blade-rotation", "10", "--width", "256", "--height", "192", "-q",
                    "-o", str(out), *map(str, extra)], check=True, cwd=ROOT)
    return time.perf_counter() - t0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "images" /
                    "bokeh-field-vs-pixel.png")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="povlens-bokeh-") as tmp:
        scene = Path(tmp) / "highlight.pov"
        scene.write_text(SCENE)
        t_auto = render(scene, Path(tmp) / "auto")
        plan = read_plan(Path(tmp) / "auto")
        n = plan.inputs.samples
        t_pix = render(scene, Path(tmp) / "pixel", "--method", "mesh", "--ray-mesh", "pixel",
                       "--samples", n)
        a = read_image(Path(tmp) / "auto" / "image.exr")[..., :3]
        p = read_image(Path(tmp) / "pixel" / "image.exr")[..., :3]
    lum = p.mean(axis=2)
    cy, cx = (int(v) for v in np.argwhere(lum > 0.5 * lum.max()).mean(axis=0))
    cy, cx = min(max(cy, 32), 192 - 32), min(max(cx, 32), 256 - 32)
    crop = (slice(cy - 32, cy + 32), slice(cx - 32, cx + 32))
    strip = np.concatenate([a[crop], np.zeros((64, 2, 3), np.float32), p[crop]], axis=1)
    strip = np.repeat(np.repeat(strip, 3, axis=0), 3, axis=1)     # 3x, pixels as squares
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_png_srgb(args.out, np.clip(strip, 0, None))
    fm = plan.field_mesh
    print(f"auto: {plan.inputs.method} {n} samples"
          + (f", {fm.interleave}x{fm.interleave} tiles" if fm is not None else "")
          + f", {t_auto:.1f} s; per-pixel {n} samples {t_pix:.1f} s; FLIP between them "
          f"{flip_error(p, a)[0]:.4f}; wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
