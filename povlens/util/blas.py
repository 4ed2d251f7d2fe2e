"""BLAS on one thread while povlens works beside POV-Ray.

povlens's dense linear algebra is small (the field-mesh normal fit factorises at most
600 x 600), and it runs while POV-Ray processes hold every core.  A multi-threaded
OpenBLAS then spreads each call over threads that wait on each other for time slices,
and its idle threads spin after every call, taking CPU from POV-Ray (measured:
docs/decisions/planning.md, "BLAS on one thread").  :func:`single_threaded_blas` limits
every BLAS loaded in the process to one thread for the duration of a povlens call
(threadpoolctl), and a BLAS loaded during it (scipy's own OpenBLAS, for the sparse fit
of a large grid) starts with one thread (``OPENBLAS_NUM_THREADS``); both are restored
afterwards.
"""

from __future__ import annotations

import contextlib
import functools
import os
from typing import Callable, Iterator, TypeVar

__all__ = ["single_threaded_blas", "one_blas_thread"]

F = TypeVar("F", bound=Callable)
#: What an OpenBLAS reads when it is loaded.
_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS",)


@contextlib.contextmanager
def one_blas_thread() -> Iterator[None]:
    """Within the block, BLAS runs on one thread (module docstring)."""
    from threadpoolctl import threadpool_limits
    saved = {k: os.environ.get(k) for k in _THREAD_VARIABLES}
    os.environ.update({k: "1" for k in _THREAD_VARIABLES})
    try:
        with threadpool_limits(limits=1, user_api="blas"):
            yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def single_threaded_blas(fn: F) -> F:
    """Decorate ``fn`` to run within :func:`one_blas_thread`."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with one_blas_thread():
            return fn(*args, **kwargs)
    return wrapper  # type: ignore[return-value]
