"""Shared fixtures: the ``ship-ident`` command as a subprocess and a noise-free simulation."""

import os
import subprocess
import sys
from pathlib import Path

# As in the node: the fits solve systems of a few columns, where a BLAS thread pool only burns the
# CPU that the other test worker needs (the online diagnosis tests took three times as long).
# Set before numpy loads; subprocesses inherit it.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import pytest  # noqa: E402

from ship_ident.simulator import simulate  # noqa: E402

SHIP_IDENT = Path(sys.executable).parent / "ship-ident"


@pytest.fixture(scope="session")
def ship_ident_cli():
    """``run(*args)``: ``ship-ident ARGS`` as a subprocess with a copy of os.environ (ROS_ON_PIP.md)."""

    def run(*args, cwd=None) -> subprocess.CompletedProcess:
        return subprocess.run(
            [str(SHIP_IDENT), *map(str, args)],
            capture_output=True,
            text=True,
            cwd=cwd,
            env=dict(os.environ),
            timeout=300,
        )

    return run


@pytest.fixture(scope="session")
def clean_nomoto2():
    """Noise-free nomoto2 (no effects) zigzag of the seed001 vessel, 300 s at 10 Hz."""
    return simulate("zigzag20", "seed001", effects=(), duration=300.0, noise=0.0, seed=3)
