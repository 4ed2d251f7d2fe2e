"""Errors: the core names API parameters, the command line shows its options.

For each parameter whose message used to name a command-line option, the API raises
:class:`ParameterError` carrying the parameter (and no ``--`` in its text), and the
command line prints the option with exit code 2 and no traceback.
"""

import importlib
import os
import shutil
import subprocess
import sys

import pytest

from conftest import ROOT

from povlens.cli import DEBUG_ENV_VAR, build_parser, main, option_strings
from povlens.cli.flags import FLAG_OF, error_text, with_flags
from povlens.errors import OpticsError, ParameterError, PovrayError, UsageError
from povlens.lens.film import Film, parse_film_size
from povlens.lens.focus import focus, thick_lens_film_distance_mm, to_mm
from povlens.lens.paraxial import stopped_down
from povlens.lens.prescription import read_lens
from povlens.plan.convert import ConvertOptions, convert, make_plan
from povlens.pov.sdl import SceneCameraError, parse_scene_camera
from povlens.pupil.build import build_pupil_table, sampling_plane_z_mm
from povlens.rendering.views import render_view

SCENE = str(ROOT / "scenes" / "paper.pov")
LENS = read_lens("dgauss.50mm")
FILM_MM = thick_lens_film_distance_mm(LENS, 10_000.0)

#: A command that has the option, its arguments, and the function its parser runs.
CONVERT = ("render_cmd", "run_convert",
           ["convert", SCENE, "--lens", "dgauss.50mm", "--focus", "4", "-o", "out"])
FOCUS = ("focus_cmd", "run", ["focus", "dgauss.50mm", "--distance", "1"])
PUPIL = ("pupil_cmd", "run", ["pupil", "dgauss.50mm", "--focus", "1m"])
VIEW = ("render_cmd", "run_view", ["render-view", "out", "--view", "pinhole"])


def options(tmp_path, **kw) -> ConvertOptions:
    kw = {"method": "pinhole", "focus": 4.0, **kw}
    return ConvertOptions.of(scene=SCENE, lens="dgauss.50mm", outdir=str(tmp_path / "out"),
                          width=16, height=12, **kw)


# (id, API call raising the error, parameter, command that has the option, option)
CASES = [
    ("f_number-negative", lambda t: stopped_down(LENS, f_number=-1.0), "f_number",
     CONVERT, "--f-number"),
    ("f_number-too-wide", lambda t: stopped_down(LENS, f_number=1.2), "f_number",
     CONVERT, "--f-number"),
    ("f_number-and-stop", lambda t: stopped_down(LENS, f_number=4.0, stop_diameter_mm=5.0),
     "f_number", CONVERT, "--f-number"),
    ("stop_diameter-negative", lambda t: stopped_down(LENS, stop_diameter_mm=-1.0),
     "stop_diameter_mm", CONVERT, "--stop-diameter"),
    ("stop_diameter-too-wide", lambda t: stopped_down(LENS, stop_diameter_mm=100.0),
     "stop_diameter_mm", CONVERT, "--stop-diameter"),
    ("film-diagonal", lambda t: Film.from_diagonal(-1.0, 16, 12), "diagonal_mm",
     CONVERT, "--film-diagonal"),
    ("film-width", lambda t: Film.from_diagonal(35.0, 0, 12), "width_px", CONVERT, "--width"),
    ("film-height", lambda t: Film.from_diagonal(35.0, 16, 0), "height_px", CONVERT,
     "--height"),
    ("film-size-text", lambda t: parse_film_size("36,x"), "film_size_mm", CONVERT,
     "--film-size"),
    ("film-size-negative", lambda t: parse_film_size("36,-24"), "film_size_mm", CONVERT,
     "--film-size"),
    ("to_mm-units", lambda t: to_mm(1.0, "ft"), "units", FOCUS, "--units"),
    ("focus-distance", lambda t: focus(LENS, -1.0), "distance_mm", FOCUS, "--distance"),
    ("pupil-plane", lambda t: sampling_plane_z_mm(LENS, FILM_MM, "front"), "plane", PUPIL,
     "--plane"),
    ("pupil-tolerance", lambda t: build_pupil_table(LENS, FILM_MM, 17.5, tolerance=0.0),
     "tolerance", PUPIL, "--tolerance"),
    ("plan-method-auto", lambda t: make_plan(options(t, method="auto")), "method", CONVERT,
     "--method"),
    ("plan-method-unknown", lambda t: make_plan(options(t, method="bogus")), "method",
     CONVERT, "--method"),
    ("plan-units", lambda t: make_plan(options(t, units="ft")), "units", CONVERT, "--units"),
    ("plan-focus", lambda t: make_plan(options(t, focus=0.0)), "focus", CONVERT, "--focus"),
    ("plan-samples", lambda t: make_plan(options(t, samples=0)), "samples", CONVERT,
     "--samples"),
    ("convert-tolerance", lambda t: convert(options(t, method="auto", tolerance_px=0.0)),
     "tolerance_px", CONVERT, "--tolerance"),
    ("location-without-look_at", lambda t: make_plan(options(t, location=(0, 1, -3))),
     "look_at", CONVERT, "--look-at"),
    ("look_at-without-location", lambda t: make_plan(options(t, look_at=(0, 0, 0))),
     "location", CONVERT, "--location"),
    ("sky-parallel", lambda t: make_plan(options(t, location=(0, 0, 0), look_at=(0, 1, 0))),
     "sky", CONVERT, "--sky"),
]


