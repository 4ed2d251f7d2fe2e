"""Even aspheres from lentil and Zemax (issue 26 item 1), and through the pipeline: the
imported coefficients, EFLs against independent y-nu traces of the sources (base
curvature, plus 2 a2), the pupil table's file, and one tiny render."""

import math
import warnings

import numpy as np
import pytest

from conftest import ROOT
from import_reference import lentil_system, reference

from povlens.cli import main
from povlens.lens.asphere import aspheric_rows
from povlens.lens.import_lentil import import_lentil
from povlens.lens.import_zemax import import_zmx
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import read_lens
from povlens.pupil.build import build_pupil_table
from povlens.pupil.table import PupilTable
from povlens.util.images import read_image

LENTIL = ROOT / "tests" / "data" / "lentil-lenses.json"
ZMX = ROOT / "tests" / "data" / "zmx"
SINGLET = (ZMX / "singlet-pcx-25mm.zmx").read_text()


def _quiet(fn, *args):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*args)


def test_lentil_0014_imports_its_four_aspheres(tmp_path):
    """lentil's production fisheye: rows 6, 7, 9, 10 carry [A4, A6, A8, A10] as stated,
    conic 0; its EFL is the y-nu trace of the JSON's base curvatures."""
    imported = _quiet(import_lentil, LENTIL, "0014")
    lens = _quiet(imported.write, tmp_path / "0014.dat")       # written and read back equal
    assert np.flatnonzero(aspheric_rows(lens)).tolist() == [6, 7, 9, 10]
    assert lens.asphere[9].tolist() == [0, 0, 0.00039901, -1.4077e-05, 2.7313e-07,
                                        -2.6707e-09, 0, 0, 0]
    want = reference(*lentil_system(LENTIL, "0014"))
    assert paraxial_data(lens).efl == pytest.approx(want["efl"], rel=1e-12)
    assert "#!asphere k=0 a4=-1.5313" in (tmp_path / "0014.dat").read_text()
    scaled = imported.scaled_to_efl(50.0).lens            # a_2i scale as length^(1 - 2i)
    k = 50.0 / paraxial_data(lens).efl
    assert scaled.asphere[9, 2] == pytest.approx(lens.asphere[9, 2] * k ** -3, rel=1e-14)
    assert paraxial_data(scaled).efl == pytest.approx(50.0, rel=1e-12)


def _thick_lens_efl(c1, c2, t, n):
    power = (n - 1) * (c1 - c2) + (n - 1) ** 2 * t * c1 * c2 / n
    return 1 / power


@pytest.mark.parametrize("unit,mm", [("MM", 1.0), ("CM", 10.0)])
def test_zemax_evenasph_and_its_r2_term(tmp_path, unit, mm):
    """The flat back of the singlet made an EVENASPH with PARM 1 (r^2: paraxial curvature
    2 a2) and PARM 2 (r^4); in CM the terms are converted to mm (a_2i x 10^(1 - 2i))."""
    text = SINGLET.replace("SURF 2\n  TYPE STANDARD", "SURF 2\n  TYPE EVENASPH\n"
                           "  PARM 1 -0.004\n  PARM 2 2e-6\n  PARM 3 0", 1)
    text = text.replace("UNIT MM", f"UNIT {unit}", 1)
    p = tmp_path / "asph.zmx"
    p.write_text(text)
    lens = _quiet(import_zmx, p).lens
    row = np.flatnonzero(aspheric_rows(lens))
    assert row.size == 1
    a = lens.asphere[row[0]]
    assert a[1] == pytest.approx(-0.004 / mm, rel=1e-15)
    assert a[2] == pytest.approx(2e-6 / mm ** 3, rel=1e-15)
    c1 = 0.05017561465127948
    want = mm * _thick_lens_efl(c1, 2 * -0.004, 7.0, 1.78472)
    assert paraxial_data(lens).efl == pytest.approx(want, rel=1e-12)


