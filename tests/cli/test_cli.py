import json
import subprocess
import sys

import pytest

from conftest import LENS_DIR, ROOT


def povlens(*args, stdin=None):
    return subprocess.run([sys.executable, "-m", "povlens", *args], input=stdin,
                          capture_output=True, text=True, cwd=ROOT, timeout=120)


def test_inspect_json_has_the_documented_keys():
    r = povlens("inspect", "dgauss.50mm", "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["efl"] == pytest.approx(50.3582, abs=1e-4)
    assert d["bfl"] == pytest.approx(36.1059, abs=1e-4)
    assert d["f_number"] == pytest.approx(2.030, abs=1e-3)
    assert d["entrance_pupil"]["position"] == pytest.approx(19.946, abs=1e-3)
    assert d["entrance_pupil"]["diameter"] == pytest.approx(24.8051, abs=1e-4)
    assert d["exit_pupil"]["position"] == pytest.approx(-17.771, abs=1e-3)
    assert set(d["principal_planes"]) == {"front", "rear"}
    assert d["stop_index"] == 5


def test_inspect_table_and_stop_down():
    r = povlens("inspect", str(LENS_DIR / "dgauss.50mm.dat"), "--f-number", "4")
    assert r.returncode == 0
    assert "f-number" in r.stdout and "4.0000" in r.stdout and "<- stop" in r.stdout


def test_focus_json():
    r = povlens("focus", "dgauss.50mm", "--distance", "1", "--units", "m", "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["film_distance_mm"]["thick_lens"] == pytest.approx(38.918, abs=1e-3)
    assert abs(d["film_distance_mm"]["exact"] - 38.918) < 0.1


def test_trace_reads_and_writes_json():
    rays = {"rays": [{"origin": [0, 0, 0], "direction": [0, 0, 1]},
                     {"origin": [0, 0, 0], "direction": [1, 0, 0.1]}]}
    r = povlens("trace", "dgauss.50mm", "--film-distance", "36.1059", stdin=json.dumps(rays))
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)["rays"]
    assert out[0]["origin"][2] == pytest.approx(36.1059 + 32.04)
    assert out[0]["direction"] == [0.0, 0.0, 1.0]
    assert out[1] is None  # blocked


@pytest.mark.parametrize("args, stdin, words", [
    (("inspect", "no-such-lens.dat"), None, "no such lens file"),
    (("inspect", "dgauss.50mm", "--f-number", "1.2"), None, "opens only to"),
    (("focus", "telephoto.250mm", "--distance", "1", "--units", "m"), None,
     "closest distance that works"),
    (("trace", "dgauss.50mm", "--film-distance", "36"), "{not json", "not valid JSON"),
    (("trace", "dgauss.50mm", "--film-distance", "36"), '{"rays": [{"origin": [0]}]}',
     "ray 0"),
])
def test_bad_input_gives_a_clear_error_and_no_traceback(args, stdin, words):
    r = povlens(*args, stdin=stdin)
    assert r.returncode == 2
    assert words in r.stderr
    assert "Traceback" not in r.stderr


def test_bad_lens_file_names_file_and_line(tmp_path):
    bad = tmp_path / "bad.dat"
    bad.write_text("# a lens\n50 5 1.5 20\n-50 0 x 20\n")
    r = povlens("inspect", str(bad))
    assert r.returncode == 2
    assert f"{bad}:3:" in r.stderr and "not a number" in r.stderr
    assert "Traceback" not in r.stderr


def test_help_lists_the_subcommands():
    r = povlens("--help")
    assert r.returncode == 0
    for cmd in ("inspect", "focus", "trace", "check"):
        assert cmd in r.stdout
