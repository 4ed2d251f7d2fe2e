"""Published prescriptions (patent designs of the lentil lens database) load and trace.

Their aperture column is a housing radius, which may exceed what a surface can
physically be; povlens clips it with a ``LensClipWarning`` per row.  The entries of
``lentil-lenses-subset.json`` are converted to Kolb files here; the clipping itself is
also tested on small hand-made lenses.
"""

from __future__ import annotations

import json
import math
import re
import warnings

import numpy as np
import pytest

from povlens.errors import LensClipWarning, LensFileError
from povlens.lens.focus import thick_lens_film_distance_mm
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import clip_to_physical_apertures, parse_lens_text, read_lens
from povlens.lens.tracer import trace_from_film, trace_from_scene
from povlens.pupil.build import build_pupil_table

from conftest import ROOT, SHIPPED_LENSES

#: Eight entries of the lentil database (provenance in tests/data/README.md).
LENTIL = ROOT / "tests" / "data" / "lentil-lenses-subset.json"
ENTRIES = json.loads(LENTIL.read_text())

#: lentil writes flat faces (and the iris) with a radius of 9999 or more.
FLAT_RADIUS_MM = 9999.0

#: Rows clipped on reading, and to what diameter (mm): both faces across an air gap
#: whose housing diameters overlap.
EXPECTED_CLIPS = {
    "0004": {10: 48.8882, 11: 48.8882},  # R 188.11 / -323.43, 2.52 mm apart, 50 mm housings
    "0005": {20: 14.3245, 21: 14.3245},  # R 50.377 / -80.749, 0.83 mm apart, 15 mm housings
}


def kolb_text(entry: dict) -> str:
    """A lentil entry's patent prescription as a Kolb/pbrt lens file.

    Rows are the patent's surfaces in order: radius (0 for the iris and for flat faces,
    |R| >= 9999), thickness, index of the medium after (0 for air: ``ior`` None or
    material "air"), aperture diameter (2 x the housing radius) and the Abbe number
    (0 where not given).
    """
    out = [f"# {entry['company']} {entry['product-name']} ({entry.get('patent-number')})",
           "# radius thickness index aperture abbe"]
    for e in entry["optical-elements-patent"]:
        assert e["lens-geometry"] == "spherical"
        iris = e["material"] == "iris"
        radius = 0.0 if iris or abs(e["radius"]) >= FLAT_RADIUS_MM else float(e["radius"])
        air = iris or e["ior"] is None or e["material"] == "air"
        index = 0.0 if air else float(e["ior"])
        abbe = float(e["abbe"] or 0.0)
        out.append(f"{radius!r} {float(e['thickness'])!r} {index!r} "
                   f"{2.0 * float(e['housing-radius'])!r} {abbe!r}")
    return "\n".join(out) + "\n"


def read_recording(path):
    """(lens, the LensClipWarnings read_lens issued)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        lens = read_lens(path)
    clips = [w.message for w in caught if issubclass(w.category, LensClipWarning)]
    assert len(clips) == len(caught), [str(w.message) for w in caught]
    return lens, clips


def clipped_rows(clips) -> dict[int, float]:
    """Row -> clipped diameter (mm) from the warnings' text."""
    out = {}
    for m in clips:
        found = re.search(r": row (\d+): aperture diameter \S+ mm clipped to (\S+) mm", str(m))
        assert found, str(m)
        row = int(found.group(1))
        assert row not in out, f"row {row} warned twice"
        out[row] = float(found.group(2))
    return out


@pytest.fixture(scope="module")
def lentil_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("lentil")
    for key, entry in ENTRIES.items():
        (d / f"{key}.dat").write_text(kolb_text(entry))
    return d


def test_the_subset_is_there():
    assert len(ENTRIES) == 8, LENTIL


@pytest.mark.parametrize("key", sorted(ENTRIES))
def test_published_lens_loads_with_clip_warnings_where_clipped(lentil_dir, key):
    path = lentil_dir / f"{key}.dat"
    lens, clips = read_recording(path)
    expected = EXPECTED_CLIPS.get(key, {})
    rows = clipped_rows(clips)
    assert sorted(rows) == sorted(expected)
    for row, diameter in expected.items():
        assert rows[row] == pytest.approx(diameter, abs=1e-4)
        assert lens.aperture_diameter_mm[row] == pytest.approx(diameter, abs=1e-4)
    for m in clips:  # the file, its line and the housing reading are named
        assert str(m).startswith(f"{path}:") and "housing" in str(m)
    stated = [2.0 * e["housing-radius"] for e in ENTRIES[key]["optical-elements-patent"]]
    untouched = [i for i in range(lens.n_surfaces) if i not in expected]
    np.testing.assert_array_equal(lens.aperture_diameter_mm[untouched],
                                  np.asarray(stated)[untouched])
    assert lens.is_aperture.sum() == 1  # the iris is the one stop


