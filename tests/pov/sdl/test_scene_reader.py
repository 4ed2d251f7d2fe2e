"""The SDL reader behind parse_scene_camera: expressions, directives, macros, includes.

Expressions are checked against POV-Ray's own ``#debug`` output; the directive semantics
(``#switch`` fall-through, ``#break``, ``#local`` scopes, the frame values of a still)
were measured with POV-Ray 3.7.0.10 and are written down here with known answers.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from povlens.pov.sdl import control_flow
from povlens.pov.sdl.include_paths import default_library_paths, find_include
from povlens.pov.sdl.scene_camera import SceneCameraError, parse_scene_camera
from povlens.pov.sdl.scene_reader import SceneReader, still_constants
from povlens.pov.sdl.values import SdlArray, UnknownValue, promote

HAVE_POVRAY = shutil.which("povray") is not None

# (kind, expression, declarations before it); kind "v": a vector, "f": a float
EXPRESSIONS = [
    ("v", "<1 -2 3>", ""),  # commas are optional: <1-2, 3>
    ("v", "<1, 2> + z", ""),  # a 2-vector is padded with 0
    ("v", "<1,2>*3", ""),
    ("v", "2 + <1,2,3>", ""),
    ("v", "-<1,2,3>/4", ""),
    ("v", "x + y*2 - z/3", ""),
    ("f", "<1,2,3>.x + <1,2,3>.y*10 + <1,2,3>.z*100", ""),
    ("v", "<u.x, u.v + v.v, 0> + u", ""),
    ("f", "C1.gray", "#declare C1 = rgb <0.2,0.4,0.6>;"),
    ("v", "vaxis_rotate(<1,2,3>, <0.3,1,0.2>, 37)", ""),
    ("v", "vrotate(<1,2,3>, <10,20,30>)", ""),
    ("v", "vcross(<1,2,3>, <-2,0.5,1>)", ""),
    ("v", "vnormalize(<3,4,12>)", ""),
    ("f", "vlength(<3,4,12>)", ""),
    ("f", "vdot(<1,2,3>, <4,5,6>)", ""),
    ("f", "select(-1, 10, 20) + select(0, 1, 2, 3)*100", ""),
    ("f", "div(-7, 2) + 10*mod(-7, 2)", ""),
    ("f", "int(-2.5) + floor(-2.5)*10 + ceil(2.1)*100", ""),
    ("f", "pow(2, 0.5) + exp(1) + ln(10) + log(1000)", ""),
    ("f", "atan2(1, -1) + degrees(1) + radians(90)", ""),
    ("f", "min(3, -1, 2) + max(3, 7, 2)", ""),
    ("f", "(1 < 2 ? 5 : 6) + (2 <= 1) + (3 = 3) + (3 != 3)", ""),
    ("f", "(1 & 0) + (1 | 0)*2 + !0*4", ""),
    ("f", 'strlen(concat("ab", str(12.5, 0, 2), chr(65)))', ""),
    ("f", 'strcmp("abc", "abd") + val("2.5")*10 + asc("A")', ""),
    ("f", "bitwise_and(12, 10) + bitwise_or(1, 4)*100", ""),
    ("f", "sinh(1) + cosh(1) + tanh(0.5) + asinh(1) + acosh(2) + atanh(0.5)", ""),
    ("v", "C2.red*x + C3.transmit*y + C4.transmit*z",
     "#declare C2 = color red 0.3 green 0.6 blue 0.9; #declare C3 = rgbft <1,2,3,4,5>;"
     " #declare C4 = rgbt <1,2,3,4>;"),
    ("v", "<C5.filter, C6.filter, C7.blue>",
     "#declare C5 = rgbf <1,2,3,4>; #declare C6 = color rgb 0.25 filter 0.5; #declare C7 = rgb 2;"),
    ("f", "pi + true + yes*2 + on*4 + off + no + false", ""),
    ("v", "<1,2,3> * <2,3,4> - <1,2,3>/<2,4,8>", ""),
    ("f", "1 + 2 * 3 - 4 / 8 * -2", ""),
    ("f", 'strlen(vstr(3, <1,2,3>, ", ", 0, 1)) + strlen(substr("abcdef", 2, 3))*100', ""),
    ("f", "defined(Undeclared_Name) + 2*defined(pi) + 4*defined(E0)", ""),
    ("v", "A[1][0] + <0, dimension_size(A, 2), dimensions(A)>",
     "#declare A = array[2][3] {{<1,2,3>, x, y}, {<6,7,8>, z, <1,1,1>}}"),
]


def _read(tmp_path: Path, text: str, name: str = "s", **kw) -> SceneReader:
    p = tmp_path / f"{name}.pov"
    p.write_text("#version 3.7;\n" + text + "\n")
    reader = SceneReader(p, still_constants(kw.pop("clock", None), None, None), **kw)
    reader.run()
    return reader


def _value(reader: SceneReader, name: str):
    return reader.stream.symbols.get(name)


@pytest.mark.skipif(not HAVE_POVRAY, reason="POV-Ray is not installed")
def test_expressions_match_povray(tmp_path):
    lines = []
    for i, (kind, expr, pre) in enumerate(EXPRESSIONS):
        fmt = f'vstr(3, E{i}, ",", 0, 12)' if kind == "v" else f"str(E{i}, 0, 12)"
        lines += [pre, f"#declare E{i} = {expr};", f'#debug concat("E{i}=", {fmt}, "\\n")']
    scene = tmp_path / "e.pov"
    scene.write_text("#version 3.7;\n" + "\n".join(lines) + "\nsphere { 0, 1 }\n")
    out = subprocess.run(["povray", "-D", "+W4", "+H3", f"+I{scene}", "+O/dev/null"],
                         capture_output=True, text=True, cwd=tmp_path, timeout=60).stderr
    want = {m.group(1): [float(v) for v in m.group(2).split(",")]
            for m in re.finditer(r"^(E\d+)=(.*)$", out, re.M)}
    assert len(want) == len(EXPRESSIONS), out[-2000:]
    reader = SceneReader(scene, still_constants(None, None, None))
    reader.run()
    bad = {}
    for i, (kind, expr, _) in enumerate(EXPRESSIONS):
        got = _value(reader, f"E{i}")
        if isinstance(got, UnknownValue):
            bad[expr] = got.reason
            continue
        got = promote(got, 3)[:3] if kind == "v" else [got]
        if not np.allclose(got, want[f"E{i}"], rtol=1e-11, atol=1e-11):
            bad[expr] = (list(got), want[f"E{i}"])
    assert not bad


def test_switch_as_povray_runs_it(tmp_path):
    """Measured with POV-Ray 3.7: a case falls through later #case/#range/#else to the
    #break; #break inside an #if leaves the #switch; #else starts the default."""
    r = _read(tmp_path, """
        #declare Log = "";
        #switch (2)
          #case (1) #declare Log = concat(Log, "1") #break
          #case (2) #declare Log = concat(Log, "2")
          #case (3) #declare Log = concat(Log, "3")
          #else #declare Log = concat(Log, "e")
          #if (1) #break #end
          #declare Log = concat(Log, "x")
        #end
        #switch (7)
          #range (0, 5) #declare Log = concat(Log, "r")
          #else #declare Log = concat(Log, "E")
          #case (7) #declare Log = concat(Log, "7")
        #end
        #switch (4.5) #range (4, 5) #declare Log = concat(Log, "R") #break #end""")
    assert _value(r, "Log") == "23eE7R"


