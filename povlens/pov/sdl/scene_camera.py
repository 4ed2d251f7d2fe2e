"""Read the camera of an ordinary POV-Ray scene.

:func:`parse_scene_camera` finds the camera statement POV-Ray would use (the
*last* ``camera { ... }`` the parser meets) and evaluates it the way POV-Ray
3.7 does (``Parse_Camera`` in ``source/backend/parser/parse.cpp``), returning
the world-space camera basis in scene units.

The reading is done in layers: :mod:`povlens.pov.sdl.lexer` (tokens, comments,
strings), :mod:`povlens.pov.sdl.directives` (``#include``, ``#if``, ``#switch``,
loops, macros; with :mod:`~povlens.pov.sdl.declarations` for ``#declare``),
:mod:`povlens.pov.sdl.expressions` (numbers, vectors, colours, strings),
:mod:`povlens.pov.sdl.camera_block` (the ``camera { }`` block) and
:mod:`povlens.pov.sdl.scene_reader` (statements); this module turns the camera found into
a :class:`SceneCamera`.

What is understood
------------------
* comments, strings, ``#include`` found as POV-Ray finds it (the scene's folder, then
  POV-Ray's library paths from its ``povray.ini`` and the standard include folder,
  then ``library_paths``), with ``#local`` scopes per file, ``#version``;
* ``#declare`` / ``#local`` / ``#undef`` of numbers, vectors, colours, strings,
  arrays, cameras and transforms (anything else -- objects, textures, user functions,
  splines -- is known to exist but has no value);
* ``#if`` / ``#ifdef`` / ``#ifndef`` / ``#elseif`` / ``#else``, ``#switch`` /
  ``#case`` / ``#range`` / ``#break``, ``#while`` and ``#for`` loops, ``#macro``
  definitions and calls (a camera made by a macro, a vector returned by one),
  anywhere -- also inside the camera block; ``#debug`` & co., ``#error``;
* expressions: numbers, vectors of 2 to 5 components (commas optional, a float or a
  2-vector promoted as POV-Ray does), ``x y z u v t pi`` ``true``..., ``clock`` and
  the other frame values (POV-Ray's values for a still, or ``clock``),
  ``image_width`` ``image_height`` ``version``, ``+ - * /``, comparisons, ``& | !``,
  ``? :``, ``.x .y .z .u .v .t .red`` ... ``.gray``, ``A[i]``, ``defined()`` and the
  built-in functions (``vnormalize vcross vrotate vaxis_rotate vlength vdot``, ``sin``
  ... ``select``, the string functions);
* every camera type (``perspective orthographic fisheye ultra_wide_angle omnimax
  panoramic spherical cylinder N``); items ``location look_at sky up right direction
  angle aperture focal_point blur_samples confidence variance normal{} bokeh{}`` and
  the transforms ``translate rotate scale matrix transform{} transform T``, applied in
  POV-Ray's order (for ``#version`` >= 3.5: right, direction, angle, up, sky,
  location, look_at, then the transforms; older versions apply the items in the order
  written).

povlens replaces the camera's projection with its lens: what it takes from the scene is
the position and orientation.  :attr:`SceneCamera.replaced` lists, in words, what of
the scene's camera the lens replaces or povlens ignores (another projection, focal
blur, a camera ``normal``, proportions other than the image's, POV-Ray's default
camera for a scene without one, a camera read at clock 0).  A ``mesh_camera`` scene
is refused; a camera povlens cannot evaluate raises :class:`SceneCameraError`,
naming the construct (``file:line``) and what to pass instead.

Conventions (POV-Ray 3.7 ``Parse_Camera`` and ``CreateCameraRay``)
-------------------------------------------------------------------
POV-Ray is left-handed (+x right, +y up, +z into the screen) but all vector
formulas are the ordinary ones.  With ``look_at``: ``forward`` =
normalize(look_at - location), ``right`` = normalize(cross(sky, forward)),
``up`` = cross(forward, right).  The perspective camera's pixel (i, j) looks
along ``D + x0 R + y0 U`` with ``x0 = (i + 0.5)/W - 0.5``, ``y0 = 0.5 -
(j + 0.5)/H`` (row 0 at the top).
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
import re
import threading
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

from povlens.pov.sdl.camera_block import CameraState
from povlens.pov.sdl.errors import SceneCameraError, with_explicit_hint
from povlens.pov.sdl.include_paths import default_library_paths
from povlens.pov.sdl.scene_reader import SceneReader, still_constants
from povlens.pov.sdl.values import UnknownValue

__all__ = ["SceneCamera", "SceneCameraError", "parse_scene_camera", "DEFAULT_CAMERA_NOTE"]

#: The note for a scene without a camera statement (POV-Ray's ``Camera::Init``).
DEFAULT_CAMERA_NOTE = ("the scene has no camera statement: POV-Ray's default camera is used "
                       "(location <0, 0, 0>, looking along +z, up y, right 1.33 x)")

#: |right|/|up| may differ from the image's width/height by this much without a note
#: (the common ``right x*1.33`` for a 4:3 image is 0.25 % off).
ASPECT_TOLERANCE = 0.01

#: The clock at which a scene that reads ``clock`` is read a second time, to tell
#: whether its camera moves with it.
PROBE_CLOCK = 0.37


@dataclasses.dataclass(frozen=True)
class SceneCamera:
    """The camera of a POV-Ray scene in world coordinates (scene units).

    location : (3,) camera position (for a perspective camera, the pinhole).
    forward, right, up : (3,) unit vectors; ``right`` points to the image's
        right edge (column W-1), ``up`` to its top edge (row 0).  They are the
        normalized, orthogonalized POV-Ray vectors below (for a ``look_at``
        camera they are already orthonormal).  A camera with a left-handed
        ``right`` (mirrored image, e.g. ``right -4/3*x``) gives
        ``cross(up, forward) == -right``.
    direction_vector, right_vector, up_vector : (3,) the final POV-Ray
        ``direction``, ``right``, ``up`` vectors, unnormalized, exactly as the
        renderer uses them.
    hfov_deg, vfov_deg : full horizontal / vertical field of view in degrees
        of a perspective camera, ``2 atan(|right| / (2 |direction|))``;
        ``None`` for other projections.
    projection : ``"perspective"``, ``"orthographic"``, ``"fisheye"``,
        ``"cylinder 1"`` ...; for any but perspective only the pose is meaningful.
    look_at : (3,) the look_at point (after camera transforms) or ``None``.
    sky : (3,) the sky vector as written (not transformed).
    aperture, focal_distance : focal blur settings if the camera has them,
        else ``None``; ``focal_distance`` = |focal_point - location| before
        camera transforms (scene units).
    source : ``"file:line"`` of the camera statement used (for POV-Ray's default
        camera, the scene file and ``"(default camera)"``).
    replaced : what of the scene's camera povlens's lens replaces or povlens ignores,
        one human-readable note each (empty for a plain perspective camera); see
        the module docstring.
    global_settings : the items of the scene's ``global_settings`` blocks, sorted
        (``"radiosity"``, ``"photons"``, ...; read on the way, not evaluated).
    photon_settings : the items of the scene's last ``photons`` block in
        ``global_settings`` as SDL text a later block can repeat (names replaced by
        their values); "" when povlens cannot repeat it whole; None without one.
    radiosity_pretrace : (pretrace_start, pretrace_end) the scene's radiosity leaves
        POV-Ray with (:attr:`SceneReader.radiosity_pretrace`); None without radiosity
        or when povlens cannot tell.
    written_files : ``"file:line"`` of each ``#fopen`` that writes or appends a file
        while the scene is parsed.
    image_size_uses : ``"file:line"`` of each ``image_width`` / ``image_height`` the
        scene's files hold outside a camera block (:func:`image_size_uses`).
    """

    location: np.ndarray
    forward: np.ndarray
    right: np.ndarray
    up: np.ndarray
    direction_vector: np.ndarray
    right_vector: np.ndarray
    up_vector: np.ndarray
    hfov_deg: float | None
    vfov_deg: float | None
    projection: str
    look_at: np.ndarray | None
    sky: np.ndarray
    aperture: float | None
    focal_distance: float | None
    source: str
    replaced: list[str] = dataclasses.field(default_factory=list)
    global_settings: tuple[str, ...] = ()
    photon_settings: str | None = None
    radiosity_pretrace: tuple[float, float] | None = None
    written_files: tuple[str, ...] = ()
    image_size_uses: tuple[str, ...] = ()


def parse_scene_camera(
    path: str | os.PathLike,
    image_width: int | None = None,
    image_height: int | None = None,
    *,
    library_paths: Iterable[str | os.PathLike] = (),
    clock: float | None = None,
    declares: Mapping[str, float | str] | None = None,
    povray_library: bool = True,
) -> SceneCamera:
    """Read the camera POV-Ray would use for the scene file ``path``.

    Parameters
    ----------
    path : the scene (``.pov``) file; its folder is where ``#include`` files are
        looked for first (as when POV-Ray is run there).
    image_width, image_height : pixels; the values of POV-Ray's ``image_width`` /
        ``image_height`` keywords (commonly used as ``right x*image_width/image_height``),
        needed only if the camera uses them; with both, a camera whose proportions
        differ from the image's gets a note in ``replaced``.
    library_paths : more folders for ``#include`` files, searched after POV-Ray's own
        (POV-Ray's ``+L``).
    clock : POV-Ray's ``clock`` (``+K``); None reads the scene as a still (clock 0,
        ``clock_on`` false), as POV-Ray does without ``+K``.
    declares : names declared before the scene is read, as POV-Ray's
        ``declare=NAME=VALUE`` (floats or strings).
    povray_library : also search POV-Ray's library paths (its ``povray.ini``
        ``Library_Path`` entries and the standard include folder).

    Returns
    -------
    SceneCamera
        World coordinates, scene units; ``replaced`` says what the lens replaces.
        Remembered in this process for the same arguments while the scene, the files
        it includes and their folders are unchanged (a copy each call).

    Raises
    ------
    SceneCameraError
        (a :class:`PovlensError`) naming the file, line and construct when the camera
        cannot be evaluated, when it is a ``mesh_camera``, or when the scene has no
        camera but includes files that were not found; its hint says what to pass.
    """
    path = Path(path)
    libs = [*(default_library_paths() if povray_library else []), *map(Path, library_paths)]
    key = (str(path.absolute()), image_width, image_height, tuple(str(p.absolute()) for p in libs),
           clock, tuple(sorted((declares or {}).items())))
    with _READ_LOCK:
        known = _READ.get(key)
    if known is not None and _stamps(known[0]) == known[1]:
        return _copy(known[2])
    cam, notes = _read_camera(path, image_width, image_height, libs, clock, declares)
    if clock is None and "clock" in notes.pop("used", ()):
        moved = _moves_with_clock(path, image_width, image_height, libs, declares, cam)
        if moved:
            notes.setdefault("replaced", []).append(moved)
    files = notes.get("files")
    if cam is None:
        cam = CameraState(where=f"{path} (default camera)")
    extra = list(notes.get("replaced", []))
    found = dataclasses.replace(_world_camera(cam),
                                replaced=extra + _notes(cam, image_width, image_height),
                                global_settings=notes.get("global_settings", ()),
                                photon_settings=notes.get("photon_settings"),
                                radiosity_pretrace=notes.get("radiosity_pretrace"),
                                written_files=notes.get("written_files", ()),
                                image_size_uses=notes.get("image_size_uses", ()))
    if files is not None:
        # the folders too: a file added there may shadow an include found elsewhere
        watched = [*files, path.parent, *libs]
        stamps = _stamps(watched)
        if stamps is not None:
            with _READ_LOCK:
                while len(_READ) >= _READ_LIMIT:
                    _READ.pop(next(iter(_READ)))
                _READ[key] = (watched, stamps, found)
    return _copy(found)


#: Cameras read in this process: key -> (files and folders read, their stamps, camera).
#: A conversion reads the scene's camera twice (for its focus, then for its plan), and
#: a big scene's include files take a while to walk (docs/decisions/cli.md, issue 14).
_READ: dict = {}
_READ_LIMIT = 32
_READ_LOCK = threading.Lock()         # conversions may run in threads (API callers)


def _stamps(paths) -> tuple | None:
    """A file's content hash, a folder's (modification time, inode), for each path;
    None if one cannot be read.  Contents, not times: a file rewritten within the
    clock's granularity (milliseconds) keeps its modification time."""
    out = []
    try:
        for p in paths:
            if os.path.isdir(p):
                st = os.stat(p)
                out.append((st.st_mtime_ns, st.st_ino))
            else:
                out.append(hashlib.blake2b(Path(p).read_bytes(), digest_size=16).digest())
    except OSError:
        return None
    return tuple(out)


