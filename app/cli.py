"""`avatar-studio`: one entry point, a subcommand per task (DESIGN 7); options come from config dataclasses.

Exit status 0 on success, 2 on bad arguments or input files (one line naming the file and the problem),
1 on anything else.
"""

from __future__ import annotations

import argparse
import os
import sys
import traceback

if sys.argv[1:2] == ["studio"]:
    # The window shares two cores with rendering threads: idle OpenMP threads must sleep, not spin (read by
    # the OpenMP runtime when torch loads, so before the imports below).
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from app.commands import COMMANDS
from app.config_cli import add_config_arguments, config_from_args
from app.errors import INPUT_ERRORS


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="avatar-studio", description="Make and drive neural 3D head portraits.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for cmd in COMMANDS:
        p = sub.add_parser(cmd.name, help=cmd.summary, description=cmd.summary)
        add_config_arguments(p, cmd.config, cmd.positional)
        p.set_defaults(_command=cmd)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    cmd = args._command
    try:
        config = config_from_args(cmd.config, args)
        return int(cmd.run(config) or 0)
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
