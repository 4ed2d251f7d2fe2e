"""Anamorphic lenses in the plan (povlens.plan.anamorphic): the desqueeze option on the
command line and in the API, the desqueezed film (its pitch against the squeeze, its
diagonal), the thin lens's two image distances against first-order optics, the POV-Ray
camera framed per meridian, and a lens without power in one meridian refused clearly."""

from __future__ import annotations

import argparse
import math
import warnings

import numpy as np
import pytest

from conftest import ROOT
from povlens.cli.convert_args import add_convert_arguments, keywords_from_args
from povlens.errors import OpticsError, ParameterError
from povlens.lens.film import Film
from povlens.lens.focus import focus
from povlens.lens.import_lentil import import_lentil
from povlens.lens.paraxial import anamorphic_data
from povlens.lens.prescription import parse_lens_text, write_lens
from povlens.plan.anamorphic import anamorphic_data_of, squeezed_film
from povlens.plan.options import ConvertOptions
from povlens.plan.plan_start import start_plan
from povlens.thinlens.model import fit_thin_lens

LENTIL = ROOT / "tests" / "data" / "lentil-lenses.json"
SCENE = str(ROOT / "scenes" / "bokeh.pov")


@pytest.fixture(scope="module")
def lens2004():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return import_lentil(LENTIL, "2004").lens


def test_desqueeze_option_on_the_command_line_and_in_the_api():
    p = argparse.ArgumentParser()
    add_convert_arguments(p)
    assert "--no-desqueeze" in p.format_help()
    on = ConvertOptions.of(SCENE, "l", "o", **keywords_from_args(
        p.parse_args([SCENE, "--lens", "l", "-o", "o"])))
    off = ConvertOptions.of(SCENE, "l", "o", **keywords_from_args(
        p.parse_args([SCENE, "--lens", "l", "-o", "o", "--no-desqueeze"])))
    assert on.film.desqueeze is True and off.film.desqueeze is False
    assert ConvertOptions.of(SCENE, "l", "o", desqueeze=False).film.desqueeze is False
    with pytest.raises(ParameterError, match="desqueeze"):
        ConvertOptions.of(SCENE, "l", "o", desqueeze="sometimes")


def test_desqueezed_film_keeps_the_diagonal_and_has_pitch_y_over_x_equal_to_the_squeeze(lens2004):
    data = anamorphic_data(lens2004)
    film = Film.from_diagonal(35.0, 640, 360)
    out, note = squeezed_film(film, data, True, False)
    assert math.isclose(math.hypot(out.width_mm, out.height_mm), 35.0, rel_tol=1e-12)
    pitch_x, pitch_y = out.width_mm / 640, out.height_mm / 360
    assert math.isclose(pitch_y / pitch_x, data.squeeze, rel_tol=1e-12)
    assert "desqueezed" in note and "no resampling" in note
    same, note = squeezed_film(film, data, False, False)
    assert same == film and "not desqueezed" in note
    given = Film(36.0, 24.0, 640, 360)
    kept, note = squeezed_film(given, data, True, True)
    assert kept == given and f"{data.squeeze * 1.5:.4g}" in note


def test_thin_lens_image_distances_per_meridian_follow_the_focal_lengths(lens2004):
    """On a small film (little distortion) the fitted image distances' ratio is the
    paraxial squeeze within 1 %, and the x pupil is the x meridian's entrance pupil."""
    data = anamorphic_data(lens2004)
    fd = focus(lens2004, 20_000.0).exact_film_distance_mm
    m = fit_thin_lens(lens2004, fd, 20_000.0, Film(3.0, 2.0, 30, 20))
    assert m.anamorphic
    vx, vy = m.image_distances_mm
    assert abs((vy / vx) / data.squeeze - 1) < 0.01
    assert math.isclose(m.pupil_diameter_x_mm, data.efl_x_mm / data.f_number_x, rel_tol=1e-9)
    # the projection uses both: a direction at tan 0.01 in x and in y
    f = m.image_of_direction(np.array([[0.01, 0.01, 1.0]]))[0]
    assert np.allclose(f, [-0.01 * vx, -0.01 * vy])
    assert np.allclose(m.tan_of_film(f[None]), [[0.01, 0.01]])


def test_start_plan_frames_the_views_per_meridian(lens2004, tmp_path):
    lens_file = tmp_path / "a.dat"
    write_lens(lens2004, lens_file)
    st = start_plan(ConvertOptions.of(SCENE, str(lens_file), str(tmp_path / "o"), focus=5.0,
                                      width=96, height=72, method="mesh", film_diagonal_mm=10))
    vx, vy = st.thin_lens.image_distances_mm
    cam = st.povray_camera
    assert math.isclose(np.linalg.norm(cam.right), st.film.width_mm / vx, rel_tol=1e-12)
    assert math.isclose(np.linalg.norm(cam.up), st.film.height_mm / vy, rel_tol=1e-12)
    # desqueezed: the view's right/up are the image's proportions (square pixels shown) up
    # to the fitted image distances' distortion (1 % on a 10 mm film; 3.7 % on 35 mm)
    assert abs(np.linalg.norm(cam.right) / np.linalg.norm(cam.up) / (96 / 72) - 1) < 0.01
    assert st.anamorphic["desqueeze"] is True
    assert math.isclose(st.anamorphic["film_pixel_aspect"], st.anamorphic["squeeze"],
                        rel_tol=1e-9)


def test_a_lens_without_power_in_one_meridian_is_refused_with_a_reason():
    # a lone plano-cylinder curving in x only: no power in the y-z plane
    lens = parse_lens_text("0 5 1.5 20 0 #!toric rx=50\n0 40 1 20 0\n", "cyl.dat")
    assert lens.is_anamorphic
    with pytest.raises(OpticsError, match="no power in its y-z plane"):
        anamorphic_data_of(lens)
