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

# Modules holding the longest tests (measured on 2 cores: the soak 100 s of paced DDS, the online
# core's change tests 30-50 s, the node's 15-60 s), run first and each kept whole: with
# ``pytest -n 2 --maxschedchunk 1`` (make test) each worker takes the next test when it is free, so
# the short tests come last and the two workers end together. The soak runs beside the online
# core's tests (compute), not beside the node's (paced by their own clocks). Within a module its
# slow tests come first; its module-scoped fixtures are built at most once per worker.
LONGEST_FIRST = (
    "test_soak.py",
    "test_online.py",
    "test_node.py",
    "test_bench.py",
    "test_colcon.py",
    "test_peers.py",
    "test_hidden_effects.py",
    "test_online_diagnosis.py",
    "test_cli.py",
    "test_vessels.py",
    "test_fleet.py",
    "test_diagnose.py",
    "test_replay.py",
)


def pytest_collection_modifyitems(items):
    """Longest modules first (LONGEST_FIRST, then the others as collected), slow tests first in each."""
    first_seen = {}
    for index, item in enumerate(items):
        first_seen.setdefault(item.path.name, index)

    def rank(item):
        name = item.path.name
        module = LONGEST_FIRST.index(name) if name in LONGEST_FIRST else len(LONGEST_FIRST)
        return module, first_seen[name], item.get_closest_marker("slow") is None

    items.sort(key=rank)


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
