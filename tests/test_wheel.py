"""A built wheel, installed into a fresh virtual environment, renders from a folder
outside the checkout: the package carries its lenses, templates and scenes."""
from __future__ import annotations

import os
import subprocess
import sys
import venv

import pytest

from conftest import ROOT


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("wheel")
    build = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q",
         "-w", str(tmp / "dist"), str(ROOT)], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    wheel = next((tmp / "dist").glob("povlens-*.whl"))
    env_dir = tmp / "venv"
    # the dependencies (numpy, OpenImageIO, ...) come from the system; povlens from the wheel
    venv.EnvBuilder(system_site_packages=True, with_pip=False).create(env_dir)
    python = env_dir / "bin" / "python"
    install = subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps",
         "--force-reinstall", "-q", str(wheel)], capture_output=True, text=True)
    assert install.returncode == 0, install.stderr
    return env_dir, tmp


def _clean_env():
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH",)}
    return env


def test_wheel_carries_its_data(installed):
    env_dir, tmp = installed
    where = subprocess.run(
        [str(env_dir / "bin" / "python"), "-c",
         "import povlens, povlens.util.resources as r; print(povlens.__file__); "
         "print(r.LENS_DIR); print(sorted(p.name for p in r.LENS_DIR.glob('*.dat')))"],
        cwd=tmp, capture_output=True, text=True, env=_clean_env())
    assert where.returncode == 0, where.stderr
    pkg, lens_dir, names = where.stdout.splitlines()
    assert str(env_dir) in pkg and str(ROOT) not in pkg
    assert str(env_dir) in lens_dir
    assert "dgauss.50mm.dat" in names


def test_wheel_renders_a_bundled_scene_from_another_folder(installed):
    env_dir, tmp = installed
    work = tmp / "elsewhere"
    work.mkdir()
    run = subprocess.run(
        [str(env_dir / "bin" / "povlens"), "render", "paper", "--lens", "dgauss.50mm",
         "--focus", "4", "--method", "mesh", "--samples", "2", "--width", "32",
         "--height", "24", "-o", "out", "--quiet"],
        cwd=work, capture_output=True, text=True, env=_clean_env())
    assert run.returncode == 0, run.stderr
    assert (work / "out" / "image.exr").is_file() and (work / "out" / "image.png").is_file()
