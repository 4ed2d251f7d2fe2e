import os
import pathlib

import pytest
from hypothesis import settings

# The property-based stress tests (test_stress.py) draw the same examples on every
# run, so the suite (and CI) passes or fails reproducibly; HYPOTHESIS_PROFILE=explore
# draws new random examples each run (a failure prints the example to reproduce).
settings.register_profile("deterministic", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "deterministic"))

ROOT = pathlib.Path(__file__).resolve().parent.parent
LENS_DIR = ROOT / "lenses"
SHIPPED_LENSES = sorted(p.name for p in LENS_DIR.glob("*.dat"))
#: The rotationally symmetric ones: the radial exit-pupil table's (an anamorphic lens
#: gets the grid table, tests/pupil/test_grid_table.py, lentil 2004 = anamorphic.60mm).
ROUND_LENSES = [n for n in SHIPPED_LENSES if "#!toric" not in (LENS_DIR / n).read_text()]


def paper_options(tmp_path, **kw):
    """A small mesh conversion of the bundled paper scene through dgauss.50mm (48x36,
    4 samples in batches of 2, into ``tmp_path/out``); ``kw`` changes any option."""
    from povlens.plan.options import ConvertOptions
    base = dict(method="mesh", scene=str(ROOT / "scenes" / "paper.pov"), lens="dgauss.50mm",
                focus=4.0, outdir=str(tmp_path / "out"), width=48, height=36, samples=4,
                batch_size=2)
    base.update(kw)
    return ConvertOptions.of(**base)


@pytest.fixture
def lens_dir():
    return LENS_DIR
