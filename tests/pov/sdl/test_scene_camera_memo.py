"""parse_scene_camera remembers a scene's camera in the process (a conversion reads it
twice: issue 14), but never past a change of the scene or of a file it includes."""

import numpy as np

import povlens.pov.sdl.scene_camera as sc
from povlens.pov.sdl.scene_camera import parse_scene_camera


def _write(path, text):
    path.write_text(text)
    return path


def test_a_second_read_is_remembered_and_a_copy(tmp_path, monkeypatch):
    scene = _write(tmp_path / "s.pov", "camera { location <0, 1, -5> look_at <0, 1, 0> }\n")
    first = parse_scene_camera(scene, 32, 24)
    reads = []
    real = sc._read_camera
    monkeypatch.setattr(sc, "_read_camera", lambda *a: reads.append(a) or real(*a))
    again = parse_scene_camera(scene, 32, 24)
    assert reads == []                                            # not read again
    np.testing.assert_array_equal(again.location, first.location)
    again.location[0] = 99.0                                      # a copy each call
    assert parse_scene_camera(scene, 32, 24).location[0] == 0.0
    parse_scene_camera(scene, 64, 48)                             # other arguments: read
    assert len(reads) == 1


def test_a_changed_scene_or_include_is_read_again(tmp_path):
    inc = _write(tmp_path / "cam.inc", "#declare Z = -5;\n")
    scene = _write(tmp_path / "s.pov", '#include "cam.inc"\n'
                                       "camera { location <0, 1, Z> look_at <0, 1, 0> }\n")
    assert parse_scene_camera(scene, 32, 24).location[2] == -5.0
    _write(inc, "#declare Z = -6;\n")                             # same size, same moment
    assert parse_scene_camera(scene, 32, 24).location[2] == -6.0
    _write(scene, '#include "cam.inc"\n'
                  "camera { location <0, 2, Z> look_at <0, 1, 0> }\n")
    assert parse_scene_camera(scene, 32, 24).location[1] == 2.0