def test_zemax_conic_on_a_standard_surface(tmp_path):
    p = tmp_path / "coni.zmx"
    p.write_text(SINGLET.replace("SURF 2\n  TYPE STANDARD\n  FIMP \n  CURV 0.0",
                                 "SURF 2\n  TYPE STANDARD\n  FIMP \n  CURV -0.01\n  CONI -2.5", 1))
    lens = _quiet(import_zmx, p).lens
    assert lens.asphere[-1].tolist() == [-2.5] + [0.0] * 8
    assert lens.radius_mm[-1] == pytest.approx(-100.0)


def test_public_evenasph_sample_us08427765():
    """A real EVENASPH file (surface 4: CONI 0.02, PARM 2 and 3); glasses given here, so
    the EFL is a y-nu trace of the file's CURV and DISZ with those indices."""
    n = {"J-LAK14": 1.697, "L-TIM28_MOLD": 1.689, "SF11": 1.785, "TAF3": 1.804,
         "TAFD30": 1.883}
    lens = _quiet(import_zmx, ZMX / "US08427765-1.ZMX", {k: (v, 40.0) for k, v in n.items()}).lens
    row = np.flatnonzero(aspheric_rows(lens))
    assert row.size == 1 and lens.asphere[row[0]][[0, 2, 3]].tolist() == [0.02, 1.10721e-5,
                                                                          1.837e-7]
    surfaces = [(7.766990291262135200e-2, 3.34, n["J-LAK14"]), (2.824858757062146900e-2, 0.29, 1),
                (7.230657989877079000e-2, 1.85, n["L-TIM28_MOLD"]),
                (1.117818019226470000e-1, 4.25, 1), (0.0, 5.4, 1),
                (-1.204819277108433600e-1, 0.65, n["SF11"]), (-1.866019779809665800e-2, 0.22, 1),
                (-2.668801708033093100e-2, 3.62, n["TAF3"]), (-8.501232678738417100e-2, 0.12, 1),
                (4.847309743092583300e-3, 3.5, n["TAFD30"]), (-3.770739064856711700e-2, 0, 1)]
    want = reference(surfaces, 4, 10.4)["efl"]
    assert paraxial_data(lens).efl == pytest.approx(want, rel=1e-12)


ASPHERIC_DGAUSS = (ROOT / "lenses" / "dgauss.50mm.dat").read_text().replace(
    "-39.73\t0\t1\t20", "-39.73\t0\t1\t20\t#!asphere k=-2 a4=4e-6 a6=-2e-9")


def test_pupil_table_file_keeps_the_asphere(tmp_path):
    p = tmp_path / "asph.dat"
    p.write_text(ASPHERIC_DGAUSS)
    lens = _quiet(read_lens, p)
    fd = paraxial_data(lens).bfl
    table = build_pupil_table(lens, fd, 21.6)
    back = PupilTable.load(table.save(tmp_path / "pupil.npz"))
    assert back.lens == lens and back.lens.sha256() == lens.sha256()
    assert np.array_equal(back.lens.asphere, lens.asphere)
    spherical = build_pupil_table(_quiet(read_lens, "dgauss.50mm"), fd, 21.6)
    assert (spherical.rho.shape != table.rho.shape
            or not np.allclose(spherical.rho, table.rho, rtol=1e-6))   # the asphere is seen


def test_render_through_an_aspheric_lens(tmp_path):
    p = tmp_path / "asph.dat"
    p.write_text(ASPHERIC_DGAUSS)
    out = tmp_path / "out"
    rc = main(["render", str(ROOT / "scenes" / "chart.pov"), "--lens", str(p), "--focus", "2",
               "--method", "mesh", "--samples", "4", "--width", "48", "--height", "36", "-q",
               "-o", str(out)])
    assert rc == 0
    img = read_image(out / "image.exr")
    assert img.shape[:2] == (36, 48) and np.all(np.isfinite(img)) and img.max() > 0
    assert math.isfinite(float(img.mean()))


def test_inspect_names_the_aspheric_rows(tmp_path):
    from povlens.cli.inspect_cmd import inspect_dict
    p = tmp_path / "asph.dat"
    p.write_text(ASPHERIC_DGAUSS)
    rows = inspect_dict(_quiet(read_lens, p))["surface_rows"]
    assert [r["kind"] for r in rows].count("asphere") == 1
    assert rows[-1]["asphere"]["k"] == -2 and rows[-1]["asphere"]["a6"] == -2e-9
