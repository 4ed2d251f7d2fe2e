"""Read the camera of an ordinary POV-Ray scene.

:func:`parse_scene_camera` finds the camera statement POV-Ray would use (the
*last* ``camera { ... }`` the parser meets) and evaluates it the way POV-Ray
3.7 does (``Parse_Camera`` in ``source/backend/parser/parse.cpp``), returning
the world-space camera basis in scene units.

What is understood
------------------
* comments (``//``, nested ``/* */``), strings, ``#include "file"`` of files
  found next to the including file or the scene (system include files such as
  ``colors.inc`` are not read), ``#version``;
* ``#declare`` / ``#local`` of numbers and vectors, and of ``camera { }``;
* ``#if`` / ``#ifdef`` / ``#ifndef`` / ``#elseif`` / ``#else`` whose
  condition can be evaluated; ``#macro`` definitions are skipped;
* expressions: numbers, ``<a, b, c>``, ``x`` ``y`` ``z`` ``pi`` ``tau``
  ``true`` ``false`` ``clock`` (= 0) ``image_width`` ``image_height``
  ``version``, ``+ - * /``, parentheses, unary minus, comparisons, ``& | !``,
  ``? :``, ``.x .y .z``, and the functions ``abs sqrt sin cos tan asin acos
  atan atan2 radians degrees pow exp ln log min max int floor ceil mod
  vlength vnormalize vcross vdot vrotate``;
* camera items ``perspective orthographic fisheye ultra_wide_angle omnimax
  panoramic spherical cylinder N location look_at sky up right direction
  angle aperture focal_point blur_samples confidence variance normal{}
  bokeh{}`` and the transforms ``translate rotate scale matrix transform{}``,
  applied in POV-Ray's order (for ``#version`` >= 3.5: right, direction,
  angle, up, sky, location, look_at, then the transforms; older versions
  apply the items in the order written).

Anything else used by the camera -- macros, user functions, declared
transforms, arrays, camera items inside ``#if`` -- raises
:class:`SceneCameraError`, which tells the user to give the camera explicitly
(``--location``, ``--look-at``, ``--sky``).

Conventions (reference §11)
---------------------------
POV-Ray is left-handed (+x right, +y up, +z into the screen) but all vector
formulas are the ordinary ones.  With ``look_at``: ``forward`` =
normalize(look_at - location), ``right`` = normalize(cross(sky, forward)),
``up`` = cross(forward, right).  The perspective camera's pixel (i, j) looks
along ``D + x0 R + y0 U`` with ``x0 = (i + 0.5)/W - 0.5``, ``y0 = 0.5 -
(j + 0.5)/H`` (row 0 at the top).
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np

from povlens.errors import PovlensError

__all__ = ["SceneCamera", "SceneCameraError", "parse_scene_camera"]

_HINT = "give the camera explicitly with --location, --look-at and --sky (and --hfov if needed)"

#: Include files larger than this are not read (they are mesh data, not cameras).
MAX_INCLUDE_BYTES = 16 * 1024 * 1024


class SceneCameraError(PovlensError):
    """The scene's camera cannot be found or evaluated."""

    def __init__(self, message: str, hint: str | None = _HINT):
        super().__init__(message, hint)


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
    projection : ``"perspective"``, ``"orthographic"``, ``"fisheye"``, ...
    look_at : (3,) the look_at point (after camera transforms) or ``None``.
    sky : (3,) the sky vector as written (not transformed).
    aperture, focal_distance : focal blur settings if the camera has them,
        else ``None``; ``focal_distance`` = |focal_point - location| before
        camera transforms (scene units).
    source : ``"file:line"`` of the camera statement used.
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


# ---------------------------------------------------------------------------
# tokens

_TOKEN_RE = re.compile(
    r"""
    (?P<ws>\s+)
  | (?P<lcomment>//[^\n]*)
  | (?P<bcomment>/\*)
  | (?P<string>"(?:[^"\\\n]|\\.)*")
  | (?P<number>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)
  | (?P<directive>\#\s*[A-Za-z_][A-Za-z0-9_]*)
  | (?P<ident>[A-Za-z_][A-Za-z0-9_]*)
  | (?P<op><=|>=|!=|[{}()<>\[\],;=+\-*/.?:!&|%^$@])
    """,
    re.VERBOSE,
)


class _Tok(NamedTuple):
    kind: str  # "number", "string", "directive", "ident", "op", "eof"
    text: str
    path: str
    line: int

    @property
    def where(self) -> str:
        return f"{self.path}:{self.line}"


#: What a text-level block skip must look at: braces, strings, comments, and
#: directives (a block containing directives is walked token by token).
_SKIP_RE = re.compile(r'[{}"]|/\*|//|\#\s*[A-Za-z_]')
_STRING_RE = re.compile(r'"(?:[^"\\\n]|\\.)*"?')


def _block_comment_end(text: str, i: int) -> int:
    """Position after the (nested) block comment whose '/*' ends at ``i``."""
    depth, n = 1, len(text)
    while depth and i < n:
        j_open = text.find("/*", i)
        j_close = text.find("*/", i)
        if j_close < 0:
            return n
        if 0 <= j_open < j_close:
            depth, i = depth + 1, j_open + 2
        else:
            depth, i = depth - 1, j_close + 2
    return i


