"""The user's cache (povlens.util.user_cache): Sobol' blocks read back equal to scipy's,
damaged entries made again, an unwritable cache folder harmless."""

from __future__ import annotations

import numpy as np

from povlens.pupil import monte_carlo
from povlens.pupil.monte_carlo import sobol_points
from povlens.util.user_cache import cache_folder


def _scipy(n, d, seed):
    from scipy.stats import qmc
    m = max(0, int(np.ceil(np.log2(n))))
    return np.minimum(qmc.Sobol(d=d, scramble=True, seed=seed).random_base2(m)[:n],
                      np.nextafter(1.0, 0.0))


def test_cached_sobol_points_are_scipys(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    fresh = monte_carlo._cached_sobol_block.cache_clear     # as a new process would start
    fresh()
    first = sobol_points(300, 3, seed=7)                    # made and stored
    (entry,) = cache_folder().glob("sobol-d3-seed7-m9-*.npy")
    entry.unlink()
    assert np.array_equal(sobol_points(300, 3, seed=7), first)  # kept in memory
    assert not entry.exists()
    fresh()
    first = sobol_points(300, 3, seed=7)                    # made and stored again
    fresh()
    again = sobol_points(300, 3, seed=7)                    # read back
    assert np.array_equal(first, _scipy(300, 3, 7)) and np.array_equal(again, first)
    np.save(entry, np.full((512, 3), 2.0))                  # damaged: out of range
    fresh()
    assert np.array_equal(sobol_points(300, 3, seed=7), first)
    entry.write_bytes(b"not an array")
    fresh()
    assert np.array_equal(sobol_points(300, 3, seed=7), first)
    assert np.load(entry).shape == (512, 3)                  # written again
    fresh()


def test_an_unwritable_cache_folder_is_harmless(tmp_path, monkeypatch):
    blocked = tmp_path / "file"
    blocked.write_text("a file where the cache folder would be")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocked))
    assert np.array_equal(sobol_points(100, 2, seed=1), _scipy(100, 2, 1))


def test_big_blocks_are_not_cached(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    n = 2 ** monte_carlo.CACHED_SOBOL_LOG2 + 1
    assert sobol_points(n, 2, seed=0).shape == (n, 2)
    assert not list(tmp_path.rglob("*.npy"))