def cli(monkeypatch, capsys, command, error) -> tuple[int, str]:
    """Run ``main`` with ``command``'s function replaced by one raising ``error``."""
    module, attr, argv = command

    def fail(args):
        raise error
    monkeypatch.setattr(importlib.import_module(f"povlens.cli.{module}"), attr, fail)
    rc = main(argv)
    return rc, capsys.readouterr().err


@pytest.mark.parametrize("call, parameter, command, flag", [c[1:] for c in CASES],
                         ids=[c[0] for c in CASES])
def test_the_api_names_the_parameter_and_the_cli_the_option(
        tmp_path, monkeypatch, capsys, call, parameter, command, flag):
    with pytest.raises(ParameterError) as info:
        call(tmp_path)
    err = info.value
    assert err.parameter == parameter
    assert isinstance(err, UsageError) and err.exit_code == 2
    assert "--" not in str(err)
    assert parameter in err.message
    rc, stderr = cli(monkeypatch, capsys, command, err)
    assert rc == 2
    assert flag in stderr
    assert f"{parameter}=" not in stderr and f"'{parameter}'" not in stderr
    assert "Traceback" not in stderr


@pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")
def test_render_view_names_the_view(tmp_path, monkeypatch, capsys):
    convert(options(tmp_path))
    with pytest.raises(ParameterError) as info:
        render_view(tmp_path / "out", "bogus")
    assert info.value.parameter == "view" and "--" not in str(info.value)
    rc, stderr = cli(monkeypatch, capsys, VIEW, info.value)
    assert rc == 2 and "--view 'bogus'" in stderr and "Traceback" not in stderr


def test_the_value_and_the_hint_follow_the_option():
    with pytest.raises(ParameterError) as info:
        stopped_down(LENS, f_number=1.2)
    assert info.value.value == 1.2
    assert "f_number=1.2:" in info.value.message and "f_number=2.04" in info.value.hint
    text = error_text(info.value)
    assert text.startswith("--f-number 1.2: ") and "hint: use --f-number 2.04 or more" in text


def test_hints_of_other_errors_name_options_too():
    tiny = stopped_down(LENS, stop_diameter_mm=1e-3)
    with pytest.raises(OpticsError) as info:
        build_pupil_table(tiny, FILM_MM, 17.5)
    assert "--" not in str(info.value) and "stop_diameter_mm=" in info.value.hint
    text = error_text(info.value, {"--stop-diameter", "--method"})
    assert "use --stop-diameter " in text and "render with --method 'pinhole'" in text


def test_the_scene_camera_hint_names_options_that_exist(tmp_path):
    nocam = tmp_path / "userfn.pov"         # a camera placed by a user function
    nocam.write_text("#version 3.7;\n#declare F = function(x) { 2 * x }\n"
                     "camera { location <F(1), 0, -5> look_at 0 }\n")
    with pytest.raises(SceneCameraError) as info:
        parse_scene_camera(nocam)
    assert "--" not in str(info.value) and "hfov" not in str(info.value)
    convert_options = option_strings(build_parser("convert"), "convert")
    text = error_text(info.value, convert_options)
    for flag in ("--location", "--look-at", "--sky", "--film-diagonal", "--film-size"):
        assert flag in text


def test_a_parameter_the_command_has_no_option_for_keeps_its_name():
    err = ParameterError("film_distance_mm", -1.0, "film_distance_mm=-1.0: must be positive")
    pupil = option_strings(build_parser("pupil"), "pupil")
    trace = option_strings(build_parser("trace"), "trace")
    assert error_text(err, pupil) == "film_distance_mm=-1.0: must be positive"
    assert error_text(err, trace) == "--film-distance -1.0: must be positive"


def test_only_parameter_errors_and_hints_are_rewritten():
    # Other messages can quote the user's text: a scene identifier named like a parameter.
    err = SceneCameraError("s.pov:3: 'width' is not defined", "give 'width'")
    assert error_text(err) == "s.pov:3: 'width' is not defined\n  hint: give --width"
    pov = PovrayError("POV-Ray said: focus=3 'sky'")
    assert error_text(pov) == "POV-Ray said: focus=3 'sky'"
    assert with_flags("sky==0, the_focus=1, opts.focus=2, focus=3") == \
        "sky==0, the_focus=1, opts.focus=2, --focus 3"


