"""The ``camera { ... }`` block of POV-Ray scene description language (SDL).

:class:`CameraState` mirrors POV-Ray 3.7's ``pov::Camera`` while a block is parsed
(``Parse_Camera`` in ``source/backend/parser/parse.cpp``); :func:`parse_camera_block`
reads one block's items -- projection, ``location``, ``look_at``, ``sky``, ``up``,
``right``, ``direction``, ``angle``, focal blur, ``normal``, transforms -- and applies them
in POV-Ray's order: for ``#version`` >= 3.5 right, direction, angle, up, sky, location,
look_at, focal_point, then the transforms; older versions apply the items as written.
Directives and macros inside the block are handled by the stream it reads
(:class:`povlens.pov.sdl.directives.DirectiveStream`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable, Mapping

import numpy as np

from povlens.pov.sdl.errors import MeshCameraError, SdlEvalError
from povlens.pov.sdl.expressions import ExpressionParser
from povlens.pov.sdl.lexer import Token
from povlens.pov.sdl.transforms import TRANSFORM_WORDS, TransformReader
from povlens.pov.sdl.values import UnknownValue, as_float, as_vector

__all__ = ["CameraState", "CAMERA_WORDS", "PROJECTIONS", "parse_camera_block"]


@dataclasses.dataclass
class CameraState:
    """A POV-Ray camera being parsed (mirrors ``pov::Camera``): world vectors in scene
    units, unnormalized as POV-Ray keeps them; ``where`` is ``"file:line"``."""

    type: str = "perspective"
    location: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    direction: np.ndarray = dataclasses.field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    up: np.ndarray = dataclasses.field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    right: np.ndarray = dataclasses.field(default_factory=lambda: np.array([1.33, 0.0, 0.0]))
    sky: np.ndarray = dataclasses.field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    look_at: np.ndarray | None = None
    aperture: float | None = None
    focal_point: np.ndarray | None = None
    focal_distance: float | None = None
    has_normal: bool = False  # a camera normal { } (perturbed rays)
    where: str = ""

    def copy(self) -> "CameraState":
        """A copy with its own arrays."""
        return dataclasses.replace(
            self,
            **{
                f.name: getattr(self, f.name).copy()
                for f in dataclasses.fields(self)
                if isinstance(getattr(self, f.name), np.ndarray)
            },
        )

    def transform(self, m: np.ndarray) -> None:
        """Apply a 4x4 row-vector transform (POV-Ray ``Camera::Transform``)."""
        self.location = np.append(self.location, 1.0) @ m[:, :3]
        self.direction = self.direction @ m[:3, :3]
        self.up = self.up @ m[:3, :3]
        self.right = self.right @ m[:3, :3]
        if self.look_at is not None:
            self.look_at = np.append(self.look_at, 1.0) @ m[:, :3]

    def apply_angle(self, angle: float) -> None:
        """``angle`` (full horizontal field, degrees): scale ``direction`` so that
        ``right`` spans it (perspective and orthographic cameras)."""
        if self.type in ("perspective", "orthographic") and angle > 0.0:
            if angle >= 180.0:
                raise SdlEvalError(f"{self.where}: camera angle {angle} must be below 180 degrees")
            d = np.linalg.norm(self.direction)
            if d == 0:
                raise SdlEvalError(f"{self.where}: camera direction has zero length")
            dir_len = np.linalg.norm(self.right) / math.tan(math.radians(angle) / 2.0) / 2.0
            self.direction = self.direction / d * dir_len

    def fit_orthographic(self) -> None:
        """Scale ``right`` and ``up`` of an orthographic camera so that it frames what a
        perspective camera would at the look_at distance (POV-Ray's "apply orthographic":
        by |look_at - location| / |direction|, look_at defaulting to <0, 0, 1>)."""
        target = np.array([0.0, 0.0, 1.0]) if self.look_at is None else self.look_at
        k1 = float(np.linalg.norm(target - self.location))
        k2 = float(np.linalg.norm(self.direction))
        if k1 > 1e-10 and k2 > 1e-10:
            self.right = self.right * (k1 / k2)
            self.up = self.up * (k1 / k2)

    def apply_look_at(self, look_at: np.ndarray) -> None:
        """Turn the camera to ``look_at`` (3,) about ``sky``, keeping the lengths of
        ``direction``, ``up``, ``right`` and the handedness of ``right``."""
        dir_len = np.linalg.norm(self.direction)
        up_len = np.linalg.norm(self.up)
        right_len = np.linalg.norm(self.right)
        handedness = float(np.dot(np.cross(self.up, self.direction), self.right))
        d = look_at - self.location
        if float(np.dot(d, d)) < 1e-10:
            raise SdlEvalError(f"{self.where}: camera location and look_at are the same point")
        d = d / np.linalg.norm(d)
        r = np.cross(self.sky, d)
        if np.all(np.abs(r) < 1e-10):
            r = self.right  # POV-Ray warns and keeps the given right vector
        rn = np.linalg.norm(r)
        if rn == 0:
            raise SdlEvalError(f"{self.where}: camera sky is parallel to the viewing direction")
        r = r / rn
        self.up = np.cross(d, r) * up_len
        self.direction = d * dir_len
        self.right = r * (right_len if handedness > 0.0 else -right_len)
        self.look_at = look_at


#: The words that may start a camera item.
CAMERA_WORDS = {
    "location", "look_at", "direction", "up", "right", "sky", "angle", "aperture",
    "focal_point", "blur_samples", "confidence", "variance", "normal", "bokeh",
    "translate", "rotate", "scale", "matrix", "transform", "cylinder",
    "mesh_camera", "user_defined",
}  # fmt: skip

#: The projection keywords (``cylinder N`` is read separately).
PROJECTIONS = {
    "perspective",
    "orthographic",
    "fisheye",
    "ultra_wide_angle",
    "omnimax",
    "panoramic",
    "spherical",
}


#: Camera items whose vector value is set (new style: remembered, then applied in
#: POV-Ray's order).
_VECTOR_ITEMS = ("location", "look_at", "direction", "up", "right", "sky", "focal_point")


def parse_camera_block(
    stream,
    expr: ExpressionParser,
    tok: Token,
    *,
    declared: bool,
    symbol: Callable[[Token], object],
    version: float,
    previous: CameraState,
) -> CameraState | UnknownValue:
    """Parse ``camera { ... }``; the stream is at its '{'.

    Parameters
    ----------
    stream : the scene's tokens after directives and macros
        (:class:`~povlens.pov.sdl.directives.DirectiveStream`: ``peek``, ``next``,
        ``mark``, ``reset``, ``skip_rest_raw``).
    expr : the expression evaluator reading ``stream``.
    tok : the ``camera`` token (its place names the camera).
    declared : True inside ``#declare NAME = camera { ... }``.
    symbol : the value of the declared name a token names (or None); a block may start
        with a declared camera, and ``transform T`` names a declared transform.
    version : the scene's ``#version``; below 3.5 items apply as written.
    previous : for ``#version`` < 3.5, the last camera statement, which an undeclared
        block modifies.

    Returns
    -------
    CameraState or UnknownValue
        The camera, or why it cannot be evaluated (the block is skipped then, so
        reading continues after it); a ``mesh_camera`` gives an UnknownValue of kind
        ``"mesh_camera"``.
    """
    expr.expect("{")
    mark = stream.mark()  # just after '{', to skip the block on errors
    try:
        return _CameraBlock(stream, expr, symbol, version >= 3.5).items(tok, declared, previous)
    except SdlEvalError as exc:
        if mark is not None and stream.reset(mark):
            stream.skip_rest_raw()
        else:
            stream.abandon()  # cannot resynchronize: stop reading
        kind = "mesh_camera" if isinstance(exc, MeshCameraError) else ""
        return UnknownValue(str(exc), kind=kind, hint=exc.hint)


class _CameraBlock:
    """The items of one camera block, read into a :class:`CameraState`."""

    def __init__(self, stream, expr: ExpressionParser, symbol: Callable[[Token], object],
                 new_style: bool):
        self.stream, self.expr, self.symbol, self.new_style = stream, expr, symbol, new_style
        self.transforms = TransformReader(stream, expr, symbol)

    def _eval(self, no_gt: bool = False):
        return self.expr.parse(no_gt)

    def _start(self, tok: Token, declared: bool, previous: CameraState) -> tuple[CameraState, bool]:
        """The camera the block starts from, and whether only transforms may follow
        (a declared camera's name, new style)."""
        first = self.stream.peek()
        if first.kind == "ident" and first.text not in PROJECTIONS and first.text not in CAMERA_WORDS:
            sym = self.symbol(first)
            if sym is not None:
                if isinstance(sym, UnknownValue):
                    raise SdlEvalError(f"{first.where}: camera '{first.text}' is unknown: {sym.reason}",
                                       sym.hint)
                if not isinstance(sym, CameraState):
                    raise SdlEvalError(f"{first.where}: '{first.text}' is not a camera")
                self.stream.next()
                return sym.copy(), self.new_style
        if self.new_style or declared:
            return CameraState(), False
        return previous.copy(), False

    def items(self, tok: Token, declared: bool, previous: CameraState) -> CameraState:
        """Read the items up to the closing '}' and return the camera they make."""
        cam, only_mods = self._start(tok, declared, previous)
        cam.where = tok.where
        trans = np.eye(4)
        pending: dict[str, object] = {}
        while True:
            t = self.stream.next()
            if t.kind == "op" and t.text == "}":
                break
            if t.kind in ("eof", "stop"):
                raise SdlEvalError(f"{tok.where}: the camera block is not closed")
            if t.kind != "ident":
                raise SdlEvalError(f"{t.where}: unexpected '{t.text}' in the camera")
            m = self.transforms.item(t.text, t) if t.text in TRANSFORM_WORDS else None
            if m is not None:
                if self.new_style:
                    trans = trans @ m
                else:
                    cam.transform(m)
                continue
            if only_mods:
                raise SdlEvalError(
                    f"{t.where}: '{t.text}' after the camera identifier; only transforms are allowed there"
                )
            self._item(cam, t, pending)
        if self.new_style and not only_mods:
            _apply_in_povray_order(cam, pending)
        cam.transform(trans)
        return cam

    def _item(self, cam: CameraState, t: Token, pending: dict[str, object]) -> None:
        """Read one non-transform item ``t``: set it on ``cam`` (old style) or keep it
        in ``pending`` (new style)."""
        word = t.text
        if word in PROJECTIONS:
            cam.type = word
            if word == "orthographic" and not self.new_style:
                cam.fit_orthographic()
        elif word == "cylinder":
            n = int(as_float(self._eval(), "cylinder type"))
            cam.type = f"cylinder {n}"
        elif word == "mesh_camera":
            raise MeshCameraError(
                f"{t.where}: the scene's camera is a mesh_camera, whose rays come from a mesh "
                f"rather than from a position and orientation; povlens has no pose to put its "
                f"lens at and does not read mesh_camera scenes")
        elif word == "user_defined":
            raise SdlEvalError(f"{t.where}: the scene uses a user_defined camera, which povlens cannot read")
        elif word == "normal":
            self._skip_block()
            cam.has_normal = True
        elif word == "bokeh":
            self._skip_block()
        elif word in _VECTOR_ITEMS:
            v = as_vector(self._eval(), word)
            if self.new_style:
                pending[word] = v
            else:
                _old_style_item(cam, word, v)
        elif word == "angle":
            a = as_float(self._eval(), "angle")
            if a < 0:
                raise SdlEvalError(f"{t.where}: negative camera angle")
            if cam.type == "spherical" and self.stream.peek(0, expand=False).text == ",":
                self.stream.next()
                self._eval()
            if self.new_style:
                pending["angle"] = a
            else:
                cam.apply_angle(a)
        elif word == "aperture":
            cam.aperture = as_float(self._eval(), "aperture")
        elif word == "blur_samples":
            self._eval()
            if self.stream.peek(0, expand=False).text == ",":
                self.stream.next()
                self._eval()
        elif word in ("confidence", "variance"):
            self._eval()
        else:
            raise SdlEvalError(f"{t.where}: unknown camera item '{word}'")

    def _skip_block(self) -> None:
        """Skip a ``{ ... }`` (a camera normal or bokeh) with its directives processed."""
        tok = self.stream.next()
        if tok.text != "{":
            raise SdlEvalError(f"{tok.where}: expected '{{'")
        self.stream.skip_rest()


def _apply_in_povray_order(cam: CameraState, pending: Mapping[str, object]) -> None:
    """Apply the items of a new-style block (``#version`` >= 3.5) in POV-Ray's fixed
    order: right, direction, angle, up, sky, location, look_at, focal_point (the
    transforms come after, in :meth:`_CameraBlock.items`)."""
    for key in ("right", "direction"):
        if key in pending:
            setattr(cam, key, pending[key])
    if "angle" in pending:
        cam.apply_angle(float(pending["angle"]))
    for key in ("up", "sky", "location"):
        if key in pending:
            setattr(cam, key, pending[key])
    if "look_at" in pending:
        cam.apply_look_at(pending["look_at"])
    if cam.type == "orthographic" and (("up" not in pending and "right" not in pending)
                                       or "angle" in pending):
        cam.fit_orthographic()
    if "focal_point" in pending:
        cam.focal_point = pending["focal_point"]
        cam.focal_distance = float(np.linalg.norm(cam.focal_point - cam.location))


def _old_style_item(cam: CameraState, word: str, v: np.ndarray) -> None:
    """Apply a vector item at once, as written (``#version`` < 3.5)."""
    if word == "look_at":
        cam.apply_look_at(v)
    elif word == "focal_point":
        cam.focal_point = v
        cam.focal_distance = float(np.linalg.norm(v - cam.location))
    else:
        setattr(cam, word, v)