def test_loops_break_and_for(tmp_path):
    r = _read(tmp_path, """
        #declare I = 0; #while (1) #declare I = I + 1; #if (I >= 6) #break #end #end
        #declare S = 0; #for (K, 1, 7, 3) #declare S = S + K; #end
        #declare D = 0; #for (K2, 3, 1, -1) #declare D = D*10 + K2; #end
        #declare N = 0; #while (N < 3) #declare M = 0; #while (M < 4) #declare M = M + 1;
          #end #declare N = N + M/4; #end""")
    assert _value(r, "I") == 6.0
    assert _value(r, "S") == 1 + 4 + 7 and _value(r, "K") == 10.0  # as POV-Ray leaves it
    assert _value(r, "D") == 321.0
    assert _value(r, "N") == 3.0


def test_macros_scopes_and_values(tmp_path):
    r = _read(tmp_path, """
        #macro Twice(V) #local T = V*2; #declare Last = T; T #end
        #macro Nest(A) Twice(A) + 1 #end
        #declare P = Twice(<1, 2, 3>);
        #declare Q = Nest(5);
        #macro Opt(A, optional B) #ifdef (B) #declare HasB = 1; #else #declare HasB = 0; #end #end
        Opt(1, )
        #declare Leak = defined(T);""")
    np.testing.assert_allclose(_value(r, "P"), [2, 4, 6])
    assert _value(r, "Q") == 11.0 and _value(r, "Last") == 10.0
    assert _value(r, "HasB") == 0.0 and _value(r, "Leak") == 0.0


def test_declares_end_at_the_next_declare(tmp_path):
    """Without ';' a value ends where the next #declare starts, as in POV-Ray."""
    r = _read(tmp_path, "#declare A = 1\n#declare A = A + 1\n#declare B = A*10\n"
                        "#declare O = sphere { 0, 1 }\n#declare C = B + 1;")
    assert (_value(r, "A"), _value(r, "B"), _value(r, "C")) == (2.0, 20.0, 21.0)
    assert isinstance(_value(r, "O"), UnknownValue) and _value(r, "O").kind == "sphere"


def test_arrays_strings_and_includes_by_expression(tmp_path):
    (tmp_path / "part3.inc").write_text("#declare FromInclude = 3; #local NotSeen = 1;\n")
    r = _read(tmp_path, """
        #declare A = array[3] {1, <0, 1, 0>, 3}
        #declare A[2] = 30;
        #declare N = 3;
        #include concat("part", str(N, 0, 0), ".inc")
        #declare Seen = defined(NotSeen);""")
    arr = _value(r, "A")
    assert isinstance(arr, SdlArray) and arr.items[2] == 30.0
    assert _value(r, "FromInclude") == 3.0 and _value(r, "Seen") == 0.0


