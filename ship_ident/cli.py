"""``ship-ident``: the command-line door onto the numeric core.

Each subcommand lives in ``ship_ident/commands/<name>.py`` and provides
``add_parser(subparsers)`` (which sets ``func``) and its run function. Every
error a user can cause ends in one line on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

# The fits solve small systems (a few columns): a BLAS thread pool only costs CPU.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from .commands import SUMMARIES
from .errors import CommandError

COMMANDS = tuple(SUMMARIES)

EXIT_USAGE = 2


class OneLineParser(argparse.ArgumentParser):
    """argparse whose usage errors (unknown option, a value of the wrong type or choice) are one
    line, ``prog: error: message (see prog --help)``, exit code 2; subcommand parsers inherit it."""

    def error(self, message):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser(commands=COMMANDS) -> argparse.ArgumentParser:
    """The parser with every subcommand of ``commands`` in full and the others by name and summary
    (``SUMMARIES``): a command's module, and the numeric core it imports, load only when it runs."""
    parser = OneLineParser(
        prog="ship-ident",
        description="Identify USV steering models (Nomoto) from bags and CSV files, replay bags, "
        "diagnose missing physics.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        if name in commands:
            importlib.import_module(f"ship_ident.commands.{name}").add_parser(sub)
        else:
            sub.add_parser(name, help=SUMMARIES[name])
    return parser


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser(commands=tuple(argv[:1])).parse_args(argv)

    from .estimators import MethodError  # the errors a user can cause: after --help, which needs none
    from .model.dataset import DataError
    from .model.structure import StructureError

    try:
        return int(args.func(args) or 0)
    except (
        CommandError,
        DataError,
        StructureError,
        MethodError,
        FileNotFoundError,
        PermissionError,
        IsADirectoryError,
        ValueError,
    ) as exc:
        print(f"ship-ident {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:
        sys.stderr.close()  # the reader went away (e.g. `| head`): nothing more to say
        return 0
    except KeyboardInterrupt:
        print(f"ship-ident {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    from ship_ident.cli import main as installed_main  # one module object, so errors match

    sys.exit(installed_main())
