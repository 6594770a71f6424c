"""OnlineIdentifier: window bounds, input checks, schedule, gating, with numbers."""

import json
import math
import re
from dataclasses import replace

import numpy as np
import pytest

from ship_ident.bench import vessels
from ship_ident.estimators.base import Estimate
from ship_ident.io.files import Sample
from ship_ident.model.dataset import cut_segments
from ship_ident.model.metrics import noise_limited_correlation
from ship_ident.model.simulator import Noise, random_vessel, simulate
from ship_ident.online.change import ChangeDetector, fit_gain, variance_change_point, with_held_errors
from ship_ident.online.config import ConfigError, OnlineConfig
from ship_ident.online.estimate_log import EstimateLog
from ship_ident.online.identifier import WATCHES_PER_REFIT, OnlineIdentifier, run_schedule
from ship_ident.online.trust import TrustPolicy
from ship_ident.online.verdicts import FOLLOWED


def stream(dataset, start=0.0, rudder=None):
    """The dataset as time-ordered samples (heading wrapped as a compass gives it)."""
    rudder = dataset.rudder if rudder is None else rudder
    wrapped = np.mod(dataset.heading + np.pi, 2 * np.pi) - np.pi
    return [
        Sample(float(t) + start, role, float(v))
        for i, t in enumerate(dataset.time)
        for role, v in (("rudder", rudder[i]), ("heading", wrapped[i]), ("yaw_rate", dataset.yaw_rate[i]))
    ]


@pytest.fixture(scope="module")
def sim():
    return simulate("mixed", duration=300.0, seed=2)


def test_add_rejects_bad_samples_and_counts_them():
    ident = OnlineIdentifier(OnlineConfig())
    assert ident.add(Sample(1.0, "rudder", 0.1)) == "accepted"
    assert ident.add(Sample(1.1, "rudder", math.nan)) == "non_finite"
    assert ident.add(Sample(1.1, "heading", math.inf)) == "non_finite"
    assert ident.add(Sample(1.1, "rudder", 2.0)) == "absurd"  # 115 deg of rudder
    assert ident.add(Sample(1.1, "yaw_rate", -10.0)) == "absurd"  # 570 deg/s
    assert ident.add(Sample(1.0, "rudder", 0.1)) == "duplicate"
    assert ident.add(Sample(0.5, "rudder", 0.1)) == "out_of_order"  # 0.5 s back: < 1 s jump threshold
    assert ident.add(Sample(1.2, "rudder", 0.1)) == "accepted"
    assert ident.counts == {
        "accepted": 2,
        "non_finite": 2,
        "absurd": 2,
        "out_of_order": 1,
        "duplicate": 1,
        "clock_jumps": 0,
    }


def test_clock_jump_back_resets_window_and_schedule(sim):
    ident = OnlineIdentifier(OnlineConfig(window_length=60.0, min_window_length=30.0))
    records = list(run_schedule(ident, stream(sim.dataset.slice(0, 1000))))  # 0 .. 100 s
    assert records[-1].new_estimate
    assert ident.add(Sample(40.0, "rudder", 0.0)) == "accepted"  # 60 s back: a jump, not out of order
    assert ident.counts["clock_jumps"] == 1
    assert not ident.due(44.9) and ident.due(45.0)  # schedule restarted at 40 s
    record = ident.refit(45.0)
    assert "clock_jump" in record.conditions and "no_data" in record.conditions
    assert not record.new_estimate and record.estimate is not None  # the last good one is kept


def test_window_is_bounded_by_length_and_count(sim):
    ident = OnlineIdentifier(OnlineConfig(window_length=20.0, min_window_length=10.0, max_window_samples=200))
    records = list(run_schedule(ident, stream(sim.dataset.slice(0, 600))))  # 0 .. 60 s at 10 Hz
    last = records[-1]
    assert last.time == 55.0 and last.window[0] >= 35.0 - 1e-9  # never older than window_length
    for k in range(1000):  # a rudder sensor suddenly at 100 Hz: the count bound holds
        ident.add(Sample(60.0 + 0.01 * k, "rudder", 0.01))
    assert len(ident._window["rudder"]) == 200


def test_schedule_runs_every_refit_period_and_skips_ahead():
    ident = OnlineIdentifier(OnlineConfig(refit_period=5.0))
    assert not ident.due(100.0)  # the schedule starts at the first call
    assert not ident.due(104.9)
    assert ident.due(105.0)
    record = ident.refit(105.0)
    assert "no_data" in record.conditions and record.level == 2
    assert not ident.due(109.99) and ident.due(110.0)
    ident.skip(110.0)  # a refit still running: skipped
    assert not ident.due(114.99) and ident.due(115.0)
    ident.refit(200.0)  # far behind: the schedule moves on from now
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
    quiet = [
        Sample(float(t), role, float(v))
        for i, t in enumerate(time)
        for role, v in (
            ("rudder", 0.002 + 0.0017 * rng.standard_normal()),
            ("heading", heading + 0.0017 * rng.standard_normal()),
            ("yaw_rate", 0.0035 * rng.standard_normal()),
        )
    ]
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


@pytest.mark.slow
def test_replay_schedule_recovers_truth(sim):
    ident = OnlineIdentifier(OnlineConfig())
    records = list(run_schedule(ident, stream(sim.dataset)))
    final = records[-1]
    assert final.new_estimate and final.status == "OK"
    assert final.estimate["parameters"]["K"] == pytest.approx(sim.truth["K"], rel=0.05)
    assert final.estimate["parameters"]["T1"] == pytest.approx(sim.truth["T1"], rel=0.10)
    assert abs(final.predicted_yaw_rate - final.measured_yaw_rate) < math.radians(1.0)


@pytest.mark.parametrize(
    "values, message",
    [
        (dict(model="nomoto3"), "unknown model"),
        (dict(effects=("rudder_offset", "barnacles")), "unknown effect"),
        (dict(method="magic"), "unknown method"),
        (dict(window_length=-1.0), "window_length"),
        (dict(refit_period=math.nan), "refit_period"),
        (dict(min_window_length=500.0), "min_window_length"),
        (dict(max_window_samples=10), "max_window_samples"),
        (dict(max_window_samples=50_000_000), "GB"),  # a window that would not fit in memory
        (dict(effects="speed_dependence"), "speed_topic"),
        (dict(change_ratio=0.5), "change_ratio"),
        (dict(change_test_length=0.0), "change_test_length"),
    ],
)
def test_config_errors_say_what_is_wrong(values, message):
    with pytest.raises(ConfigError, match=message):
        OnlineConfig(**values).validate()


LOADED = {"K": 0.7 * 0.5883, "T1": 1.3 * 1.4397}  # seed001 vessel after loading: K -30 %, T1 +30 %


def k_trace(records):
    """(times, K in force) over the records that carry an estimate."""
    pairs = [(r.time, r.estimate["parameters"]["K"]) for r in records if r.estimate]
    return np.array([t for t, _ in pairs]), np.array([k for _, k in pairs])


def settled_after(times, ks, truth, since):
    """Time of the first record after ``since`` from which K stays within 5 % of ``truth``."""
    from ship_ident.bench.peers import recovery_time

    return since + recovery_time(times, ks, since, truth)


