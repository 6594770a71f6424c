"""Helpers shared by the benchmarks: relative errors, table formatting."""

from __future__ import annotations

import numpy as np


def relative_error_percent(value: float, truth: float) -> float:
    return float(100.0 * (value - truth) / truth) if truth != 0 else float("nan")


def table(header: list[str], rows: list[list], title: str = "") -> str:
    """A plain-text table (Markdown pipe syntax, so it pastes into the README)."""

    def cell(v):
        if isinstance(v, float):
            return "nan" if not np.isfinite(v) else f"{v:.4g}" if abs(v) >= 1e-3 or v == 0 else f"{v:.2e}"
        return str(v)

    lines = ([title, ""] if title else []) + [
        "| " + " | ".join(header) + " |",
        "|" + "|".join("---" for _ in header) + "|",
    ]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)
