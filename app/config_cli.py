"""Command-line options generated from frozen config dataclasses: one option per field, the field's
docstring as its help text, Literal choices as argparse choices."""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import itertools
import textwrap
import types
import typing
from functools import cache
from pathlib import Path

from models.ranges import OptionError, check_config


@cache
def field_docs(cls: type) -> dict[str, str]:
    """Attribute docstrings (the string literal under each field) of a dataclass, by field name."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass):
            continue
        tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        body = tree.body[0].body
        for node, nxt in itertools.pairwise(body):
            if (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)
                    and isinstance(nxt, ast.Expr) and isinstance(nxt.value, ast.Constant)
                    and isinstance(nxt.value.value, str)):
                docs[node.target.id] = " ".join(nxt.value.value.split())
    return docs


def _strip_optional(tp: object) -> tuple[object, bool]:
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1:
            return args[0], True
    return tp, False


def add_config_arguments(parser: argparse.ArgumentParser, cls: type, positional: tuple[str, ...] = ()) -> None:
    """Add an option per dataclass field; names in `positional` become positional arguments."""
    hints = typing.get_type_hints(cls)  # Annotated ranges stripped: the parser needs the plain types
    docs = field_docs(cls)
    for f in dataclasses.fields(cls):
        tp, optional = _strip_optional(hints[f.name])
        required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        default = None if required else (f.default if f.default is not dataclasses.MISSING
                                         else f.default_factory())
        name = f.name.rstrip("_")
        help_text = docs.get(f.name, "")
        if not required and default not in (None, (), False, ""):
            help_text += f" (default: {' '.join(map(str, default)) if isinstance(default, tuple) else default})"
        # Help texts are the fields' docstrings, not format strings: a "10%" must not reach argparse's % formatting.
        kw: dict = {"help": help_text.replace("%", "%%"), "dest": f.name}
        origin = typing.get_origin(tp)
        if tp is bool:
            kw.update(action=argparse.BooleanOptionalAction, default=default)
        elif origin is typing.Literal:
            kw.update(choices=typing.get_args(tp), default=default)
        elif origin is tuple:
            args = typing.get_args(tp)
            if len(args) == 2 and args[1] is Ellipsis:
                kw.update(nargs="*", type=args[0], default=default)
            else:
                kw.update(nargs=len(args), type=args[0], default=default, metavar=tuple(
                    a.__name__.upper() for a in args))
        else:
            kw.update(type=tp if tp in (int, float, str, Path) else str, default=default)
        if name in positional:
            kw.pop("dest")
            if not required:
                kw["nargs"] = "?"
            parser.add_argument(f.name, **kw)
        else:
            kw["required"] = required
            parser.add_argument("--" + name.replace("_", "-"), **kw)
        del optional


def config_from_args(cls: type, args: argparse.Namespace):
    """The dataclass instance from parsed arguments (tuples stay tuples), its fields checked against their declared
    ranges (models/ranges.py): OptionError naming the option."""
    values = {}
    for f in dataclasses.fields(cls):
        v = getattr(args, f.name)
        values[f.name] = tuple(v) if isinstance(v, list) else v
    cfg = cls(**values)
    try:
        check_config(cfg)
    except ValueError as e:
        raise OptionError(str(e)) from None
    return cfg
