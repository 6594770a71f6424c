"""The documentation says what the product is and does: README.md within a newcomer's reach, its
commands true to the CLI and the Makefile, no project history in README.md or docs/, and no code
comment citing a bench seed as its reason (a comment states the physical rule; the case that
proves it is a test)."""

import argparse
import ast
import io
import re
import shlex
import tokenize
from pathlib import Path

import pytest

from ship_ident.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = sorted((ROOT / "docs").glob("*.md"))
MAX_README_LINES = 250
MAX_README_LINE_CHARS = 400
# A bench seed in a comment: a seed, draw or case followed by its number (6+ digits), or any bare
# number of 9-10 digits (bench seeds are drawn below 2^32)
SEED_CITATION = re.compile(r"\b(seed|draw|case)s?\b\D{0,30}\d{6,}|\b\d{9,10}\b", re.IGNORECASE)
FENCE = re.compile(r"^```(\w*)\s*$")
INLINE_CODE = re.compile(r"`([^`\n]+)`")


def readme_lines() -> list[str]:
    return README.read_text(encoding="utf-8").splitlines()


def test_readme_is_short_with_no_overlong_line():
    lines = readme_lines()
    assert len(lines) <= MAX_README_LINES, f"README.md has {len(lines)} lines"
    long = [(n, len(line)) for n, line in enumerate(lines, 1) if len(line) > MAX_README_LINE_CHARS]
    assert not long, f"README.md lines over {MAX_README_LINE_CHARS} characters (line, length): {long}"


@pytest.mark.parametrize("path", [README, *DOCS], ids=lambda p: p.name)
def test_no_project_history_in_the_documentation(path):
    """The word a lab notebook uses for a day's work has no meaning for a user."""
    hits = [n for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1) if "session" in line.lower()]
    assert not hits, f"{path.name}: 'session' on lines {hits}"


def test_readme_links_and_pictures_exist():
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", README.read_text(encoding="utf-8"))
    local = [t for t in targets if "://" not in t]
    assert local, "README.md links to no file of the repository"
    missing = [t for t in local if not (ROOT / t).exists()]
    assert not missing, f"README.md links to missing files: {missing}"


def readme_commands() -> list[str]:
    """Every shell command of README.md's code blocks (``text`` blocks are output, not commands;
    continuation lines joined) and of its tables' inline code, split at ``&&``, ``;`` and ``|``."""
    commands, block, language = [], None, ""
    text = README.read_text(encoding="utf-8")
    for line in text.splitlines():
        fence = FENCE.match(line.strip())
        if fence:
            if block is None:
                block, language = [], fence.group(1)
            else:
                if language != "text":
                    commands += "\n".join(block).replace("\\\n", " ").splitlines()
                block = None
            continue
        if block is not None:
            block.append(line)
        elif line.startswith("|"):  # a table's command column; prose may name a command without its arguments
            commands += INLINE_CODE.findall(line)
    pieces = []
    for command in commands:
        command = re.sub(r"(^|\s)#.*$", "", command)  # a comment, not an argument
        pieces += [p.strip() for p in re.split(r"&&|;|\|", command) if p.strip()]
    return pieces


def arguments(command: str) -> list[str]:
    return shlex.split(command, comments=True)


def make_targets() -> set:
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    return set(re.findall(r"^([A-Za-z][\w-]*)\s*:(?!=)", makefile, re.MULTILINE))


def test_readme_shows_the_cli_and_make_commands():
    words = [arguments(c)[0] for c in readme_commands() if arguments(c)]
    assert words.count("ship-ident") >= 5 and "make" in words


@pytest.mark.parametrize(
    "command", [c for c in readme_commands() if c.startswith(("ship-ident ", "python -m ship_ident.cli "))]
)
def test_readme_cli_command_parses(command, capsys):
    """The subcommand and every option of the command exist and take the values given."""
    argv = arguments(command)
    argv = argv[1:] if argv[0] == "ship-ident" else argv[3:]
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit:
        pytest.fail(f"{command!r} does not parse: {capsys.readouterr().err.strip()}")
    assert callable(args.func)
    subcommands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    known = subcommands.choices[args.command]._option_string_actions
    abbreviated = [a.split("=")[0] for a in argv if a.startswith("-") and a.split("=")[0] not in known]
    assert not abbreviated, f"{command!r}: options written in part (argparse accepts a prefix): {abbreviated}"


@pytest.mark.parametrize("command", [c for c in readme_commands() if c.startswith("make ")])
def test_readme_make_command_is_a_target(command):
    targets = [a for a in arguments(command)[1:] if not a.startswith("-") and "=" not in a]
    assert targets and set(targets) <= make_targets(), f"{command!r}: Makefile targets are {sorted(make_targets())}"


def comments_and_docstrings(path: Path):
    """(line, text) of every comment and docstring of a Python file."""
    source = path.read_text(encoding="utf-8")
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT:
            yield token.start[0], token.string
    for node in ast.walk(ast.parse(source)):
        body = getattr(node, "body", None)
        if isinstance(body, list):
            for statement in body:  # docstrings, also of module attributes (a string after them)
                if isinstance(statement, ast.Expr) and isinstance(statement.value, ast.Constant):
                    if isinstance(statement.value.value, str):
                        yield statement.lineno, statement.value.value


def test_no_comment_cites_a_bench_seed():
    """A rule is stated as physics where it is coded; a bench seed changes meaning whenever the way
    vessels are drawn changes."""
    citations = [
        f"{path.relative_to(ROOT)}:{line}: {SEED_CITATION.search(text).group(0)}"
        for path in sorted((ROOT / "ship_ident").rglob("*.py"))
        for line, text in comments_and_docstrings(path)
        if SEED_CITATION.search(text)
    ]
    assert not citations, "comments citing bench seeds:\n" + "\n".join(citations)


def test_the_seed_citation_pattern_finds_seeds_and_spares_physics():
    assert SEED_CITATION.search("(bench vessels seed 568021594: a USV")
    assert SEED_CITATION.search("draw 1747880332 its interval")
    assert SEED_CITATION.search("seeds 2904823692 and 3796294218")
    assert not SEED_CITATION.search("seed 001's vessel, T1 1.44 s, 6000 samples, 1e-4 rad")