def _copy(cam: SceneCamera) -> SceneCamera:
    """A copy of ``cam`` whose arrays and notes the caller may change."""
    return dataclasses.replace(cam, **{f.name: getattr(cam, f.name).copy()
                                       for f in dataclasses.fields(cam)
                                       if isinstance(getattr(cam, f.name), (np.ndarray, list))})


_SIZE_WORD = re.compile(r"/\*.*?\*/|//[^\n]*|\"(?:[^\"\\\n]|\\.)*\"|\bcamera\b|[{}]|"
                        r"\bimage_(?:width|height)\b", re.S)


def image_size_uses(files) -> tuple[str, ...]:
    """``"file:line"`` of each ``image_width`` / ``image_height`` in ``files`` outside a
    ``camera { }`` block (comments and strings skipped): what a scene computes from the
    size POV-Ray renders, which a mesh render's passes change
    (:mod:`povlens.rendering.sample_stacks`)."""
    out: list[str] = []
    for f in dict.fromkeys(files):
        try:
            text = Path(f).read_text(errors="replace")
        except OSError:
            continue
        depth, camera_at = 0, None     # brace depth; the depth a camera block opened at
        pending = False
        for m in _SIZE_WORD.finditer(text):
            w = m.group(0)
            if w == "camera":
                pending = True
            elif w == "{":
                if pending and camera_at is None:
                    camera_at = depth
                pending = False
                depth += 1
            elif w == "}":
                depth -= 1
                if camera_at is not None and depth <= camera_at:
                    camera_at = None
            elif w.startswith("image_") and camera_at is None:
                out.append(f"{f}:{text.count(chr(10), 0, m.start()) + 1}")
    return tuple(out)


