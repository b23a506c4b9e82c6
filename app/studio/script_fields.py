"""What a scripted run's steps may hold (app/studio/script.py): each action's value and the fields beside it, checked
before the window opens so that a mistake is one line naming the step, never a traceback halfway through a run.
Plain values, no imgui."""

from __future__ import annotations

import difflib
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from app.errors import UserInputError


class Checked(Protocol):
    def problem(self, value: Any) -> str | None:
        """What is wrong with the value (for a message after "steps[3] (gaze): "); None where it is right."""


def shown(value: Any, limit: int = 60) -> str:
    """A value as the script wrote it (JSON), cut short.

    >>> shown([10, 0, 0]), shown(True), shown("x" * 70)[-4:]
    ('[10, 0, 0]', 'true', 'x...')
    """
    text = json.dumps(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


@dataclass(frozen=True)
class Kind:
    """A kind of value: what it is called in messages and the test a value passes."""

    what: str
    test: Callable[[Any], bool]

    def problem(self, value: Any) -> str | None:
        return None if self.test(value) else f"{self.what}, not {shown(value)}"


def _number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


NUMBER = Kind("a number", _number)
INTEGER = Kind("an integer", lambda v: isinstance(v, int) and not isinstance(v, bool))
COUNT = Kind("a whole number, 0 or more", lambda v: INTEGER.test(v) and v >= 0)
SECONDS = Kind("a number of seconds, 0 or more", lambda v: _number(v) and v >= 0)
TEXT = Kind("a string", lambda v: isinstance(v, str) and v != "")
PATH = Kind("a path (a string)", TEXT.test)
TRUE = Kind("true", lambda v: v is True)
BOOL = Kind("true or false", lambda v: isinstance(v, bool))


def vector(n: int, meaning: str) -> Kind:
    """A list of n numbers: `meaning` says what they are (\"yaw, pitch in degrees\")."""
    return Kind(f"a list of {n} numbers ({meaning})",
                lambda v: isinstance(v, list) and len(v) == n and all(_number(x) for x in v))


def one_of(names: tuple[str, ...]) -> Kind:
    listed = (", ".join(names[:-1]) + f" or {names[-1]}") if len(names) > 1 else names[0]
    return Kind(f"one of {listed}", lambda v: isinstance(v, str) and v in names)


def either(*kinds: Kind) -> Kind:
    return Kind(" or ".join(k.what for k in kinds), lambda v: any(k.test(v) for k in kinds))


def optional(kind: Kind) -> Kind:
    return Kind(f"{kind.what} or null", lambda v: v is None or kind.test(v))


def unknown_key(key: str, known: list[str]) -> str:
    """An unknown key's message, with the closest known one.

    >>> unknown_key("vaule", ["value", "timeout_s"])
    "unknown field 'vaule' (did you mean value?)"
    """
    close = difflib.get_close_matches(key, known, n=1)
    if close:
        return f"unknown field {key!r} (did you mean {close[0]}?)"
    return f"unknown field {key!r} " + (f"(known: {', '.join(known)})" if known else "(it takes none)")


@dataclass(frozen=True)
class Record:
    """A JSON object: its required and optional fields, each of a kind."""

    required: Mapping[str, Checked] = field(default_factory=dict)
    optional: Mapping[str, Checked] = field(default_factory=dict)

    def problem(self, value: Any) -> str | None:
        if not isinstance(value, dict):
            fields = ", ".join([*self.required, *self.optional])
            return f"an object ({fields}), not {shown(value)}"
        return self.fields_problem(value)

    def fields_problem(self, value: Mapping[str, Any]) -> str | None:
        known = {**self.required, **self.optional}
        for key in value:
            if key not in known:
                return unknown_key(key, list(known))
        for key in self.required:
            if key not in value:
                return f"no {key!r} (it needs {', '.join(self.required)})"
        for key, kind in known.items():
            if key in value and (p := kind.problem(value[key])) is not None:
                return f"{key}: {p}"
        return None


@dataclass(frozen=True)
class StepSpec:
    """One action of a script: the kind of its value and the fields a step may hold beside it (a wait's
    "timeout_s")."""

    value: Checked
    beside: Record = field(default_factory=Record)


class ScriptError(UserInputError):
    """A script that cannot run: the message names the step (steps[INDEX] (ACTION)) and the problem."""


def step_problem(s: Any, specs: Mapping[str, StepSpec]) -> tuple[str, str | None]:
    """A step's action and what is wrong with it (None: nothing): an object with one action's key, that action's
    value of its kind, and beside it only the fields the action takes."""
    if not isinstance(s, dict):
        return "?", f"a step is an object such as {{\"wait_frames\": 2}}, not {shown(s)}"
    actions = [k for k in s if k in specs]
    if len(actions) != 1:
        if actions:
            return "+".join(actions), f"one action a step, not {len(actions)}"
        if not s:
            return "?", "an empty step"
        key = next(iter(s))
        close = difflib.get_close_matches(key, list(specs), n=1)
        return key, "no such action" + (f" (did you mean {close[0]}?)" if close else "")
    action = actions[0]
    spec = specs[action]
    problem = spec.value.problem(s[action])
    if problem is None:
        problem = spec.beside.fields_problem({k: v for k, v in s.items() if k != action})
    return action, problem


def check_script(data: Any, specs: Mapping[str, StepSpec]) -> None:
    """ScriptError unless `data` is {"report": PATH (optional), "steps": [STEP, ...]} with every step right."""
    if isinstance(data, list):
        raise ScriptError(f"a script is an object {{\"steps\": [...], \"report\": PATH}}, not a list: "
                          f"{{\"steps\": {shown(data, 30)}}}")
    problem = Record({"steps": Kind("a list of steps", lambda v: isinstance(v, list))},
                     {"report": optional(PATH)}).problem(data)
    if problem is not None:
        raise ScriptError(problem)
    for i, s in enumerate(data["steps"]):
        action, problem = step_problem(s, specs)
        if problem is not None:
            raise ScriptError(f"steps[{i}] ({action}): {problem}")
