"""POV-Ray 3.7's built-in functions, constants and vector components, as the camera
reader evaluates them (``Parse_Float_Function`` / ``Parse_Vector_Function`` /
``Parse_String`` in ``source/backend/parser``).

Functions that need the scene's geometry or a random stream (``min_extent``, ``trace``,
``inside``, ``rand``, ``vturbulence``...) are in :data:`UNKNOWABLE`: a value computed from
them is unknown.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from povlens.pov.sdl.errors import SdlEvalError
from povlens.pov.sdl.values import (as_float, as_string, as_vector, axis_rotation_matrix,
                                    describe, rotation_matrix)

__all__ = ["FUNCTIONS", "CONSTANTS", "COMPONENTS", "UNKNOWABLE", "COLOUR_WORDS", "component",
           "format_float", "srgb_to_linear"]


def _f1(fn: Callable[[float], float]) -> Callable:
    return lambda a: fn(as_float(a, "argument"))


def _f2(fn: Callable[[float, float], float]) -> Callable:
    return lambda a, b: fn(as_float(a, "argument"), as_float(b, "argument"))


def _vnormalize(a) -> np.ndarray:
    v = as_vector(a, "argument")
    n = float(np.linalg.norm(v))
    if n == 0.0:
        raise SdlEvalError("vnormalize() of a zero-length vector")
    return v / n


def _select(a, b, c, d=None):
    s = as_float(a, "argument")
    if d is None:
        return b if s < 0 else c
    return b if s < 0 else (c if s == 0 else d)


def format_float(v: float, length: float, precision: float) -> str:
    """POV-Ray's ``str(V, L, P)``: at least ``|L|`` characters (zero padded if L < 0) and
    ``P`` decimals (6 if P < 0)."""
    p = int(precision)
    text = f"{v:.{p if p >= 0 else 6}f}"
    width = int(length)
    if width < 0:
        text = text.zfill(-width)
    elif width > 0:
        text = text.rjust(width)
    return text


def _str(v, length, precision) -> str:
    return format_float(as_float(v, "argument"), as_float(length, "argument"),
                        as_float(precision, "argument"))


def _vstr(n, v, sep, length, precision) -> str:
    k = int(as_float(n, "argument"))
    vec = v if isinstance(v, np.ndarray) else np.array([as_float(v, "argument")] * max(k, 1))
    vec = np.concatenate([vec, np.zeros(max(0, k - len(vec)))])
    return as_string(sep, "separator").join(
        format_float(float(c), as_float(length, "argument"), as_float(precision, "argument"))
        for c in vec[:k])


def _substr(s, start, length) -> str:
    s = as_string(s, "argument")
    i = int(as_float(start, "argument")) - 1
    n = int(as_float(length, "argument"))
    if i < 0 or n < 0 or i + n > len(s):
        raise SdlEvalError("substr() range outside the string")
    return s[i:i + n]


def _val(s) -> float:
    text = as_string(s, "argument").strip()
    try:
        return float(text)
    except ValueError:
        return 0.0


def _strcmp(a, b) -> float:
    a, b = as_string(a, "argument"), as_string(b, "argument")
    return float((a > b) - (a < b))


#: Built-in functions: name -> (smallest and largest number of arguments, implementation).
FUNCTIONS: dict[str, tuple[int, int, Callable]] = {
    "abs": (1, 1, lambda a: np.abs(a) if isinstance(a, np.ndarray) else abs(as_float(a, "argument"))),
    "sqrt": (1, 1, _f1(math.sqrt)),
    "sin": (1, 1, _f1(math.sin)),
    "cos": (1, 1, _f1(math.cos)),
    "tan": (1, 1, _f1(math.tan)),
    "asin": (1, 1, _f1(math.asin)),
    "acos": (1, 1, _f1(math.acos)),
    "atan": (1, 1, _f1(math.atan)),
    "sinh": (1, 1, _f1(math.sinh)),
    "cosh": (1, 1, _f1(math.cosh)),
    "tanh": (1, 1, _f1(math.tanh)),
    "asinh": (1, 1, _f1(math.asinh)),
    "acosh": (1, 1, _f1(math.acosh)),
    "atanh": (1, 1, _f1(math.atanh)),
    "atan2": (2, 2, _f2(math.atan2)),
    "radians": (1, 1, lambda a: a * (math.pi / 180.0)),
    "degrees": (1, 1, lambda a: a * (180.0 / math.pi)),
    "pow": (2, 2, _f2(math.pow)),
    "exp": (1, 1, _f1(math.exp)),
    "ln": (1, 1, _f1(math.log)),
    "log": (1, 1, _f1(math.log10)),
    "min": (1, 99, lambda *a: min(as_float(v, "argument") for v in a)),
    "max": (1, 99, lambda *a: max(as_float(v, "argument") for v in a)),
    "int": (1, 1, lambda a: float(math.trunc(as_float(a, "argument")))),
    "floor": (1, 1, lambda a: float(math.floor(as_float(a, "argument")))),
    "ceil": (1, 1, lambda a: float(math.ceil(as_float(a, "argument")))),
    "mod": (2, 2, _f2(math.fmod)),
    "div": (2, 2, _f2(lambda a, b: float(math.trunc(a / b)))),
    "select": (3, 4, _select),
    "bitwise_and": (2, 99, lambda *a: float(_bits(a, lambda x, y: x & y))),
    "bitwise_or": (2, 99, lambda *a: float(_bits(a, lambda x, y: x | y))),
    "bitwise_xor": (2, 99, lambda *a: float(_bits(a, lambda x, y: x ^ y))),
    "vlength": (1, 1, lambda a: float(np.linalg.norm(as_vector(a, "argument")))),
    "vnormalize": (1, 1, _vnormalize),
    "vcross": (2, 2, lambda a, b: np.cross(as_vector(a, "argument"), as_vector(b, "argument"))),
    "vdot": (2, 2, lambda a, b: float(np.dot(as_vector(a, "argument"), as_vector(b, "argument")))),
    "vrotate": (2, 2, lambda a, b: as_vector(a, "argument") @ rotation_matrix(as_vector(b, "argument"))),
    "vaxis_rotate": (3, 3, lambda a, b, c: as_vector(a, "argument")
                     @ axis_rotation_matrix(as_vector(b, "argument"), as_float(c, "argument"))),
    "str": (3, 3, _str),
    "vstr": (5, 5, _vstr),
    "concat": (1, 99, lambda *a: "".join(as_string(s, "argument") for s in a)),
    "chr": (1, 1, lambda a: chr(int(as_float(a, "argument")))),
    "asc": (1, 1, lambda a: float(ord(as_string(a, "argument")[:1] or "\0"))),
    "substr": (3, 3, _substr),
    "strupr": (1, 1, lambda a: as_string(a, "argument").upper()),
    "strlwr": (1, 1, lambda a: as_string(a, "argument").lower()),
    "strlen": (1, 1, lambda a: float(len(as_string(a, "argument")))),
    "strcmp": (2, 2, _strcmp),
    "val": (1, 1, _val),
}


def _bits(args, op) -> int:
    vals = [int(as_float(a, "argument")) for a in args]
    out = vals[0]
    for v in vals[1:]:
        out = op(out, v)
    return out


#: Functions whose value depends on the scene's objects, files or random streams.
UNKNOWABLE = {"min_extent", "max_extent", "trace", "inside", "rand", "seed", "vturbulence",
              "file_exists", "eval_pigment", "internal", "datetime", "now", "vtransform"}

#: Built-in names with a fixed value (floats or vectors).
CONSTANTS = {
    "pi": math.pi,
    "true": 1.0,
    "yes": 1.0,
    "on": 1.0,
    "false": 0.0,
    "no": 0.0,
    "off": 0.0,
    "x": np.array([1.0, 0.0, 0.0]),
    "y": np.array([0.0, 1.0, 0.0]),
    "z": np.array([0.0, 0.0, 1.0]),
    "u": np.array([1.0, 0.0]),
    "v": np.array([0.0, 1.0]),
    "t": np.array([0.0, 0.0, 0.0, 1.0]),
}

#: Vector components: name -> index (``gray`` is computed, see :func:`component`).
COMPONENTS = {"x": 0, "u": 0, "red": 0, "y": 1, "v": 1, "green": 1, "z": 2, "blue": 2,
              "t": 3, "filter": 3, "transmit": 4, "gray": -1, "grey": -1}

#: Words that start a colour: ``rgb`` & co. take a vector, ``color`` is a mere prefix.
COLOUR_WORDS = {"rgb": 3, "rgbf": 4, "rgbt": 4, "rgbft": 5, "srgb": 3, "srgbf": 4,
                "srgbt": 4, "srgbft": 5}


def srgb_to_linear(c: float) -> float:
    """The sRGB transfer function's inverse (``srgb`` colours)."""
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


def component(v, name: str, where: str) -> float:
    """``v.name`` (``.x``, ``.red``, ``.gray``...)."""
    if not isinstance(v, np.ndarray):
        raise SdlEvalError(f"{where}: '.{name}' applied to {describe(v)}")
    k = COMPONENTS[name]
    if k < 0:
        if len(v) < 3:
            raise SdlEvalError(f"{where}: '.{name}' needs a colour")
        return float(0.297 * v[0] + 0.589 * v[1] + 0.114 * v[2])
    if k >= len(v):
        raise SdlEvalError(f"{where}: '.{name}' of a {len(v)}-component vector")
    return float(v[k])