class _File:
    """One scene file being tokenized lazily."""

    __slots__ = ("text", "path", "pos", "line", "buf")

    def __init__(self, text: str, path: str):
        self.text = text
        self.path = path
        self.pos = 0
        self.line = 1
        self.buf: list[_Tok] = []

    def _advance(self, end: int) -> None:
        self.line += self.text.count("\n", self.pos, end)
        self.pos = end

    def scan(self) -> _Tok | None:
        """The next token from the text (not the buffer), or None at the end."""
        text, n = self.text, len(self.text)
        match = _TOKEN_RE.match
        while self.pos < n:
            m = match(text, self.pos)
            if m is None:  # a stray character POV-Ray would reject: skip it
                self._advance(self.pos + 1)
                continue
            kind = m.lastgroup
            end = m.end()
            if kind == "bcomment":
                end = _block_comment_end(text, end)
            elif kind not in ("ws", "lcomment"):
                tok_text = m.group()
                if kind == "directive":
                    tok_text = "#" + tok_text[1:].strip()
                tok = _Tok(kind, tok_text, self.path, self.line + text.count("\n", self.pos, m.start()))
                self._advance(end)
                return tok
            self._advance(end)
        return None

    def skip_block_text(self, force: bool) -> bool:
        """Skip to just after the '}' matching an already consumed '{'.

        Works on the raw text (fast for bulky mesh data).  Unless ``force``,
        gives up (returning False, nothing consumed) when the block contains
        a directive, so that it can be walked token by token instead.
        """
        assert not self.buf
        text, n = self.text, len(self.text)
        depth, i = 1, self.pos
        search = _SKIP_RE.search
        while depth:
            m = search(text, i)
            if m is None:
                i = n
                break
            t = m.group()
            if t == "{":
                depth += 1
                i = m.end()
            elif t == "}":
                depth -= 1
                i = m.end()
            elif t == '"':
                i = _STRING_RE.match(text, m.start()).end()
            elif t == "/*":
                i = _block_comment_end(text, m.end())
            elif t == "//":
                j = text.find("\n", m.end())
                i = n if j < 0 else j
            else:  # a directive
                if not force:
                    return False
                i = m.end()
        self._advance(i)
        return True


class _Stream:
    """Tokens of the scene with ``#include``d files spliced in."""

    def __init__(self) -> None:
        self.files: list[_File] = []  # the include stack, innermost last
        self._eof = _Tok("eof", "", "<end of scene>", 0)

    def push_file(self, path: Path) -> None:
        try:
            text = path.read_text(encoding="utf-8", errors="replace")
        except OSError as exc:
            raise SceneCameraError(
                f"cannot read the scene file {path}: {exc.strerror or exc}",
                "check the path and permissions",
            ) from None
        self.files.append(_File(text, str(path)))

    def _fill(self, k: int) -> _File | None:
        """Make the innermost non-exhausted file's buffer hold >= k+1 tokens if it can."""
        while self.files:
            f = self.files[-1]
            while len(f.buf) <= k:
                tok = f.scan()
                if tok is None:
                    break
                f.buf.append(tok)
            if f.buf:
                return f
            self.files.pop()
        return None

    def peek(self, ahead: int = 0) -> _Tok:
        f = self._fill(ahead)
        if f is None or ahead >= len(f.buf):
            # (look-ahead across a file boundary counts as the end)
            return self._eof
        return f.buf[ahead]

    def next(self) -> _Tok:
        f = self._fill(0)
        if f is None:
            return self._eof
        return f.buf.pop(0)

    def skip_block(self, force: bool = False) -> bool:
        """After consuming a '{': skip the rest of its block at text level."""
        f = self.files[-1] if self.files else None
        if f is None or f.buf:
            return False
        return f.skip_block_text(force)

    def mark(self) -> tuple[_File, int, int] | None:
        """Position just after the last consumed token (its buffer must be empty)."""
        f = self.files[-1] if self.files else None
        if f is None or f.buf:
            return None
        return f, f.pos, f.line

    def reset(self, mark: tuple[_File, int, int]) -> bool:
        f, pos, line = mark
        if f not in self.files:
            return False
        while self.files[-1] is not f:
            self.files.pop()
        f.pos, f.line, f.buf = pos, line, []
        return True

    def is_open(self, path: Path) -> bool:
        return any(Path(f.path).resolve() == path for f in self.files)


# ---------------------------------------------------------------------------
# values and expressions


class _EvalError(Exception):
    """An expression povlens cannot evaluate (message names what and where)."""


@dataclasses.dataclass(frozen=True)
class _Unknown:
    """A declared name whose value povlens cannot know."""

    reason: str
    maybe: bool = False  # True: may or may not be declared at all


@dataclasses.dataclass
class _Macro:
    name: str
    has_camera: bool
    where: str


def _rotation_matrix(deg: np.ndarray) -> np.ndarray:
    """POV-Ray ``rotate <ax, ay, az>`` (degrees) as a 3x3 row-vector matrix.

    Rotates about x, then y, then z; ``p' = p @ M``.
    """
    ax, ay, az = np.radians(np.asarray(deg, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, sx], [0, -sx, cx]])
    ry = np.array([[cy, 0, -sy], [0, 1, 0], [sy, 0, cy]])
    rz = np.array([[cz, sz, 0], [-sz, cz, 0], [0, 0, 1]])
    return rx @ ry @ rz