@pytest.mark.slow
def test_a_changed_vessel_restarts_the_window():
    """K -30 % and T1 +30 % at 400 s (loaded mid-trip): the change test finds it, the window
    restarts within a few seconds of it, and K is back within 5 % long before the 180 s window
    would have flushed the old data; with the test off it takes about a window. The identifier
    starts at 100 s (300 s of the old vessel: a full window and two minutes of its refits) and
    stops at 600 s, as long as the test off needs (measured: the same alarm, restart and settling
    times as from 0 s to 700 s); with the test off it starts at 220 s, its window full at the
    change (measured: settled 180 s after it, as from 100 s)."""
    change = 400.0
    sim = simulate("zigzag20", duration=700.0, seed=31, change=(change, LOADED))
    k_new = sim.info["truth_after"]["K"]
    samples = [s for s in stream(sim.dataset) if 100.0 <= s.time <= 600.0]
    records = list(run_schedule(OnlineIdentifier(OnlineConfig()), samples))
    alarms = [r for r in records if "vessel_changed" in r.conditions]
    assert alarms and change < alarms[0].time <= change + 30.0
    restart = re.search(r"restarts at ([0-9.]+) s", alarms[0].conditions["vessel_changed"])
    assert abs(float(restart.group(1)) - change) < 2.0
    assert "diagnose" in alarms[0].conditions["vessel_changed"] and alarms[0].status == "WARN"
    assert not [r for r in records if r.time < change and "vessel_changed" in r.conditions]
    assert settled_after(*k_trace(records), k_new, change) - change <= 80.0
    assert all(r.window[0] >= float(restart.group(1)) - 0.1 for r in records if r.new_estimate and r.time > change + 60)

    full_at_the_change = [s for s in samples if s.time >= change - OnlineConfig().window_length]
    off = list(run_schedule(OnlineIdentifier(OnlineConfig(change_ratio=0.0)), full_at_the_change))
    assert not [r for r in off if "vessel_changed" in r.conditions]
    assert settled_after(*k_trace(off), k_new, change) - change >= 150.0


def test_variance_step_is_located_to_a_few_samples():
    rng = np.random.default_rng(4)
    errors = np.concatenate([rng.normal(0, 1.0, 370), rng.normal(0, 4.0, 230)])  # steps at 370
    assert abs(variance_change_point(errors**2) - 370) <= 5


@pytest.mark.slow
def test_no_change_alarm_on_a_steady_vessel():
    sim = simulate("mixed", duration=900.0, seed=5)
    records = list(run_schedule(OnlineIdentifier(OnlineConfig()), stream(sim.dataset)))
    assert sum(r.new_estimate for r in records) > 150
    assert not [r.conditions["vessel_changed"] for r in records if "vessel_changed" in r.conditions]


def test_a_quick_usv_on_rudder_steps_run_with_its_true_model_raises_no_change():
    """bench vessels seed 568021594: a USV with T1 11.6 s, T2 1.5 s, T3 2.4 s on rudder steps at
    0.7x noise. Its true model, run free over each 30 s test block from the measured state at the
    block's start, missed blocks that open just after a rudder step by 6-26 times its usual error
    (the transient of the unknown initial yaw acceleration, dying out over T1): two in a row, a
    false change. Run from one block earlier, every block stays within 3 times."""
    case = vessels.draw_case(568021594, quick=True)
    config, seed = case["config"], case["seed"]
    noise = Noise().scaled(case["noise"])
    sim = simulate(
        case["maneuver"], case["vessel"], duration=300.0, sample_time=config.sample_time, noise=noise, seed=seed
    )
    data = sim.dataset
    structure = config.structure()
    truth = {name: case["vessel"].parameters[name] for name in structure.parameter_names}
    known = Estimate(structure, "truth", truth, dict.fromkeys(truth, 0.0), {}, 0)
    detector = ChangeDetector(config.change_ratio, config.change_test_length, config.refit_period)
    ratios, changes = [], []
    for end in np.arange(config.window_length, 300.0 + 1e-9, config.refit_period):
        window = data.slice(*np.searchsorted(data.time, [end - config.window_length, end]))
        if end > config.window_length:
            ratio, changed_at = detector.test(structure, window)
            ratios.append(ratio)
            changes.append(changed_at)
        detector.calibrate(structure, known, window)
    assert len(ratios) == 24 and max(ratios) < 3.0
    assert changes == [None] * 24


def test_a_hull_changed_while_coasting_is_found_as_its_rudder_moves_and_restarted_at_the_change():
    """bench peers --quick, random: seed 001's hull loses 30 % of K (T1 +30 %) at 240 s, its rudder
    amidships from 238 s to 247.3 s. Its true model (the reference) misses the newest 2 s by 83 times
    its usual error at 249.5 s, the whole 5 s of the quick test by 35 times (upper quartile) only at
    250 s: the change is found at 249.5 s. Its error stepped up at 247.8 s, but the coasting hull's
    yaw-rate decay and heading already show the new time constant: the window restarts within 2 s
    of 240 s (at 247.8 s K refitted 2.6 s after it was 6 % off, from 240 s 1 %)."""
    config = OnlineConfig()
    structure = config.structure()
    sim = simulate("random", duration=480.0, seed=31, change=(240.0, LOADED))
    data = sim.dataset
    truth = {name: sim.truth[name] for name in structure.parameter_names}
    detector = ChangeDetector(config.change_ratio, config.change_test_length, config.refit_period)
    detector.calibrate(
        structure, Estimate(structure, "truth", truth, dict.fromkeys(truth, 0.0), {}, 0), data.slice(600, 2400)
    )
    found = None
    for end in np.arange(245.0, 252.0, 0.5):
        newest = data.slice(*np.searchsorted(data.time, [end - 2 * config.change_test_length, end]))
        ratio, changed_at = detector.quick_test(structure, newest)
        if changed_at is not None:
            found = end
            break
    assert found == 249.5 and abs(changed_at - 240.0) <= 2.0


def test_the_quick_test_reads_its_own_span_as_it_reads_the_newest_two_test_lengths():
    """The watch hands the quick test its own span (``quick_span``) and the newest 2 test lengths
    only where a change shows: the same ratios and the same change time as on the wider data, on
    the coasting hull that changes at 240 s."""
    config = OnlineConfig()
    structure = config.structure()
    sim = simulate("random", duration=480.0, seed=31, change=(240.0, LOADED))
    data = sim.dataset
    truth = {name: sim.truth[name] for name in structure.parameter_names}
    reference = Estimate(structure, "truth", truth, dict.fromkeys(truth, 0.0), {}, 0)
    wide, narrow = (ChangeDetector(config.change_ratio, config.change_test_length, 5.0) for _ in range(2))
    for detector in (wide, narrow):
        detector.calibrate(structure, reference, data.slice(600, 2400))
    span = narrow.quick_span(data.sample_time)
    assert span < 2 * config.change_test_length
    outcomes = []
    for end in (100.0, 200.0, 249.0, 249.5):
        newest = data.slice(*np.searchsorted(data.time, [end - 2 * config.change_test_length, end]))
        own = data.slice(*np.searchsorted(data.time, [end - span, end]))
        outcomes.append((wide.quick_test(structure, newest), narrow.quick_test(structure, own, lambda n=newest: n)))
    assert all(a == b for a, b in outcomes)
    assert outcomes[-1][1][1] is not None and all(b[1] is None for _, b in outcomes[:-1])


def test_the_followed_gain_carries_the_errors_of_the_hull_held_under_it():
    """K refitted on 40 s of seed 001's loaded hull with the rest held from a reference: the held
    parameters' own errors move it, and its published error says by how much. Hulls drawn within
    those errors (10 % each of T1, T2, T3, the cubic damping and the rudder offset) give K's that
    scatter as the widened error says beyond the data's own (their ratio within 0.7-1.4 over
    40 draws: 1.06); the data's own error alone is 60 times smaller (0.03 % against 1.6 %)."""
    structure = OnlineConfig().structure()
    sim = simulate("random", duration=300.0, seed=31, change=(240.0, LOADED))
    new = sim.dataset.slice(*np.searchsorted(sim.dataset.time, [240.0, 280.0]))
    truth = {name: sim.info["truth_after"][name] for name in structure.parameter_names}
    held_errors = {name: 0.1 * abs(truth[name]) for name in ("T1", "T2", "T3", "alpha", "delta_r")}
    blocks = cut_segments(new.segments, int(round(30.0 / new.sample_time)), min_samples=2, align="end")
    fitted, own = fit_gain(structure, truth, new, blocks, ("K",))
    widened = with_held_errors(structure, fitted, own, held_errors, new, blocks)
    predicted = math.sqrt(widened["K"] ** 2 - own["K"] ** 2)
    rng = np.random.default_rng(5)
    drawn = [
        fit_gain(
            structure,
            dict(truth, **{n: truth[n] + rng.normal(0.0, e) for n, e in held_errors.items()}),
            new,
            blocks,
            ("K",),
        )[0]["K"]
        for _ in range(40)
    ]
    assert 0.7 < np.std(drawn, ddof=1) / predicted < 1.4
    assert predicted > 3 * own["K"]


