"""Errors povlens reports to users.

Every error a user can cause derives from :class:`PovlensError`.  The command
line prints its message (never a traceback) and exits with ``exit_code``.

Messages speak the Python API.  Hints, and the messages of
:class:`ParameterError`, write a parameter as the API spells it: ``name=value``
where they give its value (``f_number=1.2: ...``) and ``'name'`` where they name
the parameter alone (``give 'location' and 'look_at'``).  The command line
(:mod:`povlens.cli.flags`) rewrites both forms to the option that sets the
parameter (``--f-number 1.2``, ``--location``).  Other messages may quote the
user's own text (a scene identifier ``'width'``) and are printed as they are.
"""

from __future__ import annotations

__all__ = ["PovlensError", "LensFileError", "OpticsError", "UsageError", "ParameterError",
           "PovrayError", "WriteError", "PovrayWriteError", "PovlensWarning",
           "LensClipWarning", "NominalFNumberWarning"]


class PovlensError(Exception):
    """An error with a message meant for the user; ``exit_code`` for the CLI.

    Parameters
    ----------
    message : str
        What went wrong, naming the file, parameter or value concerned.
    hint : str, optional
        What to do about it (printed on a second line, after ``hint:``).
    """

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
    """A bad option, argument or parameter value."""


class ParameterError(UsageError):
    """A bad value of one API parameter.

    Parameters
    ----------
    parameter : str
        The parameter as the API spells it (``"f_number"``, ``"tolerance_px"``,
        ``"focus"``); the command line maps it to its option.
    value : object
        The value given (``None`` when the parameter is missing).
    message : str
        What is wrong, naming the parameter as ``parameter=value`` or
        ``'parameter'`` (see the module docstring), e.g.
        ``"f_number=1.2: dgauss.50mm opens only to F/2.03"``.
    hint : str, optional
        What to do about it, naming parameters the same way.
    """

    def __init__(self, parameter: str, value, message: str, hint: str | None = None):
        self.parameter = parameter
        self.value = value
        super().__init__(message, hint)


class PovrayError(PovlensError):
    """POV-Ray is missing or failed; the message carries POV-Ray's own output."""

    exit_code = 3


class WriteError(PovlensError, OSError):
    """The system refused to write an output: the device is full, a quota is reached,
    the file system is read-only or the folder not writable.  Names the path.

    Exit code 4: neither the input nor POV-Ray is at fault, and a later run in the same
    folder resumes once there is room (nothing half-written is left at a final name).
    It is an ``OSError`` too (``errno``, ``strerror`` = ``reason``, ``filename`` =
    ``path``), so code that lets an optional cache write fail quietly still does.

    Parameters
    ----------
    path : the file (or folder) that could not be written.
    reason : the cause in words ("no space left on device", ...).
    message : the whole message (default: ``cannot write PATH: REASON``).
    hint : what to do (default: free space or choose another folder).
    code : the ``errno`` value, if known.
    """

    exit_code = 4

    def __init__(self, path, reason: str, message: str | None = None, hint: str | None = None,
                 code: int | None = None):
        self.path = str(path)
        self.reason = reason
        super().__init__(message or f"cannot write {self.path}: {reason}",
                         hint or "free some space there (or raise the quota), or write to "
                                 "another folder; a rerun resumes where this one stopped")
        self.errno, self.strerror, self.filename = code, reason, self.path

    def __str__(self) -> str:                  # the message, not OSError's "[Errno N] ..."
        return Exception.__str__(self)


class PovrayWriteError(WriteError, PovrayError):
    """POV-Ray could not write its output (image, render-state file or error log):
    a :class:`WriteError` (exit code 4) that is also a :class:`PovrayError`; the
    message keeps POV-Ray's own words."""


class PovlensWarning(UserWarning):
    """A notice for the user: povlens went on, but read or used something other than
    what was given.  Issued with :func:`warnings.warn`; the command line prints each
    distinct one once, on one line."""


class LensClipWarning(PovlensWarning):
    """A lens row's aperture was larger than its surface can physically be (a housing
    diameter, not a clear aperture) and was clipped; names the file, row, line and
    the clipped diameter."""


class NominalFNumberWarning(PovlensWarning):
    """An f-number slightly faster than the lens's widest (a nominal, rounded one) was
    taken as the lens wide open."""
