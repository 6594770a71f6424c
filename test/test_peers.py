"""bench peers: quick accuracy and tracking give sane, real numbers for ours and every peer."""

import math

import numpy as np
import pytest

from ship_ident.bench import benchmarks, peer_experiments, peers
from ship_ident.bench.peer_rendering import OURS_LABEL

pytestmark = pytest.mark.slow  # the peers benchmark's experiments run minutes of simulated data


@pytest.fixture(scope="module")
def accuracy():
    return peer_experiments.accuracy(quick=True)["methods"]


@pytest.fixture(scope="module")
def tracking():
    return peer_experiments.tracking(quick=True)


def test_peers_is_registered_with_plots():
    bench = benchmarks()["peers"]
    assert bench.plots and bench.run is peers.run and bench.render is peers.render


def test_our_accuracy_and_the_peers_give_finite_results(accuracy):
    ours = accuracy[OURS_LABEL]["quantities"]
    assert ours["K"]["rms_percent"] < 1.0
    assert ours["T1"]["rms_percent"] < 3.0
    assert ours["delta_r"]["rms_percent"] < 5.0
    for name in ("rls", "ukf (filterpy)", "lssvm-dual (seed)"):
        assert all(math.isfinite(q["rms_percent"]) for q in accuracy[name]["quantities"].values()), name
    # the seed's dual swallows the rudder offset in the bias (seed 001, Table 2)
    assert accuracy["lssvm-dual (seed)"]["quantities"]["delta_r"]["rms_percent"] == pytest.approx(100.0, abs=1.0)
    for name, method in accuracy.items():
        assert math.isfinite(method["rmse_heading_deg"]) and method["rmse_heading_deg"] > 0, name
    floor = accuracy["truth"]["rmse_heading_deg"]
    assert accuracy[OURS_LABEL]["rmse_heading_deg"] < 2 * floor


def test_tracking_recovers_within_a_window_and_the_peers_track(tracking):
    ours = tracking["methods"][OURS_LABEL]
    assert ours["recovery_s"] < 2 * tracking["window_s"]  # the target (one window + one period) is the bench's
    assert ours["error_before_percent"] < 2.0
    for name, method in tracking["methods"].items():
        assert len(method["K"]) > 10 and np.all(np.isfinite(method["K"])), name
    assert any(name.startswith("rls") for name in tracking["methods"])
    assert any(name.startswith("ukf") for name in tracking["methods"])


def test_recovery_time_is_the_last_exit_from_the_band():
    times = np.arange(0.0, 100.0, 10.0)
    settled = np.where(times < 40, 1.0, 0.7)
    assert peer_experiments.recovery_time(times, settled, 20.0, 0.7) == 20.0  # outside until t = 30, inside from 40
    never = np.where(times < 90, 0.7, 1.0)
    assert peer_experiments.recovery_time(times, never, 20.0, 0.7) == math.inf
