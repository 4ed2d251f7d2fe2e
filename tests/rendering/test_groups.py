"""Groups of lens samples (povlens.rendering.groups): cutting, sizes, files, float32
partial sums.  No POV-Ray (the cluster tests render groups: tests/cluster)."""

from __future__ import annotations

import numpy as np
import pytest

from povlens.errors import PovlensError
from povlens.plan.render_folder import RenderFolder
from povlens.rendering.groups import (GROUP_MAX, UnitSums, choose_group_size, chunk_groups,
                                      load_group, pack_group, write_group)


def test_groups_are_runs_of_consecutive_samples_at_most_size_long():
    assert chunk_groups([0, 1, 2, 3, 4, 5, 6], 3) == [[0, 1, 2], [3, 4, 5], [6]]
    assert chunk_groups([0, 2, 3, 5, 6, 7, 8], 3) == [[0], [2, 3], [5, 6, 7], [8]]
    assert chunk_groups([], 4) == []


@pytest.mark.parametrize("samples, workers, size", [
    (16, 2, 4), (64, 2, GROUP_MAX), (64, 8, 6), (256, 10, 13), (256, 100, 12), (3, 2, 2),
    (1, 1, 1), (6, 2, 2), (4096, 1000, GROUP_MAX)])
def test_the_group_size_balances_workers_and_the_client(samples, workers, size):
    assert choose_group_size(samples, workers) == size


def test_group_files_are_found_by_name_and_overlaps_left_out(tmp_path):
    (tmp_path / "samples").mkdir()
    for ks in ([0, 1, 2], [3, 4], [2, 3]):           # the last overlaps both
        write_group(tmp_path, ks, pack_group(ks, None, list(ks)))
    (tmp_path / "samples" / ".group_0005_0006.123.tmp.npz").write_bytes(b"")  # being written
    folder = RenderFolder(tmp_path)
    assert [(a, b) for a, b, _ in folder.group_files()] == [(0, 3), (3, 5)]
    assert folder.grouped(4) and not folder.grouped(5)
    assert folder.sample_done(4) and not folder.sample_done(5)
    assert load_group(tmp_path / "samples" / "group_0000_0003.npz") is None   # all blocked


def test_a_float32_partial_is_within_its_rounding_of_the_float64_sums(tmp_path):
    rng = np.random.default_rng(1)
    total = rng.random((6, 5, 3)) * 40
    wsum = rng.random((6, 5)) * 7
    (tmp_path / "samples").mkdir()
    path = write_group(tmp_path, [4, 5], pack_group([4, 5], (total, wsum), []))
    t, w = load_group(path)
    assert t.dtype == np.float64 and t.shape == (6, 5, 3) and w.shape == (6, 5)
    assert np.all(np.abs(t - total) <= 2.0 ** -24 * np.abs(total))
    assert np.all(np.abs(w - wsum) <= 2.0 ** -24 * np.abs(wsum))
    assert not np.array_equal(t, total)              # it is float32: rounded


def test_units_are_added_in_sample_order_whatever_the_arrival_order():
    terms = {(0, 2): (np.full((1, 1, 4), 1e16), np.ones((1, 1))),
             (2, 3): (np.full((1, 1, 4), 1.0), np.ones((1, 1))),
             (3, 5): (np.full((1, 1, 4), -1e16), np.ones((1, 1)))}
    sums = UnitSums(5, lambda k0, k1: terms[(k0, k1)])
    sums.add(3, 5)
    sums.add(2, 3)
    with pytest.raises(PovlensError, match="lens sample 0 never came back"):
        sums.result("o")
    sums.add(0, 2)
    total, wsum = sums.result()
    # (1e16 + 1) - 1e16 in float64 is 0: the order is the sample order, not arrival's
    assert total.shape == (1, 1, 3) and total[0, 0, 0] == 0.0 and wsum[0, 0] == 3.0


def test_a_damaged_group_file_names_itself(tmp_path):
    (tmp_path / "samples").mkdir()
    path = write_group(tmp_path, [0], b"PK not a zip")
    with pytest.raises(PovlensError, match="group_0000_0001.npz: cannot read") as e:
        load_group(path)
    assert "delete it" in e.value.hint