def test_effects_accept_comma_text():
    assert OnlineConfig(effects="rudder_offset, cubic_yaw").effects == ("rudder_offset", "cubic_yaw")


def conditions_seen(records) -> dict:
    """{condition: its last sentence} over all records."""
    return {c: m for r in records for c, m in r.conditions.items()}


def test_clock_jump_forward_restarts_schedule_and_keeps_recent_window(sim):
    ident = OnlineIdentifier(OnlineConfig(window_length=60.0, min_window_length=30.0))
    records = list(run_schedule(ident, stream(sim.dataset.slice(0, 1000))))  # 0 .. 100 s
    later = stream(sim.dataset.slice(1000, 1600), start=-100.0 + 130.0)  # resumes at 130 s
    records = list(run_schedule(ident, later))
    assert ident.counts["clock_jumps"] == 1
    jump = records[0]
    assert jump.time == 135.0  # schedule restarted at 130 s, not a burst of missed refits
    assert "forward 30.1 s" in jump.conditions["clock_jump"]
    assert "gap_in_window" in jump.conditions and jump.new_estimate  # the 30 s gap splits the window
    assert all(r.time - q.time == 5.0 for q, r in zip(records, records[1:]))


@pytest.mark.slow
def test_dropouts_of_one_topic_for_5_s_and_5_min(sim):
    ident = OnlineIdentifier(OnlineConfig(window_length=60.0, min_window_length=30.0))
    samples = [
        s
        for s in stream(sim.dataset)
        if not (s.role == "heading" and (100.0 <= s.time < 105.0 or 150.0 <= s.time < 450.0))
    ]
    records = {r.time: r for r in run_schedule(ident, samples)}
    assert "heading" in records[105.0].conditions["stale_input"]
    assert "gap_in_window" in records[110.0].conditions and records[110.0].new_estimate
    blind = records[240.0]  # more than a window without heading: no data, last good estimate kept
    assert "no_data" in blind.conditions and blind.status == "ERROR" and blind.estimate
    assert not blind.new_estimate
    # the simulation ends at 300 s: fill again after the 5 min gap is not possible; the window restarts
    assert all("no_data" in records[t].conditions for t in (250.0, 295.0))


@pytest.mark.slow
def test_heading_in_degrees_is_reported(sim):
    degrees = [
        Sample(s.time, s.role, math.degrees(s.value) if s.role == "heading" else s.value)
        for s in stream(sim.dataset.slice(0, 1200))
    ]
    records = list(run_schedule(OnlineIdentifier(OnlineConfig(window_length=60.0, min_window_length=30.0)), degrees))
    sentence = records[-1].conditions["heading_in_degrees"]
    assert "degrees" in sentence and re.search(r"5[4-9]x as fast", sentence)
    warned = [r for r in records if "heading_in_degrees" in r.conditions]
    assert len(warned) >= 0.8 * len([r for r in records if r.time >= 35.0])
    # the heading 57x too large wrecks the fit: its standard errors say so and nothing is published
    assert not any(r.new_estimate for r in records)
    assert records[-1].verdicts["too_little_excitation"].code == "parameters_undetermined"
    clean = list(
        run_schedule(
            OnlineIdentifier(OnlineConfig(window_length=60.0, min_window_length=30.0)),
            stream(sim.dataset.slice(0, 1200)),
        )
    )
    assert "heading_in_degrees" not in conditions_seen(clean)


def test_heading_in_degrees_on_a_steady_course_shows_in_its_wraps():
    ident = OnlineIdentifier(OnlineConfig(window_length=60.0, min_window_length=30.0))
    for k in range(400):  # steady course of 180 deg, noise wrapping it between +179.9 and -179.9
        t = 0.1 * k
        ident.add(Sample(t, "rudder", 0.0))
        ident.add(Sample(t, "heading", 179.95 if k % 2 else -179.95))
        ident.add(Sample(t, "yaw_rate", 0.0))
    assert "steps by about 360" in ident.refit(40.0).conditions["heading_in_degrees"]


@pytest.mark.slow
def test_yaw_rate_in_the_other_sign_convention_is_reported(sim):
    flipped = [
        Sample(s.time, s.role, -s.value if s.role == "yaw_rate" else s.value)
        for s in stream(sim.dataset.slice(0, 1200))
    ]
    records = list(run_schedule(OnlineIdentifier(OnlineConfig(window_length=60.0, min_window_length=30.0)), flipped))
    last = records[-1]
    assert "opposite ways" in last.conditions["yaw_rate_sign"] and last.status in ("WARN", "ERROR")
    assert not any(r.new_estimate for r in records)  # K < 0 is never accepted


@pytest.mark.slow
def test_saturated_rudder_is_reported_but_zigzag_is_not():
    zigzag = simulate("zigzag20", duration=200.0, seed=3)
    records = list(
        run_schedule(OnlineIdentifier(OnlineConfig(window_length=60.0, min_window_length=30.0)), stream(zigzag.dataset))
    )
    assert "rudder_saturated" not in conditions_seen(records)
    hard_over = np.where(zigzag.dataset.time < 120.0, zigzag.dataset.rudder, np.radians(35.0))
    records = list(
        run_schedule(
            OnlineIdentifier(OnlineConfig(window_length=60.0, min_window_length=30.0)),
            stream(zigzag.dataset, rudder=hard_over),
        )
    )
    assert "+35.0 deg for 100 %" in records[-1].conditions["rudder_saturated"]
    assert "too_little_excitation" in records[-1].conditions and not records[-1].new_estimate


@pytest.mark.slow
@pytest.mark.parametrize("method", ["rwlssvm", "rwlssvm+oe"])
def test_spikes_of_50_times_the_noise_move_K_less_than_3_percent(sim, method):
    """1 % of all samples (rudder, heading, yaw rate) off by 50 noise standard deviations.

    The weighted LS-SVM's robust weights and the output-error stage's Huber
    weights hold K within 3 % of its clean value in every window published OK; an estimate the
    spikes leave loose (published WARN uncertain_estimate) is within 3 of its standard errors.
    """
    noise = {"rudder": Noise.rudder, "heading": Noise.heading, "yaw_rate": Noise.yaw_rate}
    rng = np.random.default_rng(1)
    clean = stream(sim.dataset)
    spiky = [
        Sample(s.time, s.role, s.value + 50 * noise[s.role] * rng.choice([-1.0, 1.0])) if rng.random() < 0.01 else s
        for s in clean
    ]
    config = OnlineConfig(method=method)
    clean_K = {
        r.time: r.estimate["parameters"]["K"] for r in run_schedule(OnlineIdentifier(config), clean) if r.new_estimate
    }
    spiky = {r.time: r for r in run_schedule(OnlineIdentifier(config), spiky) if r.new_estimate}
    both = sorted(set(clean_K) & set(spiky))
    assert len(both) >= 20
    ok = [t for t in both if spiky[t].status == "OK"]
    assert len(ok) >= 15
    assert max(abs(spiky[t].estimate["parameters"]["K"] / clean_K[t] - 1) for t in ok) < 0.03
    for t in set(both) - set(ok):
        estimate = spiky[t].estimate
        assert abs(estimate["parameters"]["K"] - clean_K[t]) < 3 * estimate["std_errors"]["K"]


