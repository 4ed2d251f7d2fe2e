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

from ..errors import PovlensError

#: Subcommand modules, in the order ``--help`` lists them.
COMMANDS = ["inspect", "focus", "trace", "check", "plan", "render", "pupil", "compare", "bench", "report"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="povlens",
        description="Real camera lenses for POV-Ray: inspect and focus lens prescriptions, "
                    "trace rays, build exit-pupil tables, and render POV-Ray scenes through them.")
    from .. import __version__
    parser.add_argument("--version", action="version", version=f"povlens {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMANDS:
        importlib.import_module(f".{name}_cmd", __name__).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
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
