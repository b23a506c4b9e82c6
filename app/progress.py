"""Progress of a long command, through tqdm, wherever its output goes: on a terminal a bar with the time left,
redrawn at each update; in a log (a file, a pipe, the studio's job list, which reads "reenact: 12/40 frames" back) a
plain line every tenth of the way, with the time left, and at the end with the time taken, so that a log also says
how far it got and how long the rest will take."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import TextIO

from tqdm import tqdm

# The words end each line, so that the last one reads "turntable: 24/24 frames" on a terminal as in a log. The
# finished bar says how long it took where the running one says how long is left; three spaces keep the cursor off
# the words.
RUNNING = "{percentage:3.0f}%|{bar:12}| {remaining} left  {desc}: {n}/{total} {unit}{extra}   "
FINISHED = "{percentage:3.0f}%|{bar:12}| {elapsed} in all  {desc}: {n}/{total} {unit}{extra}   "
LOG_LINE = "{desc}: {n}/{total} {unit}{extra}"
# A log's lines say the time left once a rate is known (from the first update on: the warm-up left out), and the
# last one the time taken, so that a log (and the studio's job list, which shows its last line) tells them too.
LOG_RUNNING = LOG_LINE + " ({remaining} left)"
LOG_FINISHED = LOG_LINE + " ({elapsed} in all)"


class _Bar(tqdm):
    """tqdm with the caller's few words after the count (`{extra}` in a format) and, for a log, a line per display
    where a terminal has the line redrawn."""

    def __init__(self, *args, extra: str = "", log: bool = False, **kwargs):
        self.extra, self.log = extra, log  # before tqdm's __init__, which may draw
        super().__init__(*args, **kwargs)

    @property
    def format_dict(self):
        return {**super().format_dict, "extra": f"  {self.extra}" if self.extra else ""}

    def display(self, msg=None, pos=None):
        if not self.log:
            return super().display(msg, pos)
        self.fp.write(self.__str__() + "\n")
        self.fp.flush()
        return True


class Progress:
    """`done` of `total` things (frames, steps), with a few words after the count. The bar starts with the first
    update, so that the time left leaves out the first thing's warm-up (shader builds, CUDA start)."""

    def __init__(self, what: str, total: int, unit: str = "frames", stream: TextIO | None = None,
                 tty: bool | None = None):
        self.what, self.total, self.unit = what, max(int(total), 1), unit
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty() if tty is None else tty
        self._next_tenth = 1
        self._bar: _Bar | None = None

    def update(self, done: int, extra: str = "") -> None:
        finished = done >= self.total
        if self.tty:
            self._redraw(done, extra, finished)
        else:
            self._log(done, extra, finished)

    def _redraw(self, done: int, extra: str, finished: bool) -> None:
        if self._bar is None:  # drawn at once
            self._bar = _Bar(total=self.total, initial=done, desc=self.what, unit=self.unit, file=self.stream,
                             bar_format=RUNNING, extra=extra, mininterval=0, miniters=0)
        elif finished:
            self._bar.n, self._bar.extra = done, extra
        else:
            self._bar.extra = extra
            self._bar.update(done - self._bar.n)  # redraws, and updates the rate that the time left comes from
        if finished:
            self._bar.bar_format = FINISHED
            self._bar.close()  # draws the finished bar and ends its line

    def _log(self, done: int, extra: str, finished: bool) -> None:
        if self._bar is None:  # drawn only here: an endless delay keeps tqdm from drawing it, closing included
            self._bar = _Bar(total=self.total, initial=done, desc=self.what, unit=self.unit, file=self.stream,
                             bar_format=LOG_LINE, extra=extra, log=True, delay=float("inf"))
        self._bar.n, self._bar.extra = done, extra
        if finished or done * 10 >= self._next_tenth * self.total:
            moved = done > self._bar.initial  # else no rate, and no time left to say
            self._bar.bar_format = LOG_FINISHED if finished else LOG_RUNNING if moved else LOG_LINE
            self._bar.refresh()
            while done * 10 >= self._next_tenth * self.total:
                self._next_tenth += 1
        if finished:
            self._bar.close()


def progress_callback(what: str, unit: str = "frames") -> Callable[[int, int], None]:
    """A (done, total) callback for work that learns its total as it goes: a Progress made on the first call (and
    again if the work starts over)."""
    update = progress_by_stage(unit)
    return lambda done, total: update(what, done, total)


def progress_by_stage(unit: str = "frames") -> Callable[[str, int, int], None]:
    """A (stage, done, total) callback for work in named stages (a training's frames read, then placed): a Progress
    for each stage as it starts, a new one when a stage starts again (the second of a whole head's two trainings)."""
    bars: dict[str, Progress] = {}
    last: dict[str, int] = {}

    def update(stage: str, done: int, total: int) -> None:
        if stage not in bars or done <= last[stage]:
            bars[stage] = Progress(stage, total, unit)
        bars[stage].update(done)
        last[stage] = done

    return update
