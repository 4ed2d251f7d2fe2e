"""povlens.pov.povray_options: the user's library paths, clock and passthrough options,
checked, on the command line, and in real renders."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from povlens.errors import ParameterError, PovrayError
from povlens.pov import process as povray
from povlens.pov.povray_options import PovrayOptions, check_povray_option
from povlens.util.images import read_image

needs_povray = pytest.mark.skipif(shutil.which("povray") is None,
                                  reason="POV-Ray is not installed")


@pytest.mark.parametrize("option", [
    "+W320", "-w320", "+H10", "+O/tmp/x.png", "+Iscene.pov", "+FN", "-F", "+fe", "+SR2",
    "+ER0.5", "+SC1", "+EC3", "+UA", "-UA", "+D", "-D", "+P", "+GFlog.txt", "+GA",
    "+WT4", "+K0.5", "+KFI1", "+KFF9", "+KI0", "+KF1", "+KC", "+SF2", "+EF3", "+L/tmp",
    "Width=320", "output_file_type=N", "Output_Alpha=on", "Clock=0.5", "Library_Path=/x",
    "Work_Threads=4", "Final_Frame=10", "Declare=PovlensFrame=3", "Include_Ini=my.ini",
    "my.ini", "scene.pov", "+A0.3 +J", "+Z", "--help", "",
])
def test_options_povlens_controls_are_refused(option):
    with pytest.raises(ParameterError) as info:
        PovrayOptions(extra_options=[option])
    assert info.value.parameter == "povray_options" and info.value.value == option
    assert str(info.value).startswith(f"povray_options={option!r}: ")


def test_refusals_say_why_and_what_to_do():
    with pytest.raises(ParameterError, match="image width, which povlens controls"):
        check_povray_option("+W320")
    with pytest.raises(ParameterError) as info:
        check_povray_option("+K0.5")
    assert "'clock'" in info.value.hint
    with pytest.raises(ParameterError) as info:
        check_povray_option("+L../inc")
    assert "'library_paths'" in info.value.hint


@pytest.mark.parametrize("option", [
    "+A0.3", "-A", "Antialias=on", "antialias_threshold=0.1", "+AM2", "+R3", "+J", "-J",
    "+WL2", "+Q9", "+MV3.6", "Declare=Foo=1", "+GD", "+GWwarn.txt", "+HIheader.inc",
    "+SU", "Jitter=off", "Version=3.6", "+RFIfile.rca", "+SS5",
])
def test_other_options_pass_through_unchanged(option):
    assert PovrayOptions(extra_options=[option]).extra_options == (option,)


def test_library_paths_and_clock_are_checked(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "inc").mkdir()
    opts = PovrayOptions(library_paths="inc", clock=1, extra_options="+A0.3")
    assert opts.library_paths == (str(tmp_path / "inc"),)      # absolute, one str = one path
    assert opts.clock == 1.0 and opts.extra_options == ("+A0.3",)
    assert opts.switches() == [f"+L{tmp_path / 'inc'}", "+K1.0", "+A0.3"]
    with pytest.raises(ParameterError) as info:
        PovrayOptions(library_paths=["inc", "nowhere"])
    assert info.value.parameter == "library_paths" and "nowhere" in str(info.value)
    for bad in (float("nan"), float("inf"), "soon"):
        with pytest.raises(ParameterError) as info:
            PovrayOptions(clock=bad)
        assert info.value.parameter == "clock"
    assert PovrayOptions(clock=0.1).switches() == ["+K0.1"]     # shortest exact text
    with pytest.raises(AttributeError):
        opts.clock = 2.0                                         # frozen


def test_the_command_line_carries_them_after_povlens_switches(tmp_path):
    opts = PovrayOptions(library_paths=[tmp_path], clock=0.5, extra_options=["+A0.3", "+R2"])
    switches = povray.render_switches("out.exr", 16, 12, library_paths=["/scenes"],
                                      extra_args=["Declare=PovlensFrame=1"],
                                      povray_options=opts)
    assert switches == ["+FE", "+W16", "+H12", "-A", "+WT1", "+L/scenes", f"+L{tmp_path}",
                        "+K0.5", "+A0.3", "+R2", "Declare=PovlensFrame=1"]
    cmd = povray.povray_command("povray", "a.pov", "out.exr", switches)
    assert cmd[-len(switches):] == switches
    assert povray.render_switches("out.exr", 16, 12) == povray.render_switches(
        "out.exr", 16, 12, povray_options=PovrayOptions())
    with pytest.raises(ParameterError, match="PovrayOptions"):
        povray.render_switches("out.exr", 16, 12, povray_options=["+A0.3"])


FLAT = """#version 3.7;
global_settings { assumed_gamma 1.0 }
camera { location <0, 0, -3> look_at 0 }
"""


@needs_povray
def test_a_library_path_finds_an_include_in_another_folder(tmp_path):
    extra = tmp_path / "extra"
    extra.mkdir()
    (extra / "povlens_test_grey.inc").write_text("#declare Grey = rgb 0.25;\n")
    scene = tmp_path / "scene" / "s.pov"
    scene.parent.mkdir()
    scene.write_text(FLAT + '#include "povlens_test_grey.inc"\n'
                     "plane { -z, 0 pigment { Grey } finish { ambient 1 diffuse 0 } }\n")
    with pytest.raises(PovrayError, match="povlens_test_grey.inc"):
        povray.render(scene, tmp_path / "a.exr", 8, 6)
    out = povray.render(scene, tmp_path / "b.exr", 8, 6,
                        povray_options=PovrayOptions(library_paths=[extra]))
    np.testing.assert_allclose(read_image(out), 0.25, atol=1e-3)


@needs_povray
def test_the_clock_renders_a_still_of_an_animation(tmp_path):
    scene = tmp_path / "anim.pov"
    scene.write_text(FLAT + "plane { -z, 0 pigment { rgb clock }\n"
                            "        finish { ambient 1 diffuse 0 } }\n")
    start = read_image(povray.render(scene, tmp_path / "k0.exr", 8, 6))
    mid = read_image(povray.render(scene, tmp_path / "k05.exr", 8, 6,
                                   povray_options=PovrayOptions(clock=0.5)))
    np.testing.assert_allclose(start, 0.0, atol=1e-3)
    np.testing.assert_allclose(mid, 0.5, atol=1e-3)


@needs_povray
def test_passthrough_options_reach_povray(tmp_path):
    """Anti-aliasing (+A0.1, after povlens's -A) smooths a hard edge."""
    scene = tmp_path / "edge.pov"
    scene.write_text(FLAT + "plane { -z, 0 pigment { gradient x color_map { [0.5 rgb 0] "
                            "[0.5 rgb 1] } scale 0.37 } finish { ambient 1 diffuse 0 } }\n")
    hard = read_image(povray.render(scene, tmp_path / "hard.exr", 16, 12))
    soft = read_image(povray.render(scene, tmp_path / "soft.exr", 16, 12,
                                    povray_options=PovrayOptions(extra_options=["+A0.1", "+R3"])))
    grey = lambda img: np.mean((img > 0.02) & (img < 0.98))   # noqa: E731
    assert grey(hard) == 0.0 and grey(soft) > 0.05
