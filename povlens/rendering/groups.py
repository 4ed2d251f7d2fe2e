"""Groups of lens samples summed where they render: partial sums of the composite.

A distributed render (:mod:`povlens.cluster`) sends a *group* of consecutive lens
samples ``k0 .. k1-1`` to a worker, which renders them and adds their terms of the
composite's sums (:func:`povlens.rendering.folder_composite.sample_sums`, float64, in
sample order) into one partial sum.  The client keeps it as ``samples/group_K0_K1.npz``
(:meth:`~povlens.plan.render_folder.RenderFolder.group_file`; written atomically,
:func:`pack_group`):

* ``total`` (H, W, 3) float32, ``sum_k w_k I_k`` over the group's samples (the colour
  channels only: the composite reads no others);
* ``wsum`` (H, W) float32 ``sum_k w_k`` ((H, W, 4) with ``--dispersion``);
* ``samples`` (n,) int64, the group's sample numbers; ``blocked``: those whose rays
  were all blocked (no image, weight 0).

float32 because a partial is 16 bytes a pixel where a sample's EXR is ~6 bits
compressed: float64 would double what every group sends back, and the float32
rounding of a partial (relative 6e-8) is that of the float32 ``image.exr`` itself
(measured: docs/decisions/cluster.md).

A render folder then holds *units*: groups, and single samples rendered one by one
(``sample_KKKK.*``: a local render, ``make``, a cluster render with group size 1).
:func:`render_units` lists them and what is left to render; a sample a group covers
counts as rendered (:meth:`~povlens.plan.render_folder.RenderFolder.sample_done`), so a
local resume, ``make`` and ``povlens composite`` skip it, and :func:`group_sums` gives
``composite_outdir`` the sums, units added in the order of their first sample.
With single samples only, that order is the sample order of a local composite, so
the sums are its sums bit for bit.
"""

from __future__ import annotations

import io
import math
import os
import zipfile
import zlib
from pathlib import Path

import numpy as np

from povlens.errors import PovlensError
from povlens.plan.render_folder import RenderFolder
from povlens.util.files import write_bytes

__all__ = ["GROUP_MAX", "render_units", "chunk_groups", "choose_group_size", "GroupSums",
           "group_terms", "pack_group", "write_group", "load_group", "UnitSums", "unit_terms",
           "group_sums"]

#: What to do about a damaged group file (``make`` renders a batch again when a file
#: its marker lists is gone).
_GROUP_REDO = ("delete it and render again ('povlens render' with the same options, or "
               "'make' in the folder): its samples render again")

#: Largest automatic group (samples): past it a dead worker loses too much work and
#: the slowest group ends the render late.
GROUP_MAX = 16

def render_units(outdir: str | os.PathLike, plan) -> tuple[list[tuple[int, int]], list[int]]:
    """What a render folder holds and lacks: its group files and the samples rendered
    one by one (:meth:`~povlens.plan.render_folder.RenderFolder.sample_done`).

    Returns
    -------
    done : list of (k0, k1)
        Units on disk, by k0: group files, and single samples (k, k + 1) not in a group.
    todo : list of int
        Samples neither in a group nor rendered, ascending.
    """
    folder = RenderFolder(outdir)
    groups = folder.group_files()
    covered = np.zeros(plan.inputs.samples, dtype=bool)
    for k0, k1, _ in groups:
        covered[k0:k1] = True
    done = [(k0, k1) for k0, k1, _ in groups]
    todo = []
    for k in np.flatnonzero(~covered).tolist():
        if folder.sample_done(k):
            done.append((k, k + 1))
        else:
            todo.append(k)
    return sorted(done), todo


def chunk_groups(todo: list[int], size: int) -> list[list[int]]:
    """``todo`` (ascending) cut into groups of at most ``size`` consecutive samples."""
    groups: list[list[int]] = []
    for k in todo:
        if groups and len(groups[-1]) < size and groups[-1][-1] == k - 1:
            groups[-1].append(k)
        else:
            groups.append([k])
    return groups


