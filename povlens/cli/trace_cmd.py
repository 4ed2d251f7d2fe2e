"""``povlens trace LENS --film-distance MM``: trace JSON rays from the film to the scene."""

from __future__ import annotations

import json
import sys

import numpy as np

from povlens.errors import UsageError
from povlens.lens.tracer import trace_from_film
from povlens.cli.common import add_lens_command, load_lens, positive_float, print_json


def register(sub) -> None:
    p = add_lens_command(
        sub, "trace", run,
        help="trace rays given as JSON from the film to the scene",
        description='Read {"rays": [{"origin": [x,y,z], "direction": [dx,dy,dz]}, '
                    '...]} on stdin, in the camera frame (origin at the film '
                    'centre, +z toward the scene, mm), trace them from the film '
                    'through LENS, and print {"rays": [...]} with each ray where '
                    'it leaves the front surface (unit direction), or null when '
                    'the lens blocks it.')
    p.add_argument("--film-distance", type=positive_float, required=True, metavar="MM",
                   help="distance from the film to the rear vertex, mm (see 'povlens focus')")


def parse_rays(text: str) -> tuple[np.ndarray, np.ndarray]:
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise UsageError(f"stdin: not valid JSON ({e.msg} at line {e.lineno}, column {e.colno})",
                         'expected {"rays": [{"origin": [x, y, z], "direction": [dx, dy, dz]}]}'
                         ) from None
    rays = doc.get("rays") if isinstance(doc, dict) else None
    if not isinstance(rays, list):
        raise UsageError('stdin: expected an object with a "rays" list')
    o = np.zeros((len(rays), 3))
    d = np.zeros((len(rays), 3))
    for k, ray in enumerate(rays):
        try:
            o[k] = [float(v) for v in ray["origin"]]
            d[k] = [float(v) for v in ray["direction"]]
        except (TypeError, KeyError, ValueError):
            raise UsageError(f"stdin: ray {k}: needs \"origin\" and \"direction\", each a list "
                             f"of 3 numbers") from None
        if not (np.all(np.isfinite(o[k])) and np.all(np.isfinite(d[k]))):
            raise UsageError(f"stdin: ray {k}: origin and direction must be finite numbers")
        if not np.any(d[k]):
            raise UsageError(f"stdin: ray {k}: direction is the zero vector")
    return o, d


def run(args) -> int:
    lens = load_lens(args)
    o, d = parse_rays(sys.stdin.read())
    r = trace_from_film(lens, args.film_distance, o, d)
    out = [None if not r.passed[k] else
           {"origin": r.origin_mm[k].tolist(), "direction": r.direction[k].tolist()}
           for k in range(len(r))]
    print_json({"rays": out})
    return 0