def _vec(v, what: str) -> np.ndarray:
    if isinstance(v, np.ndarray):
        return v
    return np.array([float(v)] * 3)


def _flt(v, what: str) -> float:
    if isinstance(v, np.ndarray):
        raise _EvalError(f"{what} must be a number, got the vector <{', '.join(map(str, v))}>")
    return float(v)


def _f1(fn: Callable[[float], float]) -> Callable:
    return lambda a: fn(_flt(a, "argument"))


_FUNCTIONS: dict[str, tuple[int, Callable]] = {
    "abs": (1, lambda a: np.abs(a) if isinstance(a, np.ndarray) else abs(a)),
    "sqrt": (1, _f1(math.sqrt)),
    "sin": (1, _f1(math.sin)),
    "cos": (1, _f1(math.cos)),
    "tan": (1, _f1(math.tan)),
    "asin": (1, _f1(math.asin)),
    "acos": (1, _f1(math.acos)),
    "atan": (1, _f1(math.atan)),
    "atan2": (2, lambda a, b: math.atan2(_flt(a, "argument"), _flt(b, "argument"))),
    "radians": (1, lambda a: a * (math.pi / 180.0)),
    "degrees": (1, lambda a: a * (180.0 / math.pi)),
    "pow": (2, lambda a, b: math.pow(_flt(a, "argument"), _flt(b, "argument"))),
    "exp": (1, _f1(math.exp)),
    "ln": (1, _f1(math.log)),
    "log": (1, _f1(math.log10)),
    "min": (-1, lambda *a: min(_flt(v, "argument") for v in a)),
    "max": (-1, lambda *a: max(_flt(v, "argument") for v in a)),
    "int": (1, lambda a: float(math.trunc(_flt(a, "argument")))),
    "floor": (1, lambda a: float(math.floor(_flt(a, "argument")))),
    "ceil": (1, lambda a: float(math.ceil(_flt(a, "argument")))),
    "mod": (2, lambda a, b: math.fmod(_flt(a, "argument"), _flt(b, "argument"))),
    "vlength": (1, lambda a: float(np.linalg.norm(_vec(a, "argument")))),
    "vnormalize": (1, lambda a: _vec(a, "argument") / np.linalg.norm(_vec(a, "argument"))),
    "vcross": (2, lambda a, b: np.cross(_vec(a, "argument"), _vec(b, "argument"))),
    "vdot": (2, lambda a, b: float(np.dot(_vec(a, "argument"), _vec(b, "argument")))),
    "vrotate": (2, lambda a, b: _vec(a, "argument") @ _rotation_matrix(_vec(b, "argument"))),
}

_CONSTANTS = {
    "pi": math.pi,
    "tau": 2.0 * math.pi,
    "true": 1.0,
    "yes": 1.0,
    "on": 1.0,
    "false": 0.0,
    "no": 0.0,
    "off": 0.0,
    "clock": 0.0,  # povlens never renders animations
    "clock_delta": 0.0,
    "clock_on": 0.0,
    "frame_number": 0.0,
    "initial_clock": 0.0,
    "final_clock": 0.0,
    "initial_frame": 0.0,
    "final_frame": 0.0,
    "x": np.array([1.0, 0.0, 0.0]),
    "y": np.array([0.0, 1.0, 0.0]),
    "z": np.array([0.0, 0.0, 1.0]),
}

_COMPONENTS = {"x": 0, "u": 0, "red": 0, "y": 1, "v": 1, "green": 1, "z": 2, "blue": 2}


