"""What values a config's fields may take, declared beside the fields (typing.Annotated), checked wherever a
config is made from user input: the command line (app/config_cli.py) and the trainer, so that a new option
cannot forget. Every float must be finite unless its range says otherwise.

    size: Annotated[int, Range(32, 2048)] = 256
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from dataclasses import dataclass


@dataclass(frozen=True)
class Range:
    lo: float | None = None
    hi: float | None = None
    above: bool = False
    """lo itself is not allowed (a value must be above it)."""

    def problem(self, value: float) -> str | None:
        """Why `value` is out of range, or None."""
        if isinstance(value, float) and not math.isfinite(value):
            return "must be a finite number"
        low_ok = self.lo is None or (value > self.lo if self.above else value >= self.lo)
        if low_ok and (self.hi is None or value <= self.hi):
            return None
        lo = None if self.lo is None else f"{'above' if self.above else 'at least'} {self.lo:g}"
        hi = None if self.hi is None else f"at most {self.hi:g}"
        return "must be " + " and ".join(x for x in (lo, hi) if x)


def option_name(field: str) -> str:
    return "--" + field.rstrip("_").replace("_", "-")


def ranges_of(hint: object) -> list[Range]:
    """The Range of a field's type: Annotated[T, Range], optionally in an Optional or as a tuple's items."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType, tuple):
        return [r for arg in typing.get_args(hint) if arg is not type(None) and arg is not Ellipsis
                for r in ranges_of(arg)][:1]
    return [m for m in getattr(hint, "__metadata__", ()) if isinstance(m, Range)]


def numeric(hint: object) -> bool:
    """A field typed int or float (alone, Annotated, optional or as a tuple's items)."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType, tuple):
        return any(numeric(arg) for arg in typing.get_args(hint) if arg is not type(None) and arg is not Ellipsis)
    base = typing.get_args(hint)[0] if typing.get_origin(hint) is typing.Annotated else hint
    return base in (int, float)


def config_problems(cfg: object) -> list[str]:
    """Every field of a config dataclass out of its range ("--size 0: must be at least 32"); floats (alone or in
    tuples) must be finite."""
    hints = typing.get_type_hints(type(cfg), include_extras=True)
    out = []
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        if value is None or isinstance(value, bool):
            continue
        ranges = ranges_of(hints[f.name])
        values = value if isinstance(value, tuple) else (value,)
        for v in values:
            if isinstance(v, str) and numeric(hints[f.name]):
                out.append(f"{option_name(f.name)} {v!r}: must be a number")
                break
            if not isinstance(v, (int, float)) or isinstance(v, bool):
                continue
            why = next((r.problem(v) for r in ranges if r.problem(v)), None) if ranges else \
                (Range().problem(float(v)) if isinstance(v, float) else None)
            if why:
                out.append(f"{option_name(f.name)} {v:g}: {why}" if isinstance(v, float) else
                           f"{option_name(f.name)} {v}: {why}")
                break
    return out


def check_config(cfg: object) -> None:
    """ValueError naming the first option out of range."""
    problems = config_problems(cfg)
    if problems:
        raise ValueError(problems[0])
