"""A render folder's layout: the name of every file and marker in it, and the readers
of the small files, in one place.

A render folder (``povlens convert -o OUTDIR``) holds

========================================  =======================================================
``plan.json``                             the plan (:mod:`povlens.plan.schema`)
``pupil.npz``                             the exit-pupil table (:mod:`povlens.pupil.storage`)
``pinhole.pov``, ``focal_blur.pov``       the views' wrappers (:mod:`povlens.plan.folder_writer`)
``Makefile``                              ``make -C OUTDIR -j2`` renders and composites
``view-<view>.exr``                       a view as POV-Ray rendered it
``.speculative-focal-blur.pov/.exr``      ``--method auto``'s guessed view, while it runs
``exposure.txt``                          the composite's exposure 1 / (E/L)(0)
``illumination.json``                     the relative illumination of a field-mesh composite
``radiosity.rca``                         the radiosity samples every lens sample reads
``radiosity.json``                        whether the lens samples share them, and why
``photons.ph``                            the photon map every lens sample loads
``photons-N.tmp``                         that map while a pinhole render writes it
``image.exr``, ``image.png``              the image (linear float; sRGB preview)
``samples/batch_BBB.pov``                 the mesh method's batch wrappers
``samples/batch_BBB.done``                make's marker: batch b is rendered (its samples' files)
``samples/batch_BBB.lock``                its lock while ``povlens render-batch`` renders it
``.povlens.lock``                         the folder's lock (:mod:`povlens.plan.folder_lock`)
``samples/sample_KKKK.exr``               lens sample k as POV-Ray rendered it
``samples/sample_KKKK.weight.exr``        its per-pixel radiometric weights (per-pixel meshes)
``samples/sample_KKKK.mask.npy``          its pass mask (field meshes, bits packed by row)
``samples/sample_KKKK.transmission.npy``  its mask stop's transmission (grey masks)
``samples/sample_KKKK.blocked``           marker: every ray of its rows is blocked
``samples/sample_KKKK.inc``               its ray mesh, while it renders
``samples/group_K0_K1.npz``               partial sums of samples k0 .. k1-1 (a cluster)
``samples/*.timing.json``                 timings (batches, the render, early samples)
========================================  =======================================================

and a focus pull's folder (:mod:`povlens.rendering.focus_pull`) holds a render folder
per frame (``frame-NNNN/``), the frames' images ``image.NNNN.exr`` / ``.png``, its
index ``frames.json`` and a ``Makefile`` (:class:`FramesFolder`).

Every other module gets these names from here (:class:`RenderFolder`), and so do the
templates (:meth:`RenderFolder.makefile_names`, :meth:`RenderFolder.mesh_include_names`):
``tests/test_architecture.py`` checks that no other module spells them.
"""

from __future__ import annotations

import io
import math
import os
import re
from pathlib import Path

import numpy as np

from povlens.errors import PovlensError
from povlens.util.files import write_bytes, write_text

__all__ = ["PLAN_FILE", "FRAMES_FILE", "VIEWS", "RenderFolder", "FramesFolder"]

#: The plan's file name in a render folder.
PLAN_FILE = "plan.json"
#: The index of a focus pull's folder.
FRAMES_FILE = "frames.json"
#: The views of a folder and their wrappers (POV-Ray's own cameras).
VIEWS = {"pinhole": "pinhole.pov", "focal-blur": "focal_blur.pov"}

_SAMPLES = "samples"
_MAKEFILE = "Makefile"
_SAMPLE_PREFIX = "sample_"
#: Digits of a sample's number in its file names (the batch templates pad to it too).
_SAMPLE_DIGITS = 4
#: A sample's files: image, weights, pass mask, mask transmission, blocked marker, mesh.
_IMAGE, _WEIGHT, _MASK, _TRANSMISSION, _BLOCKED, _MESH = (
    ".exr", ".weight.exr", ".mask.npy", ".transmission.npy", ".blocked", ".inc")
#: A file being written (renamed to its final name when complete).
_PART = ".part"
_TIMING = ".timing.json"
_LOCK = ".lock"
_SPECULATIVE = ".speculative-focal-blur"
_PHOTON_MAP = "photons.ph"
_PHOTON_PARTIAL = ("photons-", ".tmp")     # + the writing render's number


