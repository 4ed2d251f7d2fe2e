"""The directive layer of POV-Ray scene description language, as POV-Ray's tokenizer has it.

:class:`DirectiveStream` hands out the tokens POV-Ray's parser would see: ``#if`` /
``#ifdef`` / ``#ifndef`` / ``#elseif`` / ``#else``, ``#switch`` / ``#case`` / ``#range`` /
``#break``, ``#while`` and ``#for`` loops, ``#include`` (found as POV-Ray finds it),
``#declare`` / ``#local`` / ``#undef`` (:mod:`povlens.pov.sdl_declare`), ``#macro``
definitions and calls, ``#version`` and the message and file directives are processed
where they stand, also inside a camera block or an expression (``Parse_Directive`` in
``source/backend/parser/tokenize.cpp``).

A condition povlens cannot evaluate (it depends on an object, a random number, an
undeclared name) does not stop the reading: every branch is read, *uncertain*
(:attr:`DirectiveStream.certain` is False), and what is declared there becomes unknown.
Loops are followed up to :data:`MAX_LOOP_ITERATIONS` in all; past that, what they assign
becomes unknown.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from povlens.pov.sdl_declare import Declarations
from povlens.pov.sdl_errors import SceneCameraError, SdlEvalError
from povlens.pov.sdl_expressions import ExpressionParser
from povlens.pov.sdl_include import find_include
from povlens.pov.sdl_lexer import Mark, SourceFile, Token, TokenStream
from povlens.pov.sdl_symbols import SymbolTable
from povlens.pov.sdl_values import Macro, SdlArray, UnknownValue, as_float, as_string

__all__ = ["DirectiveStream", "Frame", "MacroCallError", "MAX_LOOP_ITERATIONS",
           "MAX_INCLUDE_BYTES", "OPENERS"]

#: Include files larger than this are not read (they are mesh data, not cameras).
MAX_INCLUDE_BYTES = 16 * 1024 * 1024
#: Loop iterations, and tokens read in loops, followed in a whole scene; past either,
#: loops are no longer followed (what they assign becomes unknown).  Loops mostly build
#: geometry; 100000 tokens take about a third of a second.
MAX_LOOP_ITERATIONS = 20000
MAX_LOOP_TOKENS = 100_000
#: Nested macro calls followed (POV-Ray's own limit is about as deep).
MAX_MACRO_DEPTH = 100

#: Directives closed by an ``#end``.
OPENERS = frozenset({"#if", "#ifdef", "#ifndef", "#switch", "#while", "#for", "#macro"})

_STOP = Token("stop", "", "<end of a #declare>", 0)


class MacroCallError(SdlEvalError):
    """A macro call povlens cannot run (``macro`` is the :class:`Macro`)."""

    def __init__(self, message: str, macro: Macro, hint: str = ""):
        super().__init__(message, hint)
        self.macro = macro


@dataclasses.dataclass(eq=False)
class Frame:
    """One open ``#if`` / ``#switch`` / loop / macro call.

    ``state``: ``"run"`` (tokens are read), ``"all"`` (uncertain: every branch is read),
    ``"once"`` (a loop whose condition is unknown: its body is read once, uncertain),
    ``"seek"`` (a ``#switch`` looking for its case).
    """

    kind: str  # "if", "switch", "while", "for", "macro"
    state: str
    where: str
    certain: bool = True
    reason: str = ""  # why it is uncertain
    hint: str = ""  # ... and what the user could pass
    mark: Mark | None = None  # loops: where the condition (#while) or body (#for) starts
    value: float = 0.0  # #switch: the value; #for: the end value
    step: float = 1.0  # #for
    var: str = ""  # #for: the loop variable
    log_start: int = 0  # loops: symbols.log length when the loop started
    tokens_start: int = 0  # loops: raw tokens read when the iteration started
    source: SourceFile | None = None  # macro calls: the body being read
    saved_depth: int = 0  # macro calls: the caller's declare depth


class DirectiveStream:
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

    def peek(self, ahead: int = 0) -> Token:
        """The token ``ahead`` places after the next one (directives before it processed)."""
        while len(self.buf) <= ahead:
            end = self._pull()
            if end is not None:
                return end
        return self.buf[ahead]

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
        """Read one raw token: a plain token goes to the buffer; a directive or a macro
        call is processed (its leftovers go to the buffer).  Returns the end token (eof or
        stop) instead, not buffered."""
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
            val = self.symbols.get(tok.text)
            if isinstance(val, Macro):
                self._with_own_buffer(self._invoke, tok, val)
                return None
            tok = tok._replace(bound=(val,))
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

    def _condition(self) -> tuple[bool | None, SdlEvalError | None]:
        """Evaluate ``( expression )``: (True/False, None) or (None, why not)."""
        value, err = self._paren_value()
        if value is None:
            return None, err
        return value != 0.0, None

    def _paren_value(self, two: bool = False):
        """``( float )`` (or ``( float, float )``): (the value(s), None) or (None, the
        error)."""
        mark = self.mark()
        try:
            self.expr.expect("(")
            a = as_float(self.expr.parse(), "condition")
            b = None
            if two:
                self.expr.expect(",")
                b = as_float(self.expr.parse(), "range")
            self.expr.expect(")")
            return ((a, b) if two else a), None
        except SdlEvalError as exc:
            if mark is not None and self.reset(mark):
                self.skip_parens_raw()
            return None, exc

    def skip_parens_raw(self) -> None:
        """Skip a balanced ``( ... )`` if one comes next (raw tokens)."""
        self.buf = []
        tok = self.raw.next()
        if tok.text != "(":
            self.raw.unget(tok)
            return
        depth = 1
        while depth:
            tok = self.raw.next()
            if tok.kind == "eof" or tok.kind == "directive" and tok.text in OPENERS | {"#end"}:
                self.raw.unget(tok)
                return
            if tok.kind == "op" and tok.text in "()":
                depth += 1 if tok.text == "(" else -1

    def _skip_to(self, stops: frozenset) -> Token:
        """Skip raw tokens to the first directive of ``stops`` at this nesting level
        (consumed and returned; an ``#end`` counts only at this level)."""
        depth = 0
        while True:
            tok = self.raw.next_directive()
            if tok.kind == "eof":
                return tok
            if tok.text in OPENERS:
                depth += 1
            elif tok.text == "#end":
                if depth == 0:
                    return tok
                depth -= 1
            elif depth == 0 and tok.text in stops:
                return tok

    def _uncertain_frame(self, kind: str, tok: Token, err: SdlEvalError, state: str = "all") -> Frame:
        why = f"the {tok.text} at {tok.where}, whose value povlens cannot evaluate ({err})"
        self.last_reason, self.last_hint = why, err.hint
        return Frame(kind, state, tok.where, certain=False, reason=why, hint=err.hint)

    def _make_uncertain(self, frame: Frame, tok: Token, err: SdlEvalError, state: str = "all") -> None:
        u = self._uncertain_frame(frame.kind, tok, err)
        frame.state, frame.certain, frame.reason, frame.hint = state, False, u.reason, u.hint

    def _if(self, tok: Token) -> None:
        if tok.text == "#if":
            c, err = self._condition()
        else:
            c, err = self._ifdef(tok)
        if c is None:
            self.frames.append(self._uncertain_frame("if", tok, err))
        elif c:
            self.frames.append(Frame("if", "run", tok.where))
        else:
            self.frames.append(Frame("if", "seek", tok.where))
            self._seek_branch(self.frames[-1])

    def _ifdef(self, tok: Token) -> tuple[bool | None, SdlEvalError | None]:
        self.buf = []
        p, name, q = self.raw.next(), self.raw.next(), self.raw.next()
        if p.text != "(" or name.kind != "ident" or q.text != ")":
            for t in (q, name):
                self.raw.unget(t)
            if p.text == "(":
                self.raw.unget(p)
                self.skip_parens_raw()
            return None, SdlEvalError(f"{tok.where}: {tok.text} needs '(identifier)'")
        ans = self.defined(name.text)
        if ans is None:
            return None, SdlEvalError(f"whether '{name.text}' is declared depends on an "
                                      f"uncertain branch")
        return (ans if tok.text == "#ifdef" else not ans), None

    def _seek_branch(self, frame: Frame) -> None:
        """In an ``#if`` whose branch so far is false: find the branch that is read."""
        while True:
            d = self._skip_to(frozenset({"#elseif", "#else"}))
            if d.kind == "eof" or d.text == "#end":
                self.frames.remove(frame)
                return
            if d.text == "#else":
                frame.state = "run"
                return
            c, err = self._condition()
            if c is None:
                self._make_uncertain(frame, d, err)
                return
            if c:
                frame.state = "run"
                return

    def _else(self, tok: Token) -> None:
        f = self.frames[-1] if self.frames else None
        if f is None or f.kind not in ("if", "switch"):
            if tok.text == "#elseif":
                self.skip_parens_raw()
            return
        if f.kind == "switch":
            if tok.text == "#elseif":
                self.skip_parens_raw()
            return  # a #switch's #else met while a case is read: read on
        if f.state == "run":  # the branch read ends here
            self._skip_to(frozenset())
            self.frames.pop()
        elif tok.text == "#elseif":
            self.skip_parens_raw()

    def _end(self, tok: Token) -> None:
        if not self.frames:
            return
        f = self.frames[-1]
        if f.kind == "macro":
            return  # (a macro body ends at its own #end, outside the body's text)
        self.frames.pop()
        if f.kind in ("while", "for") and f.state == "run":
            self._loop_again(f, tok)

    def _switch(self, tok: Token) -> None:
        value, err = self._paren_value()
        if value is None:
            self.frames.append(self._uncertain_frame("switch", tok, err))
            return
        frame = Frame("switch", "seek", tok.where, value=value)
        self.frames.append(frame)
        self._seek_case(frame)

    def _seek_case(self, frame: Frame) -> None:
        """In a ``#switch`` with no case read yet: find the one that is."""
        while True:
            d = self._skip_to(frozenset({"#case", "#range", "#else"}))
            if d.kind == "eof" or d.text == "#end":
                self.frames.remove(frame)
                return
            if d.text == "#else":
                frame.state = "run"
                return
            val, err = self._paren_value(two=d.text == "#range")
            if val is None:
                self._make_uncertain(frame, d, err)
                return
            if d.text == "#case":
                hit = abs(val - frame.value) < 1e-10
            else:
                hit = val[0] <= frame.value <= val[1]
            if hit:
                frame.state = "run"
                return

    def _case(self, tok: Token) -> None:
        # met while a case is read (or every case, uncertain): read on (falls through)
        self.skip_parens_raw()

    def _break(self, tok: Token) -> None:
        if not self.certain:
            return  # every branch is read anyway
        for i in range(len(self.frames) - 1, -1, -1):
            f = self.frames[i]
            if f.kind == "macro":
                return
            if f.kind in ("switch", "while", "for"):
                levels = len(self.frames) - i
                for _ in range(levels):
                    self._skip_to(frozenset())
                del self.frames[i:]
                return

    def _while(self, tok: Token) -> None:
        self.buf = []
        frame = Frame("while", "run", tok.where, mark=self.raw.mark(),
                      log_start=len(self.symbols.log), tokens_start=self.raw.tokens_read)
        self._loop_test(frame, tok)

    def _loop_test(self, frame: Frame, tok: Token) -> None:
        """Evaluate a ``#while`` condition: read the body, or skip to its ``#end``."""
        c, err = self._condition()
        if c is None:
            self._make_uncertain(frame, tok, err, state="once")
            self.frames.append(frame)
        elif c:
            self.frames.append(frame)
        else:
            self._skip_to(frozenset())

    def _for(self, tok: Token) -> None:
        mark = self.mark()
        try:
            self.expr.expect("(")
            name = self.next_name()
            if name.kind != "ident":
                raise SdlEvalError(f"{name.where}: #for needs an identifier")
            self.expr.expect(",")
            start = as_float(self.expr.parse(), "#for start")
            self.expr.expect(",")
            end = as_float(self.expr.parse(), "#for end")
            step = 1.0
            if self.peek().text == ",":
                self.next()
                step = as_float(self.expr.parse(), "#for step")
            self.expr.expect(")")
        except SdlEvalError as exc:
            if mark is not None and self.reset(mark):
                self.skip_parens_raw()
            self.frames.append(self._uncertain_frame("for", tok, exc, state="once"))
            return
        self.symbols.declare(name.text, start, local=True)
        frame = Frame("for", "run", tok.where, mark=self.raw.mark(), value=end, step=step,
                      var=name.text, log_start=len(self.symbols.log),
                      tokens_start=self.raw.tokens_read)
        if (start <= end) if step > 0 else (start >= end):
            self.frames.append(frame)
        else:
            self._skip_to(frozenset())

    def _loop_again(self, frame: Frame, tok: Token) -> None:
        """At a loop's ``#end``: go round again (within the budget) or leave."""
        self.loop_iterations += 1
        now = self.raw.tokens_read  # (nested loops: count each token once)
        self.loop_tokens += now - max(frame.tokens_start, self._loop_counted)
        self._loop_counted = now
        if self.loop_iterations > MAX_LOOP_ITERATIONS or self.loop_tokens > MAX_LOOP_TOKENS:
            reason = (f"the loop at {frame.where}, which povlens did not follow to its end (it "
                      f"follows {MAX_LOOP_ITERATIONS} iterations or {MAX_LOOP_TOKENS} tokens "
                      f"of loops in a scene)")
            self.symbols.forget(self.symbols.log[frame.log_start:], reason)
            if self.on_abandon is not None:
                self.on_abandon(frame, reason)
            return
        if frame.mark is None or not self.raw.reset(frame.mark):
            return
        self.buf = []
        frame.tokens_start = self.raw.tokens_read
        if frame.kind == "while":
            self._loop_test(frame, tok)
            return
        cur = self.symbols.get(frame.var)
        if not isinstance(cur, float):
            return
        cur += frame.step
        self.symbols.set_existing(frame.var, cur)
        if (cur <= frame.value) if frame.step > 0 else (cur >= frame.value):
            self.frames.append(frame)
        else:
            self._skip_to(frozenset())

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
        if self.peek().text == ";":
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

