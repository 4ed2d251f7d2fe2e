import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
LENS_DIR = ROOT / "lenses"
SHIPPED_LENSES = sorted(p.name for p in LENS_DIR.glob("*.dat"))


@pytest.fixture
def lens_dir():
    return LENS_DIR