@pytest.mark.parametrize("key", sorted(ENTRIES))
def test_published_lens_paraxial_data_match_the_database(lentil_dir, key):
    lens, _ = read_recording(lentil_dir / f"{key}.dat")
    p = paraxial_data(lens)
    values = [v for v in vars(p).values() if isinstance(v, float)]
    assert all(math.isfinite(v) for v in values), p
    entry = ENTRIES[key]
    # Within 2 % of the patent's focal length or of lentil's raytraced one (the
    # Petzval 0003 and the Canon 0005 differ from their patents' figures by 14 % and 7 %).
    errors = [abs(p.efl / float(entry[k]) - 1.0)
              for k in ("focal-length-mm-patent", "focal-length-mm-raytraced")]
    assert min(errors) < 0.02, (p.efl, errors)
    assert p.f_number > 0 and p.stop_is_aperture


@pytest.mark.parametrize("key", sorted(ENTRIES))
def test_published_lens_traces_and_builds_a_pupil_table(lentil_dir, key):
    lens, _ = read_recording(lentil_dir / f"{key}.dat")
    p = paraxial_data(lens)
    film = thick_lens_film_distance_mm(lens, math.inf, p)
    assert film > 0
    # On axis, from the film centre and from the scene (a pencil within the pupil).
    assert trace_from_film(lens, film, [[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]]).passed[0]
    h = 0.25 * p.entrance_pupil_diameter * np.linspace(-1.0, 1.0, 9)
    o = np.column_stack([h, np.zeros_like(h), np.full_like(h, film + p.total_track + 50.0)])
    d = np.tile([0.0, 0.0, -1.0], (len(h), 1))
    res = trace_from_scene(lens, film, o, d)
    assert res.passed.all(), res.blocked_at
    # The pupil table, at infinity focus, for a 35 mm-diagonal film scaled to the focal
    # length (35 mm for 50 mm).
    half_diagonal = 0.5 * 35.0 * p.efl / 50.0
    table = build_pupil_table(lens, film, half_diagonal)
    radii = np.array([0.0, 0.5, 0.9]) * table.max_film_radius_mm  # 0003 vignettes at 27.5 mm
    pf = table.pass_fraction(radii, n_samples=256, seed=1)
    assert pf.fraction[0] > 0 and np.all(pf.fraction > 0), pf.fraction


# ----- the clipping on hand-made lenses ---------------------------------------------------

def parse_recording(text, source="hand.dat"):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        lens = parse_lens_text(text, source)
    assert all(issubclass(w.category, LensClipWarning) for w in caught)
    return lens, [w.message for w in caught]


def test_an_aperture_beyond_the_sphere_is_clipped_to_the_hemisphere():
    # 26.24 mm on a 13.03 mm radius: the cap ends at 26.06 mm (the flat back face
    # is 14 mm behind, so it does not limit it further).
    lens, clips = parse_recording("13.03 14 1.5 26.24\n0 30 0 20\n")
    assert clipped_rows(clips) == {0: pytest.approx(26.06)}
    assert str(clips[0]).startswith("hand.dat:1: row 0:")
    assert "sphere of radius 13.03 mm" in str(clips[0])
    assert lens.aperture_diameter_mm[0] == 26.06 and lens.aperture_diameter_mm[1] == 20.0
    assert trace_from_film(lens, 30.0, [[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]]).passed[0]


def test_caps_of_an_element_that_cross_are_clipped_to_its_edge():
    # Biconvex R 10 / -10, 1 mm thick: the faces meet where each sag is 0.5 mm,
    # r^2 = 2 R s - s^2 = 9.75 mm^2.
    with pytest.warns(LensClipWarning) as record:
        lens = parse_lens_text("# a lens\n10 1 1.5 16\n-10 30 1 16\n", "hand.dat")
    edge = 2.0 * math.sqrt(9.75)
    assert len(record) == 2
    assert [str(w.message).split(": row")[0] for w in record] == ["hand.dat:2", "hand.dat:3"]
    assert all("faces of the element" in str(w.message) for w in record)
    np.testing.assert_allclose(lens.aperture_diameter_mm, [edge, edge], rtol=1e-12)
    paraxial_data(lens)


