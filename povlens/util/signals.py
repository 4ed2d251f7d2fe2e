"""Interrupts held back while code that would swallow them runs.

scipy's Sobol' initialisation is Cython that reports an exception raised inside it as
"Exception ignored" and goes on, so a Ctrl-C or SIGTERM arriving there would be lost
and the render would run to the end.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from typing import Iterator

__all__ = ["interrupts_deferred"]

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
