"""The tasks a worker process is running, and stopping those of a render that ended.

When a render ends early (a task failed, the user interrupted), the client cancels
its tasks and asks every worker to forget the render
(:func:`povlens.cluster.worker.forget_render`).  Dask does not stop a task already
running in a worker thread, and its POV-Ray processes work in the render's replica:
deleting the replica under them leaves POV-Ray 3.7 spinning at 100 % CPU (deaf to
SIGTERM) and the task's thread waiting for it forever, so the next render on that
worker never starts.  Hence, for every task (:func:`task_running`) the worker records
a stop event and the folder its POV-Ray processes run in, and :func:`stop_tasks`:

1. sets the stop events (no further sample starts:
   :func:`povlens.rendering.mesh_samples.render_samples`' ``stop``);
2. sends SIGTERM to the POV-Ray processes (this process's children working in those
   folders), and SIGKILL to those still alive :data:`TERM_GRACE_S` later; a killed
   POV-Ray fails its sample, which ends the task;
3. waits, at most ``wait_s``, for the tasks to end.

Only then is the replica deleted.  Every wait is bounded; a task still running then
deletes its replica itself when it ends (:func:`task_running`).
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["task_running", "stop_tasks", "povray_children", "TERM_GRACE_S", "STOP_WAIT_S"]

#: Seconds a POV-Ray process gets to exit after SIGTERM before SIGKILL.
TERM_GRACE_S = 1.0
#: Seconds :func:`stop_tasks` waits for the stopped tasks to end.
STOP_WAIT_S = 20.0


@dataclass(eq=False)
class _Task:
    folder: Path                                  # where its POV-Ray processes run
    stop: threading.Event = field(default_factory=threading.Event)
    ended: threading.Event = field(default_factory=threading.Event)


#: Render key -> its tasks running in this process.
_tasks: dict[str, list[_Task]] = {}
#: Keys forgotten while a task of theirs still ran: the last one cleans up.
_forgotten: dict[str, object] = {}
_lock = threading.Lock()


@contextlib.contextmanager
def task_running(key: str, folder: Path):
    """Record a task of render ``key`` whose POV-Ray processes run in ``folder``
    while the ``with`` block runs; yields its stop event.  If the render was
    forgotten while the task ran, the cleanup :func:`stop_tasks` left to it
    (deleting the replica) runs when the last such task ends."""
    task = _Task(Path(folder))
    with _lock:
        _tasks.setdefault(key, []).append(task)
        _forgotten.pop(key, None)          # a new render of the same bundle
    try:
        yield task.stop
    finally:
        with _lock:
            tasks = _tasks.get(key, [])
            if task in tasks:
                tasks.remove(task)
            if not tasks:
                _tasks.pop(key, None)
            cleanup = _forgotten.pop(key, None) if not tasks else None
        task.ended.set()
        if cleanup is not None:
            cleanup()


def povray_children(folders: list[Path]) -> list[int]:
    """Process ids of this process's children (at any depth) whose working folder is
    one of ``folders`` or inside one (Linux: ``/proc/PID/cwd``)."""
    import psutil                            # a dependency of distributed
    roots = [str(Path(f).absolute()) for f in folders]
    pids = []
    try:
        children = psutil.Process().children(recursive=True)
    except psutil.Error:
        return pids
    for child in children:
        try:
            cwd = child.cwd()
        except psutil.Error:                 # gone, or a zombie
            continue
        cwd = cwd.removesuffix(" (deleted)")
        if any(cwd == r or cwd.startswith(r + os.sep) for r in roots):
            pids.append(child.pid)
    return pids


def _alive(pid: int) -> bool:
    """Running (not gone, not a zombie waiting for its parent's ``wait``).  Never
    waits for it: the task's ``Popen`` collects its exit status."""
    import psutil
    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False


def _signal_all(pids: list[int], sig: int) -> None:
    for pid in pids:
        try:
            os.kill(pid, sig)
        except OSError:                      # already gone
            pass


def _terminate(pids: list[int], grace_s: float) -> list[int]:
    """SIGTERM, then SIGKILL for those alive ``grace_s`` later; returns the pids
    still alive after both (none, unless the kernel is slow to reap)."""
    _signal_all(pids, signal.SIGTERM)
    deadline = time.monotonic() + grace_s
    while time.monotonic() < deadline and any(_alive(p) for p in pids):
        time.sleep(0.02)
    stubborn = [p for p in pids if _alive(p)]
    _signal_all(stubborn, signal.SIGKILL)
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline and any(_alive(p) for p in stubborn):
        time.sleep(0.02)
    return [p for p in stubborn if _alive(p)]


def stop_tasks(key: str, cleanup, wait_s: float = STOP_WAIT_S,
               grace_s: float = TERM_GRACE_S) -> dict:
    """Stop the tasks of render ``key`` running in this process (see the module's
    text), then call ``cleanup()`` (delete the replica) once none runs.

    Parameters
    ----------
    key : the render's key.
    cleanup : called once no task of ``key`` runs: here, or by the last task to end
        if some still run after ``wait_s``.
    wait_s : the longest wait for the tasks to end (s).
    grace_s : between SIGTERM and SIGKILL (s).

    Returns
    -------
    dict
        ``tasks`` stopped, ``killed`` (POV-Ray processes signalled), ``left``: tasks
        still running when the wait ended (their last one cleans up).
    """
    with _lock:
        tasks = list(_tasks.get(key, []))
        if tasks:
            _forgotten[key] = cleanup
    for task in tasks:
        task.stop.set()
    killed = []
    deadline = time.monotonic() + wait_s
    while tasks and time.monotonic() < deadline:
        # again and again: a task may start one more POV-Ray before it sees the stop
        pids = povray_children([t.folder for t in tasks if not t.ended.is_set()])
        killed += [p for p in pids if p not in killed]
        _terminate(pids, grace_s)
        if all(t.ended.wait(timeout=0.1) for t in tasks):
            break
    with _lock:
        left = [t for t in tasks if not t.ended.is_set()]
        run_here = not left and _forgotten.pop(key, None) is not None
    if not tasks:
        cleanup()
    elif run_here:
        cleanup()
    return {"tasks": len(tasks), "killed": len(killed), "left": len(left)}
