"""OnlineIdentifier: window bounds, input checks, schedule, gating, with numbers."""
import math

import numpy as np
import pytest

from ship_ident.io import Sample
from ship_ident.online import ConfigError, OnlineConfig, OnlineIdentifier, run_schedule
from ship_ident.simulator import simulate


def stream(dataset, start=0.0, rudder=None):
    """The dataset as time-ordered samples (heading wrapped as a compass gives it)."""
    rudder = dataset.rudder if rudder is None else rudder
    wrapped = np.mod(dataset.heading + np.pi, 2 * np.pi) - np.pi
    return [Sample(float(t) + start, role, float(v))
            for i, t in enumerate(dataset.time)
            for role, v in (("rudder", rudder[i]), ("heading", wrapped[i]),
                            ("yaw_rate", dataset.yaw_rate[i]))]


@pytest.fixture(scope="module")
def sim():
    return simulate("mixed", duration=300.0, seed=2)


def test_add_rejects_bad_samples_and_counts_them():
    ident = OnlineIdentifier(OnlineConfig())
    assert ident.add(Sample(1.0, "rudder", 0.1)) == "accepted"
    assert ident.add(Sample(1.1, "rudder", math.nan)) == "non_finite"
    assert ident.add(Sample(1.1, "heading", math.inf)) == "non_finite"
    assert ident.add(Sample(1.1, "rudder", 2.0)) == "absurd"        # 115 deg of rudder
    assert ident.add(Sample(1.1, "yaw_rate", -10.0)) == "absurd"    # 570 deg/s
    assert ident.add(Sample(1.0, "rudder", 0.1)) == "duplicate"
    assert ident.add(Sample(0.5, "rudder", 0.1)) == "out_of_order"  # 0.5 s back: < 1 s jump threshold
    assert ident.add(Sample(1.2, "rudder", 0.1)) == "accepted"
    assert ident.counts == {"accepted": 2, "non_finite": 2, "absurd": 2, "out_of_order": 1,
                            "duplicate": 1, "clock_jumps": 0}


def test_clock_jump_back_resets_window_and_schedule(sim):
    ident = OnlineIdentifier(OnlineConfig(window_length=60.0, min_window_length=30.0))
    records = list(run_schedule(ident, stream(sim.dataset.slice(0, 1000))))  # 0 .. 100 s
    assert records[-1].new_estimate
    assert ident.add(Sample(40.0, "rudder", 0.0)) == "accepted"  # 60 s back: a jump, not out of order
    assert ident.counts["clock_jumps"] == 1
    assert not ident.due(44.9) and ident.due(45.0)                 # schedule restarted at 40 s
    record = ident.refit(45.0)
    assert "clock_jump" in record.conditions and "no_data" in record.conditions
    assert not record.new_estimate and record.estimate is not None  # the last good one is kept


def test_window_is_bounded_by_length_and_count(sim):
    ident = OnlineIdentifier(OnlineConfig(window_length=20.0, min_window_length=10.0,
                                          max_window_samples=200))
    records = list(run_schedule(ident, stream(sim.dataset.slice(0, 600))))  # 0 .. 60 s at 10 Hz
    last = records[-1]
    assert last.time == 55.0 and last.window[0] >= 35.0 - 1e-9  # never older than window_length
    for k in range(1000):  # a rudder sensor suddenly at 100 Hz: the count bound holds
        ident.add(Sample(60.0 + 0.01 * k, "rudder", 0.01))
    assert len(ident._window["rudder"]) == 200


def test_schedule_runs_every_refit_period_and_skips_ahead():
    ident = OnlineIdentifier(OnlineConfig(refit_period=5.0))
    assert not ident.due(100.0)            # the schedule starts at the first call
    assert not ident.due(104.9)
    assert ident.due(105.0)
    record = ident.refit(105.0)
    assert "no_data" in record.conditions and record.level == 2
    assert not ident.due(109.99) and ident.due(110.0)
    ident.skip(110.0)                      # a refit still running: skipped
    assert not ident.due(114.99) and ident.due(115.0)
    ident.refit(200.0)                     # far behind: the schedule moves on from now
    assert not ident.due(204.9) and ident.due(205.0)


