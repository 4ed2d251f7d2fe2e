"""``#declare`` / ``#local`` / ``#undef``, macro arguments, arrays and the file directives
of POV-Ray scene description language, for :class:`~povlens.pov.sdl.directives.DirectiveStream`.

A declared value is a number, vector, colour or string, a camera, a transform, an array,
or an :class:`~povlens.pov.sdl.values.UnknownValue` (an object, a texture, a user
function, a spline, or a value povlens cannot compute) that says why.  Like POV-Ray
(``Parse_Declare``), the value of a ``#declare`` ends where the next ``#declare`` starts,
even without its ``;``.
"""

from __future__ import annotations

import math

from povlens.pov.sdl.builtin_functions import CONSTANTS, FUNCTIONS
from povlens.pov.sdl.camera_block import CameraState, parse_camera_block
from povlens.pov.sdl.errors import SdlEvalError
from povlens.pov.sdl.lexer import Token
from povlens.pov.sdl.transforms import TransformReader
from povlens.pov.sdl.values import Macro, SdlArray, Transform, UnknownValue, as_float, as_string

__all__ = ["Declarations"]

_PASSED_AS_IS = (CameraState, Transform, SdlArray, UnknownValue)


def _copy(v):
    return v.copy() if isinstance(v, CameraState) else v