def choose_group_size(samples: int, workers: int) -> int:
    """Samples per task for ``samples`` samples on ``workers`` workers.

    The larger of two sizes, at most :data:`GROUP_MAX`:

    * ``ceil(N / (2 workers))``: about two groups per worker, so a worker that dies or
      lags holds up a fraction of the render, not half of it;
    * ``ceil(sqrt(N / 2))``: the client takes each group in one at a time (transfer,
      write, add: 16 bytes a pixel), about half a sample's render time on a 2-core
      worker (0.4 at 1920x1080 on 1 Gbit/s, docs/decisions/cluster.md).  With N / G
      groups of G samples the client's serial time N / G x t_s / 2 and one group's
      render G x t_s balance at G = sqrt(N / 2): past the workers that keep the
      client busy, more of them would only wait for it.
    """
    n = max(1, int(samples))
    g = max(math.ceil(n / (2 * max(1, int(workers)))), math.ceil(math.sqrt(n / 2)))
    return int(max(1, min(n, GROUP_MAX, g)))


class GroupSums:
    """A group's partial sums, each sample added, in sample order, as soon as it and
    those before it are rendered (a worker adds them while the group's other POV-Ray
    processes run).  ``terms(k)``: sample k's float64 sums, None if blocked
    (:func:`povlens.rendering.folder_composite.sample_sums`)."""

    def __init__(self, ks: list[int], terms):
        self.ks, self.terms = list(ks), terms
        self.next = 0
        self.total = self.wsum = None
        self.blocked: list[int] = []

    def ready(self, done) -> None:
        """Add the next samples of the group for which ``done(k)`` is true, in order."""
        while self.next < len(self.ks) and done(self.ks[self.next]):
            k = self.ks[self.next]
            terms = self.terms(k)
            if terms is None:
                self.blocked.append(k)
            elif self.total is None:
                self.total, self.wsum = np.array(terms[0][..., :3]), np.array(terms[1])
            else:
                self.total += terms[0][..., :3]
                self.wsum += terms[1]
            self.next += 1

    def result(self):
        """(sums or None if all blocked, blocked samples), once every sample is in."""
        if self.next != len(self.ks):
            raise PovlensError(f"lens sample {self.ks[self.next]} of the group "
                               f"{self.ks[0]}..{self.ks[-1]} was not rendered")
        return (None if self.total is None else (self.total, self.wsum)), self.blocked


def group_terms(outdir: str | os.PathLike, ks: list[int], plan, table, sample_sums):
    """The float64 sums (``sum w I`` (H, W, 3), ``sum w``) of rendered samples ``ks``,
    added in that order, and the blocked ones; sums None if all are blocked.
    ``sample_sums`` is :func:`povlens.rendering.folder_composite.sample_sums` (passed in: this
    module is below it)."""
    sums = GroupSums(ks, lambda k: sample_sums(outdir, k, plan, table))
    sums.ready(lambda k: True)
    return sums.result()


def pack_group(ks: list[int], sums, blocked: list[int]) -> bytes:
    """The bytes of a group file (npz, uncompressed: the client reads it at memory
    speed) of samples ``ks``; ``sums`` from :func:`group_terms` (None: all blocked)."""
    buf = io.BytesIO()
    arrays = {"samples": np.asarray(ks, dtype=np.int64),
              "blocked": np.asarray(blocked, dtype=np.int64)}
    if sums is not None:
        arrays.update(total=sums[0].astype(np.float32), wsum=sums[1].astype(np.float32))
    np.savez(buf, **arrays)
    return buf.getvalue()


def write_group(outdir: str | os.PathLike, ks: list[int], data: bytes) -> Path:
    """Write a group file atomically (``data`` from :func:`pack_group`)."""
    return write_bytes(RenderFolder(outdir).group_file(ks[0], ks[-1] + 1), data)


