"""Catalogue glasses named in lens files, Zemax files and lentil's database, and
--dispersion's n(lambda) from their formulas; values from the makers' data sheets."""

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from povlens.errors import LensFileError
from povlens.lens.dispersion import (LINE_C_NM, LINE_D_NM, LINE_F_NM, dispersion_model,
                                     disperses, has_abbe_numbers, lens_at_wavelength)
from povlens.lens.glass_catalog import GlassWarning
from povlens.lens.import_lentil import import_lentil
from povlens.lens.import_zemax import import_zmx
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import format_lens, parse_lens_text, read_lens

ROOT = Path(__file__).resolve().parents[2]
LENTIL = ROOT / "tests" / "data" / "lentil-lenses.json"
G_NM = 435.8343
# SCHOTT's N-BK7 data sheet: n at the g, F, d and C lines
NBK7_SHEET = {G_NM: 1.52668, LINE_F_NM: 1.52238, LINE_D_NM: 1.51680, LINE_C_NM: 1.51432}

# a biconvex N-BK7 singlet with a stop behind it; no Abbe column
SINGLET = """# test singlet
50.0   5.0  1.5168  20  #!glass N-BK7   # crown
-50.0  2.0  0       20
0      40   0       10
"""


def test_a_lens_file_names_its_glass_and_keeps_its_numbers():
    lens = parse_lens_text(SINGLET, "s.dat")
    assert lens.glass == ("SCHOTT:N-BK7", "", "")
    assert lens.index_after[0] == 1.5168 and lens.abbe_vd[0] == 0.0       # as stated
    # a reader of the numeric columns only (pbrt: '#' to the line's end is a comment)
    numbers = [[float(t) for t in ln.split("#")[0].split()] for ln in SINGLET.splitlines()]
    assert [r for r in numbers if r][0] == [50.0, 5.0, 1.5168, 20.0]
    back = parse_lens_text(format_lens(lens), "back.dat")
    assert back == lens and back.glass == lens.glass
    assert "\t#!glass SCHOTT:N-BK7" in format_lens(lens)
    assert lens.sub_lens(1).glass == ("", "")


def test_unknown_or_mismatched_glass_in_a_lens_file_warns_and_loads():
    with pytest.warns(GlassWarning, match=r"s.dat:2: row 0: glass 'N-BK77'.*N-BK7 \(SCHOTT\)"):
        lens = parse_lens_text(SINGLET.replace("N-BK7", "N-BK77"), "s.dat")
    assert lens.glass == () and lens.index_after[0] == 1.5168
    with pytest.warns(GlassWarning, match=r"states n_d 1.5168 \(catalogue 1.67270\)"):
        assert parse_lens_text(SINGLET.replace("N-BK7", "SF5"), "s.dat").glass == ()
    with pytest.warns(GlassWarning, match="medium after the surface is air"):
        parse_lens_text(SINGLET.replace("20  #!glass", "20  #").replace(
            "-50.0  2.0  0       20", "-50.0  2.0  0  20  #!glass SF5"), "s.dat")
    with pytest.raises(LensFileError, match="s.dat:2.*'#!glass' stands on a line of its own"):
        parse_lens_text("# x\n#!glass N-BK7\n" + SINGLET.split("\n", 1)[1], "s.dat")


