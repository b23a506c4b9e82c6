"""The README and docs/ against the repository: links that lead to files, commands the CLI knows, a README short
enough to read, and a command table that lists every subcommand and no other."""

from __future__ import annotations

import argparse
import importlib.util
import re
import shlex
from functools import cache
from pathlib import Path

import pytest

from app.cli import build_parser

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
PAGES = [README, *sorted((REPO / "docs").glob("*.md"))]
README_MAX_LINES = 240
"""The README stays short: its quick start, commands, pictures and the one table of how it does on real videos (a row
a shared clip, 15 lines)."""

FENCE = re.compile(r"^(```|~~~)")
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
INLINE_CODE = re.compile(r"`[^`\n]*`")
COMMAND = re.compile(r"(?:^|[\s/])avatar-studio\s+(.*)$")
TABLE_NAME = re.compile(r"^\|\s*`([a-z][a-z0-9-]*)`\s*\|")


def _name(page: Path) -> str:
    return str(page.relative_to(REPO))


def _prose(text: str) -> list[str]:
    """The page's lines outside fenced code blocks, inline code removed (a link there is an example, not a link)."""
    lines, fenced = [], False
    for line in text.splitlines():
        if FENCE.match(line.strip()):
            fenced = not fenced
        elif not fenced:
            lines.append(INLINE_CODE.sub("", line))
    return lines


def _code_lines(text: str) -> list[str]:
    """The logical lines of the page's fenced code blocks: backslash continuations joined, comments dropped."""
    lines, fenced, pending = [], False, ""
    for line in text.splitlines():
        if FENCE.match(line.strip()):
            fenced, pending = not fenced, ""
            continue
        if not fenced:
            continue
        line = re.sub(r"(^|\s)#.*$", "", line)  # a shell comment
        if line.rstrip().endswith("\\"):
            pending += line.rstrip()[:-1] + " "
            continue
        lines.append(pending + line)
        pending = ""
    return lines


def _anchors(page: Path) -> set[str]:
    """The fragments GitHub gives the page's headings: lower case, punctuation dropped, spaces as hyphens."""
    headings = [line.lstrip("#").strip() for line in _prose(page.read_text()) if re.match(r"#{1,6} ", line)]
    return {re.sub(r"[^\w\- ]", "", h.lower()).replace(" ", "-") for h in headings}


@cache
def _subcommands() -> dict:
    """Subcommand name -> its argparse parser, from the CLI's own parser."""
    parser = build_parser()
    return dict(next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices)


def _command_calls(text: str) -> list[tuple[str, list[str]]]:
    """Each `avatar-studio COMMAND ...` in the page's code blocks: the command's name and its words after it."""
    calls = []
    for line in _code_lines(text):
        if "..." in line:  # an elided example: its words are not all the command's own
            continue
        for part in re.split(r"&&|\|\||;|\|", line):
            m = COMMAND.search(part)
            if m:
                words = shlex.split(m.group(1))
                if words and not words[0].startswith("-"):  # `avatar-studio --help`: the top level's own
                    calls.append((words[0], words[1:]))
    return calls


def _inline_command_calls(text: str) -> list[tuple[str, list[str]]]:
    """Each `avatar-studio COMMAND ...` in the page's inline code (outside code blocks), a span over a line break
    joined; option brackets and alternatives (`[--size 256]`, `obj|ply`) are read as words."""
    lines, fenced = [], False
    for line in text.splitlines():
        if FENCE.match(line.strip()):
            fenced = not fenced
        elif not fenced:
            lines.append(line)
    calls = []
    for span in re.findall(r"`([^`]*)`", "\n".join(lines)):
        m = COMMAND.search(span.replace("\n", " "))
        if m is None or "..." in span:
            continue
        words = re.sub(r"[\[\]|]", " ", m.group(1)).split()
        # `avatar-studio COMMAND --help`: a placeholder; `avatar-studio --help`: the top level's own option
        if words and not words[0].isupper() and not words[0].startswith("-"):
            calls.append((words[0], words[1:]))
    return calls


def _unknown_options(name: str, words: list[str]) -> list[str]:
    known = _subcommands()[name]._option_string_actions
    return [w for w in words if w.startswith("--") and w.split("=", 1)[0] not in known]


def test_the_pages_exist():
    assert README.is_file()
    assert len(PAGES) > 1, "docs/ holds no pages"


@pytest.mark.parametrize("page", PAGES, ids=_name)
def test_every_relative_link_and_image_leads_to_a_file(page: Path):
    broken = []
    for line in _prose(page.read_text()):
        for target in LINK.findall(line):
            if re.match(r"[a-z][a-z0-9+.-]*:", target):  # a web address
                continue
            path, _, fragment = target.partition("#")
            file = page.parent / path if path else page
            if not file.exists():
                broken.append(target)
            elif fragment and file.suffix == ".md" and fragment not in _anchors(file):
                broken.append(target)
    assert not broken, f"{_name(page)}: links to files or headings that do not exist: {broken}"


@pytest.mark.parametrize("page", PAGES, ids=_name)
def test_every_command_in_a_code_block_is_one_the_cli_knows(page: Path):
    wrong = []
    for name, words in _command_calls(page.read_text()):
        if name not in _subcommands():
            wrong.append(f"no subcommand '{name}'")
        elif bad := _unknown_options(name, words):
            wrong.append(f"avatar-studio {name}: no option {', '.join(bad)}")
    assert not wrong, f"{_name(page)}: {wrong}"


