"""Importing the lentil lens database: every entry of the shared subset, checked against
paraxial data computed here from the JSON (``import_reference``), scaling, bad files."""
import json
import warnings

import pytest

from conftest import ROOT
from import_reference import lentil_system, reference

from povlens.errors import LensClipWarning, LensFileError, ParameterError
from povlens.lens.import_lentil import import_lentil, list_lentil, read_lentil
from povlens.lens.importers import import_lens_file
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import read_lens

SUBSET = ROOT / "tests" / "data" / "lentil-lenses-subset.json"
IDS = list(json.load(open(SUBSET)))
CASES = [(i, "optical-elements-patent") for i in IDS] + [("0001", "optical-elements-adjusted")]
KEYS = ("efl", "f_number", "entrance_pupil_position", "exit_pupil_position")


def close(a, b, rel=1e-6):
    return a == pytest.approx(b, rel=rel, abs=1e-9 * max(1.0, abs(b)))


def quiet_import(lens_id, adjusted=False):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LensClipWarning)  # 0004, 0005 clip housings
        return import_lentil(SUBSET, lens_id, adjusted)


def test_the_subset_has_eight_entries():
    assert IDS == [f"000{i}" for i in range(1, 9)]


@pytest.mark.parametrize("lens_id,table", CASES)
def test_entry_matches_an_independent_paraxial_trace(tmp_path, lens_id, table):
    imported = quiet_import(lens_id, adjusted=table.endswith("adjusted"))
    out = tmp_path / f"{lens_id}.dat"
    back = imported.write(out)
    assert back == imported.lens == read_lens(out)
    got = paraxial_data(read_lens(out))
    want = reference(*lentil_system(SUBSET, lens_id, table))
    for key in KEYS:
        assert close(getattr(got, key), want[key]), (key, getattr(got, key), want[key])


def test_file_keeps_source_id_material_and_flat_faces(tmp_path):
    out = tmp_path / "0005.dat"
    quiet_import("0005").write(out)
    text = out.read_text()
    assert "entry 0005" in text and "lentil-lenses-subset.json" in text
    assert "canon retrofocus-wideangle (1982), patent US4310222" in text
    rows = [line for line in text.splitlines() if line and not line.startswith("#")]
    assert len(rows) == 26                       # one row per row of the table
    assert rows[17].startswith("0\t") and "iris: aperture stop" in rows[17]
    # The flat filter plate (radius 99999 twice): flat refracting faces, radius 0 with glass.
    lens = read_lens(out)
    assert lens.radius_mm[11] == lens.radius_mm[12] == 0.0
    assert lens.index_after[11] == pytest.approx(1.51633, abs=1e-5)
    assert not lens.is_aperture[11] and not lens.is_aperture[12] and lens.is_aperture[17]
    assert "flat (radius 99999 in the source)" in rows[11]
    assert lens.abbe_vd[0] == pytest.approx(50.2)


def test_clipped_housings_are_reported_by_row():
    with pytest.warns(LensClipWarning) as caught:
        imported = import_lentil(SUBSET, "0004")
    texts = [str(w.message) for w in caught]
    assert any("entry 0004" in t and "row 10: aperture diameter 50 mm" in t for t in texts)
    assert "clipped where the surface ends" in imported.row_notes[10]


def test_efl_scales_the_design(tmp_path):
    base = quiet_import("0001")
    p0 = paraxial_data(base.lens)
    out = tmp_path / "s.dat"
    scaled = base.scaled_to_efl(50.0).write(out)
    p = paraxial_data(scaled)
    k = 50.0 / p0.efl
    assert p.efl == pytest.approx(50.0, rel=1e-12)
    assert p.f_number == pytest.approx(p0.f_number, rel=1e-12)
    assert p.entrance_pupil_position == pytest.approx(k * p0.entrance_pupil_position, rel=1e-12)
    assert p.exit_pupil_position == pytest.approx(k * p0.exit_pupil_position, rel=1e-12)
    assert scaled.aperture_diameter_mm == pytest.approx(k * base.lens.aperture_diameter_mm)
    assert "scaled x" in out.read_text()
    via = import_lens_file(SUBSET, lens_id="0001", efl_mm=50.0)
    assert via.lens == scaled


def test_list_gives_id_company_name_year_focal_length():
    entries = list_lentil(SUBSET)
    assert [e.lens_id for e in entries] == IDS
    e = entries[0]
    assert (e.company, e.name, e.year, e.focal_length_mm, e.surfaces, e.has_adjusted) == \
        ("angenieux", "double-gauss", 1953, 100.0, 15, True)
    assert entries[4].focal_length_mm == 14.2 and not entries[4].has_adjusted


def test_read_lentil_is_the_prescription():
    assert read_lentil(SUBSET, "0007") == quiet_import("0007").lens


def test_truncated_json_names_file_and_line(tmp_path):
    bad = tmp_path / "lenses.json"
    bad.write_text(SUBSET.read_text()[:5000])
    with pytest.raises(LensFileError) as e:
        list_lentil(bad)
    assert e.value.path == str(bad) and e.value.line is not None
    assert "not valid JSON" in str(e.value) and "download lenses.json again" in str(e.value)


def test_unknown_id_names_the_ids_and_how_to_list_them():
    with pytest.raises(ParameterError) as e:
        import_lentil(SUBSET, "0042")
    assert e.value.parameter == "lens_id"
    assert "0042" in e.value.message and "0001" in e.value.message
    assert "--list" in e.value.hint


def test_adjusted_table_must_exist():
    with pytest.raises(ParameterError) as e:
        import_lentil(SUBSET, "0002", adjusted=True)
    assert e.value.parameter == "adjusted"


def one_entry(tmp_path, **changes):
    data = json.load(open(SUBSET))
    entry = data["0003"]
    for k, v in changes.items():
        row, key = k.split("__")
        entry["optical-elements-patent"][int(row[1:])][key.replace("_", "-")] = v
    p = tmp_path / "one.json"
    p.write_text(json.dumps({"0003": entry}))
    return p


@pytest.mark.parametrize("changes,match", [
    ({"r0__lens_geometry": "freeform"}, r"row 0: lens-geometry 'freeform'"),
    ({"r0__lens_geometry": "cyl-y", "r0__aspherical_equation": [1e-6]},
     r"row 0: an aspherical-equation on a cyl-y row"),
    ({"r4__aspherical_equation": "1e-6"}, r"row 4: aspherical-equation \"1e-6\" is not a list"),
    ({"r2__thickness": [23.3, 20.0, 18.0]}, r"row 2: thickness is a list \(a zoom lens"),
    ({"r1__ior": "glass"}, r"row 1: ior is \"glass\", not a number"),
    ({"r5__thickness": -1.0}, r"row 5: thickness -1 mm is negative"),
])
def test_rows_a_kolb_file_cannot_hold_are_refused_by_row(tmp_path, changes, match):
    with pytest.raises(LensFileError, match=match) as e:
        import_lentil(one_entry(tmp_path, **changes), "0003")
    assert "one.json [entry 0003, optical-elements-patent]" in str(e.value)


def test_zero_aspheric_terms_are_spherical(tmp_path):
    p = one_entry(tmp_path, r4__aspherical_equation=[0, 0, 0, 0])
    assert read_lentil(p, "0003") == read_lentil(SUBSET, "0003")


def test_a_database_of_one_lens_needs_no_id(tmp_path):
    p = one_entry(tmp_path)
    assert import_lens_file(p).lens == read_lentil(SUBSET, "0003")
    with pytest.raises(ParameterError, match="'lens_id' is needed"):
        import_lens_file(SUBSET)