class _Expr:
    """Recursive-descent evaluator for POV-Ray float/vector expressions."""

    def __init__(self, stream: _Stream, lookup: Callable[[str, _Tok], object]):
        self.s = stream
        self.lookup = lookup

    def _err(self, tok: _Tok, msg: str) -> _EvalError:
        return _EvalError(f"{tok.where}: {msg}")

    def _expect(self, text: str) -> _Tok:
        tok = self.s.next()
        if tok.text != text or tok.kind not in ("op",):
            raise self._err(tok, f"expected '{text}' but found '{tok.text or 'end of file'}'")
        return tok

    # precedence climbing: ternary < | < & < comparison < + - < * / < unary < postfix
    def parse(self, no_gt: bool = False):
        cond = self._or(no_gt)
        tok = self.s.peek()
        if tok.kind == "op" and tok.text == "?":
            self.s.next()
            a = self.parse(no_gt)
            self._expect(":")
            b = self.parse(no_gt)
            return a if _flt(cond, "condition of '?'") != 0.0 else b
        return cond

    def _or(self, no_gt):
        v = self._and(no_gt)
        while self.s.peek().kind == "op" and self.s.peek().text == "|":
            self.s.next()
            w = self._and(no_gt)
            v = 1.0 if (_flt(v, "operand of '|'") != 0 or _flt(w, "operand of '|'") != 0) else 0.0
        return v

    def _and(self, no_gt):
        v = self._cmp(no_gt)
        while self.s.peek().kind == "op" and self.s.peek().text == "&":
            self.s.next()
            w = self._cmp(no_gt)
            v = 1.0 if (_flt(v, "operand of '&'") != 0 and _flt(w, "operand of '&'") != 0) else 0.0
        return v

    _CMP = {
        "<": lambda a, b: a < b,
        "<=": lambda a, b: a <= b,
        "=": lambda a, b: a == b,
        "!=": lambda a, b: a != b,
        ">=": lambda a, b: a >= b,
        ">": lambda a, b: a > b,
    }

    def _cmp(self, no_gt):
        v = self._add(no_gt)
        while True:
            tok = self.s.peek()
            if tok.kind != "op" or tok.text not in self._CMP or (no_gt and tok.text == ">"):
                return v
            self.s.next()
            w = self._add(no_gt)
            v = 1.0 if self._CMP[tok.text](_flt(v, "comparison"), _flt(w, "comparison")) else 0.0

    def _add(self, no_gt):
        v = self._mul(no_gt)
        while True:
            tok = self.s.peek()
            if tok.kind != "op" or tok.text not in ("+", "-"):
                return v
            self.s.next()
            w = self._mul(no_gt)
            v = _binop(v, w, tok.text)

    def _mul(self, no_gt):
        v = self._unary(no_gt)
        while True:
            tok = self.s.peek()
            if tok.kind != "op" or tok.text not in ("*", "/"):
                return v
            self.s.next()
            w = self._unary(no_gt)
            if tok.text == "/" and np.any(np.asarray(w) == 0):
                raise self._err(tok, "division by zero")
            v = _binop(v, w, tok.text)

    def _unary(self, no_gt):
        tok = self.s.peek()
        if tok.kind == "op" and tok.text in ("-", "+", "!"):
            self.s.next()
            v = self._unary(no_gt)
            if tok.text == "-":
                return -v
            if tok.text == "!":
                return 0.0 if _flt(v, "operand of '!'") != 0 else 1.0
            return v
        return self._postfix(no_gt)

    def _postfix(self, no_gt):
        v = self._primary()
        while self.s.peek().kind == "op" and self.s.peek().text == ".":
            dot = self.s.next()
            comp = self.s.next()
            if comp.kind != "ident" or comp.text not in _COMPONENTS:
                raise self._err(dot, f"unsupported vector component '.{comp.text}'")
            if not isinstance(v, np.ndarray):
                raise self._err(dot, f"'.{comp.text}' applied to a number")
            v = float(v[_COMPONENTS[comp.text]])
        return v

    def _primary(self):
        tok = self.s.next()
        if tok.kind == "number":
            return float(tok.text)
        if tok.kind == "op" and tok.text == "(":
            v = self.parse(no_gt=False)
            self._expect(")")
            return v
        if tok.kind == "op" and tok.text == "<":
            comps = [self.parse(no_gt=True)]
            while self.s.peek().kind == "op" and self.s.peek().text == ",":
                self.s.next()
                comps.append(self.parse(no_gt=True))
            self._expect(">")
            if len(comps) != 3:
                raise self._err(tok, f"vectors with {len(comps)} components are not supported")
            return np.array([_flt(c, "vector component") for c in comps])
        if tok.kind == "ident":
            name = tok.text
            nxt = self.s.peek()
            if name in _FUNCTIONS and nxt.kind == "op" and nxt.text == "(":
                nargs, fn = _FUNCTIONS[name]
                self.s.next()
                args = [self.parse()]
                while self.s.peek().kind == "op" and self.s.peek().text == ",":
                    self.s.next()
                    args.append(self.parse())
                self._expect(")")
                if nargs >= 0 and len(args) != nargs:
                    raise self._err(tok, f"{name}() takes {nargs} argument(s), got {len(args)}")
                try:
                    return fn(*args)
                except (ValueError, ZeroDivisionError, OverflowError) as exc:
                    raise self._err(tok, f"{name}(): {exc}") from None
            if name in _CONSTANTS:
                val = _CONSTANTS[name]
                return val.copy() if isinstance(val, np.ndarray) else val
            return self.lookup(name, tok)
        if tok.kind == "eof":
            raise self._err(tok, "unexpected end of the scene inside an expression")
        raise self._err(tok, f"cannot evaluate '{tok.text}' in an expression")


def _binop(a, b, op: str):
    if op == "+":
        return a + b
    if op == "-":
        return a - b
    if op == "*":
        return a * b
    return a / b


# ---------------------------------------------------------------------------
# camera state


@dataclasses.dataclass
class _Cam:
    """A POV-Ray camera being parsed (mirrors pov::Camera)."""

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
    where: str = ""

    def copy(self) -> "_Cam":
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
        if self.type in ("perspective", "orthographic") and angle > 0.0:
            if angle >= 180.0:
                raise _EvalError(f"{self.where}: camera angle {angle} must be below 180 degrees")
            d = np.linalg.norm(self.direction)
            if d == 0:
                raise _EvalError(f"{self.where}: camera direction has zero length")
            dir_len = np.linalg.norm(self.right) / math.tan(math.radians(angle) / 2.0) / 2.0
            self.direction = self.direction / d * dir_len

    def apply_look_at(self, look_at: np.ndarray) -> None:
        dir_len = np.linalg.norm(self.direction)
        up_len = np.linalg.norm(self.up)
        right_len = np.linalg.norm(self.right)
        handedness = float(np.dot(np.cross(self.up, self.direction), self.right))
        d = look_at - self.location
        if float(np.dot(d, d)) < 1e-10:
            raise _EvalError(f"{self.where}: camera location and look_at are the same point")
        d = d / np.linalg.norm(d)
        r = np.cross(self.sky, d)
        if np.all(np.abs(r) < 1e-10):
            r = self.right  # POV-Ray warns and keeps the given right vector
        rn = np.linalg.norm(r)
        if rn == 0:
            raise _EvalError(f"{self.where}: camera sky is parallel to the viewing direction")
        r = r / rn
        self.up = np.cross(d, r) * up_len
        self.direction = d * dir_len
        self.right = r * (right_len if handedness > 0.0 else -right_len)
        self.look_at = look_at


