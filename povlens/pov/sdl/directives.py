"""The directive layer of POV-Ray scene description language, as POV-Ray's tokenizer has it.

:class:`DirectiveStream` hands out the tokens POV-Ray's parser would see: ``#if`` /
``#ifdef`` / ``#ifndef`` / ``#elseif`` / ``#else``, ``#switch`` / ``#case`` / ``#range`` /
``#break``, ``#while`` and ``#for`` loops, ``#include`` (found as POV-Ray finds it),
``#declare`` / ``#local`` / ``#undef`` (:mod:`povlens.pov.sdl.declarations`), ``#macro``
definitions and calls, ``#version`` and the message and file directives are processed
where they stand, also inside a camera block or an expression (``Parse_Directive`` in
``source/backend/parser/tokenize.cpp``).

A condition povlens cannot evaluate (it depends on an object, a random number, an
undeclared name) does not stop the reading: every branch is read, *uncertain*
(:attr:`DirectiveStream.certain` is False), and what is declared there becomes unknown.
Loops are followed within a budget (:mod:`povlens.pov.sdl.control_flow`); past it, what they
assign becomes unknown.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from povlens.pov.sdl.control_flow import OPENERS, FlowDirectives, Frame
from povlens.pov.sdl.declarations import Declarations
from povlens.pov.sdl.errors import SceneCameraError, SdlEvalError
from povlens.pov.sdl.expressions import ExpressionParser
from povlens.pov.sdl.include_paths import find_include
from povlens.pov.sdl.lexer import SourceFile, Token, TokenStream
from povlens.pov.sdl.symbols import SymbolTable
from povlens.pov.sdl.values import Macro, SdlArray, UnknownValue, as_float, as_string

__all__ = ["DirectiveStream", "Frame", "MacroCallError", "MAX_INCLUDE_BYTES", "OPENERS"]

#: Include files larger than this are not read (they are mesh data, not cameras).
MAX_INCLUDE_BYTES = 16 * 1024 * 1024
#: Nested macro calls followed (POV-Ray's own limit is about as deep).
MAX_MACRO_DEPTH = 100

_STOP = Token("stop", "", "<end of a #declare>", 0)


class MacroCallError(SdlEvalError):
    """A macro call povlens cannot run (``macro`` is the :class:`Macro`)."""

    def __init__(self, message: str, macro: Macro, hint: str = ""):
        super().__init__(message, hint)
        self.macro = macro


class DirectiveStream(FlowDirectives):
    """The scene's tokens after directives and macro calls (see the module docstring).

    Parameters
    ----------
    scene : the scene file (its folder is POV-Ray's working directory).
    library_paths : searched for ``#include`` files after the scene's folder.
    constants : names with a fixed value for this read (``clock``, ``image_width``...).
    declares : names declared before the scene is read (POV-Ray's ``declare=N=V``).
    """

    def __init__(self, scene: Path, library_paths: Sequence[Path],
                 constants: dict[str, object], declares: dict[str, object]):
        self.root = scene.resolve()
        self.library_paths = list(library_paths)
        self.constants = constants
        self.raw = TokenStream()
        self.raw.on_close = self._closed
        self.symbols = SymbolTable(declares)
        self.frames: list[Frame] = []
        self.buf: list[Token] = []
        self.declare_depth = 0  # > 0 while the value of a #declare is read
        self.version = 3.7
        self.tainted = 0  # tokens handed out while uncertain
        self.last_reason = ""  # why the latest uncertain branch is uncertain
        self.last_hint = ""
        self.loop_iterations = 0
        self.loop_tokens = 0
        self._loop_counted = 0  # tokens_read when loop tokens were last counted
        self.used_names: set[str] = set()  # constants read (clock, image_width...)
        self.written_files: list[str] = []  # "file:line" of each #fopen to write or append
        self.included: list[Path] = []
        self.unread_includes: list[str] = []
        self.on_abandon: Callable[[Frame, str], None] | None = None
        self.expr = ExpressionParser(self, self.lookup, self.defined)
        self.decl = Declarations(self)

    # -- the token interface ------------------------------------------------
    def start(self) -> None:
        """Open the scene file."""
        self.raw.push_file(self.root, "scene")
        self.included.append(self.root)

    @property
    def certain(self) -> bool:
        """False inside a branch povlens cannot tell is read."""
        return all(f.certain for f in self.frames)

    def uncertain_reason(self) -> str:
        """Why the current position is uncertain ("" if it is not)."""
        for f in reversed(self.frames):
            if not f.certain:
                return f.reason
        return ""

    def uncertain_hint(self) -> str:
        """What to pass to make the current position certain ("" if nothing helps)."""
        for f in reversed(self.frames):
            if not f.certain:
                return f.hint
        return ""

    def peek(self, ahead: int = 0, expand: bool = True) -> Token:
        """The token ``ahead`` places after the next one (directives before it processed).

        A macro call is run when a token at or before ``ahead`` names the macro, unless
        ``expand`` is False (a look-ahead after a complete value, as POV-Ray's: it returns
        the macro's name and reads nothing past it).
        """
        buf = self.buf
        while True:
            for i in range(min(ahead + 1, len(buf))):
                t = buf[i]
                if t.bound is not None and isinstance(t.bound[0], Macro):
                    if not expand:
                        return t
                    del buf[i]  # (it is the last token read: nothing is read past a macro name)
                    self._with_own_buffer(self._invoke, t, t.bound[0])
                    buf = self.buf
                    break
            else:
                if len(buf) > ahead:
                    return buf[ahead]
                end = self._pull()
                if end is not None:
                    return end
                buf = self.buf  # (a directive's handler leaves a new list)

    def next(self) -> Token:
        """Consume the next token: ``"eof"`` at the end, ``"stop"`` where a ``#declare``
        starts while the value of another is read."""
        tok = self.peek()
        if self.buf and self.buf[0] is tok:
            self.buf.pop(0)
        return tok

    def next_name(self) -> Token:
        """The next token without expanding it if it names a macro (``defined(M)``)."""
        if self.buf:
            return self.buf.pop(0)
        return self.raw.next()

    def _pull(self) -> Token | None:
        """Read one raw token: a plain token (an identifier with what it names, a macro's
        name too) goes to the buffer; a directive is processed (its leftovers go to the
        buffer).  Returns the end token (eof or stop) instead, not buffered."""
        tok = self.raw.next()
        if tok.kind == "eof":
            return tok
        if tok.kind == "directive":
            if self.declare_depth > 0 and tok.text in ("#declare", "#local"):
                self.raw.unget(tok)
                return _STOP
            self._with_own_buffer(self._directive, tok)
            return None
        if tok.kind == "ident":
            tok = tok._replace(bound=(self.symbols.get(tok.text),))
        if self.frames and not self.certain:
            self.tainted += 1
        self.buf.append(tok)
        return None

    def value_of(self, tok: Token):
        """What the identifier ``tok`` names (None: nothing), as when it was read."""
        if tok.bound is not None:
            return tok.bound[0]
        return self.symbols.get(tok.text)

    def _with_own_buffer(self, fn, *args) -> None:
        """Run a directive handler on an empty buffer; what it peeked and left comes after
        the tokens already buffered."""
        saved, self.buf = self.buf, []
        try:
            fn(*args)
        finally:
            self.buf = saved + self.buf

    # -- positions ----------------------------------------------------------
    def mark(self):
        """Where the next token starts (None if that cannot be told), with the state of
        the frames, scopes and declare depth, for :meth:`reset`."""
        if self.buf:
            return None
        m = self.raw.mark()
        if m is None:
            return None
        return m, len(self.frames), len(self.symbols.scopes), self.declare_depth

    def reset(self, mark) -> bool:
        """Go back to a :meth:`mark` (after an expression that cannot be evaluated)."""
        raw_mark, n_frames, n_scopes, depth = mark
        if not self.raw.reset(raw_mark):
            return False
        self.buf = []
        del self.frames[n_frames:]
        while len(self.symbols.scopes) > n_scopes:
            self.symbols.pop()
        self.declare_depth = depth
        return True

    def abandon(self) -> None:
        """Stop reading (the stream cannot be resynchronized)."""
        self.raw.files.clear()
        self.buf = []

    def skip_rest(self) -> None:
        """After a consumed '{': skip to after its '}'.  Bulky blocks without directives are
        skipped as text; others are walked, their directives and macro calls processed."""
        if not self.buf and self.raw.skip_block(force=False):
            return
        saved, self.declare_depth = self.declare_depth, 0
        try:
            depth = 1
            while depth:
                try:
                    tok = self.next()
                except SdlEvalError:
                    continue  # a macro call in an object: it makes no camera here
                if tok.kind in ("eof", "stop"):
                    return
                if tok.kind == "op" and tok.text in "{}":
                    depth += 1 if tok.text == "{" else -1
        finally:
            self.declare_depth = saved

    def skip_rest_raw(self) -> None:
        """After a consumed '{': skip to after its '}' without processing anything."""
        self.buf = []
        self.raw.skip_rest_of_block()

    # -- names ----------------------------------------------------------------
    def lookup(self, name: str, tok: Token):
        """The value of ``name`` in an expression (:class:`SdlEvalError` if not known)."""
        if name in self.constants:
            self.used_names.add(name)
            val = self.constants[name]
            if val is None:
                raise SdlEvalError(f"{tok.where}: the scene uses {name}, which was not given",
                                   "pass image_width and image_height")
            return val
        if name == "version":
            return float(self.version)
        if name == "input_file_name":
            return self.root.name
        val = self.value_of(tok)
        if val is None:
            if self.unread_includes:
                raise SdlEvalError(
                    f"{tok.where}: '{name}' is not defined (it may come from "
                    + ", ".join(self.unread_includes[:4]) + ", which povlens did not find)",
                    "pass library_paths with the folder that holds it")
            raise SdlEvalError(f"{tok.where}: '{name}' is not defined",
                               f"pass declares={{'{name}': value}} (POV-Ray's declare={name}=value)")
        if isinstance(val, UnknownValue):
            raise SdlEvalError(f"{tok.where}: the value of '{name}' is unknown: {val.reason}", val.hint)
        if isinstance(val, (float, str)):
            return val
        if isinstance(val, np.ndarray):
            return val.copy()
        if isinstance(val, SdlArray):
            return val  # for indexing
        raise SdlEvalError(f"{tok.where}: '{name}' ({type(val).__name__}) used in an expression")

    def defined(self, name: str) -> bool | None:
        """Whether ``name`` is declared (None: it depends on an uncertain branch); POV-Ray's
        keywords (``pi``, ``clock``...) are not declared names."""
        val = self.symbols.get(name)
        if val is None:
            return False
        if isinstance(val, UnknownValue) and val.maybe:
            return None
        return True

    # -- directives -----------------------------------------------------------
    def _directive(self, tok: Token) -> None:
        name = tok.text
        handler = _HANDLERS.get(name)
        if handler is not None:
            handler(self, tok)
        elif name in ("#declare", "#local"):
            self.decl.declare(tok, local=name == "#local")
        elif name == "#undef":
            self.decl.undef(tok)
        elif name in ("#fopen", "#fclose", "#read", "#write", "#default"):
            self.decl.file_directive(tok)
        # other directives (#statistics...) are ignored

    def _version(self, tok: Token) -> None:
        mark = self.mark()
        try:
            v = as_float(self.expr.parse(), "#version")
            if self.certain:
                self.version = v
        except SdlEvalError:
            if mark is not None and self.reset(mark):
                self.decl.skip_statement_raw()
            return
        if self.peek(0, expand=False).text == ";":
            self.next()

    def _message(self, tok: Token) -> None:
        """``#debug`` / ``#warning`` / ``#render`` / ``#error`` and their string; an
        ``#error`` that is certainly reached stops POV-Ray, so it stops povlens too."""
        mark = self.mark()
        try:
            text = as_string(self.expr.parse_string(), tok.text)
        except SdlEvalError:
            text = None
            if mark is not None and self.reset(mark):
                self._skip_string_raw()
        if tok.text == "#error" and self.certain:
            said = f': "{text.strip()}"' if text else ""
            raise SceneCameraError(f"{tok.where}: the scene stops with an #error{said}; POV-Ray "
                                   f"does not render it either")

    def _skip_string_raw(self) -> None:
        self.buf = []
        tok = self.raw.next()
        if tok.kind == "ident":
            nxt = self.raw.next()
            self.raw.unget(nxt)
            if nxt.text == "(":
                self.skip_parens_raw()

    def _include(self, tok: Token) -> None:
        mark = self.mark()
        try:
            name = as_string(self.expr.parse_string(), "#include")
        except SdlEvalError as exc:
            if mark is not None and self.reset(mark):
                self._skip_string_raw()
            self.unread_includes.append(f"the #include at {tok.where} ({exc})")
            return
        path = find_include(name, self.root.parent, self.library_paths)
        if path is None:
            self.unread_includes.append(f'"{name}"')
            return
        if self.raw.is_open(path):
            return  # a recursive include
        try:
            size = path.stat().st_size
        except OSError:
            size = 0
        if size > MAX_INCLUDE_BYTES:
            self.unread_includes.append(f'"{name}" (too large)')
            return
        try:
            self.raw.push_file(path, "include")
        except SceneCameraError:
            self.unread_includes.append(f'"{name}" (unreadable)')
            return
        self.included.append(path)
        self.symbols.push()

    def _closed(self, src: SourceFile) -> None:
        """A file or macro body is exhausted (TokenStream.on_close)."""
        if src.kind == "include":
            self.symbols.pop()
        elif src.kind == "macro":
            while self.frames:
                f = self.frames.pop()
                if f.kind == "macro" and f.source is src:
                    self.declare_depth = f.saved_depth
                    break
            self.symbols.pop()

    # -- macros -----------------------------------------------------------------
    def _macro(self, tok: Token) -> None:
        """A ``#macro Name(P1, optional P2...)`` definition: remember it, skip its body."""
        self.buf = []
        name = self.raw.next()
        params, optional = [], []
        paren = self.raw.next()
        if name.kind != "ident" or paren.text != "(":
            self.raw.unget(paren)
            self._skip_to(frozenset())
            return
        while True:
            p = self.raw.next()
            if p.kind == "eof" or p.text == ")":
                break
            if p.kind == "ident" and p.text == "optional":
                optional.append(True)
                p = self.raw.next()
            elif p.kind == "ident":
                optional.append(False)
            if p.kind == "ident":
                params.append(p.text)
        src = self.raw.files[-1] if self.raw.files else None
        start = self.raw.mark()
        t = self._skip_to(frozenset())
        if t.kind == "eof" or src is None or start is None or start[0] is not src or t.path != src.path:
            return
        has_camera = "camera" in src.text[start[1]:t.offset]  # (for messages only)
        del optional[len(params):]
        self.symbols.declare(name.text, Macro(
            name.text, tuple(params), tuple(optional), src.text, src.path, start[1], start[2],
            t.offset, tok.where, has_camera))

    def _invoke(self, tok: Token, macro: Macro) -> None:
        """A macro call: its arguments, then its body is read in a scope of its own."""
        paren = self.raw.next()
        if paren.text != "(":
            self.raw.unget(paren)
            raise MacroCallError(f"{tok.where}: the macro {macro.name} is used without '('", macro)
        args = self.decl.macro_args(tok, macro)
        depth = sum(1 for f in self.frames if f.kind == "macro")
        if depth >= MAX_MACRO_DEPTH:
            raise MacroCallError(f"{tok.where}: macro calls nested more than {MAX_MACRO_DEPTH} deep",
                                 macro)
        bound: dict[str, object] = {}
        for i, pname in enumerate(macro.params):
            if i < len(args) and args[i] is not None:
                bound[pname] = args[i]
            elif not macro.optional[i]:
                raise MacroCallError(f"{tok.where}: the macro {macro.name} needs its parameter "
                                     f"'{pname}' (defined at {macro.where})", macro)
        if len(args) > len(macro.params) and any(a is not None for a in args[len(macro.params):]):
            raise MacroCallError(f"{tok.where}: too many arguments for the macro {macro.name} "
                                 f"(defined at {macro.where})", macro)
        self.symbols.push(bound)
        src = self.raw.push_range(macro.text, macro.path, macro.start, macro.line, macro.end)
        self.frames.append(Frame("macro", "run", tok.where, source=src,
                                 saved_depth=self.declare_depth))
        self.declare_depth = 0


_HANDLERS: dict[str, Callable[[DirectiveStream, Token], None]] = {
    "#if": DirectiveStream._if,
    "#ifdef": DirectiveStream._if,
    "#ifndef": DirectiveStream._if,
    "#elseif": DirectiveStream._else,
    "#else": DirectiveStream._else,
    "#end": DirectiveStream._end,
    "#switch": DirectiveStream._switch,
    "#case": DirectiveStream._case,
    "#range": DirectiveStream._case,
    "#break": DirectiveStream._break,
    "#while": DirectiveStream._while,
    "#for": DirectiveStream._for,
    "#macro": DirectiveStream._macro,
    "#include": DirectiveStream._include,
    "#version": DirectiveStream._version,
    "#debug": DirectiveStream._message,
    "#warning": DirectiveStream._message,
    "#render": DirectiveStream._message,
    "#error": DirectiveStream._message,
}

