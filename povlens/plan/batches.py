"""Lens-sample batches: the samples each ``povlens render-batch`` renders."""

from __future__ import annotations

import math
import os

__all__ = ["round_robin_batches"]


def round_robin_batches(n_samples: int, batch_size: int | None = None) -> list[list[int]]:
    """Lens samples 0..n-1 dealt round-robin to batches of at most ``batch_size``.

    A batch is the work of one ``povlens render-batch`` (make runs them in
    parallel); the default is one batch per core.  Round-robin spreads the
    samples a smaller count renders first (0..n-1, the same for any count), and
    adaptive plans' later samples, which render fewer rows, evenly over the
    batches.

    Returns
    -------
    list of list of int
        Batch b holds samples b, b + nb, b + 2 nb, ... (nb batches).
    """
    bs = batch_size or math.ceil(n_samples / (os.cpu_count() or 1))
    nb = math.ceil(n_samples / bs)
    return [list(range(b, n_samples, nb)) for b in range(nb)]
