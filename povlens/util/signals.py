"""Interrupts held back while code that would swallow them runs, and the processes
below this one stopped when a command ends.

scipy's Sobol' initialisation is Cython that reports an exception raised inside it as
"Exception ignored" and goes on, so a Ctrl-C or SIGTERM arriving there would be lost
and the render would run to the end.

Child processes are started inside :func:`starting_process`; :func:`kill_descendants`
takes the same lock, so a thread that is starting POV-Ray while the command ends
either finishes the start first (and its process is killed) or is refused
(:class:`ProcessesStopped`): none is started after the last look.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from typing import Iterator

__all__ = ["descendants", "interrupts_deferred", "kill_descendants", "starting_process",
           "ProcessesStopped"]

_SIGNALS = (signal.SIGINT, signal.SIGTERM)

#: Held while a child process starts, and by :func:`kill_descendants`.
_START_LOCK = threading.Lock()
#: Set by :func:`kill_descendants`: no process may start after it.
_stopped = False


class ProcessesStopped(RuntimeError):
    """A process start refused: the command is ending and has stopped its processes."""


@contextlib.contextmanager
def starting_process() -> Iterator[None]:
    """Hold during the start of a child process (the ``subprocess.Popen`` call).

    Raises
    ------
    ProcessesStopped
        After :func:`kill_descendants` ran: the command is ending.
    """
    with _START_LOCK:
        if _stopped:
            raise ProcessesStopped("the command is ending: no new process is started")
        yield


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
    (Linux ``/proc/PID/task/*/children``; elsewhere an empty list).  Zombies (exited,
    not yet reaped) are listed too."""
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


def _running(pid: int) -> bool:
    """True unless process ``pid`` is gone or a zombie (its state in /proc/PID/stat)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            state = f.read().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


def kill_descendants(rounds: int = 50) -> None:
    """SIGKILL every process below this one: the last step of a command that ends by an
    interrupt or an error, so that no POV-Ray outlives it even if an interrupt landed
    where its clean-up could not see the process (inside ``subprocess.Popen``, or in a
    thread that was starting the depth probe's renders).

    Afterwards no process starts (:func:`starting_process` refuses).  It looks again
    until nothing below this process runs (at most ``rounds`` looks, 10 ms apart): a
    process killed between fork and exec may leave a child of its own.
    """
    global _stopped
    with _START_LOCK:
        _stopped = True
        for _ in range(rounds):
            alive = [p for p in descendants() if _running(p)]
            if not alive:
                return
            for p in alive:
                try:
                    os.kill(p, signal.SIGKILL)
                except OSError:
                    pass
            time.sleep(0.01)
