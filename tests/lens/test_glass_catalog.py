"""Catalogue glasses by name (povlens.lens.glass_catalog) against the makers' data sheets."""

import pytest
import yaml

from povlens.lens import glass_catalog
from povlens.lens.glass_catalog import UnknownGlassError, find_glass, mismatch

# n_d, V_d as printed in the makers' data sheets (SCHOTT N-BK7 and SF5 data sheets,
# OHARA S-LAH59 and S-BAH10 catalogue pages): 4-5 decimals, 2 for V_d.
DATASHEET = {
    "N-BK7": ("SCHOTT:N-BK7", 1.5168, 64.17),
    "SF5": ("SCHOTT:SF5", 1.6727, 32.21),
    "S-LAH59": ("OHARA:S-LAH59", 1.8160, 46.62),
    "SBAH10": ("OHARA:S-BAH10", 1.67003, 47.23),   # lentil's spelling of OHARA's name
}


@pytest.mark.parametrize("name", sorted(DATASHEET))
def test_nd_vd_match_the_data_sheets(name):
    label, n_d, v_d = DATASHEET[name]
    g = find_glass(name)
    assert g.label == label
    assert g.n_d == pytest.approx(n_d, abs=6e-5)      # the sheets' last digit
    assert g.v_d == pytest.approx(v_d, abs=0.006)


def test_nbk7_index_at_the_data_sheet_lines():
    """SCHOTT's N-BK7 sheet: n at the h, g, F, e, d, C lines (5 decimals)."""
    sheet = {404.6561: 1.53024, 435.8343: 1.52668, 486.1327: 1.52238, 546.0740: 1.51872,
             587.5618: 1.51680, 656.2725: 1.51432}
    g = find_glass("n-bk7")
    for lam, n in sheet.items():
        assert float(g.index_at(lam)) == pytest.approx(n, abs=6e-6)


def test_names_without_hyphens_case_and_maker():
    assert find_glass("nbk7").label == "SCHOTT:N-BK7"
    assert find_glass("STIH6").label == "OHARA:S-TIH6"
    assert find_glass("ohara:s-lah59").label == "OHARA:S-LAH59"
    assert find_glass("CDGM:H-K9L").label == "CDGM:H-K9L"
    assert find_glass(" SF15 ").label == "SCHOTT:SF15"      # SCHOTT first


def test_unknown_glass_names_the_closest():
    with pytest.raises(UnknownGlassError) as e:
        find_glass("N-BK77")
    text = str(e.value)
    assert "'N-BK77'" in text and "N-BK7 (SCHOTT)" in text
    with pytest.raises(UnknownGlassError, match="check the spelling"):
        find_glass("QQQQQQ")


def test_every_catalogue_glass_gives_its_stated_nd_and_vd():
    """The formulas (Sellmeier and polynomial) reproduce the n_d and V_d each maker
    states beside them, for every glass of every catalogue searched."""
    worst_nd, worst_vd, checked = 0.0, 0.0, 0
    for maker, stem in glass_catalog._names().values():
        path = glass_catalog._specs_dir() / maker.lower() / "optical" / f"{stem}.yml"
        props = yaml.safe_load(path.read_text(encoding="utf-8")).get("PROPERTIES", {})
        if "nd" not in props or "Vd" not in props:
            continue
        g = find_glass(f"{maker}:{stem}")
        worst_nd = max(worst_nd, abs(g.n_d - float(props["nd"])))
        worst_vd = max(worst_vd, abs(g.v_d - float(props["Vd"])) / float(props["Vd"]))
        checked += 1
    assert checked > 1000
    assert worst_nd < 2e-4 and worst_vd < 0.01, (worst_nd, worst_vd)


def test_mismatch_of_stated_values():
    g = find_glass("SF5")
    assert mismatch(g, 1.6751, 32.3) is None           # lentil's SF5 (a patent's glass)
    assert "n_d 1.5" in mismatch(g, 1.5, 0.0)
    assert "V_d 40" in mismatch(g, 1.6727, 40.0)
