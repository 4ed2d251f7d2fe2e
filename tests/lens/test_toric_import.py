"""Importing anamorphic designs from Zemax ``TOROIDAL`` surfaces: a real Thorlabs
cylindrical lens (tests/data/zmx/README.md) and hand-made files, each checked per
meridian against a y-nu trace of the file itself (``import_reference``); refusals."""
import math
import warnings

import numpy as np
import pytest

from conftest import ROOT
from import_reference import has_power, reference, zmx_system

from povlens.errors import LensClipWarning, LensFileError
from povlens.lens.import_common import LensImportWarning
from povlens.lens.import_zemax import import_zmx
from povlens.lens.paraxial import anamorphic_data, paraxial_data
from povlens.lens.prescription import read_lens

ZMX = ROOT / "tests" / "data" / "zmx"
LJ1598 = ZMX / "thorlabs_lj1598l1.zmx"
KEYS = ("efl", "f_number", "entrance_pupil_position", "exit_pupil_position")


def quiet(path, glasses=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LensClipWarning)
        warnings.simplefilter("ignore", LensImportWarning)
        return import_zmx(path, glasses)


def test_thorlabs_cylindrical_lens_is_a_cylinder_curving_in_y(tmp_path):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        imported = import_zmx(LJ1598)
    said = [str(w.message) for w in caught]
    assert any("no power in x (afocal in x)" in m for m in said), said
    assert any("a rectangular aperture" in m for m in said), said
    back = imported.write(tmp_path / "lj1598.dat")
    text = (tmp_path / "lj1598.dat").read_text()
    assert "#!toric rx=0" in text and "#!glass SCHOTT:N-BK7" in text
    lens = read_lens(tmp_path / "lj1598.dat")
    assert lens == back and lens.is_anamorphic
    face = int(np.flatnonzero(lens.radius_mm != 0)[0])
    assert lens.radius_mm[face] == pytest.approx(1 / 0.4950495049504951)
    assert lens.radius_x_mm[face] == 0.0
    n_bk7 = float(lens.index_after[face])
    assert n_bk7 == pytest.approx(1.5168, abs=1e-6)       # SCHOTT's formula at the d line
    # y: the file's own trace; x: no power at all
    want = reference(*zmx_system(LJ1598, {"N-BK7": n_bk7}, meridian="y"))
    got = paraxial_data(lens, "y")
    for key in KEYS:
        assert getattr(got, key) == pytest.approx(want[key], rel=1e-9, abs=1e-12), key
    assert got.efl == pytest.approx(3.9, abs=0.01)        # Thorlabs' catalogue: f = 3.9 mm
    assert not has_power(zmx_system(LJ1598, {"N-BK7": n_bk7}, meridian="x")[0])
    a = anamorphic_data(lens)
    assert a.afocal == "x" and a.efl_x_mm == math.inf and a.squeeze == 0.0


TOROIDAL_FILE = """\
VERS 120928 0 30221
MODE SEQ
NAME hand-made toroidal doublet
UNIT {unit}
SURF 0
  TYPE STANDARD
  CURV 0.0 0 0 0 0 ""
  DISZ INFINITY
  DIAM 0 0 0 0 1 ""
SURF 1
  TYPE TOROIDAL
  CURV {c1} 0 0 0 0 ""
  PARM 0 0
  PARM 1 {rot1}
  PARM 3 {a4}
  CONI {k}
  DISZ {t1}
  GLAS N-BK7 0 0 1.5168 64.17
  DIAM {semi} 1 0 0 1 ""
SURF 2
  TYPE TOROIDAL
  CURV {c2} 0 0 0 0 ""
  PARM 1 {rot2}
  XDAT 1 0 0 0 1 0 0 ""
  XDAT 2 {norm} 0 0 1 0 0 ""
  {extra}
  DISZ {t2}
  DIAM {semi} 1 0 0 1 ""
SURF 3
  STOP
  TYPE STANDARD
  CURV 0.0 0 0 0 0 ""
  DISZ {t3}
  DIAM {stop} 1 0 0 1 ""
SURF 4
  TYPE STANDARD
  CURV 0.0 0 0 0 0 ""
  DISZ 0
  DIAM 0 0 0 0 1 ""
"""


def write_toroidal(tmp_path, unit="CM", extra="", **kw):
    """The hand-made file in lens units of ``unit`` (CM: 10 mm), values in mm given."""
    k = {"MM": 1.0, "CM": 10.0}[unit]
    v = dict(c1=1 / 60.0, rot1=-40.0, a4=-2e-6, k=-0.5, t1=6.0, c2=-1 / 200.0, rot2=80.0,
             t2=3.0, t3=50.0, semi=9.0, stop=6.0, norm=100.0)
    v.update(kw)
    lengths = {"rot1", "rot2", "t1", "t2", "t3", "semi", "stop", "norm"}
    shown = {n: (x / k if n in lengths else x * k if n in ("c1", "c2") else
                 x * k ** 3 if n == "a4" else x) for n, x in v.items()}
    p = tmp_path / "toroidal.zmx"
    p.write_text(TOROIDAL_FILE.format(unit=unit, extra=extra, **shown))
    return p


