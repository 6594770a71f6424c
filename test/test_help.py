"""Every default a ``--help`` shows is the value the command runs with, from the one definition the
code uses; help points to no file the repository lacks."""

import argparse
import re
from pathlib import Path

import pytest

from ship_ident.cli import build_parser
from ship_ident.commands import simulate, threedof
from ship_ident.diagnosis import diagnose
from ship_ident.estimators import DEFAULT_METHOD
from ship_ident.online.config import OnlineConfig

ROOT = Path(__file__).resolve().parent.parent
PARSER = build_parser()
COMMANDS = next(a for a in PARSER._actions if isinstance(a, argparse._SubParsersAction)).choices
SHOWN = re.compile(r"\(default:? ([^;)]*)")


def help_text(parser, action) -> str:
    return " ".join(parser._get_formatter()._expand_help(action).split()) if action.help else ""


def minimal_arguments(parser) -> list[str]:
    """The required arguments of a command, each given its first choice or a placeholder."""
    arguments = []
    for action in parser._actions:
        if action.required:
            value = next(iter(action.choices)) if action.choices else "x"
            arguments += [value] if not action.option_strings else [action.option_strings[0], value]
    return arguments


def as_shown(value) -> str:
    """How a default reads in help text: none, off, the names joined by commas, or the value."""
    if value in ("", (), None):
        return "none"
    if value is False:
        return "off"
    if isinstance(value, (tuple, list)):
        return ",".join(value)
    return str(value)


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_default_shown_is_the_value_the_command_runs_with(command):
    parser = COMMANDS[command]
    parsed = parser.parse_args(minimal_arguments(parser))
    checked = 0
    for action in parser._actions:
        shown = SHOWN.search(help_text(parser, action))
        value = getattr(parsed, action.dest, None)
        if shown is None or value is None:  # None: decided at run time, said in words (checked below)
            continue
        text = shown.group(1).strip()
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            assert float(text) == pytest.approx(value, rel=1e-5), (command, action.dest, text, value)
        else:
            assert text == as_shown(value), (command, action.dest, text, value)
        checked += 1
    assert checked or command == "bench"


def shown_for(command: str, dest: str) -> str:
    parser = COMMANDS[command]
    return help_text(parser, next(a for a in parser._actions if a.dest == dest))


def test_the_defaults_that_matter_are_the_code_s_definitions():
    assert "(default rlssvm+oe)" in shown_for("diagnose", "method") and diagnose.DEFAULT_METHOD == "rlssvm+oe"
    assert f"(default {DEFAULT_METHOD};" in shown_for("identify", "method")
    assert f"with --model 3dof: tlssvm or ols, default {threedof.METHODS[0]})" in shown_for("identify", "method")
    replay_effects = ",".join(OnlineConfig().effects)
    assert f"(default: {replay_effects})" in shown_for("replay", "effects") and replay_effects
    assert f"(default {OnlineConfig().method})" in shown_for("replay", "method")
    assert "(default: none)" in shown_for("identify", "effects")
    vessel = shown_for("simulate", "vessel")
    assert f"(default {simulate.DEFAULT_VESSEL}; with --model 3dof: {threedof.DEFAULT_VESSEL})" in vessel


def test_help_points_to_no_file_outside_the_repository():
    texts = [PARSER.description or ""]
    for parser in COMMANDS.values():
        texts.append(parser.description or "")
        texts += [help_text(parser, action) for action in parser._actions]
    named = {name for text in texts for name in re.findall(r"[\w./-]+\.(?:md|py|yaml)\b", text)}
    assert named, "no file named in any help: the check checks nothing"
    assert [name for name in named if not (ROOT / name).exists()] == []


def test_the_command_list_loads_no_command_and_no_numeric_core():
    """``ship-ident --help`` (and a command's usage error) lists every command by its summary without
    importing the command modules, the estimators or numba: a fresh process answers at once."""
    import subprocess
    import sys

    probe = (
        "import sys\n"
        "from ship_ident.cli import main\n"
        "try:\n"
        "    main(['--help'])\n"
        "except SystemExit:\n"
        "    pass\n"
        "heavy = ('ship_ident.commands.', 'ship_ident.estimators', 'numba')\n"
        "print(sorted(m for m in sys.modules if m.startswith(heavy)))\n"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "[]"
    assert all(f"    {name}  " in done.stdout for name in COMMANDS)
