"""Declared names of a POV-Ray scene, scoped as POV-Ray 3.7 scopes them.

The global table holds ``#declare``; each ``#include`` file and each macro call opens a
local table for its ``#local`` names and a macro's parameters, closed when it ends.
Lookup goes from the innermost table outwards.
"""

from __future__ import annotations

from typing import Iterable, Mapping

from povlens.pov.sdl.values import UnknownValue

__all__ = ["SymbolTable"]


class SymbolTable:
    """The scopes of declared names; ``scopes[0]`` is the global one.

    Every assignment is logged (``log``), so that the names a loop assigned can be found
    again when povlens stops following the loop.
    """

    def __init__(self, predefined: Mapping[str, object] | None = None):
        self.scopes: list[dict[str, object]] = [dict(predefined or {})]
        self.log: list[str] = []

    def get(self, name: str):
        """The value of ``name``, or None if it is not declared."""
        for scope in reversed(self.scopes):
            if name in scope:
                return scope[name]
        return None

    def __contains__(self, name: str) -> bool:
        return any(name in scope for scope in self.scopes)

    def declare(self, name: str, value: object, local: bool = False) -> None:
        """``#declare`` (global table) or ``#local`` (innermost table)."""
        (self.scopes[-1] if local else self.scopes[0])[name] = value
        self.log.append(name)

    def set_existing(self, name: str, value: object) -> None:
        """Change ``name`` in the innermost table that has it (else declare it locally)."""
        for scope in reversed(self.scopes):
            if name in scope:
                scope[name] = value
                self.log.append(name)
                return
        self.declare(name, value, local=True)

    def undef(self, name: str) -> None:
        """``#undef``: remove ``name`` from the innermost table that has it."""
        for scope in reversed(self.scopes):
            if name in scope:
                del scope[name]
                self.log.append(name)
                return

    def push(self, names: Mapping[str, object] | None = None) -> None:
        """Open a local table (an include file or a macro call)."""
        self.scopes.append(dict(names or {}))

    def pop(self) -> None:
        """Close the innermost local table (never the global one)."""
        if len(self.scopes) > 1:
            self.scopes.pop()

    def forget(self, names: Iterable[str], reason: str) -> None:
        """Make each of ``names`` unknown where it is visible (a loop povlens stopped)."""
        for name in set(names):
            if name in self:
                self.set_existing(name, UnknownValue(reason, maybe=True))
