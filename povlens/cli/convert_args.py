"""The options of a conversion as command-line arguments, derived from their one
declaration (:mod:`povlens.plan.options`): flag, type, default, help, how the flag
sets the value, which options exclude each other.  ``convert``, ``render`` and ``plan``
take them; :func:`keywords_from_args` turns parsed arguments back into the API's
keywords (:func:`povlens.api.convert`), which check the values.
"""

from __future__ import annotations

import argparse

from povlens.plan.options import RECORDS, DaskOptions, OptionSpec, dask_options, options

__all__ = ["add_convert_arguments", "add_dask_arguments", "keywords_from_args",
           "dask_keywords_from_args", "default_text"]

_BUILTIN_TYPES = (int, float, str)


def _argparse_type(parse):
    """``parse`` as an argparse type: its ValueError's message is the error shown."""
    if parse is None or parse in _BUILTIN_TYPES:
        return parse

    def typed(text: str):
        try:
            return parse(text)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
    typed.__name__ = parse.__name__
    return typed


def default_text(value) -> str | None:
    """How ``--help`` shows a default (None: not shown: no value, a switch, empty)."""
    if value is None or isinstance(value, bool) or value == ():
        return None
    if isinstance(value, tuple):
        return ",".join(f"{v:g}" for v in value)
    return f"{value:g}" if isinstance(value, float) else str(value)


def _help(spec: OptionSpec, default) -> str:
    shown = default_text(default) if spec.sets == "value" else None
    if shown is None or "default" in spec.help:
        return spec.help
    return f"{spec.help} (default {shown})"


def _add(container, name: str, default, spec: OptionSpec) -> None:
    kw: dict = {"dest": name, "help": _help(spec, default)}
    if spec.sets == "value":
        kw.update(default=default, type=_argparse_type(spec.parse), metavar=spec.metavar,
                  choices=spec.choices)
    elif spec.sets == "append":
        kw.update(action="append", default=list(default), type=_argparse_type(spec.parse),
                  metavar=spec.metavar)
    elif spec.sets == "true":
        kw.update(action="store_true")
    elif spec.sets == "false":
        kw.update(action="store_false")
    elif spec.sets == "both":
        kw.update(action=argparse.BooleanOptionalAction, default=default)
    else:
        raise ValueError(f"option {name}: unknown way of setting {spec.sets!r}")
    container.add_argument(spec.flag, **{k: v for k, v in kw.items() if v is not None})


def _add_options(p: argparse.ArgumentParser, declared) -> None:
    """An argument per declared option with a flag: ``declared`` is (title of its
    group in ``--help``, field, spec)."""
    groups = {None: p}
    exclusive: dict = {}
    for title, f, spec in declared:
        if spec.flag is None:
            continue
        if title not in groups:
            groups[title] = p.add_argument_group(title)
        container = groups[title]
        if spec.exclusive is not None:
            key = (title, spec.exclusive)
            if key not in exclusive:
                exclusive[key] = container.add_mutually_exclusive_group()
            container = exclusive[key]
        _add(container, f.name, f.default, spec)


def add_convert_arguments(p: argparse.ArgumentParser) -> None:
    """SCENE, ``--lens``, every option of :mod:`povlens.plan.options` that has a flag,
    ``-o OUTDIR`` and ``--json``."""
    p.add_argument("scene", metavar="SCENE.pov", help="an ordinary POV-Ray scene (not modified)")
    p.add_argument("--lens", required=True, help="lens file or bundled lens name")
    _add_options(p, ((RECORDS[group].TITLE, f, spec) for group, f, spec in options()))
    p.add_argument("-o", "--outdir", required=True, metavar="OUTDIR", help="output folder")
    p.add_argument("--json", action="store_true", help="print the plan as JSON")


def add_dask_arguments(p: argparse.ArgumentParser) -> None:
    """``render``'s Dask options (:class:`~povlens.plan.options.DaskOptions`)."""
    _add_options(p, ((DaskOptions.TITLE, f, spec) for f, spec in dask_options()))


def keywords_from_args(args) -> dict:
    """The API keywords of parsed :func:`add_convert_arguments` arguments: every option
    with a flag, as the user gave it (``focus`` as text: a pull is resolved by the
    caller)."""
    return {f.name: (tuple(v) if spec.sets == "append" else v)
            for _, f, spec in options() if spec.flag is not None
            for v in [getattr(args, f.name)]}


def dask_keywords_from_args(args) -> dict:
    """The API keywords of parsed :func:`add_dask_arguments` arguments."""
    return {f.name: getattr(args, f.name) for f, _ in dask_options()}
