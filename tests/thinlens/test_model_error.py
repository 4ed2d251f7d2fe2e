"""The thin-lens model error as a typed record: its fields in plan.json's order, and
its dict form reading and writing back unchanged."""

import dataclasses
import json
import math
import pathlib

import numpy as np
import pytest

from povlens.lens.film import Film
from povlens.lens.focus import thick_lens_film_distance_mm
from povlens.lens.prescription import read_lens
from povlens.thinlens.model import fit_thin_lens
from povlens.thinlens.model_error import ModelError, measure_model_error

DATA = pathlib.Path(__file__).resolve().parents[1] / "plan" / "data"
#: plan.json's model_error as povlens wrote it before the record (a dict of 13 keys).
KEYS = ["object_z_mm", "film_height_mm", "max_distortion_px", "max_blur_size_error_px",
        "max_elongation", "min_relative_illumination", "max_vignetting_error",
        "distortion_px", "blur_real_px", "blur_model_px", "elongation",
        "relative_illumination", "blur_size_error_px"]


@pytest.fixture(scope="module")
def measured() -> ModelError:
    lens = read_lens("tessar.50mm")
    film = Film.from_diagonal(43.27, 48, 32)
    f = thick_lens_film_distance_mm(lens, 3000.0)
    m = fit_thin_lens(lens, f, 3000.0, film)
    return measure_model_error(lens, f, m, film, [m.centre_z_mm + 1000.0, 3000.0, 1e5],
                               n_field=4)


def test_the_record_has_plan_json_s_keys_in_order_with_lists_of_rows(measured):
    d = measured.to_dict()
    assert list(d) == KEYS == [f.name for f in dataclasses.fields(ModelError)]
    assert len(d["object_z_mm"]) == 3 and len(d["film_height_mm"]) == 4
    assert all(isinstance(v, float) for k in KEYS[2:7] for v in [d[k]])
    for k in KEYS[7:]:
        assert isinstance(d[k], list) and np.shape(d[k]) == (3, 4)
        assert np.asarray(getattr(measured, k)).shape == (3, 4)
    assert measured.max_distortion_px == max(max(r) for r in measured.distortion_px)
    assert measured.max_vignetting_error == 1.0 - measured.min_relative_illumination


def test_the_dict_form_reads_and_writes_back_unchanged(measured):
    text = json.dumps(measured.to_dict())
    again = ModelError.from_dict(json.loads(text))
    assert again == measured and json.dumps(again.to_dict()) == text
    with pytest.raises(dataclasses.FrozenInstanceError):
        again.max_elongation = 2.0
    broken = json.loads(text)
    del broken["max_elongation"]
    with pytest.raises(KeyError):
        ModelError.from_dict(broken)


@pytest.mark.parametrize("name", ["plan_v1_pinhole.json", "plan_v1_auto_focal_blur.json",
                                  "plan_v1_release_auto_focal_blur.json"])
def test_the_model_error_of_stored_plans_writes_back_key_for_key(name):
    stored = json.loads((DATA / name).read_text())["model_error"]
    e = ModelError.from_dict(stored)
    assert json.dumps(e.to_dict()) == json.dumps(stored)
    assert e.min_relative_illumination == stored["min_relative_illumination"]


def test_null_reads_as_nan():
    """plan.json writes NaN as null (the plan's writer turns NaN back into null)."""
    d = {k: 1.0 for k in KEYS}
    d["object_z_mm"], d["film_height_mm"] = [1.0], [0.0, 1.0]
    for k in KEYS[7:]:
        d[k] = [[1.0, None]]
    e = ModelError.from_dict(d)
    assert math.isnan(e.elongation[0][1]) and e.film_height_mm == (0.0, 1.0)


def test_far_depths_are_exact_and_infinity_is_their_limit():
    """Bundles from 1 km to 1e300 mm and from infinity (a collimated beam) start near
    the lens (rays_near_lens): the blur and distortion converge, nothing is NaN, and
    the vectorized measurement equals the one-bundle-at-a-time reference."""
    import math
    import numpy as np
    from povlens.lens.film import Film
    from povlens.lens.focus import exact_film_distance_mm
    from povlens.lens.prescription import read_lens
    from povlens.thinlens.model import fit_thin_lens
    from povlens.thinlens.model_error import (measure_model_error,
                                              measure_model_error_reference)
    lens = read_lens("dgauss.50mm")
    film_d, _ = exact_film_distance_mm(lens, math.inf)
    film = Film.from_diagonal(35.0, 64, 48)
    model = fit_thin_lens(lens, film_d, math.inf, film)
    depths = [1e6, 1e10, 1e14, 1e300, math.inf]
    e = measure_model_error(lens, film_d, model, film, depths, n_field=5)
    ref = measure_model_error_reference(lens, film_d, model, film, depths, n_field=5)
    for name in ("blur_real_px", "distortion_px"):
        a = np.asarray(getattr(e, name))
        assert np.isfinite(a).all(), name
        np.testing.assert_allclose(a[1:], np.broadcast_to(a[-1], a[1:].shape), atol=2e-5)
        np.testing.assert_allclose(a, np.asarray(getattr(ref, name)), atol=1e-12)
