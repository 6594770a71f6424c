"""User-facing errors of the command line: printed as one line, exit code 2."""


class CommandError(Exception):
    """A user-facing failure: printed as one line, exit code 2."""
