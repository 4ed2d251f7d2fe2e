"""Values of POV-Ray scene description language (SDL) as the camera reader holds them.

Floats are ``float``; vectors and colours are ``np.ndarray`` of 2 to 5 components (POV-Ray
promotes a float to every component and pads a shorter vector with zeros when two meet,
``Promote_Express`` in ``source/backend/parser/express.cpp``); strings are ``str``.  Named
things that are not numbers are a :class:`Transform`, a :class:`Macro`, an
:class:`SdlArray` or, when povlens cannot know the value (an object, a texture, a user
function, a value computed from one), an :class:`UnknownValue` saying why.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from povlens.pov.sdl.errors import SdlEvalError

__all__ = ["UnknownValue", "Transform", "Macro", "SdlArray", "rotation_matrix",
           "axis_rotation_matrix", "as_vector", "as_float", "as_string", "promote", "binop",
           "describe"]


@dataclasses.dataclass(frozen=True)
class UnknownValue:
    """A declared name whose value povlens cannot know (``reason`` says why)."""

    reason: str
    maybe: bool = False  # True: may or may not be declared at all
    kind: str = ""  # what it is, if known: "function", "object", "spline", "mesh_camera"...
    hint: str = ""  # what the user could pass instead


@dataclasses.dataclass(frozen=True)
class Transform:
    """A declared ``transform { ... }``: a 4x4 row-vector matrix (``p' = [p, 1] @ m``)."""

    m: np.ndarray


@dataclasses.dataclass(frozen=True)
class Macro:
    """A ``#macro`` definition: its parameters and the text range of its body.

    ``optional`` flags the parameters declared ``optional``; ``text[start:end]`` is the
    body (``end`` is where its ``#end`` starts), ``line`` the body's first line;
    ``has_camera`` tells whether the body mentions ``camera`` (for messages when it
    cannot be run).
    """

    name: str
    params: tuple[str, ...]
    optional: tuple[bool, ...]
    text: str
    path: str
    start: int
    line: int
    end: int
    where: str
    has_camera: bool


@dataclasses.dataclass
class SdlArray:
    """A POV-Ray ``array[n1][n2]...``: ``dims`` and the elements in row-major order
    (None where not yet initialized)."""

    dims: tuple[int, ...]
    items: list

    def index(self, idx: list[float], where: str) -> int:
        """The flat position of the element ``idx`` (POV-Ray truncates indices)."""
        if len(idx) != len(self.dims):
            raise SdlEvalError(f"{where}: array has {len(self.dims)} dimension(s), indexed with {len(idx)}")
        flat = 0
        for i, n in zip(idx, self.dims):
            k = int(i)
            if not 0 <= k < n:
                raise SdlEvalError(f"{where}: array index {k} out of range 0..{n - 1}")
            flat = flat * n + k
        return flat


def rotation_matrix(deg: np.ndarray) -> np.ndarray:
    """POV-Ray ``rotate <ax, ay, az>`` (degrees) as a 3x3 row-vector matrix.

    Rotates about x, then y, then z; ``p' = p @ M``.
    """
    ax, ay, az = np.radians(np.asarray(deg, dtype=np.float64))
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, sx], [0, -sx, cx]])
    ry = np.array([[cy, 0, -sy], [0, 1, 0], [sy, 0, cy]])
    rz = np.array([[cz, sz, 0], [-sz, cz, 0], [0, 0, 1]])
    return rx @ ry @ rz


def axis_rotation_matrix(axis: np.ndarray, deg: float) -> np.ndarray:
    """POV-Ray's rotation by ``deg`` degrees about ``axis`` (``vaxis_rotate``,
    ``Compute_Axis_Rotation_Transform``) as a 3x3 row-vector matrix."""
    n = float(np.linalg.norm(axis))
    if n == 0.0:
        raise SdlEvalError("rotation axis has zero length")
    vx, vy, vz = np.asarray(axis, dtype=np.float64) / n
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    c1 = 1.0 - c
    return np.array([
        [vx * vx * c1 + c, vx * vy * c1 + vz * s, vx * vz * c1 - vy * s],
        [vx * vy * c1 - vz * s, vy * vy * c1 + c, vy * vz * c1 + vx * s],
        [vx * vz * c1 + vy * s, vy * vz * c1 - vx * s, vz * vz * c1 + c],
    ])  # fmt: skip


def describe(v) -> str:
    """A short text for a value, for messages."""
    if isinstance(v, np.ndarray):
        return "<" + ", ".join(f"{c:g}" for c in v) + ">"
    if isinstance(v, str):
        return f'the string "{v}"'
    if isinstance(v, float):
        return f"{v:g}"
    return type(v).__name__


def as_vector(v, what: str) -> np.ndarray:
    """``v`` as a (3,) vector: a float ``f`` becomes ``<f, f, f>`` and a 2-vector gets
    z = 0, as in POV-Ray; a colour (4 or 5 components) is an error naming ``what``."""
    if isinstance(v, np.ndarray):
        if len(v) == 3:
            return v
        if len(v) == 2:
            return np.array([v[0], v[1], 0.0])
        raise SdlEvalError(f"{what} must be a vector, got the colour {describe(v)}")
    if isinstance(v, (float, int)):
        return np.array([float(v)] * 3)
    raise SdlEvalError(f"{what} must be a vector, got {describe(v)}")


def as_float(v, what: str) -> float:
    """``v`` as a float; :class:`SdlEvalError` naming ``what`` if it is a vector."""
    if isinstance(v, np.ndarray):
        raise SdlEvalError(f"{what} must be a number, got the vector {describe(v)}")
    if isinstance(v, str):
        raise SdlEvalError(f"{what} must be a number, got {describe(v)}")
    return float(v)


def as_string(v, what: str) -> str:
    """``v`` as a string; :class:`SdlEvalError` naming ``what`` otherwise."""
    if not isinstance(v, str):
        raise SdlEvalError(f"{what} must be a string, got {describe(v)}")
    return v


def promote(v, n: int) -> np.ndarray:
    """``v`` (a float or a shorter vector) as an ``n``-vector (``Promote_Express``)."""
    if isinstance(v, np.ndarray):
        if len(v) >= n:
            return v
        return np.concatenate([v, np.zeros(n - len(v))])
    return np.full(n, float(v))


def binop(a, b, op: str):
    """``a op b`` for ``op`` in ``+ - * /`` with POV-Ray's promotion of floats and
    shorter vectors; strings are an error."""
    if isinstance(a, str) or isinstance(b, str):
        raise SdlEvalError(f"'{op}' applied to a string")
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        n = max(len(v) for v in (a, b) if isinstance(v, np.ndarray))
        a, b = promote(a, n), promote(b, n)
        if op == "/" and np.any(b == 0):
            raise SdlEvalError("division by zero")
    elif op == "/" and b == 0:
        raise SdlEvalError("division by zero")
    if op == "+":
        return a + b
    if op == "-":
        return a - b
    if op == "*":
        return a * b
    return a / b