def _read_camera(path: Path, image_width, image_height, libs, clock, declares
                 ) -> tuple[CameraState | None, dict]:
    """Walk the scene; the last camera statement, evaluated (None: there is none), and
    notes (``"used"``: the frame values read; ``"replaced"``: notes)."""
    if not path.is_file():
        raise SceneCameraError(f"scene file {path} does not exist", "check the path")
    reader = SceneReader(path, still_constants(clock, image_width, image_height), libs, declares)
    reader.run()
    cam = reader.camera
    # the files read (None: an include was not found, which a new file could change)
    notes: dict = {"used": set(reader.stream.used_names),
                   "files": None if reader.unread_includes else list(reader.included),
                   "global_settings": tuple(sorted(reader.global_settings)),
                   "photon_settings": reader.photon_settings,
                   "radiosity_pretrace": reader.radiosity_pretrace,
                   "written_files": tuple(reader.written_files),
                   "image_size_uses": image_size_uses(reader.included)}
    if cam is None:
        if reader.unread_includes:
            raise SceneCameraError(
                f"no camera statement found in {path}; the scene includes "
                + ", ".join(reader.unread_includes[:6])
                + ", which povlens did not find in the scene's folder or on the library paths "
                  "and which may define the camera",
                with_explicit_hint("pass library_paths with the folder that holds them"))
        notes["replaced"] = [DEFAULT_CAMERA_NOTE]
        return None, notes
    if isinstance(cam, UnknownValue):
        if cam.kind == "mesh_camera":
            raise SceneCameraError(f"cannot use the camera of {path}: {cam.reason}",
                                   with_explicit_hint(None))
        raise SceneCameraError(f"cannot read the camera of {path}: {cam.reason}",
                               with_explicit_hint(cam.hint))
    assert isinstance(cam, CameraState)
    return cam, notes


