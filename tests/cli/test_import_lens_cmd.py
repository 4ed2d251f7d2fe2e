"""``povlens import-lens``: writes a lens file every command reads; bad input exits 2 with
one message naming the file and what to do, never a traceback."""
import json
import subprocess
import sys

import pytest

from conftest import ROOT

from povlens.cli import main
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import read_lens

DATA = ROOT / "tests" / "data"
SUBSET = DATA / "lentil-lenses-subset.json"
ZMX = DATA / "zmx"


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_lentil_entry_scaled_to_a_focal_length(tmp_path, capsys):
    out = tmp_path / "panchro.dat"
    code, stdout, err = run(capsys, "import-lens", SUBSET, "--id", "0007", "--efl", "35",
                            "-o", out)
    assert code == 0, err
    assert f"wrote {out}: cooke speed-panchro (1920)" in stdout and "EFL 35.0000 mm" in stdout
    assert paraxial_data(read_lens(out)).efl == pytest.approx(35.0, rel=1e-12)
    code, stdout, err = run(capsys, "inspect", out, "--json")
    assert code == 0 and json.loads(stdout)["efl"] == pytest.approx(35.0, rel=1e-12)


def test_zmx_with_a_glass_given_on_the_command_line(tmp_path, capsys):
    out = tmp_path / "litho.dat"
    code, stdout, err = run(capsys, "import-lens", ZMX / "US05831776-1.zmx",
                            "--glass", "SILICA=1.458464,67.82", "-o", out)
    assert code == 0, err
    assert "povlens: warning:" in err and "clipped" in err        # housings, by row and line
    lens = read_lens(out)
    assert lens.index_after[0] == 1.458464 and lens.abbe_vd[0] == 67.82


def test_a_moulded_glass_is_its_catalogue_glass_with_a_warning(tmp_path, capsys):
    """Zemax's ``L-TIM28_MOLD`` (OHARA L-TIM28 after precision moulding) is in no
    catalogue; the file loads with L-TIM28's formula and a warning that says so."""
    out = tmp_path / "us8427765.dat"
    code, stdout, err = run(capsys, "import-lens", ZMX / "US08427765-1.ZMX", "-o", out)
    assert code == 0, err
    assert "L-TIM28_MOLD" in err and "OHARA:L-TIM28" in err and "moulding" in err
    lens = read_lens(out)
    assert lens.glass[2] == "OHARA:L-TIM28"
    from povlens.lens.glass_catalog import find_glass
    assert lens.index_after[2] == pytest.approx(find_glass("OHARA:L-TIM28").n_d, abs=1e-9)


def test_list_table_and_json(capsys):
    code, stdout, _ = run(capsys, "import-lens", SUBSET, "--list")
    assert code == 0
    assert "0001   angenieux" in stdout and "1953" in stdout and "100 mm" in stdout
    code, stdout, _ = run(capsys, "import-lens", SUBSET, "--list", "--json")
    entries = json.loads(stdout)
    assert [e["lens_id"] for e in entries] == [f"000{i}" for i in range(1, 9)]
    assert entries[4]["focal_length_mm"] == 14.2


@pytest.mark.parametrize("argv,needles", [
    (["{tmp}/trunc.json", "--id", "0001"], ["trunc.json:", "not valid JSON",
                                            "download lenses.json again"]),
    ([SUBSET, "--id", "0042"], ["--id '0042'", "has no entry '0042'", "--list"]),
    ([SUBSET], ["--id is needed", "holds 8 lenses", "--list"]),
    ([SUBSET, "--id", "0002", "--adjusted"], ["--adjusted: entry 0002", "leave out --adjusted"]),
    ([ZMX / "HoO-V2C18Ex03.zmx"], ["HoO-V2C18Ex03.zmx:78: surface 2", "a mirror"]),
    ([ZMX / "US05831776-1.zmx"], ["glass SILICA has no refractive index", "--glass"]),
    (["{tmp}/nostop.zmx"], ["nostop.zmx: no surface is marked STOP", "mark the aperture stop"]),
    ([ZMX / "singlet-pcx-25mm.zmx", "--id", "1"], ["--id is for a lentil database"]),
    ([DATA / "README.md"], ["README.md: is neither a lentil lens database"]),
    (["{tmp}/missing.zmx"], ["missing.zmx: no such file"]),
])
def test_bad_input_exits_2_with_one_message(tmp_path, capsys, argv, needles):
    (tmp_path / "trunc.json").write_text(SUBSET.read_text()[:4000])
    (tmp_path / "nostop.zmx").write_text(
        (ZMX / "singlet-pcx-25mm.zmx").read_text().replace("  STOP\n", ""))
    args = [str(a).replace("{tmp}", str(tmp_path)) for a in argv]
    code, stdout, err = run(capsys, "import-lens", *args, "-o", tmp_path / "out.dat")
    assert code == 2, err
    assert err.startswith("povlens import-lens: error: ") and "Traceback" not in err
    for needle in needles:
        assert needle in err, (needle, err)
    assert not (tmp_path / "out.dat").exists()


def test_output_is_required_and_list_is_for_lentil(tmp_path, capsys):
    code, _, err = run(capsys, "import-lens", SUBSET, "--id", "0001")
    assert code == 2 and "-o OUT.dat" in err
    code, _, err = run(capsys, "import-lens", ZMX / "singlet-pcx-25mm.zmx", "--list")
    assert code == 2 and "--list is for a lentil database" in err


def test_bad_glass_option_is_a_usage_error(tmp_path):
    r = subprocess.run([sys.executable, "-m", "povlens", "import-lens",
                        str(ZMX / "singlet-pcx-25mm.zmx"), "--glass", "N-SF11=abc", "-o",
                        str(tmp_path / "x.dat")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "give NAME=ND or NAME=ND,VD" in r.stderr
    assert "Traceback" not in r.stderr


def test_truncated_json_through_a_real_process_has_no_traceback(tmp_path):
    bad = tmp_path / "lenses.json"
    bad.write_text(SUBSET.read_text()[:4000])
    r = subprocess.run([sys.executable, "-m", "povlens", "import-lens", str(bad), "--id",
                        "0001", "-o", str(tmp_path / "x.dat")], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2 and f"{bad}:" in r.stderr and "Traceback" not in r.stderr