_CAMERA_WORDS = {
    "location", "look_at", "direction", "up", "right", "sky", "angle", "aperture",
    "focal_point", "blur_samples", "confidence", "variance", "normal", "bokeh",
    "translate", "rotate", "scale", "matrix", "transform", "cylinder",
    "mesh_camera", "user_defined",
}  # fmt: skip

_TYPES = {
    "perspective",
    "orthographic",
    "fisheye",
    "ultra_wide_angle",
    "omnimax",
    "panoramic",
    "spherical",
}


# ---------------------------------------------------------------------------
# the reader


@dataclasses.dataclass
class _Frame:
    kind: str  # "if", "loop", "switch"
    active: bool  # this branch may be executed
    certain: bool  # ... and if active, it certainly is
    decided: bool = False  # an earlier branch was certainly taken
    unknown: bool = False  # an earlier branch's condition was unknown
    where: str = ""


_OPENERS = {"#if", "#ifdef", "#ifndef", "#switch", "#while", "#for", "#macro"}


class _Reader:
    def __init__(self, path: Path, image_width, image_height):
        self.root = path.resolve()
        self.image_width = image_width
        self.image_height = image_height
        self.stream = _Stream()
        self.symbols: dict[str, object] = {}
        self.version = 3.7
        self.frames: list[_Frame] = []
        # the camera POV-Ray would use so far: _Cam, _Unknown (cannot tell), or None
        self.camera: object = None
        self.previous_cam = _Cam()  # for language versions < 3.5
        self.unread_includes: list[str] = []
        self.included: set[Path] = set()
        self.expr = _Expr(self.stream, self._lookup)

    # -- helpers --------------------------------------------------------
    @property
    def active(self) -> bool:
        return all(f.active for f in self.frames)

    @property
    def certain(self) -> bool:
        return all(f.certain for f in self.frames)

    def _uncertain_reason(self) -> str:
        for f in reversed(self.frames):
            if not f.certain:
                what = {"if": "#if", "loop": "#while/#for loop", "switch": "#switch"}[f.kind]
                return f"inside the {what} at {f.where}, which povlens cannot evaluate"
        return ""

    def _lookup(self, name: str, tok: _Tok):
        if name == "image_width":
            if self.image_width is None:
                raise _EvalError(f"{tok.where}: uses image_width, but no image width was given")
            return float(self.image_width)
        if name == "image_height":
            if self.image_height is None:
                raise _EvalError(f"{tok.where}: uses image_height, but no image height was given")
            return float(self.image_height)
        if name == "version":
            return float(self.version)
        if name not in self.symbols:
            extra = ""
            if self.unread_includes:
                extra = " (it may come from " + ", ".join(self.unread_includes[:4]) + ", which povlens does not read)"
            raise _EvalError(f"{tok.where}: '{name}' is not defined{extra}")
        val = self.symbols[name]
        if isinstance(val, _Unknown):
            raise _EvalError(f"{tok.where}: the value of '{name}' is unknown: {val.reason}")
        if isinstance(val, _Macro):
            raise _EvalError(f"{tok.where}: '{name}' is a macro ({val.where}); macros are not evaluated")
        if isinstance(val, _Cam):
            raise _EvalError(f"{tok.where}: camera '{name}' used in an expression")
        return val.copy() if isinstance(val, np.ndarray) else val

    def _eval(self, no_gt=False):
        return self.expr.parse(no_gt)

    def _skip_block(self) -> None:
        """Skip a balanced { ... } block; the next token must be '{'."""
        tok = self.stream.next()
        if tok.text != "{":
            raise _EvalError(f"{tok.where}: expected '{{'")
        if self.stream.skip_block():
            return
        depth = 1
        while depth:
            tok = self.stream.next()
            if tok.kind == "eof":
                return
            if tok.kind == "op":
                if tok.text == "{":
                    depth += 1
                elif tok.text == "}":
                    depth -= 1

    def _recover(self) -> None:
        """After an unevaluable value: skip to the end of the statement."""
        while True:
            tok = self.stream.peek()
            if tok.kind in ("eof", "directive"):
                return
            if tok.kind == "op" and tok.text == ";":
                self.stream.next()
                return
            if tok.kind == "op" and tok.text == "}":
                return
            if tok.kind == "op" and tok.text == "{":
                self._skip_block()
                continue
            if tok.kind == "ident" and self.stream.peek(1).text == "{":
                return
            self.stream.next()

    def _paren_cond(self, directive: _Tok):
        """Evaluate '( expr )' after #if/#elseif/#while; None if unknown."""
        try:
            self.expr._expect("(")
            v = self._eval()
            self.expr._expect(")")
            return _flt(v, "condition") != 0.0
        except _EvalError:
            self._skip_to_paren_end()
            return None

    def _skip_to_paren_end(self) -> None:
        depth = 1
        while depth:
            tok = self.stream.peek()
            if tok.kind in ("eof", "directive"):
                return
            self.stream.next()
            if tok.text == "(":
                depth += 1
            elif tok.text == ")":
                depth -= 1

    # -- main loop ------------------------------------------------------
    def run(self) -> None:
        self.stream.push_file(self.root)
        self.included.add(self.root)
        while True:
            tok = self.stream.peek()
            if tok.kind == "eof":
                break
            if tok.kind == "directive":
                self.stream.next()
                self._directive(tok)
                continue
            self.stream.next()
            if not self.active:
                continue
            if tok.kind == "ident":
                nxt = self.stream.peek()
                if tok.text == "camera" and nxt.text == "{":
                    self._camera_statement(tok)
                    continue
                if nxt.kind == "op" and nxt.text == "{":
                    # An object or other block: skip bulky data at text level
                    # unless it contains directives (then walk its tokens).
                    self.stream.next()
                    self.stream.skip_block()
                    continue
                sym = self.symbols.get(tok.text)
                if isinstance(sym, _Macro) and sym.has_camera:
                    self.camera = _Unknown(
                        f"{tok.where}: the camera is made by the macro {tok.text}() "
                        f"(defined at {sym.where}); povlens does not run macros"
                    )

    def _directive(self, tok: _Tok) -> None:
        name = tok.text
        if name in ("#if", "#ifdef", "#ifndef"):
            if not self.active:
                self._skip_parens()
                self.frames.append(_Frame("if", False, True, where=tok.where))
                return
            if name == "#if":
                c = self._paren_cond(tok)
            else:
                c = self._defined_cond(tok)
                if c is not None and name == "#ifndef":
                    c = not c
            self.frames.append(
                _Frame("if", c is not False, c is not None, decided=c is True, unknown=c is None, where=tok.where)
            )
            return
        if name in ("#elseif", "#else"):
            if not self.frames:
                return
            f = self.frames[-1]
            parent_active = all(g.active for g in self.frames[:-1])
            if f.kind != "if":
                if name == "#elseif":
                    self._skip_parens()
                return  # #else of a #switch: stays uncertain
            if not parent_active or f.decided:
                if name == "#elseif":
                    self._skip_parens()
                f.active = False
                return
            c = self._paren_cond(tok) if name == "#elseif" else True
            f.active = c is not False
            if f.unknown:
                f.certain = False
            else:
                f.certain = c is not None
                f.decided = c is True
            f.unknown = f.unknown or c is None
            f.where = tok.where if c is None else f.where
            return
        if name == "#end":
            if self.frames:
                self.frames.pop()
            return
        if name in ("#while", "#for", "#switch"):
            self._skip_parens()
            kind = "switch" if name == "#switch" else "loop"
            self.frames.append(_Frame(kind, self.active, False, where=tok.where))
            return
        if name in ("#case", "#range"):
            self._skip_parens()
            return
        if name == "#macro":
            self._macro(tok)
            return
        if not self.active:
            return
        if name in ("#declare", "#local"):
            self._declare(tok)
        elif name == "#undef":
            ident = self.stream.next()
            if ident.kind == "ident":
                if self.certain:
                    self.symbols.pop(ident.text, None)
                else:
                    self.symbols[ident.text] = _Unknown(
                        f"#undef at {ident.where} is {self._uncertain_reason()}", maybe=True
                    )
        elif name == "#include":
            self._include(tok)
        elif name == "#version":
            try:
                v = _flt(self._eval(), "#version")
                if self.certain:
                    self.version = v
            except _EvalError:
                self._recover()
            if self.stream.peek().text == ";":
                self.stream.next()

    def _skip_parens(self) -> None:
        if self.stream.peek().text == "(":
            self.stream.next()
            self._skip_to_paren_end()

    def _defined_cond(self, tok: _Tok):
        try:
            self.expr._expect("(")
            ident = self.stream.next()
            self.expr._expect(")")
        except _EvalError:
            self._skip_to_paren_end()
            return None
        if ident.text in ("image_width", "image_height", "version", "clock") or ident.text in _CONSTANTS:
            return True
        val = self.symbols.get(ident.text)
        if val is None:
            return False
        if isinstance(val, _Unknown) and val.maybe:
            return None
        return True

    def _macro(self, tok: _Tok) -> None:
        ident = self.stream.next()
        depth, has_camera = 1, False
        while depth:
            t = self.stream.next()
            if t.kind == "eof":
                break
            if t.kind == "directive":
                if t.text in _OPENERS:
                    depth += 1
                elif t.text == "#end":
                    depth -= 1
            elif t.kind == "ident" and t.text == "camera":
                has_camera = True
        if self.active and ident.kind == "ident":
            self.symbols[ident.text] = _Macro(ident.text, has_camera, tok.where)

    def _include(self, tok: _Tok) -> None:
        name_tok = self.stream.next()
        if name_tok.kind != "string":
            self._recover()
            self.unread_includes.append(f"the #include at {tok.where}")
            return
        name = name_tok.text[1:-1]
        here = Path(tok.path).parent
        # POV-Ray looks in its working directory (the scene folder) first.
        candidates = [self.root.parent / name, here / name]
        for cand in candidates:
            if cand.is_file():
                cand = cand.resolve()
                if self.stream.is_open(cand):
                    return  # recursive include
                try:
                    size = cand.stat().st_size
                except OSError:
                    size = 0
                if size > MAX_INCLUDE_BYTES:
                    self.unread_includes.append(f'"{name}" (too large)')
                    return
                self.included.add(cand)
                self.stream.push_file(cand)
                return
        self.unread_includes.append(f'"{name}"')

    def _declare(self, tok: _Tok) -> None:
        ident = self.stream.next()
        if ident.kind != "ident":
            self._recover()
            return
        name = ident.text
        nxt = self.stream.peek()
        if nxt.text == "[" or nxt.text == ".":
            self.symbols[name] = _Unknown(f"it is an array or dictionary ({ident.where})")
            self._recover()
            return
        if nxt.text != "=":
            self._recover()
            return
        self.stream.next()
        uncertain = "" if self.certain else self._uncertain_reason()
        first = self.stream.peek()
        value: object
        if first.kind == "ident" and first.text == "camera" and self.stream.peek(1).text == "{":
            self.stream.next()
            value = self._parse_camera_block(first, declared=True)
        elif first.kind == "ident" and self.stream.peek(1).text == "{":
            self.stream.next()
            self._skip_block()
            value = _Unknown(f"it is declared as '{first.text} {{...}}' at {ident.where}")
        elif first.kind == "string":
            self._recover()
            value = _Unknown(f"it is a string ({ident.where})")
        elif first.kind == "ident" and isinstance(self.symbols.get(first.text), _Cam):
            self.stream.next()
            value = self.symbols[first.text].copy()
        else:
            try:
                value = self._eval()
            except _EvalError as exc:
                value = _Unknown(f"its #declare at {ident.where} could not be evaluated ({exc})")
                self._recover()
        if self.stream.peek().text == ";":
            self.stream.next()
        if uncertain:
            value = _Unknown(f"its #declare at {ident.where} is {uncertain}", maybe=True)
        self.symbols[name] = value

    # -- cameras --------------------------------------------------------
    def _camera_statement(self, tok: _Tok) -> None:
        cam = self._parse_camera_block(tok, declared=False)
        if not self.certain:
            self.camera = _Unknown(f"{tok.where}: the camera statement is {self._uncertain_reason()}")
            return
        self.camera = cam
        if isinstance(cam, _Cam):
            self.previous_cam = cam

    def _parse_camera_block(self, tok: _Tok, declared: bool):
        """Parse 'camera { ... }' (the stream is at '{'); returns _Cam or _Unknown."""
        self.expr._expect("{")
        mark = self.stream.mark()  # just after '{', to skip the block on errors
        try:
            return self._camera_items(tok, declared)
        except _EvalError as exc:
            if mark is not None and self.stream.reset(mark):
                self.stream.skip_block(force=True)
            else:
                self.stream.files.clear()  # cannot resynchronize: stop reading
            return _Unknown(str(exc))

    def _camera_items(self, tok: _Tok, declared: bool) -> _Cam:
        new_style = self.version >= 3.5
        first = self.stream.peek()
        only_mods = False
        if (
            first.kind == "ident"
            and first.text in self.symbols
            and first.text not in _TYPES
            and first.text not in _CAMERA_WORDS
        ):
            sym = self.symbols[first.text]
            if isinstance(sym, _Unknown):
                raise _EvalError(f"{first.where}: camera '{first.text}' is unknown: {sym.reason}")
            if not isinstance(sym, _Cam):
                raise _EvalError(f"{first.where}: '{first.text}' is not a camera")
            self.stream.next()
            cam = sym.copy()
            only_mods = new_style
        elif new_style or declared:
            cam = _Cam()
        else:
            cam = self.previous_cam.copy()
        cam.where = tok.where

        trans = np.eye(4)
        pending: dict[str, object] = {}
        while True:
            t = self.stream.next()
            if t.kind == "op" and t.text == "}":
                break
            if t.kind == "eof":
                raise _EvalError(f"{tok.where}: the camera block is not closed")
            if t.kind == "directive":
                raise _EvalError(
                    f"{t.where}: the camera contains the directive {t.text}, which povlens does not evaluate inside a camera"
                )
            if t.kind != "ident":
                raise _EvalError(f"{t.where}: unexpected '{t.text}' in the camera")
            word = t.text
            m = self._transform_item(word, t)
            if m is not None:
                if new_style:
                    trans = trans @ m
                else:
                    cam.transform(m)
                continue
            if only_mods:
                raise _EvalError(
                    f"{t.where}: '{word}' after the camera identifier; only transforms are allowed there"
                )
            if word in _TYPES:
                cam.type = word
                continue
            if word == "cylinder":
                n = int(_flt(self._eval(), "cylinder type"))
                cam.type = f"cylinder {n}"
                continue
            if word in ("mesh_camera", "user_defined"):
                raise _EvalError(f"{t.where}: the scene uses a {word} camera, which povlens cannot read")
            if word in ("normal", "bokeh"):
                self._skip_block()
                continue
            if word in ("location", "look_at", "direction", "up", "right", "sky", "focal_point"):
                v = _vec(self._eval(), word)
                if new_style:
                    pending[word] = v
                else:
                    self._old_style_item(cam, word, v)
                continue
            if word == "angle":
                a = _flt(self._eval(), "angle")
                if a < 0:
                    raise _EvalError(f"{t.where}: negative camera angle")
                if cam.type == "spherical" and self.stream.peek().text == ",":
                    self.stream.next()
                    self._eval()
                if new_style:
                    pending["angle"] = a
                else:
                    cam.apply_angle(a)
                continue
            if word == "aperture":
                cam.aperture = _flt(self._eval(), "aperture")
                continue
            if word == "blur_samples":
                self._eval()
                if self.stream.peek().text == ",":
                    self.stream.next()
                    self._eval()
                continue
            if word in ("confidence", "variance"):
                self._eval()
                continue
            raise _EvalError(f"{t.where}: unknown camera item '{word}'")

        if new_style and not only_mods:
            # POV-Ray's fixed order: right, direction, angle, up, sky, location,
            # look_at, focal_point, then the transforms.
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
            if "focal_point" in pending:
                cam.focal_point = pending["focal_point"]
                cam.focal_distance = float(np.linalg.norm(cam.focal_point - cam.location))
        cam.transform(trans)
        return cam

    def _old_style_item(self, cam: _Cam, word: str, v: np.ndarray) -> None:
        if word == "look_at":
            cam.apply_look_at(v)
        elif word == "focal_point":
            cam.focal_point = v
            cam.focal_distance = float(np.linalg.norm(v - cam.location))
        else:
            setattr(cam, word, v)

    def _transform_item(self, word: str, t: _Tok) -> np.ndarray | None:
        """4x4 row-vector matrix for a transform item, or None if ``word`` is not one."""
        m = np.eye(4)
        if word == "translate":
            m[3, :3] = _vec(self._eval(), "translate")
        elif word == "rotate":
            m[:3, :3] = _rotation_matrix(_vec(self._eval(), "rotate"))
        elif word == "scale":
            s = _vec(self._eval(), "scale").copy()
            s[s == 0] = 1.0  # POV-Ray warns and uses 1
            m[:3, :3] = np.diag(s)
        elif word == "matrix":
            tok = self.stream.next()
            if tok.text != "<":
                raise _EvalError(f"{tok.where}: expected '<' after matrix")
            vals = [_flt(self._eval(no_gt=True), "matrix entry")]
            while self.stream.peek().text == ",":
                self.stream.next()
                vals.append(_flt(self._eval(no_gt=True), "matrix entry"))
            self.expr._expect(">")
            if len(vals) != 12:
                raise _EvalError(f"{t.where}: matrix needs 12 numbers, got {len(vals)}")
            m[:, :3] = np.array(vals).reshape(4, 3)
        elif word == "transform":
            if self.stream.peek().text != "{":
                ident = self.stream.next()
                raise _EvalError(
                    f"{ident.where}: camera uses the declared transform '{ident.text}', which povlens cannot read"
                )
            self.stream.next()
            inverse = False
            while True:
                it = self.stream.next()
                if it.text == "}":
                    break
                if it.kind == "eof":
                    raise _EvalError(f"{t.where}: transform block is not closed")
                if it.kind == "ident" and it.text == "inverse":
                    inverse = True
                    continue
                sub = self._transform_item(it.text, it) if it.kind == "ident" else None
                if sub is None:
                    raise _EvalError(f"{it.where}: '{it.text}' inside transform{{}} is not supported")
                m = m @ sub
            if inverse:
                m = np.linalg.inv(m)
        else:
            return None
        return m


