"""Interrupts held back while code that would swallow them runs.

scipy's Sobol' initialisation is Cython that reports an exception raised inside it as
"Exception ignored" and goes on, so a Ctrl-C or SIGTERM arriving there would be lost
and the render would run to the end.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from typing import Iterator

__all__ = ["descendants", "interrupts_deferred", "kill_descendants"]

_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def interrupts_deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM during the block; deliver them, in order, after it.

    Only the main thread receives signals; elsewhere the block runs as it is.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    saved = {s: signal.getsignal(s) for s in _SIGNALS}
    saved = {s: h for s, h in saved.items() if h is not None}   # set outside Python: leave
    for s in saved:
        signal.signal(s, lambda signum, frame: pending.append(signum))
    try:
        yield
    finally:
        for s, h in saved.items():
            signal.signal(s, h)
        for signum in pending:
            signal.raise_signal(signum)


def descendants(pid: int | None = None) -> list[int]:
    """PIDs of the processes below ``pid`` (default this one), children first
    (Linux ``/proc/PID/task/*/children``; elsewhere an empty list)."""
    found: list[int] = []
    todo = [os.getpid() if pid is None else pid]
    while todo:
        p = todo.pop()
        try:
            tasks = os.listdir(f"/proc/{p}/task")
        except OSError:
            continue
        for task in tasks:
            try:
                with open(f"/proc/{p}/task/{task}/children") as f:
                    kids = [int(c) for c in f.read().split()]
            except (OSError, ValueError):
                continue
            found += kids
            todo += kids
    return found


def kill_descendants() -> None:
    """SIGKILL every process below this one: the last step of an interrupted command,
    so that no POV-Ray outlives it even if an interrupt landed where its clean-up
    could not see the process (inside ``subprocess.Popen``, say)."""
    for p in descendants():
        try:
            os.kill(p, signal.SIGKILL)
        except OSError:
            pass
