"""Importing Zemax sequential .zmx files: public samples (mjhoptics/ray-optics) and
hand-made ones from published designs (tests/data/zmx/README.md), each checked against
paraxial data computed here from the file (``import_reference``); refusals and notices."""
import warnings

import pytest

from conftest import ROOT
from import_reference import reference, rim_sag, with_stop_plane, zmx_system

from povlens.errors import LensClipWarning, LensFileError, ParameterError
from povlens.lens.import_common import LensImportWarning
from povlens.util.files import decode_text
from povlens.lens.import_zemax import import_zmx, parse_zmx_text, read_zmx
from povlens.lens.importers import import_lens_file, source_format
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import read_lens

ZMX = ROOT / "tests" / "data" / "zmx"
SILICA = {"SILICA": (1.458464, 67.82)}
KEYS = ("efl", "f_number", "entrance_pupil_position", "exit_pupil_position")

# file, glasses, EFL (mm) and f-number for the record (the check is the reference trace)
EXACT = [
    ("US00583336-2-scaled.zmx", None, 49.3890, 4.538),    # public: double Gauss, flat stop
    ("US05831776-1.zmx", SILICA, 286.006, 1.193),         # public: stop on a convex rear face
    ("singlet-pcx-25mm.zmx", None, 25.3976, 0.9999),      # stop on the convex front face
    ("tessar-laikin-inch.zmx", None, 101.521, 4.500),     # inches, model glass, front dummy
]


def close(a, b, rel=1e-6):
    return a == pytest.approx(b, rel=rel, abs=1e-9 * max(1.0, abs(b)))


def quiet(path, glasses=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LensClipWarning)
        return import_zmx(path, glasses)


def check_against(lens, want):
    got = paraxial_data(lens)
    for key in KEYS:
        assert close(getattr(got, key), want[key]), (key, getattr(got, key), want[key])


@pytest.mark.parametrize("name,glasses,efl,f_number", EXACT)
def test_sample_matches_an_independent_paraxial_trace(tmp_path, name, glasses, efl, f_number):
    imported = quiet(ZMX / name, glasses)
    out = tmp_path / "lens.dat"
    with warnings.catch_warnings():
        warnings.simplefilter("error")            # the written file reads back without notices
        back = imported.write(out)
    assert back == imported.lens == read_lens(out)
    check_against(back, reference(*zmx_system(ZMX / name, {k: v[0] for k, v in
                                                          (glasses or {}).items()})))
    p = paraxial_data(back)
    assert p.efl == pytest.approx(efl, rel=1e-5) and p.f_number == pytest.approx(f_number,
                                                                                 abs=1e-3)


def test_cooke_triplet_in_utf16_with_the_stop_on_a_concave_face(tmp_path):
    path = ZMX / "cooke-triplet-50mm.zmx"
    assert path.read_bytes()[:2] == b"\xff\xfe"
    with pytest.warns(LensImportWarning, match=r"surface 4: .*rim, 0.359851 mm behind"):
        imported = import_zmx(path)
    surfaces, stop, stop_d = zmx_system(path)
    moved, stop = with_stop_plane(surfaces, stop, rim_sag(1 / surfaces[stop][0], stop_d / 2))
    check_against(imported.write(tmp_path / "c.dat"), reference(moved, stop, stop_d))
    # The same lens as the bundled conversion of this design (lenses/SOURCES.md 4.4).
    bundled = read_lens("cooke.triplet.50mm")
    assert paraxial_data(imported.lens).efl == pytest.approx(paraxial_data(bundled).efl,
                                                             rel=1e-5)  # 6 digits there
    assert imported.lens.thickness_mm[3] == pytest.approx(bundled.thickness_mm[3], abs=1e-6)


