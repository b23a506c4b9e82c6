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


class OptionError(ValueError):
    """A setting given on the command line that the config does not have, or cannot take."""


def config_with(cls: type, settings: tuple[str, ...], base: object = None, option: str = "--model-options"):
    """The config `cls` (base's values, else its defaults) but for `settings`, each "field=value" (bools:
    true/false, 1/0, yes/no), checked against the field's type and range.

    >>> @dataclass(frozen=True)
    ... class C:
    ...     grid: typing.Annotated[int, Range(8, 256)] = 16
    ...     swap: float = 0.0
    ...     maps: bool = False
    >>> config_with(C, ("grid=32", "maps=yes"))
    C(grid=32, swap=0.0, maps=True)
    >>> for bad in ("grid=4", "grid=x", "swap=nan", "maps=2", "size=3"):
    ...     try:
    ...         config_with(C, (bad,))
    ...     except OptionError as e:
    ...         print(e)
    --model-options grid=4: must be at least 8 and at most 256
    --model-options grid=x: grid must be int
    --model-options swap=nan: must be a finite number
    --model-options maps=2: maps must be true or false
    --model-options size=3: not a setting of this model (its settings: grid, swap, maps)
    """
    hints = typing.get_type_hints(cls)
    values = {}
    for item in settings:
        name, sep, text = item.partition("=")
        name = name.strip().replace("-", "_")
        if not sep or name not in hints:
            known = ", ".join(f.name for f in dataclasses.fields(cls))
            raise OptionError(f"{option} {item}: not a setting of this model (its settings: {known})")
        kind = hints[name]
        try:
            if kind is bool:
                flag = text.strip().lower()
                if flag not in ("true", "false", "1", "0", "yes", "no"):
                    raise ValueError(flag)
                values[name] = flag in ("true", "1", "yes")
            elif kind in (int, float):
                values[name] = kind(text)
            else:
                raise OptionError(f"{option} {item}: {name} cannot be set on the command line")
        except ValueError as e:
            if isinstance(e, OptionError):
                raise
            raise OptionError(f"{option} {item}: {name} must be {'true or false' if kind is bool else kind.__name__}"
                              ) from None
    extras = typing.get_type_hints(cls, include_extras=True)
    for name, v in values.items():
        ranges = ranges_of(extras[name]) or ([Range()] if isinstance(v, float) else [])
        why = next((r.problem(v) for r in ranges if r.problem(v)), None)
        if why:
            raise OptionError(f"{option} {name}={v:g}: {why}")
    try:  # a config's own checks of its fields together (__post_init__)
        return dataclasses.replace(base if base is not None else cls(), **values)
    except ValueError as e:
        raise OptionError(f"{option} {' '.join(settings)}: {e}") from None
