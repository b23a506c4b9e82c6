"""The command line a newcomer meets first: `--help` at once (no torch loaded to build it), `--version`, one line with
the closest name for a mistyped command or option, the research commands listed apart, and help text on every
option."""

from __future__ import annotations

import re
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest

from app.cli import build_parser, main
from app.commands import COMMANDS
from tests.conftest import REPO

SCRIPT = Path(sys.executable).parent / "avatar-studio"
CLI = [str(SCRIPT)] if SCRIPT.is_file() else [sys.executable, "-m", "app.cli"]  # what a user runs, where installed


def best_seconds(args: list[str], runs: int = 3) -> float:
    """The fastest of `runs` runs of the command (the others may have waited for a busy machine)."""
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        r = subprocess.run([*CLI, *args], cwd=REPO, capture_output=True, text=True, timeout=60)
        times.append(time.perf_counter() - t0)
        assert r.returncode == 0, r.stderr
    return min(times)


@pytest.mark.parametrize("args", [["--help"], ["render", "--help"], ["turntable", "--help"], ["train", "--help"],
                                  ["reenact", "--help"], ["studio", "--help"]], ids=" ".join)
def test_help_takes_under_half_a_second(args):
    seconds = best_seconds(args)
    assert seconds < 0.5, f"avatar-studio {' '.join(args)}: {seconds:.2f} s"


def test_building_the_parser_loads_no_torch():
    """The heavy modules load when a command runs, never to build the command line (1.4 s of torch alone)."""
    heavy = ("torch", "cv2", "mediapipe", "moderngl", "imgui_bundle")
    r = subprocess.run([sys.executable, "-c", "import sys, app.cli; app.cli.build_parser(); "
                        f"print(' '.join(m for m in {heavy!r} if m in sys.modules))"], cwd=REPO, capture_output=True,
                       text=True, timeout=60, check=True)
    assert r.stdout.strip() == "", f"building the parser imported {r.stdout.strip()}"


def test_version_is_the_package_version(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["version"]
    assert capsys.readouterr().out == f"avatar-studio {project}\n"


@pytest.mark.parametrize(("argv", "line"), [
    (["rendr"], "avatar-studio: error: unknown command rendr (did you mean render?)"),
    (["render", "AV", "--sise", "64"], "avatar-studio render: error: unknown option --sise (did you mean --size?)"),
    (["turntable", "AV", "--fames=4"],
     "avatar-studio turntable: error: unknown option --fames (did you mean --frames?)"),
    (["render", "AV", "--zzzzzz"], "avatar-studio render: error: unknown option --zzzzzz"),  # nothing close
], ids=["command", "option", "option=value", "no close match"])
def test_a_typo_is_one_line_with_the_closest_name(argv, line, capsys):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    assert capsys.readouterr().err == line + "\n"


def test_research_commands_are_listed_apart(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    everyday, research = capsys.readouterr().out.split("\nresearch commands:\n")
    listed = lambda text: set(re.findall(r"^  ([a-z][\w-]*)  ", text, re.M))
    assert listed(research) == {"corpus", "prior-train", "bench"}
    assert listed(everyday) >= {c.name for c in COMMANDS if not c.research} >= {"render", "train", "studio"}
    assert not listed(everyday) & listed(research)


@pytest.mark.parametrize("name", [c.name for c in COMMANDS])
def test_every_option_says_what_it_is(name):
    """Each option's help is its field's docstring: none may be empty or only the default, nor show an empty
    default."""
    sub = next(a for a in build_parser()._actions if a.dest == "command").choices[name]
    for action in sub._actions:
        text = action.help or ""
        assert "(default: )" not in text, (name, action.option_strings)
        assert re.sub(r"\(default: [^)]*\)$", "", text).strip(), f"{name} {action.option_strings or action.dest}"


def test_model_choices_are_the_registrys_models():
    """`train --model` reads its choices without torch (models/avatars/names.py): they are the registry's."""
    import typing

    from models.avatars.names import ModelName
    from models.avatars.registry import AVATARS

    assert typing.get_args(ModelName) == tuple(AVATARS)


@pytest.mark.parametrize("argv", [["render", "resources/demo_avatar", "--out", "{place}/x.png"],
                                  ["turntable", "resources/demo_avatar", "--out", "{place}/t.mp4"],
                                  ["export-mesh", "resources/demo_avatar", "--out", "{place}/a.ply"],
                                  ["preview", "--out", "{place}/p.png"],
                                  ["synth", "--out", "{place}/capture"],
                                  ["track", "{video}", "--out", "{place}/dataset"],
                                  ["train", "{video}", "--out", "{place}/avatar"]], ids=lambda a: a[0])
def test_an_out_that_cannot_be_written_is_named_before_any_work(argv, tmp_path, capsys):
    """Exit 2 and one line with the user's --out, at once (track found out after its minutes of fitting), never the
    program's temporary (render said '/ro/.x.png.l3j_u2l6.tmp: Permission denied'). As root, whom a read-only
    folder does not stop, the place is under a regular file."""
    import os

    if os.geteuid() != 0:
        place = tmp_path / "ro"
        place.mkdir(mode=0o555)
        why = f"no permission to write in {place}"
    else:
        place = tmp_path / "plain_file"
        place.write_text("not a folder")
        why = f"{place} is a file, not a folder"
    argv = [a.format(place=place, video=REPO / "README.md") for a in argv]
    t0 = time.perf_counter()
    assert main(argv) == 2
    out = Path(argv[argv.index("--out") + 1])
    assert capsys.readouterr().err.splitlines() == [f"avatar-studio {argv[0]}: error: {out}: cannot be written "
                                                    f"there: {why}"]
    assert time.perf_counter() - t0 < 5.0  # no avatar loaded, no video read
