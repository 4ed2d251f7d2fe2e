"""Tokens of POV-Ray scene description language (SDL), with ``#include`` files spliced in.

:class:`TokenStream` reads a scene lazily, one file at a time, and hands out
:class:`Token` s: numbers, strings, directives (``#declare``...), identifiers and
operators; whitespace, ``//`` and nested ``/* */`` comments are dropped.  Blocks of
bulky data (a mesh's vertices) can be skipped at text level without tokenizing them.
A macro body is read as a range of its file's text; a loop goes back to a
:meth:`TokenStream.mark`.  The stream does no directive processing itself (that is
:mod:`povlens.pov.sdl.directives`).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Callable, NamedTuple

from povlens.pov.sdl.errors import SceneCameraError, SdlEvalError

__all__ = ["Token", "SourceFile", "TokenStream"]

#: One token, after any whitespace and line comments (``lastgroup`` names its kind;
#: ``end`` matches only at the end of the text).
_TOKEN_RE = re.compile(
    r"""
    (?:\s+|//[^\n]*)*
    (?:
      (?P<bcomment>/\*)
    | (?P<string>"(?:[^"\\\n]|\\.)*")
    | (?P<number>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)
    | (?P<directive>\#\s*[A-Za-z_][A-Za-z0-9_]*)
    | (?P<ident>[A-Za-z_][A-Za-z0-9_]*)
    | (?P<op><=|>=|!=|[{}()<>\[\],;=+\-*/.?:!&|%^$@])
    | (?P<end>\Z)
    )
    """,
    re.VERBOSE,
)

#: What a scan for the next directive must look at: strings, comments, directives.
_DIRECTIVE_RE = re.compile(r'"|/\*|//|\#\s*[A-Za-z_][A-Za-z0-9_]*')


class Token(NamedTuple):
    """One SDL token and where it starts (``path``, 1-based ``line``, character
    ``offset`` in its file's text; -1 for made-up tokens).

    ``bound`` is set by the directive layer on an identifier: ``(value,)``, what the
    name meant when the token was read (None: not looked up).  POV-Ray looks names up
    when it reads them, so a look-ahead past the end of a macro body still knows the
    body's local names.
    """

    kind: str  # "number", "string", "directive", "ident", "op", "eof" (and "stop", see directives)
    text: str
    path: str
    line: int
    offset: int = -1
    bound: tuple | None = None

    @property
    def where(self) -> str:
        """``"file:line"``, for messages."""
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


class SourceFile:
    """One scene file (or a range of it: a macro body) being tokenized lazily.

    ``kind`` is ``"scene"``, ``"include"`` or ``"macro"``; ``end`` the text offset where
    reading stops.
    """

    __slots__ = ("text", "path", "pos", "line", "buf", "end", "kind")

    def __init__(self, text: str, path: str, kind: str = "scene", pos: int = 0, line: int = 1,
                 end: int | None = None):
        self.text = text
        self.path = path
        self.pos = pos
        self.line = line
        self.buf: list[Token] = []
        self.end = len(text) if end is None else end
        self.kind = kind

    def _advance(self, end: int) -> None:
        self.line += self.text.count("\n", self.pos, end)
        self.pos = end

    def scan(self) -> Token | None:
        """The next token from the text (not the buffer), or None at the end."""
        text, n = self.text, self.end
        match = _TOKEN_RE.match
        while self.pos < n:
            m = match(text, self.pos, n)
            if m is None:  # a stray character POV-Ray would reject: skip it
                self._advance(self.pos + 1)
                continue
            kind = m.lastgroup
            start = m.start(kind)
            line = self.line + text.count("\n", self.pos, start)
            if kind == "bcomment":
                end = _block_comment_end(text, m.end())
                self.line = line + text.count("\n", start, end)
                self.pos = end
                continue
            self.pos, self.line = m.end(), line
            if kind == "end":
                return None
            tok_text = m.group(kind)
            if kind == "directive":
                tok_text = "#" + tok_text[1:].strip()
            return Token(kind, tok_text, self.path, line, start)
        return None

    def scan_directive(self) -> Token | None:
        """Skip the text to the next directive (strings and comments honoured) and return
        it, or None at the end (the buffer must be empty)."""
        text, n = self.text, self.end
        search = _DIRECTIVE_RE.search
        i = self.pos
        while True:
            m = search(text, i, n)
            if m is None:
                self._advance(n)
                return None
            t = m.group()
            if t == '"':
                i = _STRING_RE.match(text, m.start(), n).end()
            elif t == "/*":
                i = min(n, _block_comment_end(text, m.end()))
            elif t == "//":
                j = text.find("\n", m.end(), n)
                i = n if j < 0 else j
            else:
                start = m.start()
                self._advance(start)
                line = self.line
                self._advance(m.end())
                return Token("directive", "#" + t[1:].strip(), self.path, line, start)

    def skip_block_text(self, force: bool) -> bool:
        """Skip to just after the '}' matching an already consumed '{'.

        Works on the raw text (fast for bulky mesh data).  Unless ``force``,
        gives up (returning False, nothing consumed) when the block contains
        a directive, so that it can be walked token by token instead.
        """
        assert not self.buf
        text, n = self.text, self.end
        depth, i = 1, self.pos
        search = _SKIP_RE.search
        while depth:
            m = search(text, i, n)
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
                i = _STRING_RE.match(text, m.start(), n).end()
            elif t == "/*":
                i = min(n, _block_comment_end(text, m.end()))
            elif t == "//":
                j = text.find("\n", m.end())
                i = n if j < 0 else j
            else:  # a directive
                if not force:
                    return False
                i = m.end()
        self._advance(i)
        return True


#: A position in the stream: the file, the text offset and the line there.
Mark = tuple  # (SourceFile, int, int)


class TokenStream:
    """Tokens of the scene with ``#include``d files and macro bodies spliced in.

    ``on_close(source)`` is called when a file or macro body is exhausted and left.
    """

    def __init__(self) -> None:
        self.files: list[SourceFile] = []  # the include stack, innermost last
        self._eof = Token("eof", "", "<end of scene>", 0)
        self.on_close: Callable[[SourceFile], None] | None = None
        self.tokens_read = 0  # for the reader's work budget

    def push_file(self, path: Path, kind: str = "scene") -> SourceFile:
        """Continue with the tokens of ``path`` (an ``#include``), then resume the current file."""
        try:
            text = path.read_text(encoding="utf-8", errors="replace")
        except OSError as exc:
            raise SceneCameraError(
                f"cannot read the scene file {path}: {exc.strerror or exc}",
                "check the path and permissions",
            ) from None
        src = SourceFile(text, str(path), kind)
        self.files.append(src)
        return src

    def push_range(self, text: str, path: str, pos: int, line: int, end: int) -> SourceFile:
        """Continue with ``text[pos:end]`` (a macro body starting at ``line``)."""
        src = SourceFile(text, path, "macro", pos, line, end)
        self.files.append(src)
        return src

    def _fill(self, k: int) -> SourceFile | None:
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
            if self.on_close is not None:
                self.on_close(f)
        return None

    def peek(self, ahead: int = 0) -> Token:
        """The token ``ahead`` places after the next one, without consuming it."""
        f = self._fill(ahead)
        if f is None or ahead >= len(f.buf):
            # (look-ahead across a file boundary counts as the end)
            return self._eof
        return f.buf[ahead]

    def next(self) -> Token:
        """Consume and return the next token (an ``"eof"`` token at the end)."""
        f = self._fill(0)
        if f is None:
            return self._eof
        self.tokens_read += 1
        return f.buf.pop(0)

    def next_directive(self) -> Token:
        """Consume everything up to the next directive and return it (``"eof"`` at the
        end): a fast way through text that is not read (a false branch, a macro body)."""
        while self.files:
            f = self.files[-1]
            while f.buf:
                tok = f.buf.pop(0)
                if tok.kind == "directive":
                    return tok
            tok = f.scan_directive()
            if tok is not None:
                return tok
            self.files.pop()
            if self.on_close is not None:
                self.on_close(f)
        return self._eof

    def unget(self, tok: Token) -> None:
        """Put ``tok`` back in front of the next token."""
        if tok.kind == "eof":
            return
        if not self.files:
            self.files.append(SourceFile("", tok.path))
        self.files[-1].buf.insert(0, tok)

    def skip_block(self, force: bool = False) -> bool:
        """After consuming a '{': skip the rest of its block at text level."""
        f = self.files[-1] if self.files else None
        if f is None or f.buf:
            return False
        return f.skip_block_text(force)

    def mark(self) -> Mark | None:
        """The position of the next token, to come back to with :meth:`reset`."""
        f = self.files[-1] if self.files else None
        if f is None:
            return None
        if f.buf:
            tok = f.buf[0]
            if tok.offset < 0:
                return None
            return f, tok.offset, tok.line
        return f, f.pos, f.line

    def reset(self, mark: Mark) -> bool:
        """Go back to a :meth:`mark`; False if its file is no longer open.  Files opened
        since are left without ``on_close``."""
        f, pos, line = mark
        if f not in self.files:
            return False
        while self.files[-1] is not f:
            self.files.pop()
        f.pos, f.line, f.buf = pos, line, []
        return True

    def skip_braced_block(self) -> None:
        """Skip a balanced ``{ ... }`` block; the next token must be '{'."""
        tok = self.next()
        if tok.text != "{":
            raise SdlEvalError(f"{tok.where}: expected '{{'")
        self.skip_rest_of_block()

    def skip_rest_of_block(self) -> None:
        """After a consumed '{': skip to just after its matching '}' (raw tokens)."""
        if self.skip_block(force=True):
            return
        depth = 1
        while depth:
            tok = self.next()
            if tok.kind == "eof":
                return
            if tok.kind == "op":
                if tok.text == "{":
                    depth += 1
                elif tok.text == "}":
                    depth -= 1

    def is_open(self, path: Path) -> bool:
        """True if ``path`` (resolved) is on the include stack (a recursive ``#include``)."""
        return any(f.kind != "macro" and Path(f.path).resolve() == path for f in self.files)
