"""lentil's whole lens database (24 entries, tests/data/lentil-lenses.json; issue 26):
every entry imports and agrees with paraxial data computed here from the JSON
(``import_reference``, a y-nu trace sharing no code with povlens); the anamorphic ones
(``cyl-x``/``cyl-y`` rows: 2001-2004, 9991) in each meridian, a meridian without power
having an infinite focal length."""

import json
import math
import warnings

import pytest

from conftest import ROOT
from import_reference import has_power, lentil_system, reference

from povlens.errors import OpticsError
from povlens.lens.import_common import LensImportWarning
from povlens.lens.import_lentil import import_lentil
from povlens.lens.paraxial import anamorphic_data, paraxial_data, primary_meridian
from povlens.lens.prescription import read_lens

DATABASE = ROOT / "tests" / "data" / "lentil-lenses.json"
ENTRIES = json.load(open(DATABASE))
KEYS = ("efl", "f_number", "entrance_pupil_position", "exit_pupil_position")
ANAMORPHIC = ("2001", "2002", "2003", "2004", "9991")


def _geometries(lens_id):
    return {s.get("lens-geometry") for s in ENTRIES[lens_id]["optical-elements-patent"]}


def _check_meridian(lens, lens_id, meridian):
    surfaces, stop, stop_d = lentil_system(DATABASE, lens_id, meridian=meridian)
    if not has_power(surfaces):
        with pytest.raises(OpticsError, match=f"afocal in {meridian}"):
            paraxial_data(lens, meridian)
        assert getattr(anamorphic_data(lens), f"efl_{meridian}_mm") == math.inf
        return
    got = paraxial_data(lens, meridian)
    want = reference(surfaces, stop, stop_d)
    for key in KEYS:
        assert getattr(got, key) == pytest.approx(want[key], rel=1e-6, abs=1e-9), (meridian, key)


@pytest.mark.parametrize("lens_id", sorted(ENTRIES))
def test_every_entry_imports_as_its_paraxial_trace(tmp_path, lens_id):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        imported = import_lentil(DATABASE, lens_id)
    imported.write(tmp_path / f"{lens_id}.dat")
    lens = read_lens(tmp_path / f"{lens_id}.dat")
    assert lens.is_anamorphic == bool(_geometries(lens_id) & {"cyl-x", "cyl-y"})
    assert lens.is_anamorphic == (lens_id in ANAMORPHIC)
    for meridian in ("y", "x") if lens.is_anamorphic else ("y",):
        _check_meridian(lens, lens_id, meridian)


@pytest.mark.parametrize("lens_id", ANAMORPHIC)
def test_the_squeeze_is_the_ratio_of_the_meridians_focal_lengths(lens_id):
    """EFL_y / EFL_x from the two independent y-nu traces; 9991 (cylinders curving in x
    only) has no power in y: an infinite EFL_y and squeeze, not a NaN."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lens = import_lentil(DATABASE, lens_id).lens
    a = anamorphic_data(lens)
    efl = {}
    for m in ("x", "y"):
        surfaces, stop, stop_d = lentil_system(DATABASE, lens_id, meridian=m)
        efl[m] = reference(surfaces, stop, stop_d)["efl"] if has_power(surfaces) else math.inf
    assert a.efl_x_mm == pytest.approx(efl["x"], rel=1e-9)
    assert a.efl_y_mm == pytest.approx(efl["y"], rel=1e-9)
    want = efl["y"] / efl["x"] if math.isfinite(efl["y"]) else math.inf
    assert a.squeeze == pytest.approx(want, rel=1e-9)
    assert not any(isinstance(v, float) and math.isnan(v) for v in a.to_dict().values() if v)


def test_a_lens_without_power_in_y_loads_with_a_warning():
    with pytest.warns(LensImportWarning, match=r"no power in y \(afocal in y\)"):
        lens = import_lentil(DATABASE, "9991").lens
    a = anamorphic_data(lens)
    assert a.afocal == "y" and a.efl_y_mm == math.inf and a.squeeze == math.inf
    assert a.f_number_y == math.inf and math.isfinite(a.efl_x_mm) and a.efl_x_mm > 0
    assert primary_meridian(lens) == "x"          # its main first-order data are x's


def test_a_design_without_an_iris_takes_the_surface_limiting_the_axial_beam():
    """9994 ('simple'): no iris row; the stop is the surface that limits the axial beam,
    said in a warning (it was refused)."""
    with pytest.warns(Warning, match="no iris row: the surface that limits the axial beam"):
        lens = import_lentil(DATABASE, "9994").lens
    p = paraxial_data(lens)
    surfaces, stop, stop_d = lentil_system(DATABASE, "9994")
    assert p.stop_index == stop and p.stop_diameter == pytest.approx(stop_d)
