"""``povlens inspect LENS``: the prescription and its paraxial data."""

from __future__ import annotations

from povlens.lens.asphere import TERM_NAMES, aspheric_rows
from povlens.lens.paraxial import anamorphic_data, paraxial_data, primary_meridian
from povlens.lens.toric import describe_row, toric_rows
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
    """The lens and its paraxial data as a JSON-ready dict; an anamorphic lens's are its
    primary meridian's (y unless it has power in x only), with both meridians' focal
    lengths, f-numbers and foci and the squeeze under ``anamorphic``."""
    meridian = primary_meridian(lens)
    p = paraxial_data(lens, meridian)
    d = {"lens": lens.source, "format": lens.file_format, "surfaces": lens.n_surfaces}
    aspheric = aspheric_rows(lens)
    toric = toric_rows(lens)
    d.update(p.to_dict())
    d["surface_rows"] = [
        {"radius": float(lens.radius_mm[i]), "thickness": float(lens.thickness_mm[i]),
         "index": float(lens.index_after[i]), "aperture": float(lens.aperture_diameter_mm[i]),
         "abbe_vd": float(lens.abbe_vd[i]),
         "kind": ("aperture" if lens.is_aperture[i] else
                  describe_row(lens.radius_mm[i], lens.radius_x_mm[i]).split()[0]
                  if toric[i] else "asphere" if aspheric[i] else
                  "flat" if lens.radius_mm[i] == 0 else "sphere"),
         **({"radius_x": float(lens.radius_x_mm[i])} if toric[i] else {}),
         **({"asphere": dict(zip(TERM_NAMES, map(float, lens.asphere[i])))} if aspheric[i]
            else {})}
        for i in range(lens.n_surfaces)]
    if lens.is_anamorphic:
        d["meridian"] = meridian
        d["anamorphic"] = anamorphic_data(lens).to_dict()
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
    if lens.is_anamorphic:
        a = anamorphic_data(lens)
        out.append("anamorphic: " + (f"afocal in {a.afocal} (no power there; a line image)"
                                     if a.afocal else f"squeeze EFL_y / EFL_x = {a.squeeze:.4f}")
                   + f"; its main first-order data are the {primary_meridian(lens)}-z plane's")
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
        kind = (describe_row(r["radius"], r["radius_x"]) if "radius_x" in r else r["kind"])
        print(f"  {i:>3} {r['radius']:>11.4f} {r['thickness']:>10.4f} {r['index']:>8.5f} "
              f"{r['aperture']:>9.4f}  {kind}{mark}")
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
    rows += _anamorphic_rows(d.get("anamorphic"))
    for name, v in rows:
        unit = "" if name.startswith(("f-number", "anamorphic squeeze")) else " mm"
        shown = f"{v:>11.4f}" if v is not None else f"{'inf':>11}"
        print(f"  {name:<48} {shown}{unit}")
    print(f"  {'aperture stop':<48} {lens.row_label(d['stop_index']):>11}")
    for n in d["notes"]:
        print(f"  note: {n}")
    return 0


def _anamorphic_rows(a: dict | None) -> list:
    """The table rows of an anamorphic lens's two meridians (None: an infinite value)."""
    if a is None:
        return []
    return [("effective focal length in x (x-z plane)", a["efl_x_mm"]),
            ("effective focal length in y (y-z plane)", a["efl_y_mm"]),
            ("anamorphic squeeze (EFL_y / EFL_x)", a["squeeze"]),
            ("f-number in x", a["f_number_x"]), ("f-number in y", a["f_number_y"]),
            ("paraxial focus in x from the rear vertex", a["focus_x_mm"]),
            ("paraxial focus in y from the rear vertex", a["focus_y_mm"])]
