import numpy as np
import pytest

from povlens.errors import LensFileError
from povlens.lens.prescription import format_lens, parse_lens_text, read_lens, write_lens

from conftest import LENS_DIR, SHIPPED_LENSES


@pytest.mark.parametrize("name", SHIPPED_LENSES)
def test_shipped_lenses_read_and_round_trip(name, tmp_path):
    lens = read_lens(LENS_DIR / name)
    assert lens.n_surfaces >= 3
    assert np.all(np.isfinite(lens.radius_mm)) and np.all(lens.aperture_diameter_mm > 0)
    out = tmp_path / name
    write_lens(lens, out)
    again = read_lens(out)
    assert again == lens
    assert again.file_format == "pbrt"


def test_old_kolb_tables_are_converted_to_match_the_pbrt_files():
    for old, new, scale in (("dgauss.dat", "dgauss.50mm.dat", 0.5),
                            ("wide.dat", "wide.22mm.dat", 0.22)):
        a, b = read_lens(LENS_DIR / old), read_lens(LENS_DIR / new)
        assert a.file_format == "kolb-axpos" and b.file_format == "pbrt"
        np.testing.assert_allclose(a.radius_mm * scale, b.radius_mm, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(a.thickness_mm[:-1] * scale, b.thickness_mm[:-1], atol=1e-12)
        np.testing.assert_allclose(a.index_after, b.index_after)
        np.testing.assert_allclose(a.aperture_diameter_mm * scale, b.aperture_diameter_mm,
                                   atol=1e-12)


def test_comments_crlf_tabs_and_fifth_column():
    text = ("# header\r\n"
            "  50\t5 1.5168  20  64.17  # trailing comment\r\n"
            "-50 2 0 20\t# with #hash\r\n"
            "0 0 0 10\r\n")
    lens = parse_lens_text(text, "x.dat")
    assert lens.n_surfaces == 3
    assert lens.comments == ("header",)
    assert lens.abbe_vd[0] == 64.17 and lens.abbe_vd[1] == 0
    assert list(lens.is_aperture) == [False, False, True]
    assert lens.index_after[1] == 1.0  # 0 means air


def test_flat_refracting_face_is_not_an_aperture():
    lens = parse_lens_text("0 0 0 25\n20 7 1.78 25\n0 0 1 25\n", "pcx.dat")
    assert list(lens.is_aperture) == [True, False, False]
    assert lens.curvature_per_mm[2] == 0.0


@pytest.mark.parametrize("text, line, words", [
    ("10 2 1.5 abc\n", 1, "not a number"),
    ("10 2 1.5\n", 1, "3 columns"),
    ("10 2 1.5 20 1 7\n", 1, "6 columns"),
    ("10 2 1.5 20\n-10 0 1 -3\n", 2, "must be positive"),
    ("10 2 1.5 20\n-10 0 1 0\n", 2, "must be positive"),
    ("10 2 nan 20\n-10 0 1 5\n", 1, "not a finite number"),
    ("10 2 1.5 inf\n-10 0 1 5\n", 1, "not a finite number"),
    ("10 2 0.8 5\n-10 0 1 5\n", 1, "below 1"),
    ("10 2 -1.5 5\n-10 0 1 5\n", 1, "below 1"),
    ("10 -2 1.5 5\n-10 0 1 5\n", 1, "negative"),
    # apertures beyond the sphere or past where caps cross are clipped, not refused
    # (tests/lens/test_published_lenses.py); caps crossing at the axis are refused
    ("50 5 1.5 20\n-50 0 0 16\n-20 3 1.6 16\n-30 0 0 16\n", 3,
     "cross inside their clear apertures"),
    ("10 2 1.5 8\n-10 0 1.5 8\n", 2, "film must be in air"),
])
def test_bad_rows_name_the_line_and_reason(text, line, words):
    with pytest.raises(LensFileError) as e:
        parse_lens_text(text, "bad.dat")
    assert e.value.line == line
    assert words in str(e.value)
    assert str(e.value).startswith(f"bad.dat:{line}:")


def test_empty_and_missing_files(tmp_path):
    empty = tmp_path / "empty.dat"
    empty.write_text("# only a comment\n\n")
    with pytest.raises(LensFileError, match="no lens rows"):
        read_lens(empty)
    with pytest.raises(LensFileError, match="no such lens file"):
        read_lens(tmp_path / "missing.dat")


def test_format_lens_is_exact_for_awkward_numbers():
    lens = parse_lens_text("0.1 0.30000000000000004 1.5 0.2\n-1e9 0 1 0.2\n")
    assert parse_lens_text(format_lens(lens)) == lens


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-le", "utf-16-be", "utf-8-sig"])
def test_a_lens_file_saved_as_utf16_or_with_a_bom_reads_as_the_same_lens(tmp_path, encoding):
    """Windows editors save UTF-16 (with or without a byte-order mark) or UTF-8 with a
    BOM; the lens is the same, where UTF-16 used to read as '1 columns'."""
    plain = (LENS_DIR / "dgauss.50mm.dat").read_text()
    path = tmp_path / f"dgauss-{encoding}.dat"
    path.write_bytes(plain.encode(encoding))
    got, want = read_lens(path), read_lens(LENS_DIR / "dgauss.50mm.dat")
    assert format_lens(got) == format_lens(want)