def test_input_faster_than_the_sample_bound_is_reported():
    ident = OnlineIdentifier(OnlineConfig(window_length=20.0, min_window_length=10.0, max_window_samples=200))
    for k in range(3000):  # 100 Hz for 30 s: 200 samples hold 2 s of the 20 s window
        for role in ("rudder", "heading", "yaw_rate"):
            ident.add(Sample(0.01 * k, role, 0.01 * math.sin(0.01 * k)))
    record = ident.refit(30.0)
    assert "raise max_window_samples" in record.conditions["window_truncated"]
    assert all(len(ident._window[r]) <= 200 for r in ("rudder", "heading", "yaw_rate"))


def test_estimate_log_rotates_by_size_and_appends_across_restarts(tmp_path):
    log = EstimateLog(tmp_path / "trip", max_bytes=1000, backups=2)
    for k in range(60):
        log.write({"stamp": float(k), "parameters": {"K": 0.5}, "predicted_yaw_rate": math.nan})
    EstimateLog(tmp_path / "trip", max_bytes=1000, backups=2).write({"stamp": 60.0})  # after a restart
    files = sorted((tmp_path / "trip").iterdir())
    assert [f.name for f in files] == ["estimates.jsonl", "estimates.jsonl.1", "estimates.jsonl.2"]
    assert all(f.stat().st_size <= 1000 for f in files)
    lines = [json.loads(line) for f in reversed(files) for line in f.read_text().splitlines()]
    stamps = [line["stamp"] for line in lines]
    assert stamps == sorted(stamps) and stamps[-1] == 60.0 and len(stamps) < 61  # oldest dropped
    assert lines[0]["predicted_yaw_rate"] is None  # strict JSON


def test_estimate_log_in_an_unwritable_place_is_a_config_error(tmp_path):
    (tmp_path / "file").write_text("")
    with pytest.raises(ConfigError, match="log_directory"):
        EstimateLog(tmp_path / "file" / "logs")


@pytest.mark.slow
def test_change_test_survives_a_clock_jump_back():
    """A clock reset (bag looped, simulator restarted) keeps detecting changes on the new time line."""
    sim = simulate("zigzag20", duration=440.0, seed=31, change=(400.0, LOADED))
    ident = OnlineIdentifier(OnlineConfig())
    list(run_schedule(ident, stream(sim.dataset.slice(0, 3000), start=1000.0)))  # 1000 .. 1300 s
    records = list(run_schedule(ident, stream(sim.dataset)))  # back to 0 s, on to 440 s
    assert ident.counts["clock_jumps"] == 1
    alarms = [r.time for r in records if "vessel_changed" in r.conditions]
    assert alarms and 400.0 < alarms[0] <= 430.0


@pytest.mark.slow
def test_nothing_absurd_is_published_after_a_vessel_changes():
    """The issue's scenario: a second-order vessel (T1 10.6 s, random rudder steps of +-25 deg) loses
    30 % of its gain while T1 grows 30 %: every estimate published as new is near the truth of its
    time, and after the change the K in force is never further from the new truth than the one before."""
    vessel = random_vessel(np.random.default_rng(1), "usv")
    k_old, t1 = vessel.parameters["K"], vessel.parameters["T1"]
    change = 300.0
    sim = simulate(
        "random",
        vessel,
        duration=480.0,
        seed=1,
        change=(change, {"K": 0.7 * k_old, "T1": 1.3 * t1, "T": vessel.parameters["T"] + 0.3 * t1}),
    )
    k_new = sim.info["truth_after"]["K"]
    records = list(run_schedule(OnlineIdentifier(OnlineConfig()), stream(sim.dataset)))
    new = [r for r in records if r.new_estimate]
    assert len(new) >= 0.8 * len([r for r in records if r.time >= 65.0])
    for r in new:
        k = r.estimate["parameters"]["K"]
        near = [abs(k / k_old - 1)] + ([abs(k / k_new - 1)] if r.time > change else [])
        assert min(near) < 0.1, (r.time, k)
    before = [r for r in records if r.time <= change][-1].estimate["parameters"]["K"]
    after = [r.estimate["parameters"]["K"] for r in records if r.time > change]
    assert all(abs(k - k_new) <= abs(before - k_new) + 0.05 * k_new for k in after), (before, after)
    assert abs(after[-1] / k_new - 1) < 0.05


def test_a_jump_beyond_its_uncertainty_or_a_worse_free_run_is_held(sim):
    """A window's estimate compared with a fabricated last good one: a far smaller gain with a tiny
    uncertainty makes the true estimate a jump of many standard errors that its free run justifies
    (accepted); a last good estimate equal to the truth is never replaced by a worse free run."""
    from ship_ident.estimators import make_estimator
    from ship_ident.online.trust import largest_jump

    config = OnlineConfig()
    window = sim.dataset.slice(0, 1800)
    structure = config.structure()
    estimate = make_estimator(config.method).fit(structure, window)
    trust = TrustPolicy()
    truth = replace(estimate, parameters=dict(estimate.parameters, **sim.truth))
    verdict = trust.plausibility(config, structure, estimate, window, truth)
    assert verdict is None or verdict.code == "misses_window"
    wrong = replace(
        estimate,
        parameters=dict(estimate.parameters, K=1.4 * estimate.parameters["K"]),
        std_errors=dict(estimate.std_errors, K=1e-4),
    )
    assert largest_jump(estimate, wrong)[0] > 100
    assert trust.plausibility(config, structure, estimate, window, wrong) is None  # its free run is clearly better
    reason = trust.plausibility(config, structure, wrong, window, estimate)
    assert reason.code == "misses_window" and reason.keeping
    assert reason.figures["new_mean_square"] > 1.25 * reason.figures["old_mean_square"]
    assert "misses the window more" in reason.sentence and "deg/s" in reason.sentence  # worded in deg/s
    bound = replace(estimate, parameters=dict(estimate.parameters, T1=1000.0))
    on_bound = trust.plausibility(config, structure, bound, window, None)
    assert on_bound.code == "on_bound" and on_bound.figures["bounds"] == [("T1", 1000.0, "s", 1000.0)]


def test_published_uncertainty_covers_the_scatter_of_successive_estimates():
    """Over 100 draws of 21 estimates (windows of 180 s, 5 s apart, estimator std 0.001 on K): an
    error of each fit's own (0.003 whatever the windows share) is published as about
    sqrt(0.001^2 + 0.003^2), not inflated by 1 / f = 36; estimates drifting 3.5 times their
    errors as the windows move (a missed effect) get about 3.5 times their errors; estimates that
    scatter within their errors keep them; 14 errors apart alternately, far wider errors."""
    from ship_ident.estimators.base import Estimate
    from ship_ident.online.uncertainty import EstimateScatter

    structure = OnlineConfig(model="nomoto1", effects=()).structure()
    fresh = 5.0 / 180.0

    def published(ks):
        scatter = EstimateScatter()
        estimates = [
            Estimate(
                structure, "x", {"K": k, "T": 50.0}, {"K": 0.001, "T": 1.0}, {}, 100, window=(5.0 * i, 180 + 5.0 * i)
            )
            for i, k in enumerate(ks)
        ]
        for estimate in estimates[:-1]:
            scatter.add(estimate)
        return scatter.honest(estimates[-1])

    rng = np.random.default_rng(7)
    own = [published(0.1 + 0.003 * rng.standard_normal(21))["K"] for _ in range(100)]
    assert np.median(own) == pytest.approx(math.hypot(0.001, 0.003), rel=0.15)
    drift = [
        published(0.1 + np.cumsum(0.001 * math.sqrt(12.5 * 2 * fresh) * rng.standard_normal(21)))["K"]
        for _ in range(100)
    ]
    assert 0.0025 < np.median(drift) < 0.0045  # phi^2 = 12.5: 0.0035
    steady = [published(0.1 + 0.001 * math.sqrt(2 * fresh) * rng.standard_normal(21)) for _ in range(100)]
    assert np.median([s["K"] for s in steady]) < 0.0011 and all(s["T"] == 1.0 for s in steady)
    assert published([0.10, 0.114] * 10 + [0.10])["K"] > 0.005