def load_group(path: str | os.PathLike, shape: tuple[int, int] | None = None):
    """A group file's sums as float64 (``total``, ``wsum``), or None if every sample
    of it was blocked.  ``shape``: the film's (H, W), which the sums must have.

    Raises
    ------
    PovlensError
        The file is not a group file, or not of the film's size, or holds NaN or
        infinite values (damaged): names it and says to delete it.
    """
    try:
        with np.load(path, allow_pickle=False) as z:
            if "total" not in z.files:
                return None
            total, wsum = z["total"].astype(np.float64), z["wsum"].astype(np.float64)
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error) as e:
        raise PovlensError(f"{path}: cannot read the group's partial sums ({e})",
                           _GROUP_REDO) from None
    if shape is not None and (total.shape != tuple(shape) + (3,)
                              or wsum.shape[:2] != tuple(shape)):
        raise PovlensError(f"{path}: partial sums of {total.shape[:2]} pixels, not the "
                           f"film's {tuple(shape)}", _GROUP_REDO)
    if not (np.all(np.isfinite(total)) and np.all(np.isfinite(wsum))):
        raise PovlensError(f"{path}: the group's partial sums hold NaN or infinite values",
                           _GROUP_REDO)
    return total, wsum


class UnitSums:
    """The composite's sums, units added in the order of their first sample as they
    arrive; one that comes early waits (on disk) for those before it.

    ``terms(k0, k1)`` gives a unit's float64 sums (None: all blocked)."""

    def __init__(self, samples: int, terms):
        self.samples, self.terms = samples, terms
        self.next_k, self.ready = 0, {}
        self.total = self.wsum = None

    def add(self, k0: int, k1: int) -> None:
        """Unit k0 .. k1-1 is on disk; add it and those after it that wait."""
        self.ready[k0] = k1
        while self.next_k in self.ready:
            k1 = self.ready.pop(self.next_k)
            sums = self.terms(self.next_k, k1)
            if sums is not None and self.total is None:
                self.total, self.wsum = np.array(sums[0][..., :3]), np.array(sums[1])
            elif sums is not None:
                self.total += sums[0][..., :3]
                self.wsum += sums[1]
            self.next_k = k1

    def result(self, where: str = ""):
        """(total, wsum) of all samples (None: all blocked)."""
        if self.next_k != self.samples:
            raise PovlensError(f"{where}: lens sample {self.next_k} never came back")
        return None if self.total is None else (self.total, self.wsum)


def unit_terms(outdir: str | os.PathLike, plan, table, sample_sums):
    """``terms(k0, k1)`` of :class:`UnitSums` for the units of ``outdir``: a group
    file's sums, or a single sample's (``sample_sums``:
    :func:`povlens.rendering.folder_composite.sample_sums`)."""

    def terms(k0: int, k1: int):
        path = RenderFolder(outdir).group_file(k0, k1)
        if path.exists():
            return load_group(path, (plan.film.height_px, plan.film.width_px))
        return sample_sums(outdir, k0, plan, table)
    return terms


def group_sums(outdir: str | os.PathLike, plan, table, sample_sums):
    """``composite_outdir``'s sums of a folder holding group files (None: it has none,
    the composite reads the samples as usual), which has checked that every sample is
    rendered: the samples no group covers are added one by one (``sample_sums``)."""
    groups = RenderFolder(outdir).group_files()
    if not groups:
        return None
    sums = UnitSums(plan.inputs.samples, unit_terms(outdir, plan, table, sample_sums))
    covered = np.zeros(plan.inputs.samples, dtype=bool)
    for k0, k1, _ in groups:
        covered[k0:k1] = True
        sums.add(k0, k1)
    for k in np.flatnonzero(~covered).tolist():
        sums.add(k, k + 1)
    result = sums.result(str(outdir))
    if result is None:          # all blocked: black, weight 0
        film = plan.film
        wshape = (film.height_px, film.width_px) + ((4,) if _spectral(plan) else ())
        result = np.zeros((film.height_px, film.width_px, 3)), np.zeros(wshape)
    return result


def _spectral(plan) -> bool:
    from povlens.rendering.spectral import plan_channel_factors
    return plan_channel_factors(plan) is not None
