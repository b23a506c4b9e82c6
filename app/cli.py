"""`avatar-studio`: one entry point, a subcommand per task (docs/commands.md); options come from config dataclasses.

Exit status 0 on success, 2 on bad arguments or input files (one line naming the file and the problem),
1 on anything else.
"""

from __future__ import annotations

import argparse
import difflib
import os
import shutil
import sys
import textwrap
import traceback
from pathlib import Path
from typing import NoReturn

if sys.argv[1:2] == ["studio"]:
    # The window shares two cores with rendering threads: idle OpenMP threads must sleep, not spin (read by
    # the OpenMP runtime when torch loads, so before the imports below).
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from app.commands import COMMANDS, Command
from app.config_cli import add_config_arguments, config_from_args

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"


class Parser(argparse.ArgumentParser):
    """argparse's parser with its errors on one line, `PROG: error: WHAT` (the usage is in --help)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n")


def version() -> str:
    """The installed package's version; in a checkout that was never installed, pyproject.toml's."""
    import importlib.metadata

    try:
        return importlib.metadata.version("avatar-studio")
    except importlib.metadata.PackageNotFoundError:
        import tomllib

        return tomllib.loads(PYPROJECT.read_text())["project"]["version"]


def command_listing(commands: list[Command], width: int) -> str:
    """Commands and their summaries, a column of names and the summaries wrapped beside it, as argparse lists
    options."""
    column = max(len(c.name) for c in commands) + 2
    return "\n".join(textwrap.fill(c.summary, max(width, column + 20), initial_indent=c.name.ljust(column),
                                   subsequent_indent=" " * column, break_on_hyphens=False) for c in commands)


def build_parser() -> Parser:
    # argparse lists one subparsers action in one section: the two listings are written here, as the groups'
    # descriptions (kept as written: RawDescriptionHelpFormatter), at argparse's width less the sections' indent.
    width = shutil.get_terminal_size().columns - 4
    parser = Parser(prog="avatar-studio", description="Make and drive neural 3D head portraits.",
                    usage="%(prog)s [-h] [--version] COMMAND ...", formatter_class=argparse.RawDescriptionHelpFormatter,
                    epilog="avatar-studio COMMAND --help: the command's options.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    for research in (False, True):
        parser.add_argument_group("research commands" if research else "commands", command_listing(
            [c for c in COMMANDS if c.research == research], width))
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", prog=parser.prog,
                                help=argparse.SUPPRESS)
    for cmd in COMMANDS:
        p = sub.add_parser(cmd.name, description=cmd.summary)
        add_config_arguments(p, cmd.config, cmd.positional)
        p.set_defaults(_command=cmd, _parser=p)
    return parser


def did_you_mean(word: str, choices: list[str]) -> str:
    """" (did you mean X?)" for the closest of the choices, or "".

    >>> did_you_mean("rendr", ["render", "train"]), did_you_mean("--sise", ["--size", "--out"]), did_you_mean("x", [])
    (' (did you mean render?)', ' (did you mean --size?)', '')
    """
    close = difflib.get_close_matches(word, choices, n=1)
    return f" (did you mean {close[0]}?)" if close else ""


def parse(parser: Parser, argv: list[str]) -> argparse.Namespace:
    """The arguments parsed; an unknown command or option is an error on one line naming the closest one."""
    names = [c.name for c in COMMANDS]
    given = next((a for a in argv if not a.startswith("-")), None)  # the top level has no option with a value
    if given is not None and given not in names:
        parser.error(f"unknown command {given}{did_you_mean(given, names)}")
    args, extras = parser.parse_known_args(argv)
    if extras:
        command: Parser = args._parser
        unknown = next((a.partition("=")[0] for a in extras if a.startswith("-")), None)
        if unknown is None:
            command.error(f"unrecognized arguments: {' '.join(extras)}")
        options = [s for a in command._actions for s in a.option_strings if s.startswith("--")]
        command.error(f"unknown option {unknown}{did_you_mean(unknown, options)}")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse(build_parser(), sys.argv[1:] if argv is None else argv)
    cmd = args._command
    code = run_command(cmd, args)
    if cmd.window and code == 0:  # the window opened and closed (bad input returns 2 before it opens)
        end_window_process(code)
    return code


def end_window_process(code: int) -> None:
    """End a process that had the studio's window at once, its output flushed, once every file is written and every
    child has ended: left to the interpreter's shutdown, a native library's thread pool now and then aborts in its
    static destructors ("terminate called without an active exception", exit status -6, in about 1 of 3 runs of
    the live window test, after the studio had written its report and closed)."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def run_command(cmd, args) -> int:
    """The command run on its parsed arguments: its exit status, with one line on stderr for bad input."""
    from app.errors import INPUT_ERRORS, UserInputError  # they import torch: loaded once a command runs
    from models.files import unwritable

    try:
        config = config_from_args(cmd.config, args)
        out = getattr(config, "out", None)
        if isinstance(out, Path) and (why := unwritable(out)):  # before the work, not after it
            raise UserInputError(f"{out}: cannot be written there: {why}")
        return int(cmd.runner()(config) or 0)
    except INPUT_ERRORS as e:
        print(f"avatar-studio {cmd.name}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"avatar-studio {cmd.name}: interrupted", file=sys.stderr)
        return 130
    except OSError as e:
        if e.filename is None:  # not about a path the user gave: the program's failure
            traceback.print_exc()
            return 1
        # An output whose parent is a file, a folder without write permission, a read-only place...
        print(f"avatar-studio {cmd.name}: error: {e.filename}: {e.strerror or e}", file=sys.stderr)
        return 2
    except Exception:
        traceback.print_exc()
        return 1


if __name__ == "__main__":
    sys.exit(main())
