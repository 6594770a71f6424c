"""Helpers shared by the benchmarks: relative errors, table formatting, the machine a timing ran on."""

from __future__ import annotations

import os
import platform
from pathlib import Path

import numpy as np

CPU_INFO = Path("/proc/cpuinfo")


def processor_name() -> str:
    """The processor's model name: Linux's ``/proc/cpuinfo``, else what ``platform`` reports."""
    try:
        for line in CPU_INFO.read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine() -> dict:
    """The machine a timing is measured on: CPUs, processor model, the load average over the last
    minute and the BLAS threads. Timings move by half and more between processors (a refit loop
    on an AMD EPYC took 1.6 times its time on a Xeon), so every timing says where it ran."""
    return {
        "cpus": os.cpu_count(),
        "processor": processor_name(),
        "load_average": os.getloadavg()[0],
        "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "unset"),
    }


def machine_line(m: dict) -> str:
    """``machine()`` in a few words: '2 CPUs (AMD EPYC), load average 0.3'."""
    return f"{m['cpus']} CPUs ({m['processor']}), load average {m['load_average']:.1f}"


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
