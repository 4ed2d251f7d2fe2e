"""``povlens pupil``: the comparison table, JSON, saved tables, plots and errors."""

import json
import subprocess
import sys

import pytest

from conftest import ROOT
from povlens.cli import main

FAST = ["--pbrt-rays", "512", "--samples", "256", "--bands", "4", "--radii-per-band", "2"]


def run(capsys, *args):
    code = main(["pupil", *args])
    out, err = capsys.readouterr()
    return code, out, err


def test_json_compares_table_pbrt_and_naive(capsys):
    code, out, err = run(capsys, "cooke.triplet.50mm", "--focus", "10m", "--json", *FAST)
    assert code == 0, err
    d = json.loads(out)
    assert d["film_distance_mm"] == pytest.approx(42.6890, abs=1e-3)
    assert d["film"] == {"diagonal_mm": 35.0}
    assert len(d["bands"]) == 4 and d["bands"][0]["film_radius_mm"] == [0.0, 4.375]
    worst = {k: d["all"][k]["worst"] for k in ("povlens", "pbrt", "naive")}
    assert worst["povlens"] >= 0.95
    assert worst["povlens"] > worst["pbrt"] > 0 and worst["povlens"] > worst["naive"]
    b = d["build"]
    assert b["pbrt"]["rays_per_interval"] == 512
    # pbrt's count: 2048 x more rays generated; estimated from the traced fraction
    assert b["pbrt"]["time_at_pbrt_count_s"] > 100 * b["pbrt"]["time_s"] / 2048
    assert b["pbrt"]["time_at_pbrt_count_is"].startswith("estimated")
    assert b["povlens"]["rays_traced"] > 0 and not b["povlens"]["reused"]
    assert d["table"]["lens"]["sha256"] and d["table"]["knots"] >= 2
    assert d["exposure_normalisation"] == pytest.approx(1 / d["axial_irradiance_factor"])
    assert d["axial_irradiance_factor"] == pytest.approx(0.0302, rel=0.01)


def test_text_report_and_vignetted_fisheye(capsys):
    code, out, err = run(capsys, "fisheye.10mm", "--focus", "10", "--units", "m", *FAST)
    assert code == 0, err
    assert "no ray leaves the film beyond radius 13.4" in out
    last_band = next(line for line in out.splitlines() if line.strip().startswith("13.12"))
    assert "vignetted" in last_band  # the table (and pbrt) know; naive sampling does not
    assert "povlens table" in out and "pbrt 64 boxes" in out and "naive rear element" in out
    assert "at pbrt 2^20/interval" in out
    assert "nan" not in out.lower()


def test_saved_table_is_reused_while_inputs_are_unchanged(capsys, tmp_path):
    path = tmp_path / "t.npz"
    args = ["tessar.50mm", "--focus", "10m", "-o", str(path), "--no-compare", "--json",
            "--samples", "128", "--bands", "2", "--radii-per-band", "1"]
    code, out, _ = run(capsys, *args)
    assert code == 0 and path.exists() and not json.loads(out)["table_reused"]
    code, out, _ = run(capsys, *args)
    d = json.loads(out)
    assert code == 0 and d["table_reused"] and set(d["all"]) == {"povlens"}
    code, out, _ = run(capsys, *args, "--f-number", "8")  # the stop changed: rebuilt
    assert code == 0 and not json.loads(out)["table_reused"]
    code, out, _ = run(capsys, *args[:2], "2m", *args[3:])  # the focus changed: rebuilt
    assert code == 0 and not json.loads(out)["table_reused"]
    code, out, _ = run(capsys, *args, "--film-size", "36,24")  # another film: rebuilt
    assert code == 0 and not json.loads(out)["table_reused"]


def test_plot_writes_a_png(capsys, tmp_path):
    png = tmp_path / "pupil.png"
    code, out, err = run(capsys, "wide.22mm", "--focus", "inf", "--plot", str(png), *FAST)
    assert code == 0, err
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"plot: {png}" in out


@pytest.mark.parametrize("args, needle", [
    (["--film-size", "36x24"], "--film-size"),
    (["--film-size", "36,-1"], "--film-size"),
    (["--focus", "near"], "--focus"),
    (["--focus=-3m"], "--focus"),
    (["--focus", "10m", "--samples", "0"], "--samples"),
    (["--tolerance", "2"], "--tolerance"),
])
def test_bad_options_give_a_clear_message(capsys, args, needle):
    base = ["dgauss.50mm", "--focus", "10m"]
    if args[0].startswith("--focus"):
        base = ["dgauss.50mm"]
    try:
        code, _, err = run(capsys, *base, *args, "--no-compare")
    except SystemExit as e:  # argparse's own checks
        code, (_, err) = e.code, capsys.readouterr()
    assert code == 2
    assert needle in err and "Traceback" not in err


def test_errors_without_traceback_from_the_command_line():
    r = subprocess.run([sys.executable, "-m", "povlens", "pupil", "telephoto.250mm",
                        "--focus", "1m", "--no-compare"], capture_output=True, text=True,
                       cwd=ROOT, timeout=120)
    assert r.returncode == 2
    assert "closest focus distance" in r.stderr and "Traceback" not in r.stderr
    r = subprocess.run([sys.executable, "-m", "povlens", "pupil", "dgauss.50mm", "--focus",
                        "10m", "--film-diagonal", "0"], capture_output=True, text=True,
                       cwd=ROOT, timeout=120)
    assert r.returncode == 2 and "--film-diagonal" in r.stderr
