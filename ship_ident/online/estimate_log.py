"""The estimate log: accepted estimates of the online identifier as rotated JSON-lines files.

The node's only file writer, kept apart from the identifier (which knows no files).
"""

from __future__ import annotations

from pathlib import Path

from ..io.jsonio import dumps_json
from .config import ESTIMATE_LOG_MIN_BYTES, ConfigError


class EstimateLog:
    """Accepted estimates as JSON lines in ``directory/estimates.jsonl``, rotated by size.

    A line that would take the file past ``max_bytes`` first moves it to
    ``estimates.jsonl.1`` (older files shift to ``.2`` ... up to ``backups``;
    the oldest is deleted). Each line is written and flushed at once and the
    file is appended to across restarts, so a trip's history survives them.
    """

    FILE_NAME = "estimates.jsonl"

    def __init__(self, directory, max_bytes: int = 10_000_000, backups: int = 5):
        if max_bytes < ESTIMATE_LOG_MIN_BYTES or backups < 0:
            raise ConfigError(
                f"log_max_bytes must be >= {ESTIMATE_LOG_MIN_BYTES} and log_backups >= 0, got {max_bytes} and {backups}"
            )
        self.path = Path(directory) / self.FILE_NAME
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with self.path.open("ab"):
                pass
        except OSError as exc:
            raise ConfigError(
                f"cannot write the estimate log {self.path}: {exc.strerror or exc}; choose another log_directory"
            ) from None
        self.max_bytes, self.backups = max_bytes, backups

    def write(self, record: dict) -> None:
        """Append one record as a line of strict JSON (NaN as null), rotating the file when it is full.

        Parameters
        ----------
        record : dict
            The accepted estimate's record (``RefitRecord.to_json``).

        Raises
        ------
        OSError
            When the disk refuses (full, directory removed).
        """
        line = (dumps_json(record) + "\n").encode()
        size = self.path.stat().st_size if self.path.exists() else 0
        if size and size + len(line) > self.max_bytes:
            self._rotate()
        with self.path.open("ab") as f:
            f.write(line)

    def _rotate(self) -> None:
        name = self.path.name
        for k in range(self.backups, 0, -1):
            older = self.path if k == 1 else self.path.with_name(f"{name}.{k - 1}")
            if older.exists():
                older.replace(self.path.with_name(f"{name}.{k}"))
        self.path.unlink(missing_ok=True)