def test_dispersion_follows_the_catalogue_formula_not_cauchy():
    lens = parse_lens_text(SINGLET, "s.dat")
    assert has_abbe_numbers(lens) and disperses(lens)          # no V_d column: the glass
    for lam, n in NBK7_SHEET.items():
        assert lens_at_wavelength(lens, lam).index_after[0] == pytest.approx(n, abs=6e-6)
    # Cauchy through the same n_d, V_d (by hand) misses the g line by ~5e-5: the
    # secondary spectrum only the formula has
    n_d, v_d = 1.5168, 64.17
    b = (n_d - 1) / v_d / (LINE_F_NM ** -2 - LINE_C_NM ** -2)
    cauchy_g = n_d + b * (G_NM ** -2 - LINE_D_NM ** -2)
    assert abs(cauchy_g - NBK7_SHEET[G_NM]) > 3e-5
    assert "catalogue formulas (secondary spectrum): row 0 SCHOTT:N-BK7" in dispersion_model(lens)
    cauchy = parse_lens_text(SINGLET.replace("#!glass N-BK7", "64.17"), "c.dat")
    assert dispersion_model(cauchy) == ("Cauchy n = A + B/lambda^2 through n_d and "
                                        "n_F - n_C = (n_d - 1)/V_d: row 0")


def test_the_plan_of_an_all_catalogue_lens_names_no_cauchy(tmp_path):
    """angenieux.100mm names a catalogue glass on every glass row: plan.json's
    dispersion model is the catalogue formulas only."""
    from conftest import ROOT
    from povlens.api import convert
    plan = convert(ROOT / "scenes" / "cards.pov", lens="angenieux.100mm",
                   outdir=tmp_path / "o", focus=2.1, width=48, height=36, method="mesh",
                   samples=4, dispersion=True)
    model = plan.dispersion["model"]
    assert model.startswith("catalogue formulas (secondary spectrum): row 0 SCHOTT:SF5")
    assert "Cauchy" not in model


def test_a_stated_index_keeps_its_value_and_takes_the_glass_dispersion():
    """lentil's SF5 is stated n_d 1.6751 (SCHOTT's: 1.6727): d line as stated, n_F - n_C
    the catalogue's, (1.6727 - 1) / 32.21 by SF5's data-sheet n_d and V_d."""
    text = SINGLET.replace("1.5168  20  #!glass N-BK7", "1.6751  20  32.3  #!glass SF5")
    lens = parse_lens_text(text, "sf5.dat")
    n = [lens_at_wavelength(lens, lam).index_after[0] for lam in (LINE_F_NM, LINE_D_NM, LINE_C_NM)]
    assert n[1] == pytest.approx(1.6751, abs=1e-12)
    assert n[0] - n[2] == pytest.approx(0.6727 / 32.21, rel=3e-4)


ZMX = """VERS 140101 00 00
MODE SEQ
NAME glass test
UNIT MM X W X CM MR CPMM
ENPD 10
SURF 0
  TYPE STANDARD
  CURV 0.0
  DISZ INFINITY
SURF 1
  STOP
  TYPE STANDARD
  CURV 0.0
  DISZ 2
  DIAM 5 0 0 0 1 ""
SURF 2
  TYPE STANDARD
  CURV 0.02
  DISZ 5
  GLAS {glass} 0 0 1.5 40 0 0 0 0 0 0
  DIAM 10 0 0 0 1 ""
SURF 3
  TYPE STANDARD
  CURV -0.02
  DISZ 40
  DIAM 10 0 0 0 1 ""
SURF 4
  TYPE STANDARD
  CURV 0.0
  DISZ 0
  DIAM 5 0 0 0 1 ""
"""


