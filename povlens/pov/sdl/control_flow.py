"""Conditionals and loops of POV-Ray scene description language, for
:class:`~povlens.pov.sdl.directives.DirectiveStream` (``Parse_Directive`` in
``source/backend/parser/tokenize.cpp``).

``#if`` / ``#ifdef`` / ``#ifndef`` / ``#elseif`` / ``#else``; ``#switch`` / ``#case`` /
``#range`` / ``#break`` as POV-Ray 3.7 runs them (measured: a case falls through later
``#case``, ``#range`` and ``#else`` up to its ``#break``; a ``#break`` inside an ``#if``
leaves the ``#switch``); ``#while`` and ``#for`` loops, followed within a budget.  A
condition that cannot be evaluated makes its branches *uncertain*: all are read, and the
frame says why (:attr:`Frame.reason`) and what to pass (:attr:`Frame.hint`).
"""

from __future__ import annotations

import dataclasses

from povlens.pov.sdl.errors import SdlEvalError
from povlens.pov.sdl.lexer import Mark, SourceFile, Token
from povlens.pov.sdl.values import as_float

__all__ = ["Frame", "FlowDirectives", "OPENERS", "MAX_LOOP_ITERATIONS", "MAX_LOOP_TOKENS"]

#: Loop iterations, and tokens read in loops, followed in a whole scene; past either,
#: loops are no longer followed (what they assign becomes unknown).  Loops mostly build
#: geometry; 100000 tokens take about a third of a second.
MAX_LOOP_ITERATIONS = 20000
MAX_LOOP_TOKENS = 100_000
#: Directives closed by an ``#end``.
OPENERS = frozenset({"#if", "#ifdef", "#ifndef", "#switch", "#while", "#for", "#macro"})


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


class FlowDirectives:
    """The conditional and loop directives of a ``DirectiveStream`` (a mixin: it uses the
    stream's ``raw``, ``frames``, ``symbols``, ``expr``, ``mark`` and ``reset``)."""

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
            if self.peek(0, expand=False).text == ",":
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
