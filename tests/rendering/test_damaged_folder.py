"""Damaged files in a render folder (issue 24 item 5): each is validated when read and
either built again or named with what to do, and that advice works with 'make' as
with 'povlens render'; no NaN reaches an image.  The real commands, the real POV-Ray,
small images."""

import shutil
import subprocess
import sys

import numpy as np
import pytest

from povlens.plan.render_folder import RenderFolder
from povlens.plan.schema import read_plan
from povlens.pupil.table import PupilTable
from povlens.rendering.folder_composite import sample_sums
from povlens.rendering.folder_inputs import lens_for, pupil_table_for
from povlens.rendering.groups import group_terms, pack_group, write_group
from povlens.rendering.mesh_samples import mark_batches_done
from povlens.util.images import read_image, write_exr

from conftest import ROOT

pytestmark = pytest.mark.skipif(shutil.which("povray") is None, reason="POV-Ray not installed")

OPTIONS = [str(ROOT / "scenes" / "paper.pov"), "--lens", "dgauss.50mm", "--focus", "4",
           "--method", "mesh", "--width", "48", "--height", "36", "--samples", "4",
           "--batch-size", "2"]


def povlens(*args):
    return subprocess.run([sys.executable, "-m", "povlens", *map(str, args)],
                          capture_output=True, text=True, cwd=ROOT, timeout=600)


def make(out):
    return subprocess.run(["make", "-C", str(out)], capture_output=True, text=True,
                          timeout=600)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """A folder 'povlens render' rendered, and its image."""
    out = tmp_path_factory.mktemp("damaged") / "ref"
    r = povlens("render", *OPTIONS, "-o", out, "-q")
    assert r.returncode == 0, r.stderr
    return out, read_image(out / "image.exr")


@pytest.fixture
def folder(rendered, tmp_path):
    """A copy of the rendered folder to damage, without its image."""
    out = tmp_path / "out"
    shutil.copytree(rendered[0], out)
    f = RenderFolder(out)
    f.image_exr.unlink()
    f.image_png.unlink()
    return f


def assert_named(r, path, *words):
    """Exit 2 naming ``path`` (no 'internal error', no traceback) and ``words``."""
    assert r.returncode == 2, r.stderr
    assert path.name in r.stderr and "internal error" not in r.stderr, r.stderr
    assert "Traceback" not in r.stderr
    for w in words:
        assert w in r.stderr, r.stderr


def assert_image(folder, reference):
    image = read_image(folder.image_exr)
    assert np.isfinite(image).all() and np.array_equal(image, reference)


@pytest.mark.parametrize("damage", ["truncated", "nan"])
def test_a_damaged_pupil_table_is_built_again(folder, rendered, damage):
    data = folder.pupil_npz.read_bytes()
    if damage == "truncated":
        folder.pupil_npz.write_bytes(data[:3000])
    else:
        with np.load(folder.pupil_npz) as z:
            arrays = {k: z[k] for k in z.files}
        arrays["rho"][0, 0] = np.nan
        with open(folder.pupil_npz, "wb") as f:
            np.savez(f, **arrays)
    r = povlens("composite", folder.path)
    assert r.returncode == 0, r.stderr
    assert_image(folder, rendered[1])
    assert np.isfinite(PupilTable.load(folder.pupil_npz).rho).all()    # written again


def test_an_empty_pass_mask_is_named_and_deleting_the_sample_makes_it_again(folder,
                                                                             rendered):
    folder.sample_mask(1).write_bytes(b"")
    assert_named(povlens("composite", folder.path), folder.sample_mask(1),
                 "delete", "sample_0001.*", "make -C")
    for p in folder.samples.glob("sample_0001.*"):      # as the hint says
        p.unlink()
    r = make(folder.path)
    assert r.returncode == 0, r.stderr
    assert "render-batch . 001" in r.stdout and folder.sample_image(1).exists()
    assert_image(folder, rendered[1])
    assert "Nothing to be done" in make(folder.path).stdout


def test_povlens_render_renders_a_damaged_pass_mask_again(folder, rendered):
    folder.sample_mask(1).write_bytes(b"\x93NUMPY")
    r = povlens("render", *OPTIONS, "-o", folder.path, "-q")
    assert r.returncode == 0, r.stderr
    assert_image(folder, rendered[1])


def test_a_stray_blocked_marker_beside_an_image_is_not_trusted(folder, rendered):
    folder.sample_blocked(1).write_text("0 36\n")
    r = povlens("composite", folder.path)
    assert r.returncode == 0, r.stderr
    assert_image(folder, rendered[1])           # was RMSE 0.027: sample 1 taken as black


def test_a_blocked_marker_its_mask_contradicts_is_named_then_rendered_again(folder,
                                                                            rendered):
    folder.sample_image(1).unlink()
    folder.sample_blocked(1).write_text("0 36\n")
    assert_named(povlens("composite", folder.path), folder.sample_blocked(1),
                 "its pass mask passes")
    r = povlens("render", *OPTIONS, "-o", folder.path, "-q")
    assert r.returncode == 0, r.stderr
    assert not folder.sample_blocked(1).exists() and folder.sample_image(1).exists()
    assert_image(folder, rendered[1])


def test_a_truncated_group_file_is_named_and_deleting_it_makes_its_samples_again(
        folder, rendered):
    plan = read_plan(folder.path)
    table = pupil_table_for(folder.path, plan, lens_for(plan))
    sums, blocked = group_terms(folder.path, [0, 1], plan, table, sample_sums)
    group = write_group(folder.path, [0, 1], pack_group([0, 1], sums, blocked))
    for k in (0, 1):                    # as a cluster leaves them: the group, no samples
        for p in folder.samples.glob(f"sample_000{k}.*"):
            p.unlink()
    mark_batches_done(folder.path, plan)
    assert group.name in folder.batch_done(0).read_text()
    group.write_bytes(group.read_bytes()[:2000])
    assert_named(povlens("composite", folder.path), group, "delete it")
    group.unlink()                                      # as the hint says
    r = make(folder.path)
    assert r.returncode == 0, r.stderr
    assert folder.sample_image(0).exists() and folder.sample_image(1).exists()
    assert_image(folder, rendered[1])


def test_nan_in_a_sample_image_never_reaches_the_image(folder, rendered):
    image = read_image(folder.sample_image(2))
    image[3, 4, 1] = np.nan
    write_exr(folder.sample_image(2), image)
    assert_named(povlens("composite", folder.path), folder.sample_image(2),
                 "NaN or infinite", "delete it")
    assert not folder.image_exr.exists()
    for p in folder.samples.glob("sample_0002.*"):
        p.unlink()
    r = make(folder.path)
    assert r.returncode == 0, r.stderr
    assert_image(folder, rendered[1])