def _bench_case(seed: int, until: float):
    """The records of bench vessels' case ``seed`` (quick) up to ``until`` s, and its record."""
    from ship_ident.bench.peers import dataset_samples

    case = vessels.draw_case(seed, quick=True)
    sim = vessels.simulate_case(case)
    samples = [s for s in dataset_samples(sim.dataset) if s.time <= until]  # as the bench, from 0 s
    return list(run_schedule(OnlineIdentifier(case["config"]), samples)), sim


def test_a_biased_start_up_estimate_does_not_make_the_right_ones_after_it_look_scattered():
    """bench vessels' seed 799606246 USV (T1 1.73 s, mixed manoeuvre at 2x noise): its first
    windows sit at the foot of the T2 = T3 valley, T1 12 % low with a slide of 12-14 % (published
    uncertain). Entered into the scatter of successive estimates with the estimator's 5 % they
    made the right estimates after them (T1 within 1 %, +- 1.6 %) look scattered by three of their
    errors: published at +- 5-7 %, every well-excited refit from 155 to 225 s refused. Entered with
    their own slide, those are trusted."""
    records, sim = _bench_case(799606246, 230.0)
    later = [r for r in records if 160.0 <= r.time <= 230.0]
    assert len(later) >= 14
    assert sum(r.new_estimate and r.status == "OK" for r in later) >= len(later) - 1
    for r in later:
        parameters, errors = r.estimate["parameters"], r.estimate["std_errors"]
        assert abs(parameters["T1"] / sim.truth["T1"] - 1) < 0.03
        assert errors["T1"] < 0.03 * parameters["T1"]


def test_windows_sliding_off_the_steps_that_taught_them_keep_their_own_errors():
    """bench vessels' seed 799606292 USV (T1 1.72 s, mixed manoeuvre at 2x noise): from 305 s its
    windows slide off the steps onto straight legs, and successive estimates move 1-2 % in T1 with
    errors of 2 %, far more than the 5 s the windows do not share would allow (time shares: T1 at
    +- 4.4-5.1 %, every refit from 325 to 395 s refused). Judged by where each fit learnt T1 (its
    ``Influence``), the well-determined ones are trusted, and they are right."""
    records, sim = _bench_case(799606292, 400.0)
    later = [r for r in records if 340.0 <= r.time <= 400.0]
    trusted = [r for r in later if r.new_estimate and r.status == "OK"]
    assert len(trusted) >= 0.75 * len(later)
    for r in trusted:
        assert abs(r.estimate["parameters"]["T1"] / sim.truth["T1"] - 1) < 0.05


def test_min_rudder_std_below_the_default_floor_is_honoured():
    """Random rudder steps of at most 1.2 deg on seed 001's vessel, the refit at 60 s on a 60 s
    window whose rudder std is 0.68 deg: with ``min_rudder_std`` 0.5 deg it gives an estimate, K
    within 5 % of the truth; with the default 1 deg it is refused, the sentence naming the floor."""
    sim = simulate("random", duration=60.0, seed=1, amplitude=np.radians(1.2))
    window = dict(window_length=60.0, min_window_length=30.0)

    def refit_at_60_s(config):
        return next(r for r in run_schedule(OnlineIdentifier(config), stream(sim.dataset)) if r.time == 60.0)

    lowered = refit_at_60_s(OnlineConfig(min_rudder_std=np.radians(0.5), **window))
    assert lowered.new_estimate and "too_little_excitation" not in lowered.conditions
    assert abs(lowered.estimate["parameters"]["K"] / sim.truth["K"] - 1) < 0.05
    refused = refit_at_60_s(OnlineConfig(**window)).verdicts["too_little_excitation"]
    assert refused.code == "below_floors"
    assert "(the rudder hardly moves): rudder std 0.68 deg (need 1.00)" in refused.figures["shortfall"]


@pytest.mark.slow
def test_a_well_determined_window_is_used_whatever_its_yaw_rate_spread():
    """Random rudder steps of at most 3 deg: a yaw-rate spread of 3-4 noise levels (the old rule
    wanted 5) still determines K and T1, so it gives estimates; a rudder within 0.2 deg does not,
    and the sentence says the rudder hardly moves."""
    from ship_ident.estimators.base import excitation, excitation_shortfall

    sim = simulate("random", duration=400.0, seed=8, amplitude=np.radians(3.0))
    ex = excitation(sim.dataset)
    assert ex["yaw_rate_std"] < 5 * ex["yaw_rate_std_needed"] / 2
    records = list(run_schedule(OnlineIdentifier(OnlineConfig()), stream(sim.dataset)))
    new = [r for r in records if r.new_estimate]
    assert len(new) >= 0.9 * len([r for r in records if r.time >= 65.0])
    assert all(abs(r.estimate["parameters"]["K"] / sim.truth["K"] - 1) < 0.1 for r in new)
    still = simulate("zigzag10", duration=200.0, seed=2, amplitude=np.radians(0.2))
    assert "the rudder hardly moves" in excitation_shortfall(still.dataset)


def test_the_boat_hardly_turns_is_said_only_when_heading_and_yaw_rate_are_noise():
    """A slow ship's yaw rate (spread below twice its noise) with a heading that swings by degrees
    passes the floor; the same rudder with a heading and yaw rate that are only sensor noise is
    refused, and the sentence says the boat hardly turns."""
    from ship_ident.estimators.base import excitation, excitation_shortfall

    data = simulate("zigzag10", duration=600.0, seed=4).dataset
    rng = np.random.default_rng(4)
    slow = replace(data, yaw_rate=0.05 * data.yaw_rate + rng.normal(0.0, np.radians(0.2), data.time.size))
    ex = excitation(slow)
    assert ex["yaw_rate_std"] < ex["yaw_rate_std_needed"] < ex["heading_std"]
    assert excitation_shortfall(slow) is None
    noise_only = replace(
        data,
        yaw_rate=rng.normal(0.0, np.radians(0.2), data.time.size),
        heading=rng.normal(0.0, np.radians(0.1), data.time.size),
    )
    assert "the boat hardly turns" in excitation_shortfall(noise_only)


@pytest.mark.slow
@pytest.mark.parametrize("maneuver", ["random", "mixed"])
def test_a_changed_vessel_is_followed_within_10_s(maneuver):
    """bench peers' tracking scenarios: seed 001's vessel loses 30 % of K (T1 +30 %) at 600 s; the
    newest refit period's free run gives it away at the first refit the rudder moves in (the mixed
    manoeuvre holds it amidships until 607.5 s), and K refitted on the new data (T1 refitted or held
    as they allow) is within 5 % of the new value from 10 s on. The identifier runs from 300 s (a
    full window of the old vessel and two minutes of its refits) to 840 s (the new vessel alone in
    the window for a minute): the same alarms, recovery and errors as over the bench's 0-1200 s."""
    from ship_ident.bench.peers import dataset_samples, recovery_time

    change = 600.0
    sim = simulate(
        maneuver, "seed001", duration=2 * change, seed=31, change=(change, {"K": 0.7 * 0.5883, "T1": 1.3 * 1.4397})
    )
    samples = [s for s in dataset_samples(sim.dataset) if 300.0 <= s.time <= 840.0]
    records = list(run_schedule(OnlineIdentifier(OnlineConfig()), samples))
    alarms = [r.time for r in records if "vessel_changed" in r.conditions]
    assert alarms and change < alarms[0] <= change + 10.0
    times, ks = k_trace(records)
    assert recovery_time(times, ks, change, sim.info["truth_after"]["K"]) <= 10.0


