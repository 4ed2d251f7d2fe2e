"""Nominal f-numbers: within 5 % of the lens's widest, the lens is used wide open with
a notice; beyond, the refusal stands (the API, and the command line's one-line notice)."""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest

from povlens.cli import show_warnings_once
from povlens.errors import NominalFNumberWarning, ParameterError
from povlens.lens.paraxial import NOMINAL_F_NUMBER_TOLERANCE, paraxial_data, stopped_down
from povlens.lens.prescription import read_lens

from conftest import ROOT


@pytest.fixture(scope="module")
def dgauss():
    lens = read_lens("dgauss.50mm")
    return lens, paraxial_data(lens).f_number  # wide open: F/2.0302


def test_the_bundled_f2_double_gauss_opens_to_f2_03(dgauss):
    assert dgauss[1] == pytest.approx(2.0302, abs=1e-4)


def test_f2_on_the_f2_03_lens_renders_wide_open_with_a_notice(dgauss):
    lens, widest = dgauss
    with pytest.warns(NominalFNumberWarning, match=r"f_number=2: .*opens only to F/2\.03"):
        stopped = stopped_down(lens, f_number=2.0)
    np.testing.assert_array_equal(stopped.aperture_diameter_mm, lens.aperture_diameter_mm)
    assert paraxial_data(stopped).f_number == widest


@pytest.mark.parametrize("side, factor", [("inside", 1 + 1e-6), ("outside", 1 - 1e-6)])
def test_both_sides_of_the_5_percent_boundary(dgauss, side, factor):
    lens, widest = dgauss
    f_number = widest * (1 - NOMINAL_F_NUMBER_TOLERANCE) * factor
    if side == "inside":
        with pytest.warns(NominalFNumberWarning):
            stopped = stopped_down(lens, f_number=f_number)
        assert paraxial_data(stopped).f_number == pytest.approx(widest, rel=1e-12)
    else:
        with pytest.raises(ParameterError, match=r"opens only to F/2\.03") as e:
            stopped_down(lens, f_number=f_number)
        assert e.value.parameter == "f_number" and "f_number=2.04" in e.value.hint


@pytest.mark.parametrize("f_number", [2.0302, 2.1, 8.0])
def test_f_numbers_the_lens_reaches_give_no_notice(dgauss, f_number):
    lens, widest = dgauss
    f_number = max(f_number, widest)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        stopped = stopped_down(lens, f_number=f_number)
    assert paraxial_data(stopped).f_number == pytest.approx(f_number, rel=1e-12)


def test_stop_diameters_have_no_tolerance(dgauss):
    lens, _ = dgauss
    with pytest.raises(ParameterError, match="opens only to 17.1 mm"):
        stopped_down(lens, stop_diameter_mm=17.1 * 1.01)


def povlens(*args):
    return subprocess.run([sys.executable, "-m", "povlens", *args], capture_output=True,
                          text=True, cwd=ROOT, timeout=120)


def test_cli_inspect_f2_exits_0_and_prints_the_notice_once():
    r = povlens("inspect", "dgauss.50mm", "--f-number", "2")
    assert r.returncode == 0, r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith("povlens: warning: --f-number 2: ")
    assert "opens only to F/2.03" in lines[0] and "wide open" in lines[0]
    assert "2.0302" in r.stdout  # the f-number row of the table: wide open


def test_cli_refuses_beyond_5_percent():
    r = povlens("inspect", "dgauss.50mm", "--f-number", "1.9")
    assert r.returncode == 2
    assert "opens only to F/2.03" in r.stderr and "Traceback" not in r.stderr
    assert "warning" not in r.stderr


def test_cli_prints_each_distinct_warning_once(capsys):
    restore = show_warnings_once({"--f-number"})
    try:
        for text in ("f_number=2: a.dat opens only to F/2.03", "f_number=2: a.dat opens only to "
                     "F/2.03", "f_number=1.4: b.dat opens only to F/1.44"):
            warnings.warn(NominalFNumberWarning(text))
    finally:
        restore()
    err = capsys.readouterr().err.splitlines()
    assert err == ["povlens: warning: --f-number 2: a.dat opens only to F/2.03",
                   "povlens: warning: --f-number 1.4: b.dat opens only to F/1.44"]