def test_file_names_source_surfaces_and_glasses(tmp_path):
    out = tmp_path / "dg.dat"
    quiet(ZMX / "US00583336-2-scaled.zmx").write(out)
    text = out.read_text()
    assert "# Original Double Gauss" in text
    assert "US00583336-2-scaled.zmx" in text and "dummy surfaces 1 (in air, no power)" in text
    assert "note: From U.S. Patent 583336" in text
    rows = [line for line in text.splitlines() if line and not line.startswith("#")]
    assert len(rows) == 11 and "surface 2: N-BAK1 nd 1.5725 vd 57.5493" in rows[0]
    assert "aperture stop (surface 7)" in rows[5]


def test_units_encodings_and_glass_codes(tmp_path):
    tessar = quiet(ZMX / "tessar-laikin-inch.zmx").lens
    assert tessar.radius_mm[0] == pytest.approx(1.3329 * 25.4)
    text = (ZMX / "singlet-pcx-25mm.zmx").read_text()
    want = read_zmx(ZMX / "singlet-pcx-25mm.zmx")
    for i, raw in enumerate([text.encode("utf-16-le"), b"\xfe\xff" + text.encode("utf-16-be"),
                             b"\xef\xbb\xbf" + text.replace("\n", "\r\n").encode()]):
        p = tmp_path / f"s{i}.zmx"
        p.write_bytes(raw)
        assert read_zmx(p) == want, i
    coded = tmp_path / "code.zmx"
    coded.write_text(text.replace("N-SF11 0 0 1.78472 25.68", "785257 0 0 1.5 40"))
    lens = read_zmx(coded)
    assert (lens.index_after[1], lens.abbe_vd[1]) == pytest.approx((1.785, 25.7))
    assert decode_text("SURF 0".encode("utf-16-le")) == "SURF 0"


def test_glasses_without_index_are_refused_and_can_be_given():
    with pytest.raises(LensFileError) as e:
        import_zmx(ZMX / "US05831776-1.zmx")
    msg = str(e.value)
    assert "US05831776-1.zmx:97" in msg and "glass SILICA has no refractive index" in msg
    assert "surfaces 1, 3, 5" in msg and "'glasses'" in e.value.hint
    lens = quiet(ZMX / "US05831776-1.zmx", {"SILICA": 1.458464}).lens
    assert lens.index_after[0] == 1.458464 and lens.abbe_vd[0] == 0


@pytest.mark.parametrize("name,match", [
    ("HoO-V2C18Ex03.zmx", r"HoO-V2C18Ex03.zmx:78: surface 2 \(line 78\): a mirror"),
])
def test_public_samples_a_kolb_file_cannot_hold_are_refused(name, match):
    with pytest.raises(LensFileError, match=match) as e:
        import_zmx(ZMX / name)
    assert e.value.hint


SINGLET = (ZMX / "singlet-pcx-25mm.zmx").read_text()


def edited(tmp_path, old, new, name="edited.zmx"):
    assert old in SINGLET
    p = tmp_path / name
    p.write_text(SINGLET.replace(old, new, 1))
    return p


@pytest.mark.parametrize("old,new,match", [
    ("TYPE STANDARD\n  FIMP \n  CURV 0.0501", "TYPE BICONICX\n  FIMP \n  CURV 0.0501",
     r"surface 1 \(line \d+\): surface type BICONICX"),
    ("SURF 2\n  TYPE STANDARD", "SURF 2\n  TYPE COORDBRK", r"surface 2 .*coordinate break"),
    ("  DISZ 7\n", "  DISZ 7\n  CONI -1\n", r"surface 1 .*the stop lies on an aspheric face"),
    ("  DISZ 7\n", "  DISZ 7\n  SCBD 1 0 0 0 0.5 0 0 0\n", r"surface 1 .*tilted or decentered"),
    ("MODE SEQ", "MODE NSC", r":2: MODE NSC: not a sequential design"),
    ("UNIT MM", "UNIT FURLONG", r":6: UNIT FURLONG: unknown lens unit"),
    ("  DISZ 7\n", "  DISZ seven\n", r":39: surface 1 \(line 32\): DISZ thickness: 'seven' is not a number"),
])
def test_unsupported_surfaces_and_bad_lines_are_refused(tmp_path, old, new, match):
    with pytest.raises(LensFileError, match=match):
        import_zmx(edited(tmp_path, old, new))