def _sample_name(k: int, suffix: str) -> str:
    return f"{_SAMPLE_PREFIX}{int(k):0{_SAMPLE_DIGITS}d}{suffix}"


def _batch_name(b: int | str, suffix: str) -> str:
    """``batch_BBB<suffix>``; ``b`` a string (make's ``%``) is written as it is."""
    return f"batch_{b}{suffix}" if isinstance(b, str) else f"batch_{int(b):03d}{suffix}"


def _group_name(k0: int, k1: int) -> str:
    return f"group_{int(k0):04d}_{int(k1):04d}.npz"


#: A group file's name: ``group_K0_K1.npz``.
_GROUP_NAME = re.compile(r"^group_(\d{4,})_(\d{4,})\.npz$")


def _npy(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, a, allow_pickle=False)
    return buf.getvalue()


class RenderFolder:
    """The files of the render folder at ``path`` (which need not exist yet).

    Paths are ``path`` joined with the file's name, so a relative ``path`` gives
    relative paths (a Makefile's rules, a focus pull's index).

    Parameters
    ----------
    path : the render folder, OUTDIR.
    """

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)

    def __repr__(self) -> str:
        return f"RenderFolder({str(self.path)!r})"

    # -- the plan and what it derives -------------------------------------------------

    @property
    def plan_json(self) -> Path:
        """The plan (:func:`povlens.plan.schema.read_plan`)."""
        return self.path / PLAN_FILE

    @property
    def scene_link(self) -> Path:
        """An ASCII link to the scene, which the wrappers include when POV-Ray cannot
        read the scene's own path (spaces, quotes, non-ASCII:
        :func:`povlens.pov.povray_paths.include_text`); absent otherwise."""
        return self.path / "povlens-scene.pov"

    @property
    def pupil_npz(self) -> Path:
        """The exit-pupil table, reused while its inputs hold
        (:func:`povlens.pupil.storage.cached_pupil_table`)."""
        return self.path / "pupil.npz"

    @property
    def makefile(self) -> Path:
        return self.path / _MAKEFILE

    @property
    def lock_file(self) -> Path:
        """The folder's lock (:mod:`povlens.plan.folder_lock`): it stays when released,
        empty or naming its last exclusive holder."""
        return self.path / (".povlens" + _LOCK)

    def wrapper(self, view: str) -> Path:
        """The wrapper of ``view`` (``pinhole`` or ``focal-blur``, :data:`VIEWS`)."""
        return self.path / VIEWS[view]

    def view_image(self, view: str) -> Path:
        """``view-<view>.exr``: ``view`` as POV-Ray rendered it."""
        return self.path / f"view-{view}.exr"

    @property
    def speculative_wrapper(self) -> Path:
        """The wrapper of the focal_blur view ``--method auto`` starts before it decides
        (its own file: a provisional plan may rewrite ``focal_blur.pov`` meanwhile)."""
        return self.path / (_SPECULATIVE + ".pov")

    @property
    def speculative_view(self) -> Path:
        """Where that view renders (renamed to :meth:`view_image` when it is chosen)."""
        return self.path / (_SPECULATIVE + ".exr")

    @property
    def exposure_txt(self) -> Path:
        """The composite's exposure (:meth:`read_exposure`)."""
        return self.path / "exposure.txt"

    @property
    def radiosity_cache(self) -> Path:
        """The radiosity samples of one pinhole pretrace, which every lens sample reads
        (:mod:`povlens.rendering.radiosity_cache`)."""
        return self.path / "radiosity.rca"

    @property
    def sample_layout(self) -> Path:
        """How the folder's lens samples are laid out, when its first sample chose one
        run each (:mod:`povlens.rendering.run_choice`): ``{"bands": 1, ...}``; every
        later render of the folder (a resume, ``make``, a cluster worker) lays its
        samples out so, and they come out the same bits."""
        return self.samples / "layout.json"

    @property
    def radiosity_chain(self) -> Path:
        """The radiosity samples a render's stacked runs hand on, each reading the
        previous runs' and adding its own (:mod:`povlens.rendering.sample_stacks`);
        deleted when the render ends."""
        return self.samples / ".radiosity-chain.rca"

    @property
    def photon_map(self) -> Path:
        """The photon map one pinhole render shoots and every lens sample loads
        (:mod:`povlens.rendering.photon_map`)."""
        return self.path / _PHOTON_MAP

    def photon_map_partial(self, n: int) -> Path:
        """Where render ``n`` writes the photon map before it is renamed into place
        (:meth:`photon_map_names` spells it for the wrappers)."""
        return self.path / f"{_PHOTON_PARTIAL[0]}{int(n)}{_PHOTON_PARTIAL[1]}"

    @staticmethod
    def photon_map_names() -> dict[str, str]:
        """The photon map's names as SDL string expressions for the wrappers: ``save``
        (in the folder, ``PovlensPhotonSave`` the number of :meth:`photon_map_partial`)
        and ``load`` (from ``samples/``), and the flags that switch them on."""
        return {"save": f'concat("{_PHOTON_PARTIAL[0]}", str(PovlensPhotonSave, 0, 0), '
                        f'"{_PHOTON_PARTIAL[1]}")',
                "load": f'"../{_PHOTON_MAP}"',
                "save_flag": "PovlensPhotonSave", "load_flag": "PovlensPhotonLoad"}

    @property
    def radiosity_choice(self) -> Path:
        """Whether the lens samples share :meth:`radiosity_cache`, measured on two
        samples (:func:`povlens.rendering.radiosity_cache.record_probes`)."""
        return self.path / "radiosity.json"

    @property
    def illumination_json(self) -> Path:
        """The relative illumination profile a field-mesh composite used."""
        return self.path / "illumination.json"

    @property
    def image_exr(self) -> Path:
        return self.path / "image.exr"

    @property
    def image_png(self) -> Path:
        return self.path / "image.png"

    # -- lens samples, batches, groups --------------------------------------------------

    @property
    def samples(self) -> Path:
        """The folder of the lens samples, batches and groups."""
        return self.path / _SAMPLES

    def sample_image(self, k: int) -> Path:
        """Lens sample k as POV-Ray rendered it (linear EXR)."""
        return self.samples / _sample_name(k, _IMAGE)

    def sample_weight(self, k: int) -> Path:
        """Sample k's per-pixel radiometric weights (float32 EXR; per-pixel meshes)."""
        return self.samples / _sample_name(k, _WEIGHT)

    def sample_mask(self, k: int) -> Path:
        """Sample k's pass mask (field meshes: :meth:`read_pass_mask`)."""
        return self.samples / _sample_name(k, _MASK)

    def sample_transmission(self, k: int) -> Path:
        """Sample k's per-pixel transmission of a grey mask stop (float32 .npy)."""
        return self.samples / _sample_name(k, _TRANSMISSION)

    def sample_blocked(self, k: int) -> Path:
        """Marker: every ray of sample k's rows is blocked (black, weight 0, not
        rendered); it holds the rows ``R0 R1``."""
        return self.samples / _sample_name(k, _BLOCKED)

    def sample_mesh(self, k: int) -> Path:
        """Sample k's ray mesh (written just before its render, deleted after)."""
        return self.samples / _sample_name(k, _MESH)

    @staticmethod
    def partial(path: Path) -> Path:
        """The name ``path`` is written under until it is complete."""
        return path.with_name(path.name + _PART)

    def sample_temp_prefix(self, k: int) -> str:
        """Prefix of the temporary folder sample k renders in (inside :attr:`samples`)."""
        return "." + _sample_name(k, ".")

    def sample_outputs(self, k: int) -> list[Path]:
        """The files of sample k on disk but its ray mesh and files being written: what
        a cluster worker sends back."""
        return sorted(p for p in self.samples.glob(_sample_name(k, ".*"))
                      if p.is_file() and not p.name.endswith((_MESH, _PART)))

    def sample_done(self, k: int) -> bool:
        """Whether lens sample k is rendered: its weights (or a readable pass mask: field
        meshes) exist, and its image or a trusted marker that it has none
        (:meth:`blocked`); or a group file covers it."""
        weights = self.sample_weight(k).exists() or (
            self.sample_mask(k).exists() and self._load_mask(k)[1] is None)
        return ((weights and (self.sample_image(k).exists() or self.blocked(k)))
                or self.grouped(k))

    def blocked(self, k: int) -> bool:
        """Whether sample k is rendered as blocked (black, weight 0): its marker exists
        and agrees with its files (no image; a pass mask that passes nothing, or
        weights all 0).  A marker that disagrees is not trusted
        (:meth:`sample_damage` says why)."""
        return (self.sample_blocked(k).exists() and not self.sample_image(k).exists()
                and self._blocked_disagrees(k) is None)

    def sample_damage(self, k: int) -> tuple[Path, str] | None:
        """The damaged file of sample k and what is wrong with it, or None: a pass mask
        that cannot be read, a blocked marker that disagrees with the sample's files.
        (Its images are checked when they are read: :func:`povlens.util.images.read_image`.)"""
        if self.sample_mask(k).exists():
            why = self._load_mask(k)[1]
            if why is not None:
                return self.sample_mask(k), why
        marker = self.sample_blocked(k)
        if marker.exists() and not self.sample_image(k).exists():
            why = self._blocked_disagrees(k)
            if why is not None:
                return marker, why
        return None

    def redo_hint(self, k: int) -> str:
        """What to do about a damaged file of sample k: delete the sample's files and
        render again (``make`` renders a batch again when a file its marker lists
        is gone)."""
        return (f"delete {self.samples / _sample_name(k, '.*')} and render again "
                f"('povlens render' with the same options, or 'make -C {self.path}')")

    def _load_mask(self, k: int) -> tuple[np.ndarray | None, str | None]:
        """Sample k's packed pass mask, or None and why it cannot be read."""
        try:
            packed = np.load(self.sample_mask(k), allow_pickle=False)
        except (OSError, ValueError, EOFError) as e:
            return None, f"cannot read the sample's pass mask ({e or type(e).__name__})"
        if packed.dtype != np.uint8 or packed.ndim != 2:
            return None, (f"holds a {packed.dtype} array of shape {packed.shape}, not a "
                          f"pass mask")
        return packed, None

    def _blocked_disagrees(self, k: int) -> str | None:
        """Why sample k's blocked marker is not to be trusted, None if it agrees: it
        names its rows ``R0 R1``, and its pass mask passes nothing (or its weights
        are 0)."""
        marker = self.sample_blocked(k)
        try:
            r0, r1 = (int(v) for v in marker.read_text().split())
        except (OSError, ValueError):
            return "does not hold the rows 'R0 R1' it was made for"
        if self.sample_mask(k).exists():
            packed, why = self._load_mask(k)
            if packed is None:
                return f"its pass mask {self.sample_mask(k).name} {why}"
            passing = int(np.unpackbits(packed).sum())
            return (None if passing == 0 else f"says every ray of rows {r0}..{r1} is "
                    f"blocked, but its pass mask passes {passing} pixels")
        if self.sample_weight(k).exists():
            try:
                passing = int(np.count_nonzero(self.read_weight(k) > 0))
            except PovlensError as e:
                return f"its weights cannot be read ({e.message})"
            return (None if passing == 0 else f"says every ray of rows {r0}..{r1} is "
                    f"blocked, but its weights are above 0 at {passing} pixels")
        return "has neither the sample's pass mask nor its weights beside it"

    def batch_wrapper(self, b: int) -> Path:
        """The wrapper of batch b (:mod:`povlens.data` ``mesh_batch.pov.tmpl``)."""
        return self.samples / _batch_name(b, ".pov")

    def batch_done(self, b: int) -> Path:
        """make's target of batch b: the batch's sample numbers, one a line."""
        return self.samples / _batch_name(b, ".done")

    def mark_batch_done(self, b: int, ks) -> None:
        """Write :meth:`batch_done` of batch b, whose samples are ``ks``: the files they
        are made of (relative to the folder, one a line; a group file for samples a
        group covers), so that ``make`` renders the batch again when one is gone
        (the Makefile reads them: :meth:`makefile_names`)."""
        groups = self.group_files()
        names = set()
        for k in ks:
            covering = [p for k0, k1, p in groups if k0 <= k < k1]
            names.update(covering or self.sample_outputs(k))
        write_text(self.batch_done(b), "".join(
            f"{p.relative_to(self.path).as_posix()}\n" for p in sorted(names)))

    def batch_lock(self, b: int) -> Path:
        """Batch b's lock, held while ``povlens render-batch`` renders it
        (:func:`povlens.plan.folder_lock.batch_lock`)."""
        return self.samples / _batch_name(b, _LOCK)

    def batch_timing(self, b: int) -> Path:
        """The timings of ``povlens render-batch`` of batch b."""
        return self.samples / _batch_name(b, _TIMING)

    def timing(self, name: str) -> Path:
        """``samples/<name>.timing.json``: ``render`` (``povlens render``), ``early``
        (samples rendered while ``--method auto`` decides), ``cluster``."""
        return self.samples / (name + _TIMING)

    def timing_files(self) -> list[Path]:
        """Every timing file of the folder, by name."""
        return sorted(self.samples.glob("*" + _TIMING))

    def group_file(self, k0: int, k1: int) -> Path:
        """The partial sums of samples k0 .. k1-1 (:mod:`povlens.rendering.groups`)."""
        return self.samples / _group_name(k0, k1)

    def group_files(self) -> list[tuple[int, int, Path]]:
        """The group files: (k0, k1, path), by k0; a group overlapping one before it
        (not written by povlens) is left out."""
        if not self.samples.is_dir():
            return []
        found = []
        for p in self.samples.iterdir():
            m = _GROUP_NAME.match(p.name)
            if m and int(m.group(1)) < int(m.group(2)):
                found.append((int(m.group(1)), int(m.group(2)), p))
        out, end = [], 0
        for k0, k1, p in sorted(found):
            if k0 >= end:
                out.append((k0, k1, p))
                end = k1
        return out

    def grouped(self, k: int) -> bool:
        """Whether a group file covers lens sample ``k``."""
        return any(k0 <= k < k1 for k0, k1, _ in self.group_files())

    # -- what a change of the plan drops, what a worker needs ---------------------------

    def outputs_to_drop(self, stale: list[int] | None) -> list[Path]:
        """What no longer belongs to a changed plan: images, views, batch markers and
        timings always; with ``stale`` None every sample's files, exposure.txt and
        illumination.json (they depend on the lens, focus and film), else the files
        of the samples ``stale`` (that may not exist).  pupil.npz stays (it is
        checked against its inputs when read)."""
        every = _SAMPLES + "/*"
        patterns = [every + ".done", every + _TIMING, self.image_exr.name,
                    self.image_png.name, "view-*.exr"]
        if stale is None:
            patterns += [every + s for s in (_IMAGE, _BLOCKED, _MESH, _MASK)]
            patterns += [self.exposure_txt.name, self.illumination_json.name,
                         self.radiosity_cache.name, self.radiosity_choice.name,
                         self.photon_map.name, f"{_SAMPLES}/{self.sample_layout.name}"]
        out = [f for pattern in patterns for f in self.path.glob(pattern)]
        for k in stale or []:
            out += [self.samples / _sample_name(k, s)
                    for s in (_IMAGE, _WEIGHT, _MASK, _BLOCKED, _MESH)]
        return out

    def worker_inputs(self) -> list[Path]:
        """The folder's files a lens sample's POV-Ray run reads: the plan, the pupil
        table, the wrappers (the views' and the batches'), and the radiosity samples, the
        photon map and the samples' layout when there are."""
        cache = [f for f in (self.radiosity_cache, self.photon_map, self.sample_layout)
                 if f.is_file()]
        return ([self.plan_json, self.pupil_npz] + sorted(self.path.glob("*.pov"))
                + sorted(self.samples.glob("*.pov")) + cache)

    # -- names for the templates ---------------------------------------------------------

    def makefile_names(self, batches: int) -> dict[str, str]:
        """The folder's names as its Makefile (``Makefile.tmpl``) writes them, relative
        to the folder: ``image_exr``, ``image_png``, ``plan_json``, ``batch_dones``
        (the markers of the plan's ``batches`` batches) and ``batch_done_rule`` (make's
        pattern of a marker, ``%`` the batch).  The views' wrappers: :data:`VIEWS`."""
        rel = RenderFolder(".")
        return {"image_exr": rel.image_exr.name, "image_png": rel.image_png.name,
                "plan_json": PLAN_FILE,
                "batch_dones": " ".join(rel.batch_done(b).as_posix() for b in range(batches)),
                "batch_done_rule": f"{_SAMPLES}/{_batch_name('%', '.done')}"}

    @staticmethod
    def mesh_include_names() -> dict[str, str]:
        """How a batch wrapper (``mesh_batch.pov.tmpl``, ``field_batch.pov.tmpl``)
        names sample k's mesh: ``sample_prefix`` + k zero-padded to ``sample_digits``
        + ``mesh_suffix``."""
        return {"sample_prefix": _SAMPLE_PREFIX, "sample_digits": str(_SAMPLE_DIGITS),
                "mesh_suffix": _MESH}

    # -- readers and writers of the small files -----------------------------------------

    def read_exposure(self) -> float | None:
        """The exposure in :attr:`exposure_txt`, None if there is none or it is no
        positive finite number (damaged: it is then computed again, so no NaN or inf
        reaches an image)."""
        if not self.exposure_txt.exists():
            return None
        try:
            value = float(self.exposure_txt.read_text())
        except (ValueError, OSError):
            return None
        return value if math.isfinite(value) and value > 0 else None

    def write_exposure(self, exposure: float) -> None:
        write_text(self.exposure_txt, f"{exposure!r}\n")

    def read_weight(self, k: int) -> np.ndarray:
        """(H, W) float32 weights of sample k (per-pixel meshes)."""
        from povlens.util.images import read_image      # OpenImageIO: not for a conversion
        return read_image(self.sample_weight(k))[..., 0]

    def write_pass_mask(self, k: int, passed: np.ndarray) -> None:
        """Write sample k's pass mask ((H, W) bool), bits packed by row."""
        write_bytes(self.sample_mask(k), _npy(np.packbits(passed, axis=1)))

    def read_pass_mask(self, k: int, height: int, width: int) -> np.ndarray:
        """(H, W) bool pass mask of sample k.

        Raises
        ------
        PovlensError
            The file cannot be read or is not of the film's size: names it and says
            what to delete.
        """
        path = self.sample_mask(k)
        packed, why = self._load_mask(k)
        if packed is None:
            raise PovlensError(f"{path}: {why}", self.redo_hint(k))
        passed = np.unpackbits(packed, axis=1, count=width).astype(bool)
        if passed.shape != (height, width):
            raise PovlensError(f"{path} holds a {passed.shape} mask, not the film's "
                               f"{(height, width)}", self.redo_hint(k))
        return passed

    def write_transmission(self, k: int, transmission: np.ndarray) -> None:
        write_bytes(self.sample_transmission(k), _npy(transmission))

    def read_transmission(self, k: int) -> np.ndarray:
        """(H, W) float32 transmission of sample k's grey mask stop.

        Raises
        ------
        PovlensError
            The file cannot be read: names it and says what to delete.
        """
        path = self.sample_transmission(k)
        try:
            transmission = np.load(path, allow_pickle=False)
        except (OSError, ValueError, EOFError) as e:
            raise PovlensError(f"{path}: cannot read the sample's mask transmission "
                               f"({e or type(e).__name__})", self.redo_hint(k)) from None
        if (transmission.ndim != 2 or transmission.dtype.kind != "f"
                or not np.all(np.isfinite(transmission))):
            raise PovlensError(f"{path} holds a {transmission.dtype} array of shape "
                               f"{transmission.shape} (or values not finite), not the "
                               f"sample's mask transmission", self.redo_hint(k))
        return transmission


