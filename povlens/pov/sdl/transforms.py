"""Transformations of POV-Ray scene description language: ``translate``, ``rotate``,
``scale``, ``matrix``, ``transform { ... [inverse] }`` and declared transforms
(``#declare T = transform { ... }`` then ``transform T`` or ``transform { T }``), as
4x4 row-vector matrices (``p' = [p, 1] @ m``, POV-Ray's convention).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from povlens.pov.sdl.errors import SdlEvalError
from povlens.pov.sdl.expressions import ExpressionParser, TokenSource
from povlens.pov.sdl.lexer import Token
from povlens.pov.sdl.values import Transform, UnknownValue, as_float, as_vector, rotation_matrix

__all__ = ["TRANSFORM_WORDS", "TransformReader"]

#: The words that start a transformation.
TRANSFORM_WORDS = ("translate", "rotate", "scale", "matrix", "transform")


class TransformReader:
    """Reads transformations from ``stream``; ``symbol(token)`` gives the declared value
    an identifier names (or None)."""

    def __init__(self, stream: TokenSource, expr: ExpressionParser,
                 symbol: Callable[[Token], object]):
        self.stream, self.expr, self.symbol = stream, expr, symbol

    def item(self, word: str, t: Token) -> np.ndarray | None:
        """The matrix of the transform item ``word`` (just consumed as ``t``), or None if
        ``word`` is not one."""
        m = np.eye(4)
        if word == "translate":
            m[3, :3] = as_vector(self.expr.parse(), "translate")
        elif word == "rotate":
            m[:3, :3] = rotation_matrix(as_vector(self.expr.parse(), "rotate"))
        elif word == "scale":
            s = as_vector(self.expr.parse(), "scale").copy()
            s[s == 0] = 1.0  # POV-Ray warns and uses 1
            m[:3, :3] = np.diag(s)
        elif word == "matrix":
            m[:, :3] = self._matrix(t)
        elif word == "transform":
            m = self.block(t)
        else:
            return None
        return m

    def _matrix(self, t: Token) -> np.ndarray:
        """The (4, 3) rows of ``matrix <m00, ..., m32>``."""
        tok = self.stream.next()
        if tok.text != "<":
            raise SdlEvalError(f"{tok.where}: expected '<' after matrix")
        vals = [as_float(self.expr.parse(no_gt=True), "matrix entry")]
        while self.stream.peek(0, expand=False).text != ">":
            if self.stream.peek(0, expand=False).text == ",":
                self.stream.next()
            if self.stream.peek(0, expand=False).kind in ("eof", "stop"):
                break
            vals.append(as_float(self.expr.parse(no_gt=True), "matrix entry"))
        self.expr.expect(">")
        if len(vals) != 12:
            raise SdlEvalError(f"{t.where}: matrix needs 12 numbers, got {len(vals)}")
        return np.array(vals).reshape(4, 3)

    def declared(self, ident: Token) -> np.ndarray:
        """The matrix of the declared transform named by ``ident``."""
        val = self.symbol(ident)
        if isinstance(val, Transform):
            return val.m.copy()
        if isinstance(val, UnknownValue):
            raise SdlEvalError(f"{ident.where}: the transform '{ident.text}' is unknown: {val.reason}",
                               val.hint)
        if val is None:
            raise SdlEvalError(f"{ident.where}: '{ident.text}' is not defined")
        raise SdlEvalError(f"{ident.where}: '{ident.text}' is not a transform")

    def block(self, t: Token) -> np.ndarray:
        """After ``transform``: ``{ items [inverse] }`` or the name of a declared transform."""
        first = self.stream.next()
        if first.kind == "ident":
            return self.declared(first)
        if first.text != "{":
            raise SdlEvalError(f"{first.where}: expected '{{' or a transform's name after 'transform'")
        m = np.eye(4)
        inverse = False
        while True:
            it = self.stream.next()
            if it.text == "}" and it.kind == "op":
                break
            if it.kind in ("eof", "stop"):
                raise SdlEvalError(f"{t.where}: transform block is not closed")
            if it.kind == "ident" and it.text == "inverse":
                inverse = True
                continue
            sub = self.item(it.text, it) if it.kind == "ident" else None
            if sub is None and it.kind == "ident":
                sub = self.declared(it)
            if sub is None:
                raise SdlEvalError(f"{it.where}: '{it.text}' inside transform{{}} is not supported")
            m = m @ sub
        if inverse:
            try:
                return np.linalg.inv(m)
            except np.linalg.LinAlgError:
                raise SdlEvalError(f"{t.where}: the transform cannot be inverted") from None
        return m