def test_a_toroid_with_an_aspheric_profile_imports_in_both_meridians(tmp_path):
    """Surface 1: y-z radius 60 mm (conic -0.5, a y^4 term), radius of rotation -40 mm;
    surface 2: y-z radius -200, x-z 80: in centimetres, converted (PARM 1 x 10, the y^4
    coefficient / 10^3); each meridian's first-order data as the file's own trace."""
    path = write_toroidal(tmp_path)
    imported = quiet(path)
    lens = imported.write(tmp_path / "toroidal.dat")
    assert lens.radius_mm[:2] == pytest.approx([60.0, -200.0])
    assert lens.radius_x_mm[:2] == pytest.approx([-40.0, 80.0])
    assert lens.asphere[0, 0] == pytest.approx(-0.5)
    assert lens.asphere[0, 2] == pytest.approx(-2e-6)       # the y^4 term, in mm^-3
    assert not np.any(lens.asphere[1])
    for m in ("y", "x"):
        want = reference(*zmx_system(path, meridian=m))
        got = paraxial_data(lens, m)
        for key in KEYS:
            assert getattr(got, key) == pytest.approx(want[key], rel=1e-9, abs=1e-12), (m, key)
    assert anamorphic_data(lens).squeeze == pytest.approx(
        reference(*zmx_system(path, meridian="y"))["efl"]
        / reference(*zmx_system(path, meridian="x"))["efl"], rel=1e-12)


@pytest.mark.parametrize("extra,match", [
    ("XDAT 3 1.5E-3 0 0 1 0 0 \"\"", r"surface 2 \(line \d+\): a toroidal surface with "
                                     r"Zernike terms \(XDAT 3"),
    ("PARM 9 1e-9", r"surface 2 \(line \d+\): a toroidal surface with parameters beyond "
                    r"PARM 8 \(PARM 9"),
])
def test_toroidal_terms_povlens_cannot_hold_are_refused_naming_the_surface(tmp_path, extra,
                                                                          match):
    with pytest.raises(LensFileError, match=match) as e:
        import_zmx(write_toroidal(tmp_path, unit="MM", extra=extra))
    assert "toroidal.zmx" in str(e.value)


def test_a_toroid_whose_radius_of_rotation_equals_its_radius_with_a_conic_is_refused(
        tmp_path):
    """Equal radii with an aspheric profile is not the rotationally symmetric asphere a
    lens file's row would otherwise mean; refused rather than guessed."""
    path = write_toroidal(tmp_path, unit="MM", rot1=60.0)
    with pytest.raises(LensFileError, match=r"surface 1 \(line \d+\): its x-z radius "
                                            r"equals its y-z radius \(60 mm\)"):
        import_zmx(path)


def test_a_toroid_with_equal_radii_and_no_terms_is_a_sphere(tmp_path):
    path = write_toroidal(tmp_path, unit="MM", rot1=60.0, k=0.0, a4=0.0)
    lens = quiet(path).lens
    assert lens.radius_x_mm[0] == lens.radius_mm[0] == pytest.approx(60.0)
    assert lens.is_anamorphic                               # surface 2 still is
    sphere_only = quiet(write_toroidal(tmp_path, unit="MM", rot1=60.0, k=0.0, a4=0.0,
                                       rot2=-200.0)).lens
    assert not sphere_only.is_anamorphic and sphere_only.radius_x_mm is None


def test_inspect_shows_toric_rows_and_both_meridians(tmp_path):
    from povlens.cli.inspect_cmd import inspect_dict
    lens = quiet(write_toroidal(tmp_path)).lens
    d = inspect_dict(lens)
    assert [r["kind"] for r in d["surface_rows"]][:3] == ["toroid", "toroid", "aperture"]
    assert d["surface_rows"][0]["radius_x"] == pytest.approx(-40.0)
    a = d["anamorphic"]
    assert a["efl_x_mm"] == pytest.approx(paraxial_data(lens, "x").efl)
    assert a["efl_y_mm"] == pytest.approx(d["efl"]) and d["meridian"] == "y"
    assert any(n.startswith("anamorphic: squeeze EFL_y / EFL_x = ") for n in d["notes"])
    cylinder = quiet(LJ1598).lens                  # power in y only: afocal in x
    d = inspect_dict(cylinder)
    assert d["anamorphic"]["efl_x_mm"] is None and d["anamorphic"]["afocal"] == "x"
    assert any("afocal in x" in n for n in d["notes"])


def test_scaling_an_anamorphic_design_scales_both_sections(tmp_path):
    """--efl scales the primary meridian's focal length (y; x for a lens without power
    in y); the x-z radii scale with everything else, so the squeeze stays."""
    from povlens.lens.import_lentil import import_lentil
    db = ROOT / "tests" / "data" / "lentil-lenses.json"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        schneider, test_lens = import_lentil(db, "2004"), import_lentil(db, "9991")
    scaled = schneider.scaled_to_efl(50.0)
    back = scaled.write(tmp_path / "s.dat")
    a0, a1 = anamorphic_data(schneider.lens), anamorphic_data(back)
    assert a1.efl_y_mm == pytest.approx(50.0, rel=1e-12)
    assert a1.squeeze == pytest.approx(a0.squeeze, rel=1e-12)
    k = 50.0 / a0.efl_y_mm
    assert back.radius_x_mm == pytest.approx(schneider.lens.radius_x_mm * k, rel=1e-15)
    x_only = test_lens.scaled_to_efl(50.0).lens
    assert anamorphic_data(x_only).efl_x_mm == pytest.approx(50.0, rel=1e-12)