class FramesFolder:
    """The files of a focus pull's folder at ``path``: a render folder per frame, the
    frames' numbered images, the index and the Makefile.

    Parameters
    ----------
    path : the frames folder, OUTDIR.
    """

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)

    def __repr__(self) -> str:
        return f"FramesFolder({str(self.path)!r})"

    @property
    def frames_json(self) -> Path:
        """The index (:func:`povlens.rendering.focus_pull.read_frames`)."""
        return self.path / FRAMES_FILE

    @property
    def makefile(self) -> Path:
        return self.path / _MAKEFILE

    def is_frames_folder(self) -> bool:
        """Written by ``povlens render/convert --frames``: an index and no plan."""
        return self.frames_json.is_file() and not RenderFolder(self.path).plan_json.is_file()

    @staticmethod
    def frame_name(i: int) -> str:
        """The render folder of frame ``i`` (1-based), relative: ``frame-0001``."""
        return f"frame-{int(i):04d}"

    @staticmethod
    def image_name(i: int, ext: str) -> str:
        """Frame ``i``'s image in the frames folder, numbered for video tools
        (``ffmpeg -i OUTDIR/image.%04d.png``): ``image.0001.exr`` (``ext`` ``exr``
        or ``png``)."""
        return f"image.{int(i):04d}.{ext}"

    def frame(self, name: str) -> RenderFolder:
        """The render folder of the frame whose folder is ``name``."""
        return RenderFolder(self.path / name)
