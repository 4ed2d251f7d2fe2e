"""Expressions of POV-Ray scene description language (SDL).

:class:`ExpressionParser` evaluates float, vector, colour and string expressions as POV-Ray
3.7 does (``Parse_Express`` in ``source/backend/parser/express.cpp``): numbers, strings,
``<a, b, c>`` with 2 to 5 components and optional commas, colours (``rgb``, ``color red
1``...), constants (``pi``, ``x``, ``u``, ``t``...), ``+ - * /``, comparisons, ``& | !``,
``? :``, components (``.x``, ``.red``, ``.gray``...), array elements ``A[i]``,
``defined()``, ``dimension_size()`` and the built-in functions of
:data:`~povlens.pov.sdl.builtin_functions.FUNCTIONS`.  It reads tokens from a
:class:`TokenSource` (the directive layer, so that ``#if`` and macros work inside
expressions) and asks ``lookup`` for declared names.
"""

from __future__ import annotations

from typing import Callable, Protocol

import numpy as np

from povlens.pov.sdl.builtin_functions import (COLOUR_WORDS, COMPONENTS, CONSTANTS, FUNCTIONS,
                                               UNKNOWABLE, component, srgb_to_linear)
from povlens.pov.sdl.errors import SdlEvalError
from povlens.pov.sdl.lexer import Token
from povlens.pov.sdl.values import SdlArray, as_float, binop, promote

__all__ = ["TokenSource", "ExpressionParser", "decode_string"]

_ESCAPES = {"n": "\n", "t": "\t", "r": "\r", "a": "\a", "b": "\b", "f": "\f", "v": "\v",
            "\\": "\\", '"': '"', "'": "'"}

_COLOUR_MODIFIERS = {"red": 0, "green": 1, "blue": 2, "filter": 3, "transmit": 4}

#: Names that may be followed by an argument list.
_CALLABLE = frozenset(FUNCTIONS) | UNKNOWABLE | {"defined", "dimensions", "dimension_size"}


def decode_string(literal: str) -> str:
    """The text of a POV-Ray string literal (quotes included), escapes decoded."""
    body = literal[1:-1] if literal.endswith('"') and len(literal) > 1 else literal[1:]
    if "\\" not in body:
        return body
    out, i = [], 0
    while i < len(body):
        c = body[i]
        if c == "\\" and i + 1 < len(body):
            nxt = body[i + 1]
            if nxt == "u" and i + 5 < len(body):
                out.append(chr(int(body[i + 2:i + 6], 16)))
                i += 6
                continue
            out.append(_ESCAPES.get(nxt, "\\" + nxt))
            i += 2
            continue
        out.append(c)
        i += 1
    return "".join(out)


class TokenSource(Protocol):
    """Where an :class:`ExpressionParser` reads its tokens (``expand=False``: a
    look-ahead after a complete value, which must not run a macro call)."""

    def peek(self, ahead: int = 0, expand: bool = True) -> Token: ...

    def next(self) -> Token: ...

    def next_name(self) -> Token: ...