def _moves_with_clock(path, image_width, image_height, libs, declares, cam) -> str:
    """A note if the camera read at clock 0 is elsewhere at :data:`PROBE_CLOCK`."""
    try:
        other, _ = _read_camera(path, image_width, image_height, libs, PROBE_CLOCK, declares)
    except SceneCameraError:
        return ""  # (nothing to compare with)
    if other is None and cam is None:
        return ""
    same = (other is not None and cam is not None
            and all(np.allclose(getattr(cam, k), getattr(other, k), rtol=1e-9, atol=1e-12)
                    for k in ("location", "direction", "up", "right")))
    if same:
        return ""
    return ("the scene's camera moves with clock: it was read at clock 0, POV-Ray's value for "
            "a still image (pass clock for another frame, as POV-Ray's +K)")


def _notes(cam: CameraState, width, height) -> list[str]:
    """What of ``cam`` povlens replaces or ignores, in words."""
    out = []
    if cam.type != "perspective":
        out.append(f"camera type {cam.type} ({cam.where}): the lens replaces its projection; "
                   f"povlens takes only its position and orientation")
    if cam.aperture is not None and cam.aperture > 0.0:
        fd = "" if cam.focal_distance is None else f", focal_point {cam.focal_distance:.6g} away"
        out.append(f"the scene's focal blur (aperture {cam.aperture:g}{fd}; {cam.where}) is "
                   f"replaced by the lens's own depth of field")
    if cam.has_normal:
        out.append(f"the camera's normal {{ }} ({cam.where}), which perturbs its rays, is ignored")
    if width and height and cam.type in ("perspective", "orthographic"):
        r, u = float(np.linalg.norm(cam.right)), float(np.linalg.norm(cam.up))
        if u > 0.0 and abs((r / u) / (width / height) - 1.0) > ASPECT_TOLERANCE:
            out.append(f"the camera's proportions |right|/|up| = {r / u:.4g} ({cam.where}) differ "
                       f"from the image's {width}x{height} ({width / height:.4g}): POV-Ray "
                       f"stretches its picture to fit, the lens does not")
    return out


