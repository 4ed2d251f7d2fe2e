"""Field pupil points with an iris: the polygon domain's pass fraction and containment.

    python3 benchmarks/bench_aperture_domain.py

For dgauss.50mm, wide.22mm and telephoto.250mm focused at 2 m (35 mm film) and three
irises, prints R_B (the round stop's disc), R_D (the polygon domain,
:func:`povlens.pupil.aperture_domain.iris_domain`) and its search time, the largest gauge
of 20,000 random passing rays over R_D at 18 random film points (< 1: contained), and the
pass fraction at the film centre of the disc's and of the domain's points
(docs/decisions/aperture-shape.md).
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from povlens.lens.aperture_shape import ApertureShape, shaped_lens  # noqa: E402
from povlens.lens.focus import focus  # noqa: E402
from povlens.lens.prescription import read_lens  # noqa: E402
from povlens.lens.tracer import trace_from_film  # noqa: E402
from povlens.pupil.aperture_domain import iris_domain, iris_point_mm, iris_scale  # noqa: E402
from povlens.pupil.build import build_pupil_table  # noqa: E402
from povlens.pupil.field import bounding_disc_radius_mm, concentric_disc_mm  # noqa: E402

SHAPES = [ApertureShape(blades=6), ApertureShape(blades=9, rotation_deg=7),
          ApertureShape(blades=5, curvature=0.5, rotation_deg=20)]


def _passed(lens, fd, zp, f, P):
    o = np.zeros((len(P), 3))
    o[:, :2] = f
    return trace_from_film(lens, fd, o, np.c_[P - f, np.full(len(P), zp)]).passed


def main() -> None:
    for name in ("dgauss.50mm", "wide.22mm", "telephoto.250mm"):
        lens0 = read_lens(name)
        fd = focus(lens0, 2000.0).exact_film_distance_mm
        table = build_pupil_table(lens0, fd, 21.6)
        RB, zp = bounding_disc_radius_mm(table), table.plane_z_mm
        for shape in SHAPES:
            lens = shaped_lens(lens0, shape)
            t0 = time.perf_counter()
            RD, flip, _ = iris_domain(lens, fd, table)
            dt = time.perf_counter() - t0
            rng = np.random.default_rng(0)
            worst = 0.0
            for r in (0.0, 3.3, 7.7, 12.0, 17.0, 21.0):
                for phi in rng.uniform(0, 2 * math.pi, 3):
                    f = np.array([r * math.cos(phi), r * math.sin(phi)])
                    P = concentric_disc_mm(rng.random((20000, 2)), RB)
                    ok = _passed(lens, fd, zp, f, P)
                    if ok.any():
                        q = iris_scale(shape, np.arctan2(P[ok, 1], P[ok, 0]), flip)
                        worst = max(worst, float((np.hypot(P[ok, 0], P[ok, 1]) / q).max() / RD))
            u = rng.random((20000, 2))
            disc = _passed(lens, fd, zp, np.zeros(2), concentric_disc_mm(u, RB)).mean()
            Q = np.array([iris_point_mm(shape, flip, RD, RB, p)[0]
                          for p in concentric_disc_mm(u, 1.0)])
            dom = _passed(lens, fd, zp, np.zeros(2), Q).mean()
            print(f"{name:16s} {str(shape.describe()):60s} R_B {RB:.3f} R_D {RD:.3f} "
                  f"({dt:.2f} s)  worst gauge {worst:.4f} R_D  centre pass: disc {disc:.3f} "
                  f"domain {dom:.3f}", flush=True)


if __name__ == "__main__":
    main()