@pytest.mark.slow
def test_a_change_found_between_refits_is_followed_every_tenth_of_a_refit_period():
    """bench peers --quick's random record: seed 001's vessel loses 30 % of K (T1 +30 %) at 240 s
    with the rudder amidships until 247.8 s. The quick change test, run between refits, finds it
    before the next scheduled refit (255 s), and the gain is refitted every tenth of a refit
    period from then on: K is back within 5 % of the new value 11 s after the change (on the
    refit period alone, change found and K refitted at 255 s: 15 s)."""
    from ship_ident.bench.peers import dataset_samples, recovery_time

    change, config = 240.0, OnlineConfig()
    sim = simulate(
        "random", "seed001", duration=2 * change, seed=31, change=(change, {"K": 0.7 * 0.5883, "T1": 1.3 * 1.4397})
    )
    records = list(run_schedule(OnlineIdentifier(config), dataset_samples(sim.dataset)))
    following = [r.time for r in records if "vessel_changed" in r.conditions]
    assert 247.8 < following[0] < 255.0 and following[0] % config.refit_period > 0
    cadence = np.diff(following[: 2 * WATCHES_PER_REFIT])
    assert np.allclose(cadence, config.refit_period / WATCHES_PER_REFIT, atol=0.05)
    assert not [r for r in records if r.time < change and "vessel_changed" in r.conditions]
    times, ks = k_trace(records)
    assert recovery_time(times, ks, change, sim.info["truth_after"]["K"]) <= 11.0
    # once the new data span min_window_length the refits are back at the refit period
    later = [r.time for r in records if r.time > following[0] + config.min_window_length + config.refit_period]
    assert np.allclose(np.diff(later), config.refit_period, atol=0.05)


@pytest.mark.slow
def test_a_gain_followed_through_a_clock_jump_keeps_its_pace():
    """The same record with every input silent for 7 s (more than a refit period) soon after the
    change is found: the clock jump restarts the schedule at the follow's pace (a tenth of a refit
    period), not at the refit period (the node's change-follow test, played fast beside other
    tests, once saw its follow's refits every 5 s after such a silence)."""
    from ship_ident.bench.peers import dataset_samples

    change, config = 240.0, OnlineConfig()
    sim = simulate(
        "random", "seed001", duration=300.0, seed=31, change=(change, {"K": 0.7 * 0.5883, "T1": 1.3 * 1.4397})
    )
    silent = (252.0, 259.0)
    samples = [s for s in dataset_samples(sim.dataset) if not silent[0] < s.time < silent[1]]
    ident = OnlineIdentifier(config)
    records = list(run_schedule(ident, samples))
    following = [r.time for r in records if "vessel_changed" in r.conditions]
    assert following[0] < silent[0] and ident.counts["clock_jumps"] == 1
    after = [t for t in following if t >= silent[1]][:WATCHES_PER_REFIT]
    assert len(after) == WATCHES_PER_REFIT and after[0] < silent[1] + 1.0
    assert np.allclose(np.diff(after), config.refit_period / WATCHES_PER_REFIT, atol=0.05)


def _losing_gain(
    vessel_seed: int, manoeuvre: str, noise_scale: float, seed: int, change: float, duration: float | None = None
):
    """bench vessels' vessel of ``vessel_seed`` on ``manoeuvre`` (noise scaled by ``noise_scale``),
    losing 30 % of K as T1 grows 30 % at ``change`` s, for ``duration`` s (twice ``change``)."""
    vessel = random_vessel(np.random.default_rng(vessel_seed))
    truth = vessel.parameters
    return simulate(
        manoeuvre,
        vessel,
        duration=duration or 2 * change,
        noise=Noise().scaled(noise_scale),
        seed=seed,
        change=(change, {"K": 0.7 * truth["K"], "T1": 1.3 * truth["T1"]}),
    )


@pytest.mark.slow
def test_a_rudder_held_in_a_turn_after_a_change_gives_the_new_K():
    """bench vessels' seed 5000 USV (T1 7.4 s) loses 30 % of K (T1 +30 %) as the mixed manoeuvre's
    zigzag ends and its 20 deg turn begins: the rudder then hardly moves, yet r = K delta determines
    K. K refitted on the turn (its start, mid-transient, fitted too) is within 5 % of the new value
    15 s after the change (45 s when a still rudder was refused and the free run started steady)."""
    from ship_ident.bench.peers import dataset_samples, recovery_time

    change = 200.0
    sim = _losing_gain(5000, "mixed", 0.5, 5000, change)
    held = (sim.dataset.time > change + 5) & (sim.dataset.time < change + 40)
    assert np.degrees(np.std(sim.dataset.rudder[held])) < 0.2  # the rudder is held
    samples = [s for s in dataset_samples(sim.dataset) if s.time <= change + 40]
    records = list(run_schedule(OnlineIdentifier(OnlineConfig()), samples))
    k_new = sim.info["truth_after"]["K"]
    assert recovery_time(*k_trace(records), change, k_new) <= 15.0
    assert all(abs(k / k_new - 1) < 0.05 for t, k in zip(*k_trace(records)) if t >= change + 15)


@pytest.mark.slow
def test_a_gain_lost_in_a_noisy_steady_turn_is_found():
    """bench vessels' seed 2367799915 USV (T1 4.7 s) in steady turns with twice the realistic noise
    loses 30 % of K (T1 +30 %) at 200 s: its yaw rate, 30 % low, shows only about 5x the usual
    free-run error (under change_ratio 9), but K refitted on the newest 30 s moves by 30 %: the
    change is found and K is back within 5 % 30 s after it (never with the error ratio alone)."""
    from ship_ident.bench.peers import dataset_samples, recovery_time

    change = 200.0
    sim = _losing_gain(2367799915, "steady_turns", 2.0, 2, change)
    samples = [s for s in dataset_samples(sim.dataset) if s.time <= change + 80]
    records = list(run_schedule(OnlineIdentifier(OnlineConfig()), samples))
    alarms = [r.time for r in records if "vessel_changed" in r.conditions]
    assert alarms and change < alarms[0] <= change + 30.0
    assert recovery_time(*k_trace(records), change, sim.info["truth_after"]["K"]) <= 30.0


@pytest.mark.slow
def test_the_gain_is_followed_while_full_fits_of_the_new_data_are_refused():
    """The steady-turn USV above (seed 2367799915, 2x noise) losing 30 % of K at 200 s, on a record
    whose turn after the change holds the rudder still: once the new data span min_window_length
    the full fits of them are refused (K only to 7 %: the held rudder leaves T1 open), and K
    refitted on all the new data with the time constants held (r = K delta in a steady turn) is
    published instead, within 2 % of the new K (1.0 %), the refusal saying so (before, K was no
    longer refitted once the new data spanned min_window_length). With the change located where it
    most likely happened (201 s), the full fits are refused once and accepted from 266.5 s."""
    from ship_ident.bench.peers import dataset_samples, recovery_time

    change, config = 200.0, OnlineConfig()
    sim = _losing_gain(2367799915, "steady_turns", 2.0, 2, change, duration=change + 80)
    start = change - config.window_length - 2 * config.refit_period  # one full window of the old hull
    samples = [s for s in dataset_samples(sim.dataset) if s.time >= start]
    records = list(run_schedule(OnlineIdentifier(config), samples))
    k_new = sim.info["truth_after"]["K"]
    assert recovery_time(*k_trace(records), change, k_new) <= 40.0  # the change found 35 s after it
    followed = [
        r
        for r in records
        if r.window[1] - r.window[0] >= config.min_window_length
        and r.new_estimate
        and any(verdict.keeping == FOLLOWED for verdict in r.verdicts.values())
    ]
    assert followed and all(abs(r.estimate["parameters"]["K"] / k_new - 1) < 0.02 for r in followed)


