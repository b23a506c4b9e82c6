"""Declared ranges of config fields, checked where configs are made from user input."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import pytest

from app.cli import main
from models.ranges import Range, check_config, config_problems


@dataclass(frozen=True)
class Example:
    size: Annotated[int, Range(32, 2048)] = 256
    rate: Annotated[float, Range(0, 1, above=True)] | None = None
    pair: tuple[Annotated[int, Range(8)], Annotated[int, Range(8)]] = (64, 64)
    free: float = 1.0


def test_ranges_hand_worked():
    assert config_problems(Example()) == []
    assert config_problems(Example(size=31)) == ["--size 31: must be at least 32 and at most 2048"]
    assert config_problems(Example(rate=0.0)) == ["--rate 0: must be above 0 and at most 1"]
    assert config_problems(Example(rate=1.0, pair=(64, 4))) == ["--pair 4: must be at least 8"]
    assert config_problems(Example(free=float("nan"))) == ["--free nan: must be a finite number"]
    assert config_problems(Example(rate=float("inf"))) == ["--rate inf: must be a finite number"]
    with pytest.raises(ValueError, match="--size 4096"):
        check_config(Example(size=4096))


@pytest.mark.parametrize("argv", [
    ["train", "x", "--frames-per-step", "0"], ["train", "x", "--lr", "nan"], ["train", "x", "--steps", "-5"],
    ["train", "x", "--rays-per-step", "0"], ["track", "v.mp4", "--out", "o", "--fps", "0"],
    ["turntable", "a", "--fps", "0"], ["turntable", "a", "--zoom", "0"], ["turntable", "a", "--zoom", "-1"],
    ["render", "a", "--size", "0"], ["render", "a", "--size", "-8"], ["render", "a", "--yaw-deg", "nan"],
    ["preview", "--yaw-deg", "inf"], ["synth", "--size", "8"]])
def test_bad_options_are_one_line_and_exit_2(argv, capsys):
    """Checked when the options are parsed, before any file is read (the avatar 'a' does not exist)."""
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and argv[-2] in err[0], err
