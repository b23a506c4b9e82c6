"""Progress of a long command, wherever its output goes: a line redrawn in place on a terminal; in a log (a
file, a pipe, the studio's job list) a plain line every tenth of the way and at the end, so that a log also
says how far it got."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import TextIO


class Progress:
    """`done` of `total` things (frames, steps), with a few words after the count."""

    def __init__(self, what: str, total: int, unit: str = "frames", stream: TextIO | None = None,
                 tty: bool | None = None):
        self.what, self.total, self.unit = what, max(int(total), 1), unit
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty() if tty is None else tty
        self._next_tenth = 1

    def update(self, done: int, extra: str = "") -> None:
        text = f"{self.what}: {done}/{self.total} {self.unit}" + (f"  {extra}" if extra else "")
        if self.tty:
            self.stream.write(f"\r{text}   " + ("\n" if done >= self.total else ""))
        elif done >= self.total or done * 10 >= self._next_tenth * self.total:
            self.stream.write(text + "\n")
            while done * 10 >= self._next_tenth * self.total:
                self._next_tenth += 1
        self.stream.flush()


def progress_callback(what: str, unit: str = "frames") -> Callable[[int, int], None]:
    """A (done, total) callback for work that learns its total as it goes: a Progress made on the first call."""
    bar: list[Progress] = []

    def update(done: int, total: int) -> None:
        if not bar:
            bar.append(Progress(what, total, unit))
        bar[0].update(done)

    return update