@pytest.mark.slow
def test_a_loose_full_fit_after_a_change_does_not_replace_the_followed_gain():
    """bench vessels' seed 3441109605 USV (T1 2.1 s, steps) losing 30 % of K at 270 s: K followed
    on the new data is within 1 % from 279 s; the first full fits of them (94 s of new data) leave
    T1 loose, and one gave K 7 % off with its error within the trusted 3 %. Published as
    uncertain_estimate it replaced the followed K until 379 s; now the followed K is kept until a
    full fit is trusted, and the K in force stays within 5 % once it got there."""
    from ship_ident.bench.peers import recovery_time

    change = vessels.draw_case(3441109605, quick=True)["change_time"]
    records, sim = _bench_case(3441109605, change + 110.0)
    k_new = sim.info["truth_after"]["K"]
    times, ks = k_trace(records)
    recovered = recovery_time(times, ks, change, k_new)
    assert recovered <= 15.0
    assert all(abs(k / k_new - 1) < 0.05 for t, k in zip(times, ks) if t >= change + recovered)
    held = [r.verdicts["uncertain_estimate"] for r in records if "uncertain_estimate" in r.verdicts]
    held = [v for v in held if v.code in ("followed_gain_kept", "better_gain_kept")]
    assert held and all(v.keeping == FOLLOWED for v in held)


@pytest.mark.slow
def test_the_gain_follow_holds_the_hull_before_the_change_not_a_mixture():
    """bench vessels' seed 3602010553 USV (T1 9.6 s, random steps at 1.5x noise) loses 30 % of K
    (T1 +30 %) at 270 s: the windows straddling the change publish K 64 % high with a cubic
    damping of 147 (truth 0.4) before the change is found at 295 s. K refitted on the new data
    with the rest held from the reference the change was declared against is 5 % off at the alarm
    and within 5 % 30 s after the change (held from that mixture it stayed 20 % high until 85 s)."""
    from ship_ident.bench.peers import dataset_samples, recovery_time

    change = 270.0
    sim = _losing_gain(3602010553, "steps", 1.500666675010122, 3602010553, change)
    samples = [s for s in dataset_samples(sim.dataset) if s.time <= change + 30]
    records = list(run_schedule(OnlineIdentifier(OnlineConfig()), samples))
    k_new = sim.info["truth_after"]["K"]
    alarm = next(i for i, r in enumerate(records) if "vessel_changed" in r.conditions)
    assert records[alarm - 1].estimate["parameters"]["K"] > 1.5 * k_new  # the mixture in force
    assert abs(records[alarm].estimate["parameters"]["K"] / k_new - 1) < 0.1
    assert recovery_time(*k_trace(records), change, k_new) <= 30.0


def test_a_model_whose_gain_is_loosely_known_is_no_change_reference():
    """bench vessels' seed 1747880341 USV (steady turns at 2.6x noise, nothing changes): at 245 s
    a window gives K 4.6 +- 4.1 % off with a cubic damping of 15.7 (truth -0.9), published as
    uncertain. It was a change reference all the same (its K within 5 %), and its free run missed
    the next turns: a false vessel_changed at 280 s, the window restarted on the true hull. A
    reference's K must be known as well as an OK estimate's (3 %)."""
    records, sim = _bench_case(1747880341, 300.0)
    uncertain = next(r for r in records if r.time == 245.0)
    assert "uncertain_estimate" in uncertain.conditions and uncertain.estimate["parameters"]["alpha"] > 10.0
    assert not any("vessel_changed" in r.conditions for r in records)
    assert all(r.status == "OK" for r in records if 260.0 <= r.time <= 300.0)


def test_a_change_in_a_steady_turn_is_placed_where_it_happened_when_t1_cannot_be_refitted():
    """bench vessels' seed 1764177395 USV (steady turns, cubic damping 7.5) loses 30 % of K at 270 s,
    found at 295 s. Locating it refits K and T1 after each candidate time; on the steady turn that
    search diverged (T1 to its bounds, free runs blowing up) at every candidate but the earliest,
    and the window restarted at 244 s: K followed on 26 s of the old hull ran 12-28 % high. The
    K-alone fit, a point of the same model, stands in where the search over both fails: the
    restart lies within 10 s of the change and K is within 5 % from the alarm on."""
    change = 270.0
    records, sim = _bench_case(1764177395, 300.0)
    k_new = sim.info["truth_after"]["K"]
    alarm = next(i for i, r in enumerate(records) if "vessel_changed" in r.conditions)
    restart = float(re.search(r"restarts at ([0-9.]+) s", records[alarm].conditions["vessel_changed"]).group(1))
    assert abs(restart - change) <= 10.0
    assert all(abs(r.estimate["parameters"]["K"] / k_new - 1) < 0.05 for r in records[alarm:])


def test_a_steady_turn_that_determines_the_gain_alone_is_a_change_reference():
    """bench vessels' seed 1747880361 USV (steady turns, T1 1.85 s) loses 30 % of K at 270 s: its
    full windows know K within 0.3 % and T1 only within 8-20 % (published uncertain). As change
    references they find the change within 10 s and K is followed within 5 % by 285 s; with only
    OK estimates as references it went unseen until the window had slid past it (180 s)."""
    change = 270.0
    records, sim = _bench_case(1747880361, 290.0)
    assert all(r.status == "WARN" for r in records if 180.0 <= r.time <= change)
    alarm = next(r for r in records if "vessel_changed" in r.conditions)
    assert change < alarm.time <= change + 10.0
    k_new = sim.info["truth_after"]["K"]
    assert all(abs(r.estimate["parameters"]["K"] / k_new - 1) < 0.05 for r in records if r.time >= change + 15.0)


@pytest.mark.slow
def test_the_gain_follow_holds_a_well_known_hull_not_one_bent_by_the_change():
    """bench vessels' seed 4110273366 USV (steady turns, T2 0.98 s near T3 1.08 s) loses 30 % of K
    at 270 s, as it goes straight: the change shows only when it turns again, at 400 s. The
    windows straddling the change published uncertain estimates (K 18 % high, cubic damping -38
    for 26.7, T2 0.01 s); one of them was the reference the change was declared against, and K
    followed with its hull held was 20 % low at +- 1 %. Held from the last hull whose K is known
    within 3 % (270 s), the followed K is within 2 % of the new truth from the alarm on."""
    change = 270.0
    records, sim = _bench_case(4110273366, 405.0)
    k_new = sim.info["truth_after"]["K"]
    alarm = next(i for i, r in enumerate(records) if "vessel_changed" in r.conditions)
    assert records[alarm].time > change + 100.0
    assert any("uncertain_estimate" in r.conditions for r in records if change < r.time < records[alarm].time)
    followed = [r.estimate["parameters"]["K"] for r in records[alarm:]]
    assert len(followed) >= 8 and all(abs(k / k_new - 1) < 0.02 for k in followed)


def test_a_full_window_at_an_odd_sample_time_calibrates_the_change_test():
    """61.3 s at 0.37 s: the resampled window spans 2-3 sample times less than window_length (its
    newest sample a step old, the grid's floor); it is still full, and its estimates become the
    change test's references (with a margin of 1.5 steps none did: a changed vessel went unseen)."""
    config = OnlineConfig(window_length=61.3, sample_time=0.37, min_window_length=30.0)
    sim = simulate("random", duration=135.0, sample_time=0.37, seed=1)
    ident = OnlineIdentifier(config)
    records = list(run_schedule(ident, stream(sim.dataset)))
    assert sum(r.new_estimate for r in records) >= 15
    assert len(ident._change.references) >= 5


def test_a_last_good_estimate_that_diverges_blocks_nothing(sim):
    """A last good estimate whose free run runs away on the new window (a cubic damping far below
    the stability limit of the turn rates seen) is no yardstick: a good new estimate replaces it."""
    from ship_ident.estimators import make_estimator

    config = OnlineConfig()
    structure, window = config.structure(), sim.dataset.slice(0, 1800)
    estimate = make_estimator(config.method).fit(structure, window)
    runaway = replace(estimate, parameters=dict(estimate.parameters, alpha=-100.0 / np.max(window.yaw_rate) ** 2))
    assert not np.all(np.isfinite(structure.simulate(runaway.parameters, window)[1]))
    assert TrustPolicy().plausibility(config, structure, estimate, window, runaway) is None


