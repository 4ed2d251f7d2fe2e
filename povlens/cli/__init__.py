"""The ``povlens`` command line: a thin layer over the Python API.

Each subcommand lives in its own module here and exposes ``register(subparsers)``,
which adds its parser and sets ``func`` (a function taking the parsed args and
returning an exit code).  Exit codes: 0 success, 1 a check failed (``check``) or an
unexpected error, 2 bad input or usage, 3 POV-Ray failed, 4 an output could not be
written (a full device, a quota, a read-only file system, no permission: the message
names the path), 130 interrupted (Ctrl-C), 143 terminated (SIGTERM, as batch systems
and ``kill`` send).

Errors print one message (with the options the user typed, :mod:`povlens.cli.flags`)
and no traceback; ``POVLENS_DEBUG=1`` shows the traceback of an unexpected error.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import signal
import sys
import threading
import warnings

from povlens import __version__
from povlens.cli.flags import error_text, with_flags
from povlens.errors import PovlensError, PovlensWarning, WriteError
from povlens.util.files import write_error_hint, write_error_reason
from povlens.util.signals import kill_descendants

#: errno values that only a write gets (:data:`povlens.util.files.WRITE_ERRNOS`
#: without EACCES and EPERM, which a read gets too).
_REFUSED_WRITES = {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EFBIG}

#: Set to 1 to see the traceback of an unexpected error instead of a one-line message.
DEBUG_ENV_VAR = "POVLENS_DEBUG"

#: Subcommand modules, in the order ``--help`` lists them.
COMMANDS = ["inspect", "focus", "trace", "check", "plan", "render", "pupil", "compare", "bench",
            "report", "lenses", "import_lens"]

#: Commands registered by a module of another name (the others: ``<command>_cmd``).
_MODULE_OF = {"convert": "render", "composite": "render", "render-batch": "render",
              "render-view": "render", "import-lens": "import_lens"}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``povlens`` parser.  With ``command`` (the first argument), only the module
    of that command is imported (the others import numpy, scipy, OpenImageIO...);
    an unknown command, ``--help`` and ``--version`` get every command."""
    parser = argparse.ArgumentParser(
        prog="povlens",
        description="Real camera lenses for POV-Ray: inspect and focus lens prescriptions, "
                    "trace rays, build exit-pupil tables, and render POV-Ray scenes through them.")
    parser.add_argument("--version", action="version", version=f"povlens {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    module = _MODULE_OF.get(command, command)
    names = [module] if module in COMMANDS else COMMANDS
    for name in names:
        importlib.import_module(f".{name}_cmd", __name__).register(sub)
    if names is not COMMANDS and command not in sub.choices:
        return build_parser()
    return parser


def option_strings(parser: argparse.ArgumentParser, command: str) -> set[str]:
    """The options (``--f-number``, ``-o`` ...) of subcommand ``command`` of ``parser``."""
    for action in parser._actions:
        choices = getattr(action, "choices", None)
        if isinstance(choices, dict) and command in choices:
            return {s for a in choices[command]._actions for s in a.option_strings}
    return set()


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread so that the clean-up of an interrupt (stop
    POV-Ray, remove temporaries) runs for it too."""


#: The signals (SIGINT, SIGTERM) received while the command ran, in order.
RECEIVED: list[int] = []


def _terminate(signum, frame):
    RECEIVED.append(signum)
    raise Terminated()


def _interrupt(signum, frame):
    RECEIVED.append(signum)
    raise KeyboardInterrupt()


def terminate_as_interrupt():
    """While a command runs, SIGTERM raises :class:`Terminated` and SIGINT
    ``KeyboardInterrupt``, each noted in :data:`RECEIVED`; returns the restorer.
    (Only the main thread can take signals; elsewhere nothing changes.)"""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    RECEIVED.clear()
    previous = {s: signal.signal(s, h) for s, h in ((signal.SIGTERM, _terminate),
                                                     (signal.SIGINT, _interrupt))}
    return lambda: [signal.signal(s, h) for s, h in previous.items() if h is not None]


def _stopped_by_signal(command: str, error: BaseException) -> int:
    """Print that ``command`` was interrupted or terminated; its exit code (130, 143).
    The last signal received counts: its clean-up may have ended in another error
    (``error``), which would otherwise be reported as the cause."""
    terminated = (RECEIVED[-1] == signal.SIGTERM if RECEIVED
                  else isinstance(error, Terminated))
    print(f"povlens {command}: {'terminated' if terminated else 'interrupted'}",
          file=sys.stderr)
    return 143 if terminated else 130


def main(argv: list[str] | None = None) -> int:
    """Run ``povlens`` with ``argv`` (default ``sys.argv[1:]``); returns the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv[0] if argv else None)
    args = parser.parse_args(argv)
    restore_warnings = show_warnings_once(option_strings(parser, args.command))
    restore_signals = terminate_as_interrupt()
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt as e:                  # Terminated too
        return _stopped_by_signal(args.command, e)
    except BrokenPipeError:
        return 0
    except Exception as e:
        if RECEIVED:                                # an interrupt's clean-up failed
            return _stopped_by_signal(args.command, e)
        if isinstance(e, PovlensError):
            text = error_text(e, option_strings(parser, args.command))
            print(f"povlens {args.command}: error: {text}", file=sys.stderr)
            return e.exit_code
        refused = refused_write_text(e, args)
        if refused is not None:                     # a full disk, a read-only folder...
            print(f"povlens {args.command}: error: {refused}", file=sys.stderr)
            return WriteError.exit_code
        if os.environ.get(DEBUG_ENV_VAR, "") not in ("", "0"):
            raise
        print(f"povlens {args.command}: {unexpected_error_text(e)}", file=sys.stderr)
        return 1                                    # a bug, or the system failing
    finally:
        restore_signals()
        restore_warnings()


