"""povlens.util.minimize.bounded_minimum is SciPy's bounded minimize_scalar, bit for bit
(the real-ray focus uses it instead of importing scipy.optimize: issue 14)."""

import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from povlens.lens.focus import rms_spot_mm, thick_lens_film_distance_mm
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import read_lens
from povlens.util.minimize import bounded_minimum


def _scipy(f, lo, hi, xatol, maxiter):
    with np.errstate(invalid="ignore"):                      # inf - inf in its parabola
        return minimize_scalar(f, bounds=(lo, hi), method="bounded",
                               options={"xatol": xatol, "maxiter": maxiter})


FUNCTIONS = [
    (lambda x: (x - 1.3) ** 2, 0.0, 4.0),
    (lambda x: math.cos(x), 0.0, 6.0),                       # minimum at pi, inside
    (lambda x: x, -2.0, 3.0),                                # minimum at the lower bound
    (lambda x: -x * x * x, -1.0, 2.0),                       # at the upper bound
    (lambda x: abs(x - 0.2) + 0.01 * math.sin(40 * x), -1.0, 1.0),   # kinked, wiggly
    (lambda x: math.inf if x < 0.5 else (x - 0.7) ** 2, 0.0, 1.0),   # inf on part
    (lambda x: 1.0, 0.0, 1.0),                               # flat
]


@pytest.mark.parametrize("k", range(len(FUNCTIONS)))
@pytest.mark.parametrize("xatol, maxiter", [(1e-5, 500), (1e-12, 300), (1e-3, 5)])
def test_same_point_value_and_evaluations_as_scipy(k, xatol, maxiter):
    f, lo, hi = FUNCTIONS[k]
    ours, theirs = bounded_minimum(f, lo, hi, xatol=xatol, maxiter=maxiter), \
        _scipy(f, lo, hi, xatol, maxiter)
    assert ours.x == float(theirs.x)                         # bit for bit
    assert ours.fun == float(theirs.fun) or (math.isnan(ours.fun) and math.isnan(theirs.fun))
    assert ours.nfev == theirs.nfev and ours.success == bool(theirs.success)


@pytest.mark.parametrize("lens_name, distance_mm", [("dgauss.50mm", 4000.0),
                                                    ("wide.22mm", 800.0),
                                                    ("telephoto.250mm", 20000.0),
                                                    ("fisheye.10mm", 300.0)])
def test_the_real_ray_focus_search_matches_scipy(lens_name, distance_mm):
    lens = read_lens(lens_name)
    p = paraxial_data(lens)
    start = thick_lens_film_distance_mm(lens, distance_mm, p)
    half = max(0.02 * abs(start), 0.01 * p.efl, 0.1)
    f = lambda t: rms_spot_mm(lens, t, distance_mm, p)[0]   # noqa: E731
    args = (max(start - half, 1e-6), start + half, 1e-9 * max(1.0, start), 300)
    assert bounded_minimum(f, args[0], args[1], xatol=args[2], maxiter=args[3]).x \
        == float(_scipy(f, *args).x)


def test_bad_bounds_are_refused():
    with pytest.raises(ValueError, match="finite"):
        bounded_minimum(lambda x: x, 0.0, np.inf)
    with pytest.raises(ValueError, match="lower bound"):
        bounded_minimum(lambda x: x, 1.0, 0.0)
