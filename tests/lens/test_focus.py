import math

import pytest

from povlens.errors import OpticsError
from povlens.lens.focus import (closest_focus_distance_mm, exact_film_distance_mm, focus, rms_spot_mm,
                           thick_lens_film_distance_mm)
from povlens.lens.prescription import read_lens

from conftest import LENS_DIR

# realistic-camera.md §8.2: film @ 10 m, film @ 1 m
THICK = {
    "dgauss.50mm.dat": (36.3619, 38.918),
    "wide.22mm.dat": (14.3670, 14.831),
    "fisheye.10mm.dat": (23.1700, 23.265),
    "singlet.pcx.25mm.dat": (21.5406, 22.158),
    "cooke.triplet.50mm.dat": (42.6890, 45.218),
    "tessar.50mm.dat": (42.9757, 45.507),
}


@pytest.mark.parametrize("name", sorted(THICK))
def test_thick_lens_film_distance_matches_pbrt(name):
    lens = read_lens(LENS_DIR / name)
    at10, at1 = THICK[name]
    # pbrt finds its cardinal points with a ray 35 um off axis, not paraxially; for the
    # fisheye that shifts its values by 0.5 um, hence 1e-3 mm rather than 1e-4.
    assert thick_lens_film_distance_mm(lens, 10000.0) == pytest.approx(at10, abs=1e-3)
    assert thick_lens_film_distance_mm(lens, 1000.0) == pytest.approx(at1, abs=1e-3)


def test_dgauss_other_distances():
    lens = read_lens(LENS_DIR / "dgauss.50mm.dat")
    for d, film in ((500, 42.4718), (2000, 37.4382), (5000, 36.6230), (math.inf, 36.1059)):
        assert thick_lens_film_distance_mm(lens, d) == pytest.approx(film, abs=1e-4)


def test_too_close_names_the_closest_distance():
    lens = read_lens(LENS_DIR / "telephoto.250mm.dat")
    closest = closest_focus_distance_mm(lens)
    assert 1000 < closest < 1100
    with pytest.raises(OpticsError) as e:
        thick_lens_film_distance_mm(lens, 1000.0)
    assert f"{closest:.6g}" in str(e.value)
    # just beyond the closest distance works
    assert math.isfinite(thick_lens_film_distance_mm(lens, closest * 1.0001))


def test_exact_focus_is_a_minimum_of_the_rms_spot():
    lens = read_lens(LENS_DIR / "dgauss.50mm.dat")
    film, spot = exact_film_distance_mm(lens, 1000.0)
    for delta in (-0.01, 0.01):
        assert rms_spot_mm(lens, film + delta, 1000.0)[0] > spot
    # real and paraxial focus differ by tens of microns, not millimetres
    assert abs(film - 38.918) < 0.1


def test_exact_focus_of_a_strongly_aberrated_singlet():
    # f/1 plano-convex: spherical aberration pulls the best focus well inside the paraxial one
    lens = read_lens(LENS_DIR / "singlet.pcx.25mm.dat")
    r = focus(lens, math.inf)
    assert r.exact_film_distance_mm < r.thick_lens_film_distance_mm - 1.0
    assert r.exact_rms_spot_mm < r.thick_lens_rms_spot_mm


# --- far focus: an object at infinity is a collimated beam, a far one no large number --

FAR_MM = [1e6, 1e9, 1e10, 1e13, 1e17, 1e300]      # 1 km ... beyond any scene


@pytest.mark.parametrize("name", ["dgauss.50mm", "tessar.50mm", "telephoto.250mm"])
def test_far_focus_converges_to_the_focus_at_infinity(name):
    """The real-ray spot and film distance at 1 km ... 1e300 mm approach infinity's
    smoothly (within 1 % of the spot from 1e6 mm on), where the object at the origin of
    a huge number lost the rays' slopes to rounding (12.5 um at 1e4 m, 3.8 mm at 1e7 m)."""
    lens = read_lens(LENS_DIR / f"{name}.dat")
    at_inf = focus(lens, math.inf)
    assert math.isfinite(at_inf.exact_rms_spot_mm)
    for d in FAR_MM:
        r = focus(lens, d)
        assert r.exact_rms_spot_mm == pytest.approx(at_inf.exact_rms_spot_mm, rel=0.01), d
        newton = 2.0 * lens_efl(lens) ** 2 / d                # Newton: dz' = f^2 / z
        assert abs(r.thick_lens_film_distance_mm - at_inf.thick_lens_film_distance_mm) <= (
            newton + 1e-9), d
        assert abs(r.exact_film_distance_mm - at_inf.exact_film_distance_mm) <= (
            newton + 1e-6), d


def lens_efl(lens) -> float:
    from povlens.lens.paraxial import paraxial_data
    return paraxial_data(lens).efl


def test_the_bundle_started_near_the_lens_is_the_bundle_from_the_object():
    """At a near distance, where starting at the object is exact, the rays started in
    front of the lens (focus.axial_bundle) are the same lines: equal film distance and
    spot to 1e-9 mm."""
    import numpy as np
    from povlens.lens.focus import axial_bundle, pupil_disc_points
    from povlens.lens.paraxial import paraxial_data
    from povlens.lens.tracer import trace_from_scene
    lens = read_lens(LENS_DIR / "dgauss.50mm.dat")
    p = paraxial_data(lens)
    film_d, d = 37.0, 1500.0
    disc = pupil_disc_points(8) * (0.5 * p.entrance_pupil_diameter)
    origin, direction = axial_bundle(p, film_d, d, disc)
    ep_z = film_d + p.total_track - p.entrance_pupil_position
    obj = np.tile([0.0, 0.0, d], (len(disc), 1))
    old = trace_from_scene(lens, film_d, obj, np.column_stack([disc, np.full(len(disc), ep_z)])
                           - obj)
    new = trace_from_scene(lens, film_d, origin, direction)
    assert (old.passed == new.passed).all()

    def on_film(r):
        t = -r.origin_mm[:, 2] / r.direction[:, 2]
        return (r.origin_mm[:, :2] + t[:, None] * r.direction[:, :2])[r.passed]
    np.testing.assert_allclose(on_film(new), on_film(old), atol=1e-9)
