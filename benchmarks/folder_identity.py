"""Render folders byte for byte: render a fixed set of bundled scenes and lenses and
list every file's SHA-256, so a refactoring can be checked to leave them unchanged.

    python3 benchmarks/folder_identity.py OUT.json [--root DIR]      # render and list
    python3 benchmarks/folder_identity.py --diff A.json B.json       # compare two lists

The povlens imported is whichever is first on ``sys.path`` (``PYTHONPATH=/old/tree``
lists an older tree).  Images are compared by their pixels (an EXR's header carries the time it was
written), ``.npz`` archives by their arrays (zip entries carry times), JSON files
without their ``seconds`` entries; files that hold timings by design (``*.log``,
``*.timing.json``) are listed but not compared.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import pathlib
import subprocess
import sys
import tempfile

HERE = pathlib.Path.cwd()          # the tree whose scenes/ and lenses are rendered

#: (name, povlens render arguments) - small images, every method and path.
CASES = [
    ("paper-mesh-field", ["scenes/paper.pov", "--lens", "dgauss.50mm", "--focus", "4",
                          "--method", "mesh", "--samples", "4"]),
    ("chart-mesh-pixel", ["scenes/chart.pov", "--lens", "tessar.50mm", "--focus", "3",
                          "--method", "mesh", "--samples", "2", "--ray-mesh", "pixel"]),
    ("paper-focal-blur", ["scenes/paper.pov", "--lens", "dgauss.50mm", "--focus", "4",
                          "--method", "focal-blur", "--samples", "4"]),
    ("cards-pinhole", ["scenes/cards.pov", "--lens", "wide.22mm", "--method", "pinhole"]),
    ("bokeh-auto", ["scenes/bokeh.pov", "--lens", "dgauss.50mm", "--method", "auto"]),
    ("paper-iris-f8", ["scenes/paper.pov", "--lens", "dgauss.50mm", "--focus", "4",
                       "--method", "mesh", "--samples", "3", "--f-number", "8",
                       "--aperture-blades", "6"]),
    ("chart-dispersion", ["scenes/chart.pov", "--lens", "cooke.triplet.50mm", "--focus", "3",
                          "--method", "mesh", "--samples", "3", "--dispersion"]),
    ("paper-pull", ["scenes/paper.pov", "--lens", "dgauss.50mm", "--focus", "2:6",
                    "--frames", "2", "--method", "mesh", "--samples", "2"]),
]
SIZE = ["--width", "96", "--height", "72"]
SKIP_SUFFIXES = (".log", ".timing.json")


def _content(path: pathlib.Path, folder: pathlib.Path) -> bytes:
    """What of ``path`` must stay the same: pixels, arrays, JSON without timings."""
    if path.suffix in (".exr", ".png"):
        import OpenImageIO as oiio
        buf = oiio.ImageBuf(str(path))
        return buf.get_pixels(oiio.FLOAT).tobytes() + str(buf.spec().channelnames).encode()
    if path.suffix == ".npz":
        import numpy as np
        with np.load(path, allow_pickle=False) as z:
            return b"".join(k.encode() + _text(_bytes(z[k]), folder, path.parent)
                            for k in sorted(z.files))
    return _text(path.read_bytes(), folder, path.parent)


def _bytes(a) -> bytes:
    """An array's bytes; text (dtype ``U``) as UTF-8, so paths in it can be replaced."""
    return "\n".join(map(str, a.ravel())).encode() if a.dtype.kind == "U" else a.tobytes()


def _text(data: bytes, folder: pathlib.Path, here: pathlib.Path) -> bytes:
    """``data`` without the folder's and the tree's paths (absolute, or relative to
    ``here``, the file's folder: a wrapper's ``#include``) and without timings
    (``"seconds": ...``, ``"build_time_s": ...``)."""
    data = data.replace(os.path.relpath(HERE, here).encode(), b"<TREE>")   # first: it holds HERE
    data = data.replace(str(folder).encode(), b"<OUT>").replace(str(HERE).encode(), b"<TREE>")
    return re.sub(rb'"(seconds|\w+_time_s)": [0-9.e+-]+', rb'"\1": 0', data)


def _digest(folder: pathlib.Path) -> dict:
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_file():
            rel = str(p.relative_to(folder))
            if rel.endswith(SKIP_SUFFIXES):
                out[rel] = "skipped"
                continue
            out[rel] = hashlib.sha256(_content(p, folder)).hexdigest()
    return out


def render_all(root: pathlib.Path) -> dict:
    result = {}
    for name, args in CASES:
        out = root / name
        cmd = [sys.executable, "-m", "povlens", "render", *args, *SIZE, "-q", "-j", "2",
               "-o", str(out)]
        run = subprocess.run(cmd, cwd=HERE, capture_output=True, text=True)
        if run.returncode:
            result[name] = {"error": run.stderr[-2000:]}
            continue
        result[name] = _digest(out)
        print(f"{name}: {len(result[name])} files", file=sys.stderr)
    return result


def diff(a: dict, b: dict) -> list[str]:
    lines = []
    for case in sorted(set(a) | set(b)):
        fa, fb = a.get(case, {}), b.get(case, {})
        for rel in sorted(set(fa) | set(fb)):
            if fa.get(rel) != fb.get(rel):
                lines.append(f"{case}/{rel}: {fa.get(rel, 'missing')[:12]} != "
                             f"{fb.get(rel, 'missing')[:12]}")
    return lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?")
    ap.add_argument("--root", help="render here (default: a temporary folder)")
    ap.add_argument("--diff", nargs=2, metavar=("A", "B"))
    a = ap.parse_args()
    if a.diff:
        d = diff(*(json.loads(pathlib.Path(p).read_text()) for p in a.diff))
        print("\n".join(d) if d else "identical")
        return 1 if d else 0
    with tempfile.TemporaryDirectory(prefix="povlens-identity.") as tmp:
        root = pathlib.Path(a.root or tmp)
        result = render_all(root)
    pathlib.Path(a.out).write_text(json.dumps(result, indent=1, sort_keys=True))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