def test_zemax_catalogue_glass_without_index_imports_from_the_catalogue(tmp_path):
    p = tmp_path / "bk7.zmx"
    p.write_text(ZMX.format(glass="N-BK7"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        imported = import_zmx(p)
    lens = imported.lens
    row = int(np.flatnonzero(lens.index_after != 1.0)[0])
    assert lens.index_after[row] == pytest.approx(1.5168, abs=6e-5)     # SCHOTT's sheet
    assert lens.abbe_vd[row] == pytest.approx(64.17, abs=0.006)
    assert lens.glass[row] == "SCHOTT:N-BK7"
    out = tmp_path / "bk7.dat"
    assert imported.write(out).glass == lens.glass
    assert "#!glass SCHOTT:N-BK7" in out.read_text()
    # 1 / EFL = (n - 1)(2 / 50 mm) - (n - 1)^2 t / (n R^2), thick-lens formula by hand
    n = 1.5168
    efl = 1 / ((n - 1) * 2 / 50 - (n - 1) ** 2 * 5 / (n * 50 ** 2))
    assert paraxial_data(lens).efl == pytest.approx(efl, rel=1e-4)


def test_zemax_unknown_glass_names_the_closest(tmp_path):
    p = tmp_path / "bk77.zmx"
    p.write_text(ZMX.format(glass="N-BK77"))
    with pytest.raises(LensFileError) as e:
        import_zmx(p)
    assert "glass N-BK77 has no refractive index" in str(e.value)
    assert "N-BK7 (SCHOTT)" in e.value.hint and "'glasses'" in e.value.hint


def test_lentil_names_resolve_and_keep_the_stated_ior():
    """lentil 0001 (Angenieux 100 mm f/1.1): every glass row's material is a catalogue
    glass, and the EFL is the one of its stated iors (an independent y-nu trace of the
    JSON table, as tests/lens/import_reference.py does)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lens = import_lentil(LENTIL, "0001").lens
    table = json.loads(LENTIL.read_text())["0001"]["optical-elements-patent"]
    glass_rows = [r for r in table if r["material"] not in ("air", "iris")]
    assert [g for g in lens.glass if g] == [
        {"SF5": "SCHOTT:SF5", "BAF10": "HOYA:BAF10", "LAK9": "HIKARI:LAK9",
         "SF15": "SCHOTT:SF15", "SK16": "HIKARI:SK16"}[r["material"]] for r in glass_rows]
    assert [n for n in lens.index_after if n != 1.0] == [r["ior"] for r in glass_rows]
    # y-nu trace of the table (radii and thicknesses as stated; iris and air: n = 1)
    y, nu, n0 = 1.0, 0.0, 1.0
    for i, r in enumerate(table):
        n1 = r["ior"] if r["material"] not in ("air", "iris") and r["ior"] else 1.0
        c = 0.0 if r["material"] == "iris" or abs(r["radius"]) >= 9999 else 1 / r["radius"]
        nu -= y * c * (n1 - n0)
        if i < len(table) - 1:
            y += nu / n1 * r["thickness"]
        n0 = n1
    assert paraxial_data(lens).efl == pytest.approx(-1.0 / nu, rel=1e-9)


def test_written_lentil_file_reads_back_its_glasses(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        imported = import_lentil(LENTIL, "0001")
        back = imported.write(tmp_path / "a.dat")
        again = read_lens(tmp_path / "a.dat")
    assert back.glass == imported.lens.glass == again.glass
    n_f = lens_at_wavelength(again, LINE_F_NM).index_after
    n_c = lens_at_wavelength(again, LINE_C_NM).index_after
    sf5 = again.glass.index("SCHOTT:SF5")
    assert n_f[sf5] - n_c[sf5] == pytest.approx(0.6727 / 32.21, rel=3e-4)   # SF5's sheet


def test_zemax_stated_values_of_another_glass_keep_cauchy_with_a_warning(tmp_path):
    p = tmp_path / "sf5.zmx"
    p.write_text(ZMX.format(glass="N-BK7").replace("1.5 40", "1.6727 32.21"))
    with pytest.warns(Warning, match=r"glass N-BK7: the file states n_d 1.6727 \(catalogue "
                                     r"1.51680\).*not catalogue glass SCHOTT:N-BK7"):
        lens = import_zmx(p).lens
    row = int(np.flatnonzero(lens.index_after != 1.0)[0])
    assert lens.index_after[row] == 1.6727 and lens.glass == ()
    # stated values of the named glass (N-SF11 in the public singlet sample): kept
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        singlet = import_zmx(ROOT / "tests" / "data" / "zmx" / "singlet-pcx-25mm.zmx").lens
    assert "SCHOTT:N-SF11" in singlet.glass
