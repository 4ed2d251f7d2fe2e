import numpy as np
import pytest

from povlens.lens.film import Film
from povlens.lens.focus import thick_lens_film_distance_mm
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import parse_lens_text, read_lens
from povlens.lens.chief_ray import chief_rays
from povlens.pupil.build import build_pupil_table
from povlens.thinlens.model import fit_thin_lens
from povlens.thinlens.model_error import measure_model_error

from conftest import LENS_DIR

# realistic-camera.md §8.5: real chief-ray field angles, lens focused at infinity
CHIEF = {
    "dgauss.50mm.dat": ([10, 18, 21.63], [11.263, 19.862, 23.594]),
    "wide.22mm.dat": ([10, 18, 21.63], [24.596, 39.530, 44.434]),
    "telephoto.250mm.dat": ([10, 18, 21.63], [2.292, 4.112, 4.931]),
    "fisheye.10mm.dat": ([5, 8, 10, 12], [28.613, 45.661, 56.998, 68.423]),
    "singlet.pcx.25mm.dat": ([10, 18, 21.63], [21.643, 35.930, 41.268]),
    "cooke.triplet.50mm.dat": ([10, 18, 21.63], [11.304, 19.777, 23.348]),
    "tessar.50mm.dat": ([10, 18, 21.63], [11.311, 19.758, 23.300]),
}


@pytest.mark.parametrize("name", sorted(CHIEF))
def test_real_chief_ray_angles_match_reference(name):
    lens = read_lens(LENS_DIR / name)
    heights, angles = CHIEF[name]
    rays, found = chief_rays(lens, paraxial_data(lens).bfl, np.array(heights, float))
    assert found.all() and rays.passed.all()
    got = np.degrees(np.arctan2(-rays.direction[:, 0], rays.direction[:, 2]))
    np.testing.assert_allclose(got, angles, atol=2e-3)


def test_thin_lens_fit_of_dgauss():
    lens = read_lens(LENS_DIR / "dgauss.50mm.dat")
    film = Film.from_diagonal(35.0, 160, 120)
    f = thick_lens_film_distance_mm(lens, 10000.0)
    m = fit_thin_lens(lens, f, 10000.0, film)
    # entrance pupil 48.4554 mm in front of the film when focused at 10 m (§9.3)
    assert m.centre_z_mm == pytest.approx(48.4554, abs=1e-3)
    assert m.pupil_diameter_mm == pytest.approx(24.8051, abs=1e-4)
    # v_eff is close to the paraxial image distance (50.614 mm) but absorbs the distortion
    assert m.image_distance_mm == pytest.approx(50.614, abs=0.5)
    assert m.image_distance_mm != pytest.approx(50.614, abs=1e-3)


def test_model_error_is_small_for_a_slow_singlet_and_grows_with_aperture():
    # A weak, slow lens is nearly a thin lens; the same lens at f/1.4 is not.
    film = Film.from_diagonal(10.0, 80, 60)
    errs = []
    for stop in (2.0, 30.0):
        lens = parse_lens_text(f"0 1 0 {stop}\n200 3 1.5168 40\n-200 0 1 40\n")
        f = thick_lens_film_distance_mm(lens, 5000.0)
        m = fit_thin_lens(lens, f, 5000.0, film)
        e = measure_model_error(lens, f, m, film, [2500.0, 5000.0, 20000.0])
        assert np.isfinite(e.max_blur_size_error_px)
        errs.append(e)
    assert errs[0].max_distortion_px < 0.05
    assert errs[0].max_blur_size_error_px < 0.1
    assert errs[1].max_blur_size_error_px > errs[0].max_blur_size_error_px


def test_model_blur_diameter_formula():
    lens = read_lens(LENS_DIR / "dgauss.50mm.dat")
    film = Film.from_diagonal(35.0, 160, 120)
    f = thick_lens_film_distance_mm(lens, 2000.0)
    m = fit_thin_lens(lens, f, 2000.0, film)
    assert m.blur_diameter_mm(np.array([2000.0]))[0] == pytest.approx(0.0, abs=1e-12)
    d, s = 1000.0 - m.centre_z_mm, 2000.0 - m.centre_z_mm
    expect = m.pupil_diameter_mm * abs(d - s) / d * m.image_distance_mm / s
    assert m.blur_diameter_mm(np.array([1000.0]))[0] == pytest.approx(expect)


