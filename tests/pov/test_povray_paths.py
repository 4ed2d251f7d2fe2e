"""Paths POV-Ray 3.7 cannot read as written (povlens.pov.povray_paths): spaces, quotes
and non-ASCII characters in the scene's path, its include and library folders and the
user's POV-Ray options.  The real command renders such a scene, and its image equals
the same scene's at a plain path."""

import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from povlens.pov.povray_options import PovrayOptions
from povlens.pov.povray_paths import (command_line_path, include_text, quoted_value,
                                      readable_by_povray)
from povlens.util.images import read_image

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")

SCENE = """#include "colors.inc"
#include "shape.inc"
camera { location <0, 0.5, -4> look_at <0, 0, 0> }
light_source { <3, 4, -3> rgb 1 }
plane { y, -1 pigment { checker rgb 1 rgb 0.2 } }
object { Shape pigment { rgb C } }
"""


def _tree(root, scene_dir: str, lib_dir: str, header_dir: str):
    """The scene, its library folder and a header file under ``root``."""
    (root / scene_dir).mkdir(parents=True)
    (root / lib_dir).mkdir(parents=True)
    (root / header_dir).mkdir(parents=True)
    scene = root / scene_dir / "scène.pov" if not scene_dir.isascii() else root / scene_dir / "s.pov"
    scene.write_text(SCENE)
    (root / lib_dir / "shape.inc").write_text("#declare Shape = sphere { 0, 1 }\n")
    (root / header_dir / "c.inc").write_text("#declare C = <1, 0.3, 0.1>;\n")
    return scene, root / lib_dir, root / header_dir / "c.inc"


def _render(scene, lib, header, out, method):
    cmd = [sys.executable, "-m", "povlens", "render", str(scene), "--lens", "dgauss.50mm",
           "--focus", "4", "--method", method, "--samples", "2", "--width", "32",
           "--height", "24", "--library-path", str(lib),
           "--povray-option", f"Include_Header={header}", "-q", "-o", str(out)]
    r = subprocess.run(cmd, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return read_image(out / "image.exr")


@pytest.mark.parametrize("method", ["pinhole", "mesh"])
def test_a_scene_under_spaces_and_non_ascii_renders_as_at_a_plain_path(tmp_path, method):
    odd = _tree(tmp_path / "my scenes", "ünï dir", "lib ünï", "hdr dir")
    plain = _tree(tmp_path / "plain", "scene", "lib", "hdr")
    a = _render(*odd, tmp_path / "out ü", method)
    b = _render(*plain, tmp_path / "out", method)
    np.testing.assert_array_equal(a, b)
    assert a.mean() > 0.05                                # the sphere and the plane, lit


def test_paths_and_values_as_povray_reads_them(tmp_path):
    assert readable_by_povray("/usr/share/povray-3.7/include")
    assert not readable_by_povray("/a dir") and not readable_by_povray("/ünï")
    assert command_line_path("/a dir") == '"/a dir"'
    odd = tmp_path / "ünï"
    odd.mkdir()
    alias = command_line_path(odd)
    assert readable_by_povray(alias) and os.path.realpath(alias) == str(odd)
    assert command_line_path(odd) == alias                 # the same link every time
    assert quoted_value("a b") == '"a b"' and quoted_value('"a b"') == '"a b"'
    opts = PovrayOptions(library_paths=[str(tmp_path)], extra_options=["Declare=X=1",
                                                                      "+HIa b.inc"])
    assert opts.switches()[-1] == '+HI"a b.inc"'
    scene = odd / "scène.pov"
    scene.write_text("")
    text = include_text(scene, tmp_path, tmp_path / "link.pov")
    assert text == "link.pov" and os.path.realpath(tmp_path / text) == str(scene)
    assert include_text(tmp_path / "plain.pov", tmp_path / "sub", tmp_path / "x") == \
        "../plain.pov"
