"""Paraxial data computed from the *source* of an imported lens, without povlens.

A small y-nu trace (Smith, *Modern Optical Engineering*, ch. 3) and readers of the
source formats written for the tests: the importers' results are checked against
these, so the two must agree on the optics, not share code.

A system is a list of surfaces ``(c, t, n_after)``: curvature (1/mm), thickness to the
next surface (mm), index after; plus the index of the stop surface and the stop
diameter.  The stop's height is its vertex plane's.

Anamorphic sources (lentil ``cyl-x``/``cyl-y`` rows, Zemax ``TOROIDAL`` surfaces) are
read per meridian (``meridian="y"`` or ``"x"``): the system then holds each surface's
curvature in that plane, and the y-nu trace of it is that meridian's first-order optics
(a toric surface has no twist, so the two planes do not mix paraxially).
"""
from __future__ import annotations

import json
import math
import re


def trace(surfaces, y, nu):
    """Heights at every surface and the final (y, nu) of the ray (y, nu) entering surface 0."""
    n, heights = 1.0, []
    for i, (c, t, n_after) in enumerate(surfaces):
        heights.append(y)
        nu = nu - y * (n_after - n) * c
        n = n_after
        if i < len(surfaces) - 1:
            y = y + t * nu / n
    return heights, y, nu


def has_power(surfaces):
    """Whether the system bends a ray entering parallel (False: afocal)."""
    return trace(surfaces, 1.0, 0.0)[2] != 0.0


def reference(surfaces, stop, stop_diameter):
    """EFL, f-number, entrance pupil (from the first vertex) and exit pupil (from the last
    vertex) positions, positive toward the film."""
    h_marginal, _, nu_k = trace(surfaces, 1.0, 0.0)
    efl = -1.0 / nu_k
    h_angle, _, _ = trace(surfaces, 0.0, 1.0)
    a, b = h_marginal[stop], h_angle[stop]
    entrance = b / a                      # the chief ray (y = -u z, u) has height 0 at the stop
    _, y_k, nu_c = trace(surfaces, -entrance, 1.0)
    exit_ = -y_k / nu_c                   # where the chief ray crosses the axis after the lens
    return {"efl": efl, "f_number": efl / (stop_diameter / abs(a)),
            "entrance_pupil_position": entrance, "exit_pupil_position": exit_}


def lentil_system(path, lens_id, table="optical-elements-patent", meridian="y"):
    """A lentil entry: |radius| >= 9999 flat, the iris (any case) the stop, air where ior
    is null.  Without an iris, the stop is the surface that limits the axial beam: the
    largest ratio of the marginal ray's height to the semi-aperture (the housing radius,
    or where a sphere ends).  In ``meridian`` "y" a ``cyl-y`` row (lentil's cylinder with
    its axis along y: curved in x) is flat and a ``cyl-x`` row curved; in "x" the other
    way round."""
    rows = json.load(open(path))[lens_id][table]
    flat_here = "cyl-x" if meridian == "x" else "cyl-y"
    surfaces, stop, stop_d = [], None, None
    for k, r in enumerate(rows):
        flat = abs(r["radius"]) >= 9999 or r.get("lens-geometry") == flat_here
        if str(r["material"]).lower() == "iris":
            stop, stop_d = k, 2 * r["housing-radius"]
            n = surfaces[-1][2] if surfaces else 1.0
        else:
            n = 1.0 if r["ior"] in (None, 1) or r["material"] == "air" else r["ior"]
        surfaces.append((0.0 if flat else 1.0 / r["radius"], r["thickness"], n))
    if stop is None:
        heights, _, _ = trace(surfaces, 1.0, 0.0)
        semi = [min(r["housing-radius"], abs(r["radius"])) for r in rows]
        stop = max(range(len(rows)), key=lambda k: abs(heights[k]) / semi[k])
        stop_d = 2 * semi[stop]
    return surfaces, stop, stop_d


def zmx_blocks(text):
    """The SURF blocks of a .zmx text: dicts of the keys the tests need."""
    units = {"MM": 1.0, "IN": 25.4, "CM": 10.0}
    unit = units[re.search(r"^UNIT (\w+)", text, re.M).group(1)]
    blocks = []
    for chunk in re.split(r"^SURF \d+\s*$", text, flags=re.M)[1:]:
        get = lambda key: re.search(rf"^\s+{key} (.*)$", chunk, re.M)  # noqa: E731
        glas = get("GLAS")
        disz = get("DISZ")
        kind = get("TYPE")
        parm1 = re.search(r"^\s+PARM 1 (\S+)", chunk, re.M)
        blocks.append({
            "type": kind.group(1).split()[0] if kind else "STANDARD",
            "rotation": float(parm1.group(1)) * unit if parm1 else 0.0,
            "c": float(get("CURV").group(1).split()[0]) / unit,
            "t": (0.0 if disz is None or disz.group(1).startswith("INFINITY")
                  else float(disz.group(1).split()[0]) * unit),
            "glass": glas.group(1).split() if glas else None,
            "stop": re.search(r"^\s+STOP\s*$", chunk, re.M) is not None,
            "semi": float(get("DIAM").group(1).split()[0]) * unit})
    return blocks


def zmx_system(path, glasses=None, meridian="y"):
    """A .zmx lens (object and image dropped, leading flat surfaces in air dropped): the
    stop at its surface's vertex.  In ``meridian`` "x" a TOROIDAL surface's curvature is
    1 / its radius of rotation (PARM 1; 0 is flat)."""
    raw = open(path, "rb").read()
    text = raw.decode("utf-16") if raw[:2] in (b"\xff\xfe", b"\xfe\xff") else raw.decode()
    blocks = zmx_blocks(text)[1:-1]
    surfaces, stop, stop_d, n = [], None, None, 1.0
    for b in blocks:
        if b["glass"] is None:
            n_after = 1.0
        elif glasses and b["glass"][0] in glasses:
            n_after = glasses[b["glass"][0]]
        else:
            n_after = float(b["glass"][3])
        if meridian == "x" and b["type"] == "TOROIDAL":
            b = dict(b, c=1.0 / b["rotation"] if b["rotation"] else 0.0)
        dummy = b["c"] == 0 and n == 1.0 and n_after == 1.0 and not b["stop"]
        if dummy and not surfaces:
            n = n_after
            continue                          # the front vertex is the first real surface
        if b["stop"]:
            stop, stop_d = len(surfaces), 2 * b["semi"]
        surfaces.append((b["c"], b["t"], n_after))
        n = n_after
    return surfaces, stop, stop_d


def with_stop_plane(surfaces, stop, shift):
    """The system with a flat stop ``shift`` mm behind the vertex of surface ``stop`` (the
    stop plane in the rim plane of a face concave toward the air behind it)."""
    c, t, n = surfaces[stop]
    return (surfaces[:stop] + [(c, shift, n), (0.0, t - shift, n)] + surfaces[stop + 1:],
            stop + 1)


def rim_sag(radius, semi):
    return radius - math.copysign(math.sqrt(radius * radius - semi * semi), radius)