def test_first_fit_waits_for_min_window_length(sim):
    ident = OnlineIdentifier(OnlineConfig(window_length=120.0, min_window_length=60.0))
    records = list(run_schedule(ident, stream(sim.dataset.slice(0, 700))))
    filling = [r for r in records if "window_filling" in r.conditions]
    fitted = [r for r in records if r.new_estimate]
    assert [r.time for r in filling] == [5.0 * k for k in range(1, 13)]  # at 60 s: 59.9 s of data
    assert fitted and fitted[0].time == 65.0


def test_little_rudder_keeps_last_good_estimate_flagged(sim):
    ident = OnlineIdentifier(OnlineConfig(window_length=60.0, min_window_length=30.0))
    records = list(run_schedule(ident, stream(sim.dataset.slice(0, 1000))))  # 0 .. 100 s, manoeuvring
    assert records[-1].new_estimate and records[-1].status == "OK"
    rng = np.random.default_rng(0)
    heading = float(sim.dataset.heading[999])
    n = 1000  # then 100 s steady on course: rudder 0.1 deg, yaw rate and heading only noise
    time = 100.0 + 0.1 * np.arange(n)
    quiet = [Sample(float(t), role, float(v)) for i, t in enumerate(time)
             for role, v in (("rudder", 0.002 + 0.0017 * rng.standard_normal()),
                             ("heading", heading + 0.0017 * rng.standard_normal()),
                             ("yaw_rate", 0.0035 * rng.standard_normal()))]
    records += list(run_schedule(ident, quiet))
    good = [r for r in records if r.new_estimate][-1]
    last = records[-1]
    assert "too_little_excitation" in last.conditions and not last.new_estimate
    assert last.status == "WARN"
    assert last.estimate["parameters"] == good.estimate["parameters"]
    assert last.window == good.window
    assert good.estimate["fit"]["r_yaw_rate"] >= 0.8 and not good.estimate["flags"]


def test_gap_and_stale_input_are_reported(sim):
    ident = OnlineIdentifier(OnlineConfig(window_length=60.0, min_window_length=30.0))
    samples = stream(sim.dataset.slice(0, 800))
    silent = [s for s in samples if not (s.role == "yaw_rate" and 52.0 < s.time < 56.0)]
    records = {r.time: r for r in run_schedule(ident, silent)}
    assert "no new samples on yaw_rate (3.0 s)" in records[55.0].conditions["stale_input"]
    assert "stale_input" not in records[60.0].conditions
    record = ident.refit(80.0)
    assert "gap_in_window" in record.conditions and record.new_estimate
    assert record.status == "WARN"


def test_replay_schedule_recovers_truth(sim):
    ident = OnlineIdentifier(OnlineConfig())
    records = list(run_schedule(ident, stream(sim.dataset)))
    final = records[-1]
    assert final.new_estimate and final.status == "OK"
    assert final.estimate["parameters"]["K"] == pytest.approx(sim.truth["K"], rel=0.05)
    assert final.estimate["parameters"]["T1"] == pytest.approx(sim.truth["T1"], rel=0.10)
    assert abs(final.predicted_yaw_rate - final.measured_yaw_rate) < math.radians(1.0)


@pytest.mark.parametrize("values, message", [
    (dict(model="nomoto3"), "unknown model"),
    (dict(effects=("rudder_offset", "barnacles")), "unknown effect"),
    (dict(method="magic"), "unknown method"),
    (dict(window_length=-1.0), "window_length"),
    (dict(refit_period=math.nan), "refit_period"),
    (dict(min_window_length=500.0), "min_window_length"),
    (dict(max_window_samples=10), "max_window_samples"),
    (dict(effects="speed_dependence"), "speed_topic"),
])
def test_config_errors_say_what_is_wrong(values, message):
    with pytest.raises(ConfigError, match=message):
        OnlineConfig(**values).validate()


def test_effects_accept_comma_text():
    assert OnlineConfig(effects="rudder_offset, cubic_yaw").effects == ("rudder_offset", "cubic_yaw")
