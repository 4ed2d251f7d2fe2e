"""Threads: a function run in the background while the caller goes on."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Callable

__all__ = ["run_in_background"]


def run_in_background(fn: Callable):
    """Run ``fn()`` in a thread; returns a function that waits for its result (or
    raises its exception)."""
    pool = ThreadPoolExecutor(max_workers=1)
    future = pool.submit(fn)
    pool.shutdown(wait=False)
    return future.result
