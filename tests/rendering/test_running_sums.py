"""The composite's sums taken while the samples render (povlens.rendering.running_sums):
the same image bit for bit as a composite reading the samples after; a damaged sample
leaves it without a result and the composite names the file.  With the real POV-Ray."""

import shutil
import time

import numpy as np
import pytest

from povlens.errors import PovlensError
from povlens.plan.convert import convert
from povlens.plan.schema import read_plan
from povlens.rendering import driver
from povlens.rendering.driver import render_outdir
from povlens.rendering.folder_composite import composite_outdir
from povlens.rendering.folder_inputs import lens_for, pupil_table_for
from povlens.rendering.running_sums import RunningSums
from povlens.util.images import read_image

from conftest import paper_options

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")


def test_the_running_sums_give_the_composite_bit_for_bit(tmp_path, monkeypatch):
    results = []

    class Spy(RunningSums):
        def result(self):
            results.append(super().result())
            return results[-1]
    monkeypatch.setattr(driver, "RunningSums", Spy)
    convert(paper_options(tmp_path, samples=6, batch_size=6, width=64, height=48))
    out = tmp_path / "out"
    render_outdir(out, jobs=2, quiet=True)
    assert len(results) == 1 and results[0] is not None     # the render used them
    written = read_image(out / "image.exr")[..., :3]
    after = composite_outdir(out, write=False)              # reading the samples
    assert after.max() > 0
    assert np.array_equal(written, after.astype(np.float32))


def test_a_damaged_sample_leaves_no_sums_and_the_composite_names_it(tmp_path):
    convert(paper_options(tmp_path, samples=3, batch_size=3))
    out = tmp_path / "out"
    render_outdir(out, jobs=2, quiet=True)
    plan = read_plan(out)
    table = pupil_table_for(out, plan, lens_for(plan))
    assert RunningSums(out, plan, table).result() is not None
    image = out / "samples" / "sample_0001.exr"
    image.write_bytes(b"not an image")
    assert RunningSums(out, plan, table).result() is None
    with pytest.raises(PovlensError, match="sample_0001.exr"):
        composite_outdir(out, write=False)


def test_samples_that_never_come_end_it_without_a_result(tmp_path):
    convert(paper_options(tmp_path, samples=2, batch_size=2))
    out = tmp_path / "out"
    plan = read_plan(out)
    table = pupil_table_for(out, plan, lens_for(plan))
    t = time.perf_counter()
    running = RunningSums(out, plan, table)
    assert running.result() is None                 # nothing rendered: it does not wait
    stopped = RunningSums(out, plan, table)
    stopped.stop()
    assert not stopped.thread.is_alive() and stopped.result() is None
    assert time.perf_counter() - t < 5
