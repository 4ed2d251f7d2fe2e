"""``povlens lenses``: every bundled lens, its focal length, f-number, field of view and source."""
import json
import math

import pytest

from povlens.cli import main
from povlens.lens.bundled import (bundled_lens_folder, bundled_lenses,
                                  diagonal_field_of_view_deg, lens_sources)
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import read_lens

BUNDLED = [p.stem for p in sorted(bundled_lens_folder().glob("*.dat"))]


def test_every_bundled_lens_is_listed_with_its_source(capsys):
    assert main(["lenses"]) == 0
    out = capsys.readouterr().out
    for name in BUNDLED:
        assert f"\n{name} " in out, name
    assert "mmp/pbrt-v4-scenes" in out and "HarrisonKramer/optiland" in out
    assert "not listed in SOURCES.md" not in out


def test_json_numbers_are_the_lenses_own(capsys):
    assert main(["lenses", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["name"] for r in rows] == BUNDLED
    for r in rows:
        p = paraxial_data(read_lens(r["name"]))
        assert r["efl_mm"] == pytest.approx(p.efl) and r["f_number"] == pytest.approx(p.f_number)
        assert r["source"] and r["description"] and r["film_diagonal_mm"] == 35.0
        assert r["field_of_view_deg"] is not None


def test_field_of_view_is_the_real_chief_ray_on_35mm():
    by_name = {b.name: b for b in bundled_lenses()}
    tele = by_name["telephoto.250mm"]
    # A long lens has almost no distortion: 2 atan(d / 2f) to a few hundredths of a degree.
    assert tele.field_of_view_deg == pytest.approx(
        2 * math.degrees(math.atan(17.5 / tele.efl_mm)), abs=0.05)
    assert by_name["dgauss.50mm"].field_of_view_deg == pytest.approx(38.7, abs=0.1)
    assert by_name["wide.22mm"].field_of_view_deg == pytest.approx(77.5, abs=0.1)
    assert tele.image_circle_mm is None
    fisheye = by_name["fisheye.10mm"]          # its image circle is smaller than the film
    assert fisheye.image_circle_mm is not None and 20 < fisheye.image_circle_mm < 35
    assert 140 < fisheye.field_of_view_deg < 160
    fov, circle = diagonal_field_of_view_deg(read_lens("fisheye.10mm"), 20.0)
    assert circle is None and fov < fisheye.field_of_view_deg


def test_sources_table_is_parsed(tmp_path):
    md = tmp_path / "SOURCES.md"
    md.write_text("| file | format | lens | origin |\n|---|---|---|---|\n"
                  "| `a.dat` | pbrt | a lens | **me** `x.dat` @123 |\n"
                  "| `b.dat` | pbrt (converted) | b lens | you |\n| c.dat | 1 | 2 | 3 |\n")
    assert lens_sources(md) == {"a.dat": ("a lens", "me x.dat @123"),
                                "b.dat": ("b lens (converted to pbrt)", "you")}
    assert lens_sources(tmp_path / "none.md") == {}


def test_film_diagonal_option(capsys):
    assert main(["lenses", "--json", "--film-diagonal", "43.3"]) == 0
    rows = {r["name"]: r for r in json.loads(capsys.readouterr().out)}
    assert rows["dgauss.50mm"]["film_diagonal_mm"] == 43.3
    assert rows["dgauss.50mm"]["field_of_view_deg"] > 40