def _world_camera(cam: CameraState) -> SceneCamera:
    """The orthonormal basis and fields of view of a POV-Ray camera."""
    where = cam.where
    f = _unit(cam.direction, "direction", where)
    r = cam.right - np.dot(cam.right, f) * f
    r = _unit(r, "right", where)
    u = cam.up - np.dot(cam.up, f) * f - np.dot(cam.up, r) * r
    u = _unit(u, "up", where)
    hfov = vfov = None
    if cam.type == "perspective":
        dlen = float(np.linalg.norm(cam.direction))
        hfov = math.degrees(2.0 * math.atan(0.5 * float(np.linalg.norm(cam.right)) / dlen))
        vfov = math.degrees(2.0 * math.atan(0.5 * float(np.linalg.norm(cam.up)) / dlen))
    return SceneCamera(
        location=cam.location.copy(),
        forward=f,
        right=r,
        up=u,
        direction_vector=cam.direction.copy(),
        right_vector=cam.right.copy(),
        up_vector=cam.up.copy(),
        hfov_deg=hfov,
        vfov_deg=vfov,
        projection=cam.type,
        look_at=None if cam.look_at is None else cam.look_at.copy(),
        sky=cam.sky.copy(),
        aperture=cam.aperture,
        focal_distance=cam.focal_distance,
        source=where,
    )


def _unit(v: np.ndarray, what: str, where: str) -> np.ndarray:
    """``v`` / |v|; :class:`SceneCameraError` for a zero or non-finite vector."""
    n = float(np.linalg.norm(v))
    if not np.isfinite(n) or n == 0.0:
        raise SceneCameraError(f"{where}: the camera's {what} vector has zero length")
    return v / n