def run() -> None:
    """The ``povlens`` program: :func:`main`, then exit with its code.

    Whenever the command fails or is interrupted, any process left below this one is
    killed (:func:`~povlens.util.signals.kill_descendants`): a POV-Ray started by a
    thread the error or the interrupt did not reach must not outlive the command.
    After an interrupt (130, 143) the process ends with ``os._exit``: CPython kills
    itself with SIGINT at exit, whatever the exit code, once a KeyboardInterrupt has
    escaped any ``exec`` of a string (a dataclass being made, say) during the run (its
    ``unhandled_keyboard_interrupt`` flag stays set), which would turn 130 and 143
    into death by SIGINT.  The command's clean-up has run by then."""
    code = main()
    if code != 0:
        for s in (signal.SIGINT, signal.SIGTERM):   # a second signal must not cut this short
            signal.signal(s, signal.SIG_IGN)
        kill_descendants()
    if code in (130, 143):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


def show_warnings_once(options: set[str]):
    """Print each distinct :class:`~povlens.errors.PovlensWarning` once, as one line
    ``povlens: warning: ...`` on stderr (parameters written as ``options``); other
    warnings print as Python prints them.

    Parameters
    ----------
    options : set of str
        The options of the command (:func:`option_strings`).

    Returns
    -------
    callable
        Restores the warning filters and printer in place before the call.
    """
    saved = warnings.catch_warnings()
    saved.__enter__()
    python_show, shown = warnings.showwarning, set()

    def show(message, category, filename, lineno, file=None, line=None):
        if not issubclass(category, PovlensWarning):
            return python_show(message, category, filename, lineno, file, line)
        text = with_flags(str(message), options)
        if text not in shown:
            shown.add(text)
            print(f"povlens: warning: {text}", file=sys.stderr)

    warnings.simplefilter("always", PovlensWarning)  # repeats are dropped by ``show``
    warnings.showwarning = show
    return lambda: saved.__exit__(None, None, None)


def refused_write_text(error: Exception, args) -> str | None:
    """The message of an ``OSError`` of a write the system refused (a full device, a
    quota, a read-only file system, a file size limit) that reached the command line
    outside povlens's own writers: it names the file when the system did, else the
    command's output; None for any other error (a permission error may be a read's:
    it is printed as the system words it, with its file)."""
    if not isinstance(error, OSError) or error.errno not in _REFUSED_WRITES:
        return None
    named = error.filename or getattr(args, "outdir", None) or getattr(args, "output", None)
    if named is None:
        where = "a file (the system did not say which)"
    else:
        where = os.fsdecode(named) + ("" if error.filename else
                                      " (the command's output; the system named no file)")
    folder = os.path.dirname(os.path.abspath(os.fsdecode(named))) if named else "."
    return (f"cannot write {where}: {write_error_reason(folder, error.errno)}\n"
            f"  hint: {write_error_hint(error.errno)}")


def unexpected_error_text(error: Exception) -> str:
    """What the command line prints for an exception that is no :class:`PovlensError`:
    a system error (``OSError``) or a bug, with how to see its traceback."""
    if isinstance(error, OSError):
        return (f"error: {error}\n"
                f"  hint: run again with {DEBUG_ENV_VAR}=1 to see where it happened")
    return (f"internal error: {type(error).__name__}: {error}\n"
            f"  hint: this is a bug in povlens; run again with {DEBUG_ENV_VAR}=1 to see the "
            f"traceback, and report it")