def test_caps_that_cross_an_air_gap_are_clipped_where_they_touch():
    # R +20 then R -20, 0.5 mm of air between: they touch where each sag is 0.25 mm.
    lens, clips = parse_recording("0 5 1.5 20\n20 0.5 0 20\n-20 5 1.5 20\n0 30 0 20\n")
    touch = 2.0 * math.sqrt(2 * 20 * 0.25 - 0.25 ** 2)
    assert clipped_rows(clips) == {1: pytest.approx(touch, abs=1e-4),
                                   2: pytest.approx(touch, abs=1e-4)}
    assert "across the air gap" in str(clips[0]) and "row 2 (line 3)" in str(clips[0])
    np.testing.assert_allclose(lens.aperture_diameter_mm, [20, touch, touch, 20], rtol=1e-12)


def test_a_cap_reaching_through_the_stop_is_clipped_and_the_stop_is_not():
    # The cap behind the stop curves 1.2702 mm toward it at r = 10 mm, 1.25 mm away:
    # 0.02 mm past the stop's plane at its rim.  The stop keeps its 20 mm (issue 26:
    # the stop as published); the glass ends where it meets the stop's plane.
    text = "50 5 1.5 20\n-50 5 0 20\n0 1.25 0 20\n-40 5 1.5 20\n-20 40 0 24\n"
    lens, clips = parse_recording(text)
    rows = clipped_rows(clips)
    assert sorted(rows) == [3]
    meet = 2.0 * math.sqrt(2 * 40 * 1.25 - 1.25 ** 2)
    assert rows[3] == pytest.approx(meet, abs=1e-4)
    assert lens.aperture_diameter_mm[2] == 20.0
    assert paraxial_data(lens).stop_diameter == 20.0


def test_the_biotar_keeps_its_published_stop_and_f_number():
    """lentil 0009, Zeiss Biotar (1927): the rim of the glass before the stop crosses
    the stop's plane.  Optical-design programs give f/1.4367 with the stop as
    published (45 mm); shrinking the stop to the glass rim gave 44.947 mm, f/1.4384."""
    from povlens.lens.import_lentil import read_lentil
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lens = read_lentil(ROOT / "tests" / "data" / "lentil-lenses.json", "0009")
    p = paraxial_data(lens)
    assert p.stop_diameter == 45.0
    assert p.f_number == pytest.approx(1.4367, abs=5e-5)


def test_clipping_is_where_the_faces_meet_and_no_further():
    lens, _ = parse_recording("10 1 1.5 16\n-10 30 1 16\n")
    r = lens.aperture_radius_mm[0]
    gap = 1.0 - 2.0 * (10.0 - math.sqrt(100.0 - r * r))
    assert 0.0 <= gap < 1e-12


def test_a_lens_needing_no_clipping_warns_nothing_and_is_unchanged():
    text = "50 5 1.5168 20\n-50 2 0 20\n0 40 0 10\n"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        lens = parse_lens_text(text, "fine.dat")
        assert clip_to_physical_apertures(lens) is lens
    np.testing.assert_array_equal(lens.aperture_diameter_mm, [20.0, 20.0, 10.0])


@pytest.mark.parametrize("name", SHIPPED_LENSES)
def test_shipped_lenses_need_no_clipping(name):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        lens = read_lens(name)
        assert clip_to_physical_apertures(lens) is lens


@pytest.mark.parametrize("text, line, words", [
    # caps that cross from the axis on (no air between them): no light passes
    ("50 5 1.5 20\n-50 0 0 16\n-20 3 1.6 16\n-30 30 0 16\n", 3,
     "cross inside their clear apertures"),
    ("10 -1 1.5 5\n-10 30 1 5\n", 1, "negative"),
    ("10 2 1.5 8\n-10 30 1.5 8\n", 2, "film must be in air"),
])
def test_what_cannot_be_traced_is_still_refused(text, line, words):
    with pytest.raises(LensFileError, match=words) as e:
        parse_lens_text(text, "bad.dat")
    assert e.value.line == line
