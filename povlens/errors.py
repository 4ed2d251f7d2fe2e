"""Errors povlens reports to users.

Every error a user can cause derives from :class:`PovlensError`.  The command
line prints its message (never a traceback) and exits with ``exit_code``.
"""

from __future__ import annotations

__all__ = ["PovlensError", "LensFileError", "OpticsError", "UsageError", "PovrayError"]


class PovlensError(Exception):
    """An error with a message meant for the user; ``exit_code`` for the CLI."""

    exit_code = 2

    def __init__(self, message: str, hint: str | None = None):
        self.message = message
        self.hint = hint
        super().__init__(message if hint is None else f"{message}\n  hint: {hint}")


class LensFileError(PovlensError):
    """A lens prescription file that cannot be read; names the file and line."""

    def __init__(self, path, line: int | None, reason: str, hint: str | None = None):
        self.path = str(path)
        self.line = line
        self.reason = reason
        where = self.path if line is None else f"{self.path}:{line}"
        super().__init__(f"{where}: {reason}", hint)


class OpticsError(PovlensError):
    """A request the lens cannot satisfy (e.g. focusing closer than it can)."""


class UsageError(PovlensError):
    """A bad command-line option or argument value."""


class PovrayError(PovlensError):
    """POV-Ray is missing or failed; the message carries POV-Ray's own output."""

    exit_code = 3