def test_unknown_conditions_make_what_they_declare_unknown(tmp_path):
    r = _read(tmp_path, """
        #declare Known = 1;
        #if (rand(seed(3)) > 0.5) #declare Maybe = 1; #else #declare Maybe = 2; #end
        #ifdef (Maybe) #declare After = 1; #end""")
    assert _value(r, "Known") == 1.0
    maybe = _value(r, "Maybe")
    assert isinstance(maybe, UnknownValue) and maybe.maybe and "#if" in maybe.reason
    assert isinstance(_value(r, "After"), UnknownValue)


def test_frame_values_of_a_still_and_of_a_clock(tmp_path):
    """POV-Ray 3.7 without +K: clock 0, clock_on 0 (all frame values 0); with +K0.3:
    clock 0.3, clock_on 1, the rest 0 (measured)."""
    text = "#declare V = <clock, clock_on, clock_delta + frame_number + initial_clock + final_clock>;"
    np.testing.assert_allclose(_value(_read(tmp_path, text), "V"), [0, 0, 0])
    np.testing.assert_allclose(_value(_read(tmp_path, text, clock=0.3), "V"), [0.3, 1, 0])


def test_long_loops_are_cut_and_what_they_assign_is_unknown(tmp_path, monkeypatch):
    monkeypatch.setattr(control_flow, "MAX_LOOP_ITERATIONS", 50)
    scene = tmp_path / "long.pov"
    scene.write_text("#declare I = 0; #declare P = 0;\n"
                     "#while (I < 1000) #declare P = P + 1; #declare I = I + 1; #end\n"
                     "camera { location <0, 1, -P> look_at 0 }\n")
    with pytest.raises(SceneCameraError, match="did not follow to its end"):
        parse_scene_camera(scene)


def test_includes_are_found_as_povray_finds_them(tmp_path):
    """The scene's folder first, then the library paths in order; not the including
    file's folder (measured with POV-Ray 3.7.0.10); a missing suffix gets '.inc'."""
    scene_dir, lib1, lib2 = tmp_path / "scene", tmp_path / "lib1", tmp_path / "lib2"
    for d in (scene_dir, lib1, lib2, scene_dir / "sub"):
        d.mkdir()
    (lib1 / "a.inc").write_text("")
    (lib2 / "a.inc").write_text("")
    (scene_dir / "b.inc").write_text("")
    (lib2 / "b.inc").write_text("")
    (scene_dir / "sub" / "c.inc").write_text("")
    assert find_include("a.inc", scene_dir, [lib1, lib2]) == (lib1 / "a.inc").resolve()
    assert find_include("b.inc", scene_dir, [lib1, lib2]) == (scene_dir / "b.inc").resolve()
    assert find_include("b", scene_dir, [lib2]) == (scene_dir / "b.inc").resolve()
    assert find_include("c.inc", scene_dir, [lib1]) is None
    assert find_include("sub/c.inc", scene_dir, []) == (scene_dir / "sub" / "c.inc").resolve()


def test_library_paths_from_povray_ini(tmp_path, monkeypatch):
    lib = tmp_path / "mylib"
    lib.mkdir()
    ini = tmp_path / "povray.ini"
    ini.write_text(f'; a comment\nLibrary_Path="{lib}"\n+L{tmp_path}\nWidth=320\n')
    monkeypatch.setenv("POVINI", str(ini))
    paths = default_library_paths()
    assert paths[:2] == [lib, tmp_path]
    (lib / "camdef.inc").write_text("camera { location <0, 2, -7> look_at 0 }\n")
    scene = tmp_path / "scene" / "s.pov"
    scene.parent.mkdir()
    scene.write_text('#include "camdef.inc"\n')
    np.testing.assert_allclose(parse_scene_camera(scene).location, [0, 2, -7])
    with pytest.raises(SceneCameraError, match="camdef.inc") as info:
        parse_scene_camera(scene, povray_library=False)
    assert "library_paths" in info.value.hint
    np.testing.assert_allclose(
        parse_scene_camera(scene, povray_library=False, library_paths=[lib]).location, [0, 2, -7])


def test_old_versions_modify_the_previous_camera(tmp_path):
    r = _read(tmp_path, "#version 3.1;\ncamera { location <0, 1, -5> look_at 0 }\n"
                        "camera { translate <1, 0, 0> }\n")
    np.testing.assert_allclose(r.camera.location, [1, 1, -5])


def test_a_statement_that_cannot_be_read_is_skipped_alone(tmp_path):
    """An unknown array index or value is skipped to its statement's end, not past the
    macro body or the #if it is in (portfolio/__empty.pov lost its camera so)."""
    r = _read(tmp_path, """
        #macro Fill(Data)
          #local A = array[2];
          #local H = rand(seed(1));
          #local A[H] = Data[0]
          #local B = Data[1]
          #declare After = 1;
        #end
        #if (1)
          Fill(Unknown_Data)
          #declare InIf = 2;
        #end
        camera { location <0, After + InIf, -5> }""")
    np.testing.assert_allclose(r.camera.location, [0, 3, -5])