def test_no_stop_is_refused(tmp_path):
    with pytest.raises(LensFileError) as e:
        import_zmx(edited(tmp_path, "  STOP\n", ""))
    assert "no surface is marked STOP" in str(e.value) and "mark the aperture stop" in e.value.hint


def test_the_stop_inside_glass_is_refused(tmp_path):
    p = edited(tmp_path, "  STOP\n", "")
    p.write_text(p.read_text().replace("SURF 2\n", "SURF 2\n  STOP\n").replace(
        "  DISZ 21.48\n", "  DISZ 21.48\n  GLAS ___BLANK 1 0 1.5 60 0 0 0 0 0 0 \n"))
    with pytest.raises(LensFileError, match=r"surface 2 .*the stop lies between two glasses"):
        import_zmx(p)


def test_dropped_features_are_reported_by_surface(tmp_path):
    p = edited(tmp_path, "  DISZ 21.48\n", "  DISZ 21.48\n  COAT AR\n  OBSC 0 2 0\n")
    with pytest.warns(LensImportWarning) as caught:
        lens = read_zmx(p)
    texts = [str(w.message) for w in caught]
    assert any("surface 2: coating AR is dropped" in t for t in texts)
    assert any("surface 2: an obscuration" in t for t in texts)
    assert lens == read_zmx(ZMX / "singlet-pcx-25mm.zmx")


def test_format_detection_and_options_of_the_other_format(tmp_path):
    assert source_format(ZMX / "US08427765-1.ZMX") == "zemax"
    p = tmp_path / "lens.txt"
    p.write_text(SINGLET)
    assert source_format(p) == "zemax"
    with pytest.raises(ParameterError) as e:
        import_lens_file(ZMX / "singlet-pcx-25mm.zmx", lens_id="0001")
    assert e.value.parameter == "lens_id"
    scaled = import_lens_file(ZMX / "singlet-pcx-25mm.zmx", efl_mm=50.0).lens
    assert paraxial_data(scaled).efl == pytest.approx(50.0, rel=1e-12)


def test_parse_reads_notes_and_configurations():
    f = parse_zmx_text((ZMX / "US05831776-1.zmx").read_text(), "x.zmx")
    assert len(f.surfaces) == 44 and f.unit_mm == 1.0 and f.configurations == 1
    assert f.notes[0] == "The MIT License (MIT)"
    assert "including without limitation" in f.notes[2]


def test_a_stop_at_zero_gap_in_front_keeps_the_file_out_of_the_old_kolb_layout(tmp_path):
    # read_lens takes "first thickness 0, last not 0" for an old Kolb table; the singlet's
    # stop sits at zero gap in front, so its image distance is written as 0.
    out = tmp_path / "s.dat"
    imported = quiet(ZMX / "singlet-pcx-25mm.zmx")
    back = imported.write(out)
    assert back.file_format == "pbrt" and back.thickness_mm[0] == 0 == back.thickness_mm[-1]
    assert "21.48 mm to the image written as 0" in imported.row_notes[-1]


def test_the_api_writes_and_returns_the_lens(tmp_path):
    import povlens
    out = tmp_path / "t.dat"
    lens = povlens.import_lens(ZMX / "tessar-laikin-inch.zmx", out, efl_mm=50.0)
    assert lens == read_lens(out) and paraxial_data(lens).efl == pytest.approx(50.0, rel=1e-12)
    assert povlens.import_lens(ZMX / "tessar-laikin-inch.zmx") == read_zmx(
        ZMX / "tessar-laikin-inch.zmx")
