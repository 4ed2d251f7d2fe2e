"""Lens samples of the mesh method (povlens.rendering.mesh_samples): batches, several
POV-Ray processes in flight, resuming, reusing the samples a larger plan keeps.  With the
real POV-Ray, small images."""

import shutil

import numpy as np
import pytest

from povlens.plan.convert import convert
from povlens.rendering.driver import render_outdir
from povlens.rendering.folder_composite import composite_outdir
from povlens.rendering.mesh_samples import render_batch
from povlens.util.images import read_image

from conftest import paper_options

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")


def test_interrupted_render_resumes_to_the_same_image(tmp_path):
    full = tmp_path / "full"
    convert(paper_options(tmp_path, outdir=str(full)))
    render_outdir(full, jobs=1, quiet=True)
    reference = read_image(full / "image.exr")

    part = tmp_path / "part"
    convert(paper_options(tmp_path, outdir=str(part)))
    render_batch(part, 0)                              # the run stops after one batch ...
    (part / "samples" / "sample_0002.exr").unlink()    # ... and one sample of it is lost
    render_outdir(part, jobs=2, quiet=True)            # re-run
    np.testing.assert_array_equal(read_image(part / "image.exr"), reference)


def test_samples_in_flight_render_the_same_image_as_one_at_a_time(tmp_path):
    one = tmp_path / "one"
    convert(paper_options(tmp_path, outdir=str(one), samples=6, batch_size=6))
    render_batch(one, 0, in_flight=1)
    many = tmp_path / "many"
    convert(paper_options(tmp_path, outdir=str(many), samples=6, batch_size=6))
    render_batch(many, 0, in_flight=6)
    rendered = 0
    for k in range(6):
        name = f"samples/sample_{k:04d}.exr"
        assert (many / name).exists() == (one / name).exists()   # or both all blocked
        if (one / name).exists():
            np.testing.assert_array_equal(read_image(many / name), read_image(one / name))
            rendered += 1
    assert rendered >= 4
    # the meshes and the per-sample temporary folders are gone
    assert not list((many / "samples").glob("*.inc"))
    assert not list((many / "samples").glob(".sample_*"))


def test_more_samples_reuse_the_rendered_ones(tmp_path):
    """Raising N keeps samples 0..N-1 (Sobol point k does not depend on N): only the
    new samples are traced and rendered, and the image equals a fresh render."""
    out = tmp_path / "out"
    convert(paper_options(tmp_path, samples=3, batch_size=3))
    render_outdir(out, jobs=1, quiet=True)
    s = out / "samples"
    before = {k: (s / f"sample_{k:04d}.exr").stat().st_mtime_ns for k in range(3)}
    convert(paper_options(tmp_path, samples=5, batch_size=5))
    assert not (out / "image.exr").exists()
    assert (out / "exposure.txt").exists()
    rendered = render_batch(out, 0)
    assert rendered == [3, 4]
    assert {k: (s / f"sample_{k:04d}.exr").stat().st_mtime_ns for k in range(3)} == before
    composite_outdir(out)
    fresh = tmp_path / "fresh"
    convert(paper_options(tmp_path, outdir=str(fresh), samples=5, batch_size=5))
    render_outdir(fresh, jobs=1, quiet=True)
    np.testing.assert_array_equal(read_image(out / "image.exr"), read_image(fresh / "image.exr"))
    # a change that alters every sample (the seed) drops them all
    convert(paper_options(tmp_path, samples=5, batch_size=5, seed=3))
    assert not list(s.glob("sample_*.exr")) and not (out / "exposure.txt").exists()