# ---------------------------------------------------------------------------


def _unit(v: np.ndarray, what: str, where: str) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if not np.isfinite(n) or n == 0.0:
        raise SceneCameraError(f"{where}: the camera's {what} vector has zero length")
    return v / n


def parse_scene_camera(
    path: str | os.PathLike,
    image_width: int | None = None,
    image_height: int | None = None,
) -> SceneCamera:
    """Read the camera POV-Ray would use for the scene file ``path``.

    ``image_width``/``image_height`` (pixels) are the values of POV-Ray's
    ``image_width``/``image_height`` keywords (commonly used as
    ``right x*image_width/image_height``); they are needed only if the camera
    uses them.

    Returns a :class:`SceneCamera` (world coordinates, scene units).  Raises
    :class:`SceneCameraError` (a :class:`PovlensError`) naming the file, line
    and construct when there is no camera or it cannot be evaluated.
    """
    path = Path(path)
    if not path.is_file():
        raise SceneCameraError(f"scene file {path} does not exist", "check the path")
    reader = _Reader(path, image_width, image_height)
    reader.run()
    cam = reader.camera
    if cam is None:
        extra = ""
        if reader.unread_includes:
            extra = (
                "; the scene includes "
                + ", ".join(reader.unread_includes[:6])
                + ", which povlens does not read and which may define the camera"
            )
        raise SceneCameraError(f"no camera statement found in {path}{extra}")
    if isinstance(cam, _Unknown):
        raise SceneCameraError(f"cannot read the camera of {path}: {cam.reason}")
    assert isinstance(cam, _Cam)
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
