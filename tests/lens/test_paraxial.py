import math

import pytest

from povlens.errors import UsageError
from povlens.lens.paraxial import (image_of_object, lensmaker_focal_length_mm, paraxial_data,
                              stopped_down)
from povlens.lens.prescription import parse_lens_text, read_lens

from conftest import LENS_DIR

# realistic-camera.md §8.1: EFL, BFL, F/#, EP position, XP position (diameter)
REFERENCE = {
    "dgauss.50mm.dat": (50.3582, 36.1059, 2.030, 19.946, -17.771, 26.539),
    "wide.22mm.dat": (22.0235, 14.3183, 2.684, 12.089, -11.456, 9.604),
    "fisheye.10mm.dat": (9.9914, 23.1605, 3.947, 11.542, -4.744, 7.070),
    "telephoto.250mm.dat": (249.5666, 105.0704, 5.423, 15.287, -73.911, 33.001),
    "singlet.pcx.25mm.dat": (25.3980, 21.4758, 1.000, 0.000, -3.922, 25.400),
    "cooke.triplet.50mm.dat": (50.0212, 42.4363, 5.038, 12.123, -8.109, 10.033),
    "tessar.50mm.dat": (49.9612, 42.7235, 4.500, 8.235, -6.429, 10.923),
}


@pytest.mark.parametrize("name", sorted(REFERENCE))
def test_first_order_data_match_reference_values(name):
    efl, bfl, fno, ep, xp, xpd = REFERENCE[name]
    p = paraxial_data(read_lens(LENS_DIR / name))
    assert p.efl == pytest.approx(efl, abs=1e-4)
    assert p.bfl == pytest.approx(bfl, abs=1e-4)
    assert p.f_number == pytest.approx(fno, abs=1e-3)
    assert p.entrance_pupil_position == pytest.approx(ep, abs=1e-3)
    assert p.exit_pupil_position == pytest.approx(xp, abs=1e-3)
    assert p.exit_pupil_diameter == pytest.approx(xpd, abs=1e-3)


def test_dgauss_details():
    p = paraxial_data(read_lens(LENS_DIR / "dgauss.50mm.dat"))
    assert p.entrance_pupil_diameter == pytest.approx(24.8051, abs=1e-4)
    assert p.ffl == pytest.approx(27.1224, abs=1e-4)
    assert p.stop_index == 5 and p.stop_is_aperture
    assert p.total_track == pytest.approx(32.04, abs=1e-12)
    # H is 23.24 mm behind the front vertex (§9.1)
    assert p.principal_front == pytest.approx(23.2358, abs=1e-3)


def test_lensmaker_biconvex_singlet():
    f = lensmaker_focal_length_mm(80.0, -80.0, 5.0, 1.5168)
    assert f == pytest.approx(78.23235, abs=1e-5)
    lens = parse_lens_text("80 5 1.5168 30\n-80 0 1 30\n")
    assert paraxial_data(lens).efl == pytest.approx(f, rel=1e-12)


def test_lensmaker_plano_convex_singlet_of_100_mm():
    n = 1.5168
    r1 = (n - 1.0) * 100.0  # flat rear face: f = R1 / (n - 1), independent of thickness
    assert lensmaker_focal_length_mm(r1, 0.0, 4.0, n) == pytest.approx(100.0, abs=1e-12)
    lens = parse_lens_text(f"{r1!r} 4 {n} 25\n0 0 1 25\n")  # radius 0 touching glass: flat face
    p = paraxial_data(lens)
    assert p.efl == pytest.approx(100.0, abs=1e-9)
    assert p.bfl == pytest.approx(100.0 - 4.0 / n, abs=1e-9)


def test_without_aperture_row_the_limiting_surface_is_the_stop():
    lens = parse_lens_text("80 5 1.5168 10\n-80 0 1 30\n")
    p = paraxial_data(lens)
    assert p.stop_index == 0 and not p.stop_is_aperture
    assert p.entrance_pupil_diameter == pytest.approx(10.0)


def test_stopping_down_by_f_number_and_diameter():
    lens = read_lens(LENS_DIR / "dgauss.50mm.dat")
    p8 = paraxial_data(stopped_down(lens, f_number=8.0))
    assert p8.f_number == pytest.approx(8.0, rel=1e-12)
    ps = paraxial_data(stopped_down(lens, stop_diameter_mm=8.55))
    assert ps.entrance_pupil_diameter == pytest.approx(24.8051 / 2, abs=1e-4)
    with pytest.raises(UsageError, match="opens only to F/2.03"):
        stopped_down(lens, f_number=1.4)
    with pytest.raises(UsageError, match="opens only to 17.1 mm"):
        stopped_down(lens, stop_diameter_mm=20)


def test_finite_object_imaging_obeys_gauss():
    lens = read_lens(LENS_DIR / "dgauss.50mm.dat")
    p = paraxial_data(lens)
    d = 1000.0
    z, m = image_of_object(lens, d)
    u = d + p.principal_front                       # object distance from H
    v = z - p.principal_rear_from_rear_vertex       # image distance from H'
    assert 1 / u + 1 / v == pytest.approx(1 / p.efl, rel=1e-12)
    assert m == pytest.approx(-v / u, rel=1e-9)
    assert image_of_object(lens, math.inf)[0] == pytest.approx(p.bfl)
