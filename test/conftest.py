"""Shared fixtures: the ``ship-ident`` command as a subprocess and a noise-free simulation."""

import fcntl
import os
import shutil
import subprocess
import sys
from pathlib import Path

# As in the node: the fits solve systems of a few columns, where a BLAS thread pool only burns the
# CPU that the other test worker needs (the online diagnosis tests took three times as long).
# Set before numpy loads; subprocesses inherit it.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import pytest  # noqa: E402

from ship_ident.model.simulator import simulate  # noqa: E402

SHIP_IDENT = Path(sys.executable).parent / "ship-ident"

# The longest tests and the modules holding them, run first: with ``pytest -n 2 --maxschedchunk 1``
# each worker takes the next test when it is free, so the short tests come last and the two workers
# end together. ``make test`` runs the tests that start ROS nodes (marker ``node``: soak, node,
# colcon, onboard-steady; paced by their clocks, 4-111 s each, mostly waiting) in a pytest of their
# own beside the others, each run in this order. Seconds in brackets (wall for those, CPU for the
# computing tests; the node tests' measured at load average 7, the others' beside a bench). Within a module its
# slow tests come first; its module-scoped fixtures are built at most once per worker (once_per_run:
# once for all workers).
LONGEST_FIRST = (
    "test_soak.py",  # [58] 5 simulated minutes at 6x real time
    "test_node.py::test_a_change_found_between_refits_is_followed_by_the_node",  # [56] 280 s at 10x, 2.5x late
    "test_node.py::test_node_converges_to_truth_and_matches_replay",  # [51] 300 s at 10x, then replay
    "test_bench.py::test_onboard_steady_quick_raises_no_missing_effect_over_dds",  # [51] 5 min at 8x
    "test_node.py::test_diagnosis_names_a_hidden_gyro_bias_and_the_error_falls_once_it_is_added",  # [41]
    "test_node.py",  # [18 .. 4]
    "test_colcon.py",  # [44] one build, three tests
    "test_bench.py::test_onboard_diagnosis_quick_names_a_hidden_rudder_offset_once",  # [40]
    "test_hidden_effects.py::test_nothing_hidden_on_a_slow_ship_is_not_a_missing_effect",  # [56]
    # [45]
    "test_online_diagnosis.py::test_a_quick_boat_whose_yaw_damping_grows_with_the_cube_of_the_turn_rate_is_named_once_and_fixed",
    "test_hidden_effects.py::test_a_cubic_damping_on_a_course_stable_ship_is_named_before_the_quadratic_law",  # [38]
    "test_diagnose.py::test_a_slow_ship_with_quadratic_damping_keeps_its_fast_pole_where_the_valley_cost_rises",  # [27]
    "test_mmg.py::test_a_course_stable_tanker_whose_cubic_damping_shows_on_its_first_order_hull_is_missing",  # [17]
    # [15]
    "test_hidden_effects.py::test_a_rudder_delay_half_the_time_constant_on_a_usv_is_found_where_the_fit_without_it_sees_no_hull",
    "test_online_diagnosis.py::test_a_hidden_wind_is_named_added_by_itself_and_the_held_out_error_halves",  # [15]
    "test_diagnose.py::test_a_usv_with_a_rudder_offset_in_a_wind_is_told_both_are_missing_together",  # [14]
    "test_warmup.py",  # [10] a first start in a fresh cache, as a subprocess
    "test_diagnose.py::test_two_hidden_effects_are_solved_in_two_rounds",  # [9]
    "test_diagnose.py::test_a_usv_with_a_gyro_bias_in_a_wind_is_told_both_are_missing_together",  # [8]
    "test_vessels.py::test_bench_vessels_fixed_seed_sample_against_the_truth",  # [8]
    "test_online_diagnosis.py::test_nothing_hidden_raises_no_missing_effect_in_a_15_minute_trip",  # [8]
    "test_peers.py::test_tracking_recovers_within_a_window_and_the_peers_track",  # [7 of its fixture]
    "test_online.py::test_a_changed_vessel_restarts_the_window",  # [6]
    "test_fleet.py::test_local_dask_cluster_gives_the_same_rows",  # [3.5 + 4.5 of its fixture]
    "test_online.py",  # [11 .. 1]
    "test_replay.py::test_kvlcc2_zigzag_uncertainty_covers_the_scatter_and_is_not_saturated",  # [11]
    "test_cli.py",  # [10, 9 ..] subprocesses; its module fixtures are shared by most of its tests
    "test_bench.py",
    "test_peers.py",
    "test_hidden_effects.py",
    "test_online_diagnosis.py",
    "test_diagnose.py",
    "test_replay.py",
    "test_vessels.py",
    "test_fleet.py",
)


def _rank_in_longest_first(nodeid: str) -> int:
    """Index of the first LONGEST_FIRST entry naming the test (``module::test``, with or without its
    parameters) or its module; len(LONGEST_FIRST) for the others."""
    test = nodeid.rsplit("/", 1)[-1]
    module, _, name = test.partition("::")
    for index, entry in enumerate(LONGEST_FIRST):
        if entry == module or entry == f"{module}::{name.split('[')[0]}":
            return index
    return len(LONGEST_FIRST)


def pytest_collection_modifyitems(items):
    """Longest first (LONGEST_FIRST, then the others as collected), slow tests first in each module."""
    first_seen = {}
    for index, item in enumerate(items):
        first_seen.setdefault(item.path.name, index)

    def rank(item):
        return _rank_in_longest_first(item.nodeid), first_seen[item.path.name], item.get_closest_marker("slow") is None

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


@pytest.fixture(scope="session")
def run_folder(tmp_path_factory, worker_id) -> Path:
    """A folder the test workers of this run share (the run's own folder without xdist)."""
    own = tmp_path_factory.getbasetemp()
    return own if worker_id == "master" else own.parent


def once_per_run(run_folder: Path, name: str, build) -> Path:
    """``run_folder / name``, made by ``build(folder)`` in the first test worker that needs it; the
    others wait for it under a lock and use it (a build that failed is tried again)."""
    folder = run_folder / name
    with open(run_folder / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (run_folder / f"{name}.built").is_file():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir()
            build(folder)
            (run_folder / f"{name}.built").touch()
    return folder
