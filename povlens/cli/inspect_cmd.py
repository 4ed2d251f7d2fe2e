"""``povlens inspect LENS``: the prescription and its paraxial data."""

from __future__ import annotations

from povlens.lens.asphere import TERM_NAMES, aspheric_rows
from povlens.lens.paraxial import paraxial_data
from povlens.cli.common import add_lens_command, load_lens, print_json


def register(sub) -> None:
    p = add_lens_command(
        sub, "inspect", run,
        help="print a lens's surfaces and first-order data",
        description="Print the surfaces of LENS and its paraxial data: focal "
                    "lengths, cardinal points, pupils, f-number.  Lengths in mm; "
                    "positions are signed, positive toward the film.")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")


def inspect_dict(lens) -> dict:
    p = paraxial_data(lens)
    d = {"lens": lens.source, "format": lens.file_format, "surfaces": lens.n_surfaces}
    aspheric = aspheric_rows(lens)
    d.update(p.to_dict())
    d["surface_rows"] = [
        {"radius": float(lens.radius_mm[i]), "thickness": float(lens.thickness_mm[i]),
         "index": float(lens.index_after[i]), "aperture": float(lens.aperture_diameter_mm[i]),
         "abbe_vd": float(lens.abbe_vd[i]),
         "kind": ("aperture" if lens.is_aperture[i] else "asphere" if aspheric[i] else
                  "flat" if lens.radius_mm[i] == 0 else "sphere"),
         **({"asphere": dict(zip(TERM_NAMES, map(float, lens.asphere[i])))} if aspheric[i]
            else {})}
        for i in range(lens.n_surfaces)]
    d["notes"] = notes(lens, p)
    return d


def notes(lens, p) -> list[str]:
    out = []
    if lens.file_format == "kolb-axpos":
        out.append("old Kolb/CS348B table: column 2 was the distance from the previous vertex; "
                   "converted on reading (povlens does not rescale it)")
    if not lens.is_aperture.any():
        out.append(f"no aperture row: {lens.row_label(p.stop_index)} limits the axial beam and "
                   f"is taken as the aperture stop")
    if p.limiting_index != p.stop_index:
        out.append(f"the rim of {lens.row_label(p.limiting_index)} clips the paraxial axial beam "
                   f"before the stop does; the real f-number is slower than the nominal one")
    return out


def run(args) -> int:
    lens = load_lens(args)
    d = inspect_dict(lens)
    if args.json:
        print_json(d)
        return 0
    print(f"{lens.source}  ({lens.n_surfaces} surfaces, {lens.file_format} format)")
    for c in lens.comments[:4]:
        print(f"  # {c}")
    print()
    print(f"  {'row':>3} {'radius':>11} {'thickness':>10} {'index':>8} {'aperture':>9}  kind")
    for i, r in enumerate(d["surface_rows"]):
        mark = "  <- stop" if i == d["stop_index"] else ""
        print(f"  {i:>3} {r['radius']:>11.4f} {r['thickness']:>10.4f} {r['index']:>8.5f} "
              f"{r['aperture']:>9.4f}  {r['kind']}{mark}")
    print()
    rows = [
        ("effective focal length", d["efl"]),
        ("back focal length (rear vertex to F')", d["bfl"]),
        ("front focal length (F in front of front vertex)", d["ffl"]),
        ("f-number", d["f_number"]),
        ("entrance pupil: position from front vertex", d["entrance_pupil"]["position"]),
        ("entrance pupil: diameter", d["entrance_pupil"]["diameter"]),
        ("exit pupil: position from rear vertex", d["exit_pupil"]["position"]),
        ("exit pupil: diameter", d["exit_pupil"]["diameter"]),
        ("principal plane H from front vertex", d["principal_planes"]["front"]),
        ("principal plane H' from front vertex", d["principal_planes"]["rear"]),
        ("stop diameter", d["stop_diameter"]),
        ("total track (front to rear vertex)", d["total_track"]),
    ]
    for name, v in rows:
        unit = "" if name == "f-number" else " mm"
        print(f"  {name:<48} {v:>11.4f}{unit}")
    print(f"  {'aperture stop':<48} {lens.row_label(d['stop_index']):>11}")
    for n in d["notes"]:
        print(f"  note: {n}")
    return 0
