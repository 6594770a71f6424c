"""Property tests: random message sequences (values, timings, orders, gaps) against the window and the
online pipeline. Nothing escapes, every published number is finite, the window keeps its bounds."""

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ship_ident.io.files import ROLES, Sample
from ship_ident.io.jsonio import dumps_json
from ship_ident.model.simulator import simulate
from ship_ident.online.config import OnlineConfig
from ship_ident.online.identifier import OnlineIdentifier, RefitRecord, run_schedule

SMALL = OnlineConfig(
    sample_time=0.1,
    window_length=10.0,
    min_window_length=2.0,
    refit_period=1.0,
    max_window_samples=150,
    method="rwlssvm",
    gap_threshold=0.5,
)

values = st.one_of(
    st.floats(-1.0, 1.0),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, math.nan, math.inf, -math.inf, 1e300, 359.0]),
)
steps = st.one_of(st.floats(0.0, 0.2), st.floats(-3.0, 0.0), st.floats(0.0, 400.0), st.just(0.0), st.just(math.nan))
events = st.lists(st.tuples(steps, st.sampled_from(ROLES + ("refit",)), values), max_size=400)


# Top-level fields of a published record that may hold "not known" (NaN before, null after
# serialisation): the window and the yaw rates before any usable data, an infinite standard error.
MAY_BE_UNKNOWN = ("window", "predicted_yaw_rate", "measured_yaw_rate", "std_errors")


def numbers(value, field=""):
    """(top-level field, number) for every number in a JSON-like value."""
    if isinstance(value, dict):
        return [n for k, v in value.items() for n in numbers(v, field or k)]
    if isinstance(value, (list, tuple)):
        return [n for v in value for n in numbers(v, field)]
    return [(field, value)] if isinstance(value, (int, float)) and not isinstance(value, bool) else []


def reject_constant(name):
    raise AssertionError(f"published JSON holds {name}")


def check_published(record) -> None:
    """What the node would publish, checked before serialisation turns NaN into null: the
    parameters are finite numbers, a non-finite number appears only where "not known" is a legal
    answer (none at all beside the standard errors when the status is OK), and the text is strict
    JSON (no NaN or Infinity tokens)."""
    raw = record.to_json()
    assert all(isinstance(v, float | int) and math.isfinite(v) for v in raw["parameters"].values())
    unknown = {field for field, n in numbers(raw) if not math.isfinite(n)}
    assert unknown <= set(MAY_BE_UNKNOWN), unknown
    if record.status == "OK":
        assert unknown <= {"std_errors"}, unknown
    published = json.loads(dumps_json(raw), parse_constant=reject_constant)
    assert published["parameters"].keys() == raw["parameters"].keys()
    assert record.status in ("OK", "WARN", "ERROR")


def test_check_published_can_fail():
    """The check itself: a NaN parameter, a NaN fit figure and an OK record without a prediction
    are each refused."""
    good = {"parameters": {"K": 0.5, "T": 2.0}, "fit": {"rmse_yaw_rate": 0.01}}
    check_published(
        RefitRecord(
            time=1.0, conditions={}, estimate=good, window=(0.0, 1.0), predicted_yaw_rate=0.1, measured_yaw_rate=0.1
        )
    )
    for estimate, predicted in (
        (dict(good, parameters={"K": math.nan, "T": 2.0}), 0.1),
        (dict(good, fit={"rmse_yaw_rate": math.nan}), 0.1),
        (good, math.nan),
    ):
        with pytest.raises(AssertionError):
            check_published(
                RefitRecord(
                    time=1.0,
                    conditions={},
                    estimate=estimate,
                    window=(0.0, 1.0),
                    predicted_yaw_rate=predicted,
                    measured_yaw_rate=0.1,
                )
            )


def check_window(identifier: OnlineIdentifier, now: float) -> None:
    config = identifier.config
    for role in ROLES:
        window = identifier._window[role].array()
        assert len(window) <= config.max_window_samples
        if len(window):
            assert window[0, 0] >= now - config.window_length


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(events)
def test_random_messages_never_break_the_window(sequence):
    identifier = OnlineIdentifier(SMALL)
    clock = 0.0
    for step, role, value in sequence:
        clock = clock + step if math.isfinite(step) else step
        if role == "refit":
            if math.isfinite(clock) and identifier.due(clock):
                record = identifier.refit(clock)
                check_published(record)
                check_window(identifier, clock)
            clock = clock if math.isfinite(clock) else 0.0
            continue
        assert identifier.add(Sample(clock, role, value)) in (
            "accepted",
            "non_finite",
            "absurd",
            "out_of_order",
            "duplicate",
        )
        clock = clock if math.isfinite(clock) else 0.0
    assert sum(identifier.counts[k] for k in ("accepted", "non_finite", "absurd", "out_of_order", "duplicate")) == sum(
        r != "refit" for _, r, _ in sequence
    )


@pytest.fixture(scope="module")
def trip():
    """Two minutes of a manoeuvring boat as time-ordered samples, heading wrapped."""
    d = simulate("mixed", duration=120.0, seed=9).dataset
    wrapped = np.mod(d.heading + np.pi, 2 * np.pi) - np.pi
    return [
        Sample(float(t), role, float(v))
        for i, t in enumerate(d.time)
        for role, v in (("rudder", d.rudder[i]), ("heading", wrapped[i]), ("yaw_rate", d.yaw_rate[i]))
    ]


glitch = st.tuples(
    st.sampled_from(["drop", "duplicate", "swap", "nan", "spike", "shift"]),
    st.floats(0.0, 1.0),
    st.floats(0.0, 0.2),
    st.floats(-100.0, 100.0),
)


@settings(
    max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture]
)
@pytest.mark.slow
@given(st.lists(glitch, max_size=6))
def test_glitched_trip_through_the_pipeline(trip, glitches):
    """Drops, duplicates, reorderings, NaN bursts, spikes and clock shifts over a real trip."""
    samples = list(trip)
    for kind, where, length, size in glitches:
        a = int(where * len(samples))
        b = min(len(samples), a + 1 + int(length * len(samples)))
        if kind == "drop":
            del samples[a:b]
        elif kind == "duplicate":
            samples[a:a] = samples[a:b]
        elif kind == "swap":
            samples[a:b] = samples[a:b][::-1]
        elif kind == "nan":
            samples[a:b] = [Sample(s.time, s.role, math.nan) for s in samples[a:b]]
        elif kind == "spike":
            samples[a:b] = [Sample(s.time, s.role, s.value * size) for s in samples[a:b]]
        else:
            samples[a:] = [Sample(s.time + size, s.role, s.value) for s in samples[a:]]
    identifier = OnlineIdentifier(OnlineConfig(window_length=40.0, min_window_length=20.0, refit_period=10.0))
    for record in run_schedule(identifier, samples):
        check_published(record)
        check_window(identifier, record.time)
