"""The command line imports lazily what a command does not need (issue 14: a pinhole
render's overhead).  Checked in a fresh interpreter through sys.modules."""

import json
import shutil
import subprocess
import sys

import pytest

from conftest import ROOT

HEAVY = ("scipy", "matplotlib", "tqdm", "OpenImageIO")


def _imported_after(code: str) -> list[str]:
    """The heavy top-level packages loaded by running ``code`` in a new interpreter."""
    probe = (f"import sys\n{code}\n"
             f"print('MODULES', sorted({{m.split('.')[0] for m in sys.modules}} & {set(HEAVY)!r}))")
    r = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                       cwd=ROOT, timeout=300)
    assert r.returncode == 0, r.stderr
    line = [ln for ln in r.stdout.splitlines() if ln.startswith("MODULES ")][-1]
    return json.loads(line.removeprefix("MODULES ").replace("'", '"'))


@pytest.mark.parametrize("command", ["render", "convert", "plan", "focus", "inspect", "trace",
                                     "check", "lenses", "import-lens", "report", "pupil"])
def test_parsing_a_command_line_imports_no_scipy_oiio_or_tqdm(command):
    assert _imported_after(f"import povlens.cli as c\nc.build_parser({command!r})") == []


def test_focusing_a_lens_needs_no_scipy():
    code = ("import povlens\n"
            "print(povlens.focus('dgauss.50mm', 4, units='m').exact_film_distance_mm)")
    assert _imported_after(code) == []


@pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")
def test_a_pinhole_conversion_imports_no_scipy(tmp_path):
    code = ("from povlens.cli import main\n"
            f"assert main(['convert', 'scenes/paper.pov', '--lens', 'dgauss.50mm', '--method', "
            f"'pinhole', '--width', '16', '--height', '12', '-o', {str(tmp_path / 'o')!r}]) == 0")
    assert _imported_after(code) == []
    assert not (tmp_path / "o" / "pupil.npz").exists()