def test_vignetting_from_the_pupil_table_does_not_depend_on_the_stop_size():
    """The bundle of a tiny stop's pupil is found around the real chief ray, and the
    relative illumination comes from the exact pupil table: f/22 and f/64 agree."""
    from povlens.lens.paraxial import stopped_down
    from povlens.pupil.build import build_pupil_table
    film = Film.from_diagonal(35.0, 80, 60)
    ri = []
    for fno in (22.0, 64.0):
        lens = stopped_down(read_lens(LENS_DIR / "dgauss.50mm.dat"), f_number=fno)
        f = thick_lens_film_distance_mm(lens, 4000.0)
        m = fit_thin_lens(lens, f, 4000.0, film)
        t = build_pupil_table(lens, f, film.half_diagonal_mm)
        e = measure_model_error(lens, f, m, film, [2000.0, 8000.0], pupil_table=t)
        assert np.all(np.asarray(e.blur_real_px) > 0)    # every bundle found the pupil
        ri.append(e.min_relative_illumination)
    assert ri[0] == pytest.approx(ri[1], abs=0.02)
    assert 0.5 < ri[0] < 0.95  # natural (cos^4-like) fall-off at the corner remains


@pytest.mark.parametrize("lens_name", ["dgauss.50mm", "fisheye.10mm", "singlet.pcx.25mm",
                                       "wide.22mm"])
@pytest.mark.parametrize("with_table", [False, True])
def test_vectorized_model_error_equals_the_bundle_by_bundle_reference(lens_name, with_table):
    from povlens.thinlens.model_error import measure_model_error_reference
    lens = read_lens(lens_name)
    film = Film.from_diagonal(43.27, 96, 64)
    p = paraxial_data(lens)
    f = thick_lens_film_distance_mm(lens, 3000.0, p)
    m = fit_thin_lens(lens, f, 3000.0, film)
    table = build_pupil_table(lens, f, film.half_diagonal_mm) if with_table else None
    depths = [m.centre_z_mm + d for d in (300.0, 2000.0, 2900.0, 1e5, 1e7)]
    fast = measure_model_error(lens, f, m, film, depths, pupil_table=table)
    slow = measure_model_error_reference(lens, f, m, film, depths, pupil_table=table)
    fast, slow = fast.to_dict(), slow.to_dict()
    assert list(fast) == list(slow)
    for k in fast:
        np.testing.assert_allclose(np.asarray(fast[k], float), np.asarray(slow[k], float),
                                   rtol=1e-9, atol=1e-9, err_msg=k)
        assert np.all(np.isfinite(np.asarray(fast[k], float))), k


def test_model_error_searches_the_chief_rays_once_per_lens_and_focus(monkeypatch):
    """A second measurement (other depths) with the same lens object and film
    distance reuses the chief rays; another focus or another lens object (even an
    equal one) searches again, and the result equals a fresh measurement."""
    import povlens.thinlens.model_error as tl
    lens = read_lens("tessar.50mm")
    film = Film.from_diagonal(43.27, 96, 64)
    f = thick_lens_film_distance_mm(lens, 3000.0)
    m = fit_thin_lens(lens, f, 3000.0, film)
    calls = []
    real = tl.chief_rays
    monkeypatch.setattr(tl, "chief_rays", lambda *a: calls.append(a) or real(*a))
    tl.CHIEF_RAY_MEMO.clear()
    measure_model_error(lens, f, m, film, [m.centre_z_mm + 2000.0])
    again = measure_model_error(lens, f, m, film, [m.centre_z_mm + 500.0, 1e6])
    assert len(calls) == 1
    measure_model_error(lens, f + 0.01, m, film, [m.centre_z_mm + 500.0])
    assert len(calls) == 2
    copy = lens.replace()
    fresh = measure_model_error(copy, f, m, film, [m.centre_z_mm + 500.0, 1e6])
    assert len(calls) == 3
    assert again == fresh