class Declarations:
    """The declaring directives of the stream ``ds`` (a ``DirectiveStream``)."""

    def __init__(self, ds):
        self.ds = ds

    # -- #declare / #local -----------------------------------------------------
    def declare(self, tok: Token, local: bool) -> None:
        """``#declare NAME = value`` (or ``NAME[i] = value``); ``local`` for ``#local``."""
        ds = self.ds
        name = ds.raw.next()
        if name.kind != "ident":
            ds.raw.unget(name)
            self.skip_statement_raw()
            return
        index = None
        mark = ds.mark()
        try:
            if ds.peek(0, expand=False).text == "[":
                index = self._indices()
            eq = ds.next()
            if eq.text != "=":
                raise SdlEvalError(f"{eq.where}: expected '=' after {tok.text} {name.text}")
        except SdlEvalError:
            if mark is not None:
                ds.reset(mark)
            self.skip_statement_raw()
            return
        uncertain = "" if ds.certain else ds.uncertain_reason()
        value = self.value(name)
        if uncertain:
            value = UnknownValue(f"its {tok.text} at {name.where} is inside {uncertain}", maybe=True,
                                 hint=ds.uncertain_hint())
        if index is not None:
            self._set_element(name, index, value)
        else:
            ds.symbols.declare(name.text, value, local=local)

    def _indices(self) -> list[float]:
        ds = self.ds
        idx = []
        while ds.peek(0, expand=False).text == "[":
            ds.next()
            idx.append(as_float(ds.expr.parse(), "array index"))
            ds.expr.expect("]")
        return idx

    def _set_element(self, name: Token, index: list[float], value) -> None:
        arr = self.ds.symbols.get(name.text)
        if not isinstance(arr, SdlArray):
            return  # (an array povlens does not know: its elements stay unknown)
        try:
            arr.items[arr.index(index, name.where)] = value
        except SdlEvalError:
            return

    def value(self, name: Token):
        """The value after ``NAME =`` and its optional ';' (an UnknownValue if it cannot
        be evaluated; the statement is skipped then)."""
        ds = self.ds
        mark = ds.mark()
        try:
            value = self._rhs(name)
        except SdlEvalError as exc:
            if mark is not None and ds.reset(mark):
                self.skip_statement_raw()
            value = UnknownValue(f"its #declare at {name.where} could not be evaluated ({exc})",
                                 hint=exc.hint)
        # The optional ';', looked at without processing what follows: a directive or
        # macro call after the statement must not run before its value is stored.
        if ds.buf:
            if ds.buf[0].kind == "op" and ds.buf[0].text == ";":
                ds.buf.pop(0)
        else:
            t = ds.raw.next()
            if t.kind != "op" or t.text != ";":
                ds.raw.unget(t)
        return value

    def _rhs(self, name: Token):
        ds = self.ds
        first = ds.peek()
        if first.kind == "ident":
            word = first.text
            second = ds.peek(1, expand=False)
            block = second.kind == "op" and second.text == "{"
            if word == "camera" and block:
                ds.next()
                return parse_camera_block(ds, ds.expr, first, declared=True, symbol=ds.value_of,
                                          version=ds.version, previous=CameraState())
            if word == "transform" and (block or second.kind == "ident"):
                ds.next()
                return Transform(TransformReader(ds, ds.expr, ds.value_of).block(first))
            if word == "function":
                ds.next()
                self._skip_function()
                return UnknownValue(f"'{name.text}' is a user function ({name.where}), which povlens "
                                    f"does not evaluate", kind="function")
            if word == "array":
                ds.next()
                return self._array(first)
            if block:
                ds.next()
                ds.next()
                ds.skip_rest()
                return UnknownValue(f"it is declared as '{word} {{...}}' at {name.where}", kind=word)
            val = None if word in CONSTANTS or word in FUNCTIONS else ds.value_of(first)
            if isinstance(val, _PASSED_AS_IS) and not (second.kind == "op" and second.text in ".[+-*/"):
                ds.next()
                return _copy(val)
        ds.declare_depth += 1
        try:
            return ds.expr.parse()
        finally:
            ds.declare_depth -= 1

    def _skip_function(self) -> None:
        """After ``function``: skip ``(params)`` and ``{ body }`` (raw)."""
        ds = self.ds
        ds.buf = []
        ds.skip_parens_raw()
        tok = ds.raw.next()
        if tok.text == "{":
            ds.raw.skip_rest_of_block()
        else:
            ds.raw.unget(tok)

    # -- arrays -------------------------------------------------------------------
    def _array(self, tok: Token) -> SdlArray:
        """After ``array``: ``[n1][n2]... [{ initializers }]``."""
        ds = self.ds
        ds.declare_depth += 1
        try:
            dims = []
            while ds.peek(0, expand=False).text == "[":
                ds.next()
                dims.append(int(as_float(ds.expr.parse(), "array size")))
                ds.expr.expect("]")
            has_init = ds.peek(0, expand=False).text == "{"
        finally:
            ds.declare_depth -= 1
        if not dims or any(n <= 0 for n in dims) or math.prod(dims) > 10**6:
            raise SdlEvalError(f"{tok.where}: an array without fixed sizes")
        arr = SdlArray(tuple(dims), [None] * math.prod(dims))
        if has_init:
            ds.next()
            self._array_init(arr, 0, 0)
        return arr

    def _array_init(self, arr: SdlArray, level: int, base: int) -> None:
        """The elements of one ``{ ... }`` level of an array initializer (its '{' read)."""
        ds = self.ds
        n = arr.dims[level]
        stride = math.prod(arr.dims[level + 1:])
        for i in range(n):
            if level + 1 < len(arr.dims):
                ds.expr.expect("{")
                self._array_init(arr, level + 1, base + i * stride)
            else:
                arr.items[base + i] = self.argument_value()
            if ds.peek(0, expand=False).text == ",":
                ds.next()
        ds.expr.expect("}")

    # -- macro arguments -------------------------------------------------------------
    def macro_args(self, tok: Token, macro: Macro) -> list:
        """The arguments of a macro call (after its '('): values, UnknownValues for what
        cannot be evaluated, None for an argument left out."""
        ds = self.ds
        if ds.peek(0, expand=False).text == ")":
            ds.next()
            return []
        args = []
        while True:
            args.append(self.argument_value())
            t = ds.next()
            if t.text == ",":
                continue
            if t.text == ")":
                return args
            raise SdlEvalError(f"{t.where}: expected ',' or ')' in the call of the macro {macro.name}")

    def argument_value(self):
        """One macro argument or array element, up to a ',' ')' or '}' (not consumed)."""
        ds = self.ds
        first = ds.peek()
        if first.kind == "op" and first.text in ",)}":
            return None
        mark = ds.mark()
        try:
            if first.kind == "ident":
                second = ds.peek(1, expand=False)
                if (second.kind == "op" and second.text == "{") or first.text == "function":
                    raise SdlEvalError(f"{first.where}: '{first.text} {{...}}' is not a number")
                val = None if first.text in CONSTANTS else ds.value_of(first)
                if isinstance(val, _PASSED_AS_IS) and second.kind == "op" and second.text in ",)}":
                    ds.next()
                    return _copy(val)
            return ds.expr.parse()
        except SdlEvalError as exc:
            if mark is not None and ds.reset(mark):
                self._skip_argument_raw()
            return UnknownValue(f"the argument at {first.where} could not be evaluated ({exc})",
                                hint=exc.hint)

    def _skip_argument_raw(self) -> None:
        raw = self.ds.raw
        depth = 0
        while True:
            tok = raw.next()
            if tok.kind == "eof":
                return
            if tok.kind != "op":
                continue
            if depth == 0 and tok.text in ",)}":
                raw.unget(tok)
                return
            if tok.text in "({[":
                depth += 1
            elif tok.text in ")}]":
                depth -= 1

    # -- the rest ----------------------------------------------------------------------
    def skip_statement_raw(self) -> None:
        """Skip the rest of a statement that cannot be evaluated: to a ';' (consumed), or
        up to a directive, a closing '}' or the start of a block ``word {``."""
        ds = self.ds
        ds.buf = []
        raw = ds.raw
        depth = 0
        while True:
            tok = raw.next()
            if tok.kind == "eof":
                return
            if depth == 0 and tok.kind == "directive":
                raw.unget(tok)
                return
            if tok.kind == "ident" and depth == 0:
                nxt = raw.next()
                raw.unget(nxt)
                if nxt.text == "{":
                    raw.unget(tok)
                    return
                continue
            if tok.kind != "op":
                continue
            if depth == 0 and tok.text == ";":
                return
            if depth == 0 and tok.text == "}":
                raw.unget(tok)
                return
            if tok.text in "({[":
                depth += 1
            elif tok.text in ")]" and depth > 0 or tok.text == "}":
                depth -= 1

    def undef(self, tok: Token) -> None:
        """``#undef NAME``."""
        ds = self.ds
        name = ds.raw.next()
        if name.kind != "ident":
            ds.raw.unget(name)
            return
        if ds.certain:
            ds.symbols.undef(name.text)
        elif name.text in ds.symbols:
            ds.symbols.set_existing(name.text, UnknownValue(
                f"its #undef at {name.where} is inside {ds.uncertain_reason()}", maybe=True))

    def file_directive(self, tok: Token) -> None:
        """``#fopen``, ``#fclose``, ``#read`` (its variables become unknown), ``#write``,
        ``#default``."""
        ds = self.ds
        raw = ds.raw
        ds.buf = []
        if tok.text == "#fopen":
            name = raw.next()
            try:
                as_string(ds.expr.parse_string(), "#fopen")
            except SdlEvalError:
                pass
            mode = raw.next()  # read / write / append
            if mode.text in ("write", "append"):
                ds.written_files.append(tok.where)
            if name.kind == "ident":
                ds.symbols.declare(name.text, UnknownValue(f"it is a file ({name.where})", kind="file"))
        elif tok.text == "#fclose":
            raw.next()
        elif tok.text == "#read":
            self._read(tok)
        elif tok.text == "#write":
            ds.skip_parens_raw()
        elif tok.text == "#default":
            t = raw.next()
            if t.text == "{":
                raw.skip_rest_of_block()
            else:
                raw.unget(t)

    def _read(self, tok: Token) -> None:
        raw = self.ds.raw
        t = raw.next()
        if t.text != "(":
            raw.unget(t)
            return
        names, depth = [], 1
        while depth:
            t = raw.next()
            if t.kind == "eof":
                break
            if t.text == "(":
                depth += 1
            elif t.text == ")":
                depth -= 1
            elif t.kind == "ident" and depth == 1:
                names.append(t.text)
        for n in names[1:]:  # the first is the file
            self.ds.symbols.declare(n, UnknownValue(f"it is read from a file by the #read at {tok.where}"))