def test_every_option_of_the_table_exists():
    parser = build_parser()
    commands = [c for a in parser._actions if isinstance(getattr(a, "choices", None), dict)
                for c in a.choices]
    existing = set().union(*(option_strings(parser, c) for c in commands))
    assert set(FLAG_OF.values()) <= existing


@pytest.mark.parametrize("argv, words, api_names", [
    (("inspect", "dgauss.50mm", "--f-number", "1.2"),
     ["--f-number 1.2: ", "use --f-number 2.04 or more"], ["f_number"]),
    (("inspect", "dgauss.50mm", "--stop-diameter", "100"), ["--stop-diameter 100: "],
     ["stop_diameter_mm"]),
    (("convert", SCENE, "--lens", "dgauss.50mm", "--focus", "4", "--location", "0,1,-3",
      "-o", "OUT"), ["--location and --look-at go together", "give both --location and"],
     ["look_at", "'location'"]),
    (("convert", SCENE, "--lens", "dgauss.50mm", "--focus", "4", "--location", "0,0,0",
      "--look-at", "0,1,0", "-o", "OUT"), ["--sky is parallel", "choose another --sky"],
     ["'sky'"]),
])
def test_the_command_line_prints_options(tmp_path, argv, words, api_names):
    argv = [str(tmp_path / "out") if a == "OUT" else a for a in argv]
    r = subprocess.run([sys.executable, "-m", "povlens", *argv], capture_output=True,
                       text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 2, r.stderr
    for w in words:
        assert w in r.stderr
    for name in api_names:
        assert name not in r.stderr
    assert "Traceback" not in r.stderr


def test_an_unexpected_error_is_one_line_and_exit_1(monkeypatch, capsys):
    monkeypatch.delenv(DEBUG_ENV_VAR, raising=False)
    rc, stderr = cli(monkeypatch, capsys, FOCUS, RuntimeError("boom"))
    assert rc == 1
    assert "povlens focus: internal error: RuntimeError: boom" in stderr
    assert f"{DEBUG_ENV_VAR}=1" in stderr and "bug" in stderr
    assert "Traceback" not in stderr


def test_a_system_error_is_not_called_a_bug(monkeypatch, capsys):
    monkeypatch.delenv(DEBUG_ENV_VAR, raising=False)
    rc, stderr = cli(monkeypatch, capsys, FOCUS, PermissionError(13, "Permission denied", "x"))
    assert rc == 1
    assert "povlens focus: error: [Errno 13] Permission denied: 'x'" in stderr
    assert "bug" not in stderr and "Traceback" not in stderr


@pytest.mark.parametrize("error, where", [
    (OSError(28, "No space left on device"), "cannot write out (the command's output; "
                                             "the system named no file): no space left"),
    (OSError(28, "No space left on device", "out/x.exr"), "cannot write out/x.exr: no space"),
    (OSError(30, "Read-only file system", "out/x.exr"), "cannot write out/x.exr: read-only"),
])
def test_a_refused_write_names_the_path_and_exits_4(monkeypatch, capsys, error, where):
    """An OSError of a full disk that escaped povlens's own writers (which raise
    WriteError naming the file): the file the system named, else the command's output."""
    monkeypatch.delenv(DEBUG_ENV_VAR, raising=False)
    rc, stderr = cli(monkeypatch, capsys, VIEW, error)
    assert rc == 4
    assert f"povlens render-view: error: {where}" in stderr, stderr
    assert "[Errno" not in stderr and "bug" not in stderr and "hint:" in stderr


def test_the_debug_variable_shows_the_traceback(monkeypatch, capsys):
    monkeypatch.setenv(DEBUG_ENV_VAR, "1")
    with pytest.raises(RuntimeError, match="boom"):
        cli(monkeypatch, capsys, FOCUS, RuntimeError("boom"))


def test_an_unexpected_error_prints_no_traceback_from_the_command_line():
    code = ("import sys, povlens.cli, povlens.cli.focus_cmd as f\n"
            "def run(args): raise ZeroDivisionError('inside')\n"
            "f.run = run\n"
            "sys.exit(povlens.cli.main(['focus', 'dgauss.50mm', '--distance', 'inf']))\n")
    env = {k: v for k, v in os.environ.items() if k != DEBUG_ENV_VAR}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       cwd=ROOT, timeout=120, env=env)
    assert r.returncode == 1
    assert "internal error: ZeroDivisionError: inside" in r.stderr
    assert "Traceback" not in r.stderr
