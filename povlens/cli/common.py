"""Options and output helpers shared by the subcommands."""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable

import numpy as np

from povlens.lens.paraxial import stopped_down
from povlens.lens.prescription import LensPrescription, read_lens


def add_lens_command(sub, name: str, run: Callable, *, help: str,
                     description: str) -> argparse.ArgumentParser:
    """Add subcommand ``name`` that reads LENS with its stop options and runs ``run``.

    Parameters
    ----------
    sub : argparse subparsers action
        The subcommands of the ``povlens`` parser.
    name, help, description : str
        The subcommand, as ``add_parser`` takes them.
    run : callable
        Function of the parsed arguments returning the exit code.

    Returns
    -------
    argparse.ArgumentParser
        The subcommand's parser, to add its own options to.
    """
    p = sub.add_parser(name, help=help, description=description)
    add_lens_arguments(p)
    p.set_defaults(func=run)
    return p


def add_lens_arguments(p: argparse.ArgumentParser) -> None:
    """LENS plus the stop options (--f-number / --stop-diameter)."""
    p.add_argument("lens", metavar="LENS",
                   help="lens file (pbrt/Kolb format) or the name of a bundled lens, "
                        "e.g. dgauss.50mm")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--f-number", type=positive_float, metavar="N",
                   help="stop the lens down to this f-number (EFL / entrance-pupil diameter)")
    g.add_argument("--stop-diameter", type=positive_float, metavar="MM",
                   help="set the aperture-stop diameter in mm")


def load_lens(args) -> LensPrescription:
    """The lens of ``args.lens``, stopped down by ``--f-number`` / ``--stop-diameter``."""
    lens = read_lens(args.lens)
    return stopped_down(lens, stop_diameter_mm=getattr(args, "stop_diameter", None),
                        f_number=getattr(args, "f_number", None))


def positive_float(text: str) -> float:
    """A positive finite number (argparse type)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"'{text}' must be a positive finite number")
    return v


def positive_int(text: str) -> int:
    """A whole number >= 1 (argparse type)."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"'{text}' must be at least 1")
    return v


def distance(text: str) -> float:
    """A positive distance, or 'inf' for infinity."""
    if text.strip().lower() in ("inf", "infinity"):
        return math.inf
    return positive_float(text)


def print_json(obj) -> None:
    """Print ``obj`` as indented JSON; numpy scalars and arrays become numbers and lists."""
    json.dump(obj, sys.stdout, indent=2, allow_nan=False, default=_default)
    sys.stdout.write("\n")


def _default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")