@pytest.mark.parametrize("page", PAGES, ids=_name)
def test_every_command_in_inline_code_is_one_the_cli_knows(page: Path):
    wrong = []
    for name, words in _inline_command_calls(page.read_text()):
        if name not in _subcommands():
            wrong.append(f"no subcommand '{name}'")
        elif bad := _unknown_options(name, words):
            wrong.append(f"avatar-studio {name}: no option {', '.join(bad)}")
    assert not wrong, f"{_name(page)}: {wrong}"


def test_the_command_check_catches_a_wrong_command_and_a_wrong_option():
    text = ("```\n.venv/bin/avatar-studio train DATA --minutes 3 \\\n    --no-such-flag 2 --out AV  # a comment --x\n"
            "avatar-studio no-such-command --out X\nOMP_NUM_THREADS=1 avatar-studio eval AV DATA --split test\n```\n"
            "avatar-studio train DATA --not-in-a-code-block\n")
    calls = _command_calls(text)
    assert [name for name, _ in calls] == ["train", "no-such-command", "eval"]
    assert _unknown_options("train", calls[0][1]) == ["--no-such-flag"]
    assert "no-such-command" not in _subcommands()
    assert _unknown_options("eval", calls[2][1]) == []
    inline = _inline_command_calls("Run `avatar-studio render AV\n[--sise 64]` or `avatar-studio COMMAND --help`.\n")
    assert inline == [("render", ["AV", "--sise", "64"])]
    assert _unknown_options("render", inline[0][1]) == ["--sise"]


def test_heading_fragments_are_the_ones_github_makes():
    page = REPO / "docs" / "models.md"
    assert "displays-march-in-c" in _anchors(page)
    assert "1-open-the-demo" in _anchors(README)


def test_the_readme_is_short():
    lines = len(README.read_text().splitlines())
    assert lines <= README_MAX_LINES, f"README.md has {lines} lines; keep it under {README_MAX_LINES}"


def _clips_table():
    spec = importlib.util.spec_from_file_location("clips_table", REPO / "scripts" / "clips_table.py")
    clips_table = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(clips_table)
    return clips_table


def test_the_readme_real_video_table_is_the_benchmarks_results():
    """The README's figures on real videos are the ones benchmarks/results holds (scripts/clips_table.py writes the
    table from them): a figure changed by hand, or a run kept without its table, fails here."""
    clips_table = _clips_table()
    results = REPO / "benchmarks" / "results"
    lines = clips_table.table(clips_table.rows_by_clip(results / "clips_6min.json"),
                              clips_table.rows_by_clip(results / "clips_30min.json"))
    assert len(lines) == 2 + 13, "a row a shared clip"
    readme = README.read_text().splitlines()
    assert lines[0] in readme, "the README has no table of the shared clips"
    start = readme.index(lines[0])
    assert readme[start:start + len(lines)] == lines, "the README's table is not scripts/clips_table.py's"


def test_the_minutes_table_in_the_results_is_the_benchmarks_results():
    """docs/results.md's table of 3, 10 and 30 minutes is the one scripts/clips_table.py --minutes writes from
    benchmarks/results (every clip with a 10 and a 30-minute figure; five with a 3-minute one too)."""
    clips_table = _clips_table()
    results = REPO / "benchmarks" / "results"
    runs = {m: clips_table.rows_by_clip(results / f"clips_{m}min.json") for m in (3, 10, 30)}
    lines = clips_table.minutes_table(runs)
    cells = [line.strip("| ").split(" | ") for line in lines[2:]]
    assert len(cells) >= 5 and all("-" not in (c[2], c[3], c[4]) for c in cells), lines
    assert sum("-" not in c for c in cells) >= 5, lines
    page = (REPO / "docs" / "results.md").read_text().splitlines()
    start = page.index(lines[0])
    assert page[start:start + len(lines)] == lines, "docs/results.md's table is not scripts/clips_table.py's"


def test_the_readme_command_table_lists_exactly_the_subcommands():
    listed = [m.group(1) for line in README.read_text().splitlines() if (m := TABLE_NAME.match(line))]
    assert len(listed) == len(set(listed)), f"a command listed twice: {listed}"
    assert set(listed) == set(_subcommands()), (
        f"missing from the README's table: {sorted(set(_subcommands()) - set(listed))}; "
        f"listed but not commands: {sorted(set(listed) - set(_subcommands()))}")


OUTSIDE_CITATION = re.compile(r"\bDESIGN\s+\d|\bDESIGN\.md\b|\bpapers?\s+00\d|shared/papers")
"""A citation of a file the repository does not hold: the design file's numbered sections, the numbered papers."""


def test_code_and_docs_cite_the_repository_and_papers_by_name():
    """Comments, help and docs cite the repository's own docs and the papers by their names (docs/models.md lists
    them with their titles), never a design file's sections or a numbered paper that only this project's machines
    have."""
    assert OUTSIDE_CITATION.search("a sampler starts here (DESIGN 5)") and OUTSIDE_CITATION.search("(paper 002)")
    assert not OUTSIDE_CITATION.search("(Cao et al. 2022, Eq. 1; docs/architecture.md)")
    files = [*PAGES, *(p for d in ("app", "models", "render", "shaders", "scripts", "benchmarks", "tests", "web")
                      for p in sorted((REPO / d).rglob("*")) if p.suffix in (".py", ".glsl", ".sh", ".js", ".html"))]
    found = [f"{p.relative_to(REPO)}:{n}" for p in files if p != Path(__file__)
             for n, line in enumerate(p.read_text().splitlines(), 1) if OUTSIDE_CITATION.search(line)]
    assert found == []
