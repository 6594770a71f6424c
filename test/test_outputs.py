"""What the node publishes and replay writes (``outputs``): trusted parameters only, K's band, the
diagnostics status and the predicted yaw-rate stream, on records and samples of a simulated trip."""

import math

import numpy as np
import pytest

from ship_ident.model.simulator import simulate
from ship_ident.online.config import OnlineConfig
from ship_ident.online.identifier import RefitRecord
from ship_ident.online.outputs import YawRatePrediction, diagnostic_status, gain_band, trusted_parameters
from ship_ident.online.samples import Sample

STRUCTURE = {"model": "nomoto2", "effects": ["rudder_offset", "cubic_yaw"]}
NAMES = ("K", "T1", "T2", "T3", "delta_r", "alpha")  # of STRUCTURE


def record(conditions=None, parameters=None, std_errors=None, time=100.0):
    estimate = None
    if parameters is not None:
        estimate = {"structure": STRUCTURE, "parameters": parameters, "std_errors": std_errors or {}, "fit": {}}
    return RefitRecord(time=time, conditions=conditions or {}, estimate=estimate, new_estimate=True)


def test_only_an_estimate_with_status_ok_is_one_to_steer_by_with_its_own_names():
    parameters = {"K": 0.59, "T1": 1.44, "r_bias": 0.001}
    assert trusted_parameters(record(parameters=parameters)) == (["K", "T1", "r_bias"], [0.59, 1.44, 0.001])
    uncertain = record({"uncertain_estimate": "the window determines T1 only loosely"}, parameters)
    assert trusted_parameters(uncertain) is None and uncertain.status == "WARN"
    assert trusted_parameters(record(parameters={"K": math.nan, "T1": 1.0})) is None
    assert trusted_parameters(record()) is None  # no estimate yet


def test_gain_band_is_the_95_percent_interval_of_any_estimate_in_force():
    low, gain, high = gain_band(record({"uncertain_estimate": "loose"}, {"K": 0.5}, {"K": 0.1}))
    assert gain == 0.5 and low == pytest.approx(0.5 - 0.196, abs=1e-4) and high == pytest.approx(0.5 + 0.196, abs=1e-4)
    assert gain_band(record(parameters={"T": 2.0})) is None


def test_diagnostic_status_lists_the_worst_condition_first():
    level, message, values = diagnostic_status(
        record({"stale_input": "yaw_rate silent", "refit_failed": "boom"}, {"K": 0.5}), {"callback_errors": 3}
    )
    assert level == 2 and message.startswith("refit failed: boom; stale input")
    assert values[:2] == [("condition/refit_failed", "boom"), ("condition/stale_input", "yaw_rate silent")]
    assert ("callback_errors", "3") in values and ("K", "0.5") in values


@pytest.fixture(scope="module")
def trip():
    return simulate("random", duration=120.0, seed=3)


def feed(prediction, d, speed=False):
    """Each sample of the dataset ``d`` as the node takes them (rudder, heading, yaw rate per step)."""
    out, yaw_rate_times = [], []
    for i, t in enumerate(d.time):
        for role in ("rudder", "heading", "yaw_rate"):
            out += prediction.add(Sample(float(t), role, float(getattr(d, role)[i])))
        yaw_rate_times.append(float(t))
    return out, np.array(yaw_rate_times)


def test_the_prediction_stream_is_the_true_model_run_free_in_runs_of_the_horizon(trip):
    """With the true parameters as the estimate from 30 s on: a value for every yaw-rate sample after
    it (but the run in progress, until flushed), at the samples' times, within the sensor noise of the
    measured yaw rate; each run restarts from the measurement."""
    config = OnlineConfig(prediction_horizon=10.0)
    prediction = YawRatePrediction(config)
    d = trip.dataset
    half = int(np.searchsorted(d.time, 30.0))
    first, _ = feed(prediction, d.slice(0, half))
    assert first == []  # no estimate yet
    truth = {k: trip.truth[k] for k in NAMES}
    prediction.update(record(parameters=truth), config)
    predicted, times = feed(prediction, d.slice(half, d.n_samples))
    predicted += prediction.flush()
    stamps = np.array([t for t, _ in predicted])
    assert len(predicted) >= 0.99 * len(times) and np.all(np.diff(stamps) > 0)
    assert set(stamps) <= set(times)
    measured = np.interp(stamps, d.time, d.yaw_rate)
    error = np.array([v for _, v in predicted]) - measured
    noise = d.noise_std("yaw_rate")
    assert np.sqrt(np.mean(error**2)) < 2.0 * noise, (np.degrees(np.sqrt(np.mean(error**2))), np.degrees(noise))
    starts = stamps[0] + 10.0 * np.arange(1, 8)  # runs restart from the measurement: small error there
    at_start = np.abs(error[np.searchsorted(stamps, starts)])
    assert np.median(at_start) < 3.0 * noise


def test_the_prediction_stream_shows_where_a_wrong_model_fails(trip):
    """K 30 % low: the error grows along each run from the measured start."""
    config = OnlineConfig(prediction_horizon=10.0)
    prediction = YawRatePrediction(config)
    wrong = {k: trip.truth[k] for k in NAMES}
    wrong["K"] *= 0.7
    prediction.update(record(parameters=wrong), config)
    predicted, _ = feed(prediction, trip.dataset)
    stamps = np.array([t for t, _ in predicted])
    error = np.abs(np.array([v for _, v in predicted]) - np.interp(stamps, trip.dataset.time, trip.dataset.yaw_rate))
    into_run = (stamps - stamps[0]) % 10.0
    assert np.mean(error[into_run > 5.0]) > 2.0 * np.mean(error[into_run < 1.0])


def test_the_prediction_stream_leaves_out_bad_samples_and_restarts_after_the_clock_goes_back(trip):
    config = OnlineConfig(prediction_horizon=5.0)
    prediction = YawRatePrediction(config)
    prediction.update(record(parameters={k: trip.truth[k] for k in NAMES}), config)
    d = trip.dataset.slice(0, 200)
    assert prediction.add(Sample(0.0, "yaw_rate", math.nan)) == []
    predicted, _ = feed(prediction, d)
    assert predicted and all(math.isfinite(v) for _, v in predicted)
    again, _ = feed(prediction, d)  # the same times again: the clock went back, the runs start afresh
    assert again == predicted


def test_a_silent_yaw_rate_ends_the_run_and_the_stream_resumes_with_it(trip):
    """The yaw rate falls silent for 30 s: the other inputs end the run at its horizon (what is
    kept stays within one run), nothing is predicted in the silence, and runs begin again with the
    yaw rate."""
    config = OnlineConfig(prediction_horizon=10.0)
    prediction = YawRatePrediction(config)
    prediction.update(record(parameters={k: trip.truth[k] for k in NAMES}), config)
    d = trip.dataset
    predicted = []
    for i, t in enumerate(d.time):
        silent = 40.0 <= t < 70.0
        for role in ("rudder", "heading") + (() if silent else ("yaw_rate",)):
            predicted += prediction.add(Sample(float(t), role, float(getattr(d, role)[i])))
        assert len(prediction._run["rudder"]) <= 101
    stamps = np.array([t for t, _ in predicted])
    assert not np.any((stamps >= 40.0) & (stamps < 70.0))
    assert np.sum(stamps >= 70.0) >= 0.9 * np.sum((d.time >= 70.0) & (d.time < d.time[-1] - 10.0))
