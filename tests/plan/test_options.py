"""Every option declared once (povlens.plan.options): the declaration's own consistency,
its checks through the records, the API and the command line, and what is derived
from it (the argparse parser, the flag map, the plan's inputs).  No POV-Ray run: the
refused values never get that far."""

import argparse
import dataclasses
import math

import pytest

import povlens
from povlens.cli import main
from povlens.cli.convert_args import add_convert_arguments, keywords_from_args
from povlens.cli.flags import FLAG_OF
from povlens.errors import ParameterError
from povlens.plan.options import (RECORDS, ConvertOptions, DaskOptions, FIXED_SAMPLES,
                                  dask_options, options, stored_values)
from povlens.plan.schema import Inputs

from conftest import ROOT

SCENE = str(ROOT / "scenes" / "paper.pov")


def test_each_option_is_whole_and_unique():
    names, flags = set(), set()
    for group, f, spec in options():
        assert spec.help and not spec.help.endswith("."), f.name
        assert f.name not in names, f"{f.name} declared twice"
        names.add(f.name)
        if spec.flag is not None:
            assert spec.flag.startswith("--") and spec.flag not in flags, spec.flag
            flags.add(spec.flag)
            assert FLAG_OF[f.name] == spec.flag
        if spec.stored:
            assert f.name in {i.name for i in dataclasses.fields(Inputs)}, f.name
    for f, spec in dask_options():
        assert spec.flag not in flags and FLAG_OF[f.name] == spec.flag


def test_defaults_pass_their_own_checks():
    for record in RECORDS.values():
        assert record() == record()          # made, so every default was checked
    opts = ConvertOptions.of(SCENE, "dgauss.50mm", "out")
    assert opts.sampling.method == "auto" and opts.sampling.auto_samples
    assert opts.sampling.sample_count == FIXED_SAMPLES
    assert DaskOptions().scheduler is None


def test_replace_routes_each_name_to_its_record():
    opts = ConvertOptions.of(SCENE, "dgauss.50mm", "out", width=320, f_number=8)
    assert (opts.film.width, opts.aperture.f_number) == (320, 8.0)
    again = opts.replace(width=64, samples=4, clock=0.5, focus_from="look_at")
    assert (again.film.width, again.film.height) == (64, 480)
    assert again.sampling.samples == 4 and not again.sampling.auto_samples
    assert again.povray.clock == 0.5 and again.pose.focus_from == "look_at"
    assert opts.film.width == 320                         # frozen: a copy changed
    with pytest.raises(TypeError):
        opts.replace(colour="red")


def test_an_unknown_keyword_names_the_known_ones():
    with pytest.raises(ParameterError) as e:
        povlens.convert(SCENE, lens="dgauss.50mm", outdir="out", widht=320)
    assert e.value.parameter == "widht"
    assert "width" in e.value.hint and "f_number" in e.value.hint


#: (keyword, a value its check refuses, a word of the message)
REFUSED = [
    ("width", 0, "at least 1"),
    ("height", 2.5, "whole number"),
    ("samples", 0, "at least 1"),
    ("batch_size", -2, "at least 1"),
    ("f_number", -1.0, "positive"),
    ("stop_diameter_mm", math.nan, "finite"),
    ("film_diagonal_mm", 0.0, "positive"),
    ("film_size_mm", "36x24", "W,H"),
    ("shift_mm", (0.0, math.inf), "finite"),
    ("method", "fisheye", "unknown"),
    ("units", "furlong", "unknown"),
    ("ray_mesh", "voxel", "unknown"),
    ("tolerance_px", 0.0, "positive"),
    ("focus", -4.0, "positive distance"),
    ("focus_at", (-1, 3), "pixel"),
    ("sky", (0.0, 1.0), "three"),
    ("location", (0.0, math.nan, 1.0), "three"),
    ("clock", math.inf, "finite"),
    ("blade_curvature", math.nan, "finite"),
    ("jitter", "yes", "True or False"),
    ("library_paths", 3, "list of texts"),
]


@pytest.mark.parametrize("name, value, word", REFUSED, ids=[r[0] for r in REFUSED])
def test_a_refused_value_names_its_option_in_the_api(name, value, word):
    with pytest.raises(ParameterError) as e:
        povlens.convert(SCENE, lens="dgauss.50mm", outdir="out", **{name: value})
    assert e.value.parameter == name and word in str(e.value.message)


@pytest.mark.parametrize("argv, flag", [
    (["--width", "0"], "--width 0"), (["--samples", "0"], "--samples 0"),
    (["--tolerance", "0"], "--tolerance 0"), (["--focus", "-3"], "--focus -3"),
    (["--film-size", "36x24"], "--film-size"), (["--f-number", "-2"], "--f-number -2")])
def test_a_refused_value_names_its_flag_on_the_command_line(tmp_path, capsys, argv, flag):
    code = main(["convert", SCENE, "--lens", "dgauss.50mm", *argv, "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and flag in err and "Traceback" not in err, err
    assert not (tmp_path / "o").exists()            # refused before anything is written


def test_the_command_line_gives_the_api_the_declared_defaults():
    p = argparse.ArgumentParser()
    add_convert_arguments(p)
    args = p.parse_args([SCENE, "--lens", "dgauss.50mm", "-o", "out"])
    kw = keywords_from_args(args)
    assert ConvertOptions.of(SCENE, "dgauss.50mm", "out", **kw) == ConvertOptions.of(
        SCENE, "dgauss.50mm", "out")
    args = p.parse_args([SCENE, "--lens", "l", "-o", "o", "--no-jitter", "--thick-lens-focus",
                         "--library-path", "a", "--library-path", "b", "--sky", "<0,0,1>",
                         "--adaptive", "--dispersion", "--focus-at", "3,4"])
    opts = ConvertOptions.of(SCENE, "l", "o", **keywords_from_args(args))
    assert not opts.sampling.jitter and not opts.film.real_focus and opts.sampling.adaptive
    assert opts.povray.library_paths == ("a", "b") and opts.pose.sky == (0.0, 0.0, 1.0)
    assert opts.sampling.dispersion and opts.pose.focus_at == (3, 4)


def test_help_shows_the_declared_default():
    p = argparse.ArgumentParser()
    add_convert_arguments(p)
    text = p.format_help()
    assert "(default 640)" in text and "(default 35)" in text and "(default auto)" in text


def test_one_text_is_one_item():
    opts = ConvertOptions.of(SCENE, "l", "o", library_paths="inc", povray_options="+A0.3")
    assert opts.povray.library_paths == ("inc",) and opts.povray.povray_options == ("+A0.3",)


def test_the_plan_keeps_the_stored_options_as_given():
    opts = ConvertOptions.of(SCENE, "dgauss.50mm", "out", width=96, f_number=4, seed=3)
    kept = stored_values(opts)
    assert kept["width"] == 96 and kept["f_number"] == 4.0 and kept["seed"] == 3
    assert "tolerance_px" not in kept          # written only when auto decides