def test_fit_quality_is_judged_against_what_the_noise_allows():
    """A perfect model's free run correlates with a yaw rate measured through white noise of std s
    by sqrt(1 - s^2 / var): 0.77 for a yaw rate spreading 1.6 times its noise, so a slow ship's
    right model is not a poor fit at 0.8."""
    rng = np.random.default_rng(2)
    truth = np.sin(np.linspace(0, 40, 4000)) * np.sqrt(3) * 0.01  # variance 1.5e-4 (rad/s)^2
    measured = truth + rng.normal(0, 0.01, truth.size)  # total variance 2.5e-4: noise 0.01 rad/s
    best = noise_limited_correlation(measured, 0.01)
    assert best == pytest.approx(np.corrcoef(truth, measured)[0, 1], abs=0.01)
    assert best == pytest.approx(np.sqrt(1 - 1 / 2.5), abs=0.01)


@pytest.mark.slow
def test_a_hull_whose_rudder_lead_cancels_its_lag_publishes_T1_as_uncertain():
    """T3 2.8 s against T1 3 s: the zero nearly cancels the slow pole, the data determine K to 0.2 %
    but T1 only to 5-15 %: such estimates are published with their errors as uncertain_estimate
    (WARN), never as OK with T1 more than 10 % off."""
    from ship_ident.model.simulator import _EFFECT_TRUTH, Vessel

    truth = dict(_EFFECT_TRUTH, K=0.3, T1=3.0, T2=0.5, T3=2.8, T=0.7, alpha=2.0, delta_r=0.01)
    vessel = Vessel("cancel", "rudder lead near the slow lag", truth, seed_effects=("rudder_offset", "cubic_yaw"))
    sim = simulate("steps", vessel, duration=300.0, seed=3)
    records = [r for r in run_schedule(OnlineIdentifier(OnlineConfig()), stream(sim.dataset)) if r.new_estimate]
    uncertain = [r for r in records if "uncertain_estimate" in r.conditions]
    assert len(uncertain) >= 10 and all(r.status == "WARN" for r in uncertain)
    verdict = uncertain[0].verdicts["uncertain_estimate"]
    assert verdict.code == "published_uncertain" and "T1" in verdict.figures["loose"]
    for r in records:
        assert abs(r.estimate["parameters"]["K"] / truth["K"] - 1) < 0.02
        if r.status == "OK":
            assert abs(r.estimate["parameters"]["T1"] / truth["T1"] - 1) < 0.1


def test_sample_window_keeps_the_newest_samples_in_time_order_across_its_buffer_end():
    """A window of 5 samples fed 23 at 10 Hz (the buffer's end passed twice) holds the newest 5;
    pruning at 2.05 s leaves those stamped from 2.1 s; a read from 2.15 s only the newest 2."""
    from ship_ident.online.window import SampleWindow

    window = SampleWindow(5)
    for i in range(23):
        window.append(0.1 * i, float(i))
    assert window.array()[:, 1].tolist() == [18.0, 19.0, 20.0, 21.0, 22.0]
    window.prune(2.05)
    assert window.array()[:, 1].tolist() == [21.0, 22.0] and len(window) == 2
    assert window.array(2.15)[:, 1].tolist() == [22.0]
    window.append(2.3, 23.0)
    assert window.array()[:, 0] == pytest.approx([2.1, 2.2, 2.3])
    window.clear()
    assert window.array().shape == (0, 2)


def test_scatter_of_recent_estimates_is_the_same_kept_pair_by_pair_as_computed_afresh():
    """Estimates of a quick hull's K from windows sliding 5 s: 26 published (the oldest leave the
    SCATTER_PAIRS kept), some judged and not published between them, give the newest the very
    errors a scatter holding only the last SCATTER_PAIRS of them gives."""
    from ship_ident.estimators.base import Estimate
    from ship_ident.online.uncertainty import SCATTER_PAIRS, EstimateScatter

    structure = OnlineConfig(model="nomoto1", effects=()).structure()
    rng = np.random.default_rng(3)
    estimates = [
        Estimate(
            structure,
            "x",
            {"K": 0.1 + 0.003 * rng.standard_normal(), "T": 2.0 + 0.05 * rng.standard_normal()},
            {"K": 0.001 * (1 + i % 3), "T": 0.04},
            {},
            100,
            window=(5.0 * i, 180 + 5.0 * i),
        )
        for i in range(27)
    ]
    kept, afresh = EstimateScatter(), EstimateScatter()
    for i, estimate in enumerate(estimates[:-1]):
        kept.honest(estimate)
        if i % 4 == 1:
            kept.honest(estimates[-1])  # judged, refused: not added
        kept.add(estimate)
    for estimate in estimates[-1 - SCATTER_PAIRS : -1]:
        afresh.add(estimate)
    honest = kept.honest(estimates[-1])
    assert honest == afresh.honest(estimates[-1])
    assert honest["K"] > 0.001 and honest["T"] > 0.04


def test_quick_change_test_takes_the_largest_median_of_the_newest_samples():
    """Squared errors of a hull that changed 25 samples ago (124 times its level then, falling to 100
    times since, the 30 before at the level): the largest median over the newest 20 or more is the
    median of all 25 since the change; a NaN among the newest 20 gives NaN, one further back ends
    the suffixes before it."""
    from ship_ident.online.change import largest_newest_median

    squared = np.concatenate([np.full(30, 1.0), np.linspace(124.0, 100.0, 25)])
    assert largest_newest_median(squared, 20) == 112.0
    assert largest_newest_median(squared, 20) == max(np.median(squared[-k:]) for k in range(20, 56))
    lost = squared.copy()
    lost[-10] = np.nan
    assert math.isnan(largest_newest_median(lost, 20))
    lost = squared.copy()
    lost[-23] = np.nan  # the suffixes of 20 to 22 samples only
    assert largest_newest_median(lost, 20) == 110.5


def test_a_valley_slide_is_profiled_again_where_it_can_decide_whether_t1_is_trusted(monkeypatch):
    """A quick USV's T1 1.5 s at +- 0.3 % with T2 0.05 +- 0.1 s (undetermined): its slide along the
    T2 = T3 valley (profiled: 0.2 s, 13 %, far above the 4 % trusted limit) is reused by the next
    window, 5 s on, at the same point of the valley; a window 35 s on, or one whose T1 moved by a
    standard error, is profiled afresh, and a slide at the limit (0.06 s, 4 %) is profiled every time."""
    from ship_ident.estimators.base import Estimate
    from ship_ident.online import uncertainty

    structure = OnlineConfig().structure()
    profiled = []
    slides = iter((0.2, 0.2, 0.06, 0.06, 0.06))

    def profile(estimate, estimator, structure, dataset):
        profiled.append(estimate.window)
        return next(slides)

    monkeypatch.setattr(uncertainty, "valley_slide", profile)
    errors = {"K": 0.001, "T1": 0.005, "T2": 0.1, "T3": 0.1, "delta_r": 0.001, "alpha": 1.0}
    valley = uncertainty.ValleyProfile()
    for start, t1, slide, count in (
        (0.0, 1.5, 0.2, 1),
        (5.0, 1.5, 0.2, 1),  # reused
        (35.0, 1.5, 0.2, 2),  # too few samples shared
        (40.0, 1.505, 0.06, 3),  # T1 moved by its error
        (45.0, 1.505, 0.06, 4),  # at the limit
        (50.0, 1.505, 0.06, 5),
    ):
        parameters = {"K": 0.5, "T1": t1, "T2": 0.05, "T3": 0.1, "delta_r": 0.0, "alpha": 5.0}
        estimate = Estimate(structure, "m", parameters, errors, {}, 1800, window=(start, start + 180.0))
        assert valley.slide(estimate, errors, None, structure, None) == slide
        assert len(profiled) == count, start
