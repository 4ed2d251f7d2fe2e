"""The ``povlens`` command line: a thin layer over the Python API.

Each subcommand lives in its own module here and exposes ``register(subparsers)``,
which adds its parser and sets ``func`` (a function taking the parsed args and
returning an exit code).  Exit codes: 0 success, 1 a check failed (``check``),
2 bad input or usage, 3 POV-Ray failed, 130 interrupted.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from povlens.errors import PovlensError

#: Subcommand modules, in the order ``--help`` lists them.
COMMANDS = ["inspect", "focus", "trace", "check", "plan", "render", "pupil", "compare", "bench", "report"]

#: Commands registered by a module of another name (the others: ``<command>_cmd``).
_MODULE_OF = {"convert": "render", "composite": "render", "render-batch": "render",
              "render-view": "render"}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``povlens`` parser.  With ``command`` (the first argument), only the module
    of that command is imported (the others import numpy, scipy, OpenImageIO...);
    an unknown command, ``--help`` and ``--version`` get every command."""
    parser = argparse.ArgumentParser(
        prog="povlens",
        description="Real camera lenses for POV-Ray: inspect and focus lens prescriptions, "
                    "trace rays, build exit-pupil tables, and render POV-Ray scenes through them.")
    from povlens import __version__
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


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv[0] if argv else None)
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except PovlensError as e:
        print(f"povlens {args.command}: error: {e}", file=sys.stderr)
        return e.exit_code
    except KeyboardInterrupt:
        print(f"povlens {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0
