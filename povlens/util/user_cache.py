"""The user's cache folder: results that cost start-up time and never change.

``$XDG_CACHE_HOME/povlens/`` (default ``~/.cache/povlens``).  Every entry is an
optimisation only: a folder that cannot be written, or an entry that is missing or
damaged, means the value is computed again, without a word.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Callable

import numpy as np

from povlens.errors import PovlensError
from povlens.util.files import atomic_output

__all__ = ["cache_folder", "cached_array"]


def cache_folder() -> Path:
    """``$XDG_CACHE_HOME/povlens`` (default ``~/.cache/povlens``); not created here."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "povlens"


def cached_array(name: str, make: Callable[[], np.ndarray],
                 valid: Callable[[np.ndarray], bool]) -> np.ndarray:
    """The array ``make()`` returns, kept in the cache as ``name`` (a ``.npy`` file).

    Parameters
    ----------
    name : str
        The entry's file name; it must say everything the array depends on (the
        library's version, the parameters).
    make : callable
        Computes the array when the entry is missing or fails ``valid``.
    valid : callable
        Whether an array read back is the one ``make`` would return (shape, range).

    Returns
    -------
    numpy.ndarray
        Read from the cache, or made (and then stored, if the folder can be written).
    """
    path = cache_folder() / name
    try:
        found = np.load(path, allow_pickle=False)
        if valid(found):
            return found
    except (OSError, ValueError, EOFError):
        pass
    array = make()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_output(path) as tmp:
            with open(tmp, "wb") as f:
                np.save(f, array, allow_pickle=False)
    except (OSError, PovlensError):   # read-only, full: the cache is only an optimisation
        pass
    return array