class ExpressionParser:
    """Recursive-descent evaluator for POV-Ray expressions.

    ``lookup(name, token)`` gives the value of a declared name or raises
    :class:`SdlEvalError`; ``defined(name)`` answers ``defined()``: True, False or None
    (cannot tell).
    """

    def __init__(self, stream: TokenSource, lookup: Callable[[str, Token], object],
                 defined: Callable[[str], bool | None]):
        self.s = stream
        self.lookup = lookup
        self.defined = defined

    def _err(self, tok: Token, msg: str) -> SdlEvalError:
        return SdlEvalError(f"{tok.where}: {msg}")

    def _is_op(self, text: str, ahead: int = 0) -> bool:
        tok = self.s.peek(ahead, expand=False)
        return tok.kind == "op" and tok.text == text

    def _after(self, v) -> Token | None:
        """The token after the value ``v`` (a look-ahead), or None after a string, which
        POV-Ray reads without looking further."""
        return None if isinstance(v, str) else self.s.peek(0, expand=False)

    def expect(self, text: str) -> Token:
        """Consume the operator ``text`` or raise :class:`SdlEvalError`."""
        tok = self.s.next()
        if tok.text != text or tok.kind != "op":
            raise self._err(tok, f"expected '{text}' but found '{tok.text or 'end of file'}'")
        return tok

    # precedence climbing: ternary < | < & < comparison < + - < * / < unary < postfix
    def parse(self, no_gt: bool = False):
        """Evaluate the expression at the stream's position: a float, a vector
        (``np.ndarray``) or a string.

        ``no_gt`` stops at a ``>`` (the end of a vector literal ``<a, b, c>``).
        """
        cond = self._or(no_gt)
        if not isinstance(cond, str) and self._is_op("?"):
            self.s.next()
            a = self.parse(no_gt)
            self.expect(":")
            b = self.parse(no_gt)
            return a if as_float(cond, "condition of '?'") != 0.0 else b
        return cond

    def parse_string(self):
        """A string operand (a literal, a string's name, ``concat(...)``...) without
        looking at the token after it (``#include``, ``#debug``: a directive may follow)."""
        return self._primary()

    def _or(self, no_gt):
        v = self._and(no_gt)
        while not isinstance(v, str) and self._is_op("|"):
            self.s.next()
            w = self._and(no_gt)
            v = 1.0 if (as_float(v, "operand of '|'") != 0 or as_float(w, "operand of '|'") != 0) else 0.0
        return v

    def _and(self, no_gt):
        v = self._cmp(no_gt)
        while not isinstance(v, str) and self._is_op("&"):
            self.s.next()
            w = self._cmp(no_gt)
            v = 1.0 if (as_float(v, "operand of '&'") != 0 and as_float(w, "operand of '&'") != 0) else 0.0
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
            tok = self._after(v)
            if tok is None or tok.kind != "op" or tok.text not in self._CMP or (no_gt and tok.text == ">"):
                return v
            self.s.next()
            w = self._add(no_gt)
            v = 1.0 if self._CMP[tok.text](as_float(v, "comparison"), as_float(w, "comparison")) else 0.0

    def _add(self, no_gt):
        v = self._mul(no_gt)
        while True:
            tok = self._after(v)
            if tok is None or tok.kind != "op" or tok.text not in ("+", "-"):
                return v
            self.s.next()
            v = self._binop(v, self._mul(no_gt), tok)

    def _mul(self, no_gt):
        v = self._unary(no_gt)
        while True:
            tok = self._after(v)
            if tok is None or tok.kind != "op" or tok.text not in ("*", "/"):
                return v
            self.s.next()
            v = self._binop(v, self._unary(no_gt), tok)

    def _binop(self, a, b, tok: Token):
        try:
            return binop(a, b, tok.text)
        except SdlEvalError as exc:
            raise self._err(tok, str(exc)) from None

    def _unary(self, no_gt):
        tok = self.s.peek()
        if tok.kind == "op" and tok.text in ("-", "+", "!"):
            self.s.next()
            v = self._unary(no_gt)
            if tok.text == "-":
                if isinstance(v, str):
                    raise self._err(tok, "'-' applied to a string")
                return -v
            if tok.text == "!":
                return 0.0 if as_float(v, "operand of '!'") != 0 else 1.0
            return v
        return self._postfix(no_gt)

    def _postfix(self, no_gt):
        v = self._primary()
        while True:
            tok = self._after(v)
            if tok is None or tok.kind != "op" or tok.text not in (".", "["):
                return v
            self.s.next()
            if tok.text == "[":
                v = self._element(v, tok)
                continue
            comp = self.s.next()
            if comp.kind != "ident" or comp.text not in COMPONENTS:
                raise self._err(tok, f"unsupported vector component '.{comp.text}'")
            v = component(v, comp.text, tok.where)

    def _element(self, arr, tok: Token):
        """``arr[i][j]...`` after the first '['."""
        idx = [as_float(self.parse(), "array index")]
        self.expect("]")
        while self._is_op("["):
            self.s.next()
            idx.append(as_float(self.parse(), "array index"))
            self.expect("]")
        if not isinstance(arr, SdlArray):
            raise self._err(tok, "'[' applied to something that is not an array")
        item = arr.items[arr.index(idx, tok.where)]
        if item is None:
            raise self._err(tok, "array element is not initialized")
        if not isinstance(item, (float, str, np.ndarray, SdlArray)):
            raise self._err(tok, "array element is not a number, vector or string")
        return item.copy() if isinstance(item, np.ndarray) else item

    def _vector(self, tok: Token) -> np.ndarray:
        """``<a, b, c ...>`` after the '<'; commas are optional as in POV-Ray."""
        comps = [self.parse(no_gt=True)]
        while not self._is_op(">"):
            if self._is_op(","):
                self.s.next()
            if self.s.peek(0, expand=False).kind in ("eof", "stop"):
                break
            comps.append(self.parse(no_gt=True))
        self.expect(">")
        if not 2 <= len(comps) <= 5:
            raise self._err(tok, f"vectors with {len(comps)} components are not supported")
        return np.array([as_float(c, "vector component") for c in comps])

    def _primary(self):
        tok = self.s.next()
        if tok.kind == "number":
            return float(tok.text)
        if tok.kind == "string":
            return decode_string(tok.text)
        if tok.kind == "op" and tok.text == "(":
            v = self.parse(no_gt=False)
            self.expect(")")
            return v
        if tok.kind == "op" and tok.text == "<":
            return self._vector(tok)
        if tok.kind == "ident":
            return self._name(tok)
        if tok.kind in ("eof", "stop"):
            raise self._err(tok, "unexpected end of the statement inside an expression")
        raise self._err(tok, f"cannot evaluate '{tok.text}' in an expression")

    def _name(self, tok: Token):
        name = tok.text
        # (a declared name is looked up before the next token is looked at: that may
        # end the macro body or include file the name is local to)
        if name in _CALLABLE and self._is_op("("):
            if name in FUNCTIONS:
                return self._call(tok)
            if name == "defined":
                return self._defined(tok)
            if name in ("dimensions", "dimension_size"):
                return self._dimensions(tok)
            if name in UNKNOWABLE:
                raise self._err(tok, f"{name}() depends on the scene's objects, files or random "
                                     f"numbers, which povlens does not evaluate")
        if name in CONSTANTS:
            val = CONSTANTS[name]
            return val.copy() if isinstance(val, np.ndarray) else val
        if name in COLOUR_WORDS or name in ("color", "colour"):
            return self._colour(tok)
        return self.lookup(name, tok)

    def _args(self) -> list:
        self.expect("(")
        args = [self.parse()]
        while self._is_op(","):
            self.s.next()
            args.append(self.parse())
        self.expect(")")
        return args

    def _call(self, tok: Token):
        lo, hi, fn = FUNCTIONS[tok.text]
        args = self._args()
        if not lo <= len(args) <= hi:
            raise self._err(tok, f"{tok.text}() takes {lo}" + (f"-{hi}" if hi != lo else "")
                            + f" argument(s), got {len(args)}")
        try:
            return fn(*args)
        except SdlEvalError as exc:
            raise self._err(tok, f"{tok.text}(): {exc}") from None
        except (ValueError, ZeroDivisionError, OverflowError, TypeError) as exc:
            raise self._err(tok, f"{tok.text}(): {exc}") from None

    def _defined(self, tok: Token) -> float:
        self.expect("(")
        name = self.s.next_name()
        self.expect(")")
        if name.kind != "ident":
            raise self._err(name, "defined() needs an identifier")
        ans = self.defined(name.text)
        if ans is None:
            raise self._err(tok, f"whether '{name.text}' is defined depends on a branch povlens "
                                 f"cannot evaluate")
        return 1.0 if ans else 0.0

    def _dimensions(self, tok: Token) -> float:
        args = self._args()
        arr = args[0]
        if not isinstance(arr, SdlArray):
            raise self._err(tok, f"{tok.text}() needs an array")
        if tok.text == "dimensions":
            return float(len(arr.dims))
        k = int(as_float(args[1], "dimension")) if len(args) > 1 else 1
        if not 1 <= k <= len(arr.dims):
            raise self._err(tok, f"dimension_size(): the array has no dimension {k}")
        return float(arr.dims[k - 1])

    def _colour(self, tok: Token) -> np.ndarray:
        """A colour expression (5 components: red, green, blue, filter, transmit), rounded
        to single precision as POV-Ray stores it."""
        word = tok.text
        if word in ("color", "colour"):
            nxt = self.s.peek()
            if nxt.kind == "ident" and nxt.text in _COLOUR_MODIFIERS:
                col = np.zeros(5)
            else:
                col = promote(self._add(False), 5).copy()
        else:
            v = self._add(False)
            n = COLOUR_WORDS[word]
            vec = promote(v, n) if isinstance(v, np.ndarray) else np.full(n, as_float(v, word))
            col = np.zeros(5)
            if word.endswith("t") and n == 4:  # rgbt: the fourth value is transmit
                col[:3], col[4] = vec[:3], vec[3]
            else:
                col[:n] = vec[:n]
            if word.startswith("srgb"):
                col[:3] = [srgb_to_linear(float(c)) for c in col[:3]]
        while True:
            nxt = self.s.peek(0, expand=False)
            if nxt.kind != "ident" or nxt.text not in _COLOUR_MODIFIERS:
                # POV-Ray keeps colours in single precision (RGBFTColour of float)
                return col.astype(np.float32).astype(np.float64)
            self.s.next()
            col[_COLOUR_MODIFIERS[nxt.text]] = as_float(self._add(False), nxt.text)

