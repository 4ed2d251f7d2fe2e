"""The CPU floor of one-pass-per-lens-sample renders against POV-Ray's focal_blur.

    python benchmarks/bench_pass_floor.py [--sizes 640x480,1920x1080] [--scenes paper.pov,chart.pov]
        [--lens dgauss.50mm] [--mesh-samples 16]

An exact-lens render through field meshes costs one POV-Ray pass per lens sample
(distribution 3 traces one ray per pixel).  POV-Ray's focal_blur with ``blur_samples
N, N`` traces its N rays per pixel in one pass.  This measures, in CPU seconds (user +
system of the POV-Ray processes, ``RUSAGE_CHILDREN``; robust to other load on the
machine, unlike wall time):

* ``pinhole``: one pinhole pass;
* ``focal_blur N`` for N = 1, 16, 64, and the cost of one more blur sample,
  (fb(64) - fb(1)) / 63;
* ``mesh pass``: the POV-Ray CPU of one field-mesh lens sample (mean over
  ``--mesh-samples`` samples) and povlens's own CPU per sample (tracing, meshes,
  masks; this process's ``RUSAGE_SELF``).

The floor of ``mesh N / focal_blur N`` is ``N * pass / fb(N)``: what the ratio would
be if povlens cost nothing.  ``benchmarks/results/pass_floor.txt`` keeps the last run.
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
from pathlib import Path

from povlens.plan.convert import ConvertOptions, convert
from povlens.rendering.driver import render_outdir
from povlens.rendering.views import render_view

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "povlens" / "data" / "scenes"


def _cpu() -> tuple[float, float]:
    """(children, self) user + system CPU seconds so far."""
    c = resource.getrusage(resource.RUSAGE_CHILDREN)
    s = resource.getrusage(resource.RUSAGE_SELF)
    return c.ru_utime + c.ru_stime, s.ru_utime + s.ru_stime


def cpu_of(fn, *a, **kw) -> tuple[float, float]:
    """(POV-Ray CPU s, povlens CPU s) spent by ``fn(*a, **kw)``."""
    c0, s0 = _cpu()
    fn(*a, **kw)
    c1, s1 = _cpu()
    return c1 - c0, s1 - s0


def floor_of(scene: Path, lens: str, width: int, height: int, mesh_n: int, work: Path) -> dict:
    base = dict(scene=str(scene), lens=lens, focus=4.0, width=width, height=height)
    fb = {}
    for n in (1, 16, 64):
        d = work / f"fb-{scene.stem}-{width}-{n}"
        convert(ConvertOptions.of(outdir=str(d), method="focal-blur", samples=n, **base))
        if n == 1:
            fb["pinhole"], _ = cpu_of(render_view, d, "pinhole")
        fb[n], _ = cpu_of(render_view, d, "focal-blur")
    d = work / f"mesh-{scene.stem}-{width}"
    convert(ConvertOptions.of(outdir=str(d), method="mesh", samples=mesh_n, **base))
    pov_cpu, py_cpu = cpu_of(render_outdir, d, quiet=True)
    passes = max(1, len(list((d / "samples").glob("sample_*.exr"))))
    row = {"scene": scene.name, "size": f"{width}x{height}", "pinhole": fb["pinhole"],
           "fb1": fb[1], "fb16": fb[16], "fb64": fb[64], "blur_sample": (fb[64] - fb[1]) / 63,
           "mesh_pass": pov_cpu / passes, "povlens_per_sample": py_cpu / mesh_n}
    for n in (16, 64):
        row[f"floor{n}"] = n * row["mesh_pass"] / fb[n]
        row[f"floor{n}_with_povlens"] = n * (row["mesh_pass"] + row["povlens_per_sample"]) / fb[n]
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="640x480,1920x1080")
    ap.add_argument("--scenes", default="paper.pov,chart.pov")
    ap.add_argument("--lens", default="dgauss.50mm")
    ap.add_argument("--mesh-samples", type=int, default=16)
    args = ap.parse_args(argv)
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    print("CPU seconds (user + system) of POV-Ray; floor = N x mesh pass / focal_blur N")
    print(f"{'scene':10s} {'size':10s} {'pinhole':>8s} {'fb 1':>7s} {'fb 16':>7s} {'fb 64':>7s} "
          f"{'+1 blur':>8s} {'mesh pass':>9s} {'povlens':>8s} {'floor 16':>8s} {'floor 64':>8s}"
          f" {'(+povlens)':>10s}")
    with tempfile.TemporaryDirectory(prefix="povlens-floor-") as tmp:
        for scene in args.scenes.split(","):
            for w, h in sizes:
                r = floor_of(SCENES / scene, args.lens, w, h, args.mesh_samples, Path(tmp))
                print(f"{r['scene']:10s} {r['size']:10s} {r['pinhole']:8.3f} {r['fb1']:7.2f} "
                      f"{r['fb16']:7.2f} {r['fb64']:7.2f} {r['blur_sample']:8.3f} "
                      f"{r['mesh_pass']:9.3f} {r['povlens_per_sample']:8.3f} "
                      f"{r['floor16']:7.2f}x {r['floor64']:7.2f}x {r['floor64_with_povlens']:9.2f}x",
                      flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
