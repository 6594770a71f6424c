"""The diagnosis on board (online_diagnosis): the online core's window diagnosed on its schedule,
on simulated trips with known hidden effects."""

import copy
import math
import os
import pickle
import signal
import threading
import time
from dataclasses import replace

import numpy as np
import pytest

from ship_ident.bench.peers import dataset_samples
from ship_ident.diagnosis.onboard import (
    DiagnosisWorker,
    OnlineDiagnosis,
    PooledEvidence,
    diagnose_window,
    run_heading_squares,
    slice_sums,
    tight_turns,
)
from ship_ident.model.simulator import Vessel, random_vessel, simulate
from ship_ident.online.config import OnlineConfig
from ship_ident.online.identifier import OnlineIdentifier, run_schedule

SEED_EFFECTS = ("rudder_offset", "cubic_yaw")  # the seed001 vessel's own, and the node's default model


def diagnosed(sim, config, until=None):
    """(record, diagnosis) of every refit at which a diagnosis finished, replayed as the node runs;
    stops after the first for which ``until(diagnosis)`` is true."""
    out = []
    for record in run_schedule(OnlineIdentifier(config), dataset_samples(sim.dataset), OnlineDiagnosis()):
        if record.diagnosis is not None:
            out.append((record, record.diagnosis))
            if until is not None and until(record.diagnosis):
                break
    return out


@pytest.mark.slow
def test_a_hidden_wind_is_named_added_by_itself_and_the_held_out_error_halves():
    """A steady wind's heading-dependent yaw moment, hidden: a single window's t is weak (1.5-2.5), the
    pooled verdict names wind_yaw within three periods after the window fills; auto-add adds it
    after three diagnoses in a row and keeps it, the held-out error down by more than half and within
    the noise margin within two diagnoses of the add."""
    window, period = 120.0, 30.0
    config = OnlineConfig(
        window_length=window, refit_period=10.0, diagnosis_period=period, auto_add_effects=True, auto_add_after=3
    )
    sim = simulate("random", effects=SEED_EFFECTS + ("wind_yaw",), duration=400.0, seed=1)
    events = diagnosed(sim, config)
    done = [d for _, d in events if d["status"] == "done"]
    assert [d["reason"] for _, d in events if d["status"] == "skipped"][0].startswith("the window holds")
    named_record, named = next((r, d) for r, d in events if d.get("verdict") == "missing_effect")
    assert named["candidates"][0]["effect"] == "wind_yaw" and named["stamp"] <= window + 3 * period
    assert named["add_command"] == 'ros2 param set /ship_ident effects "[rudder_offset, cubic_yaw, wind_yaw]"'
    assert "wind_yaw is missing" in named_record.conditions["missing_effect"]
    assert named["held_out_error"] > 2 * named["noise_floor"]
    added = next(d for d in done if d.get("auto_add", {}).get("action") == "added")
    streak = done[done.index(added) - 2 : done.index(added) + 1]
    assert all(d["verdict"] == "missing_effect" and d["candidates"][0]["effect"] == "wind_yaw" for d in streak)
    kept = next(d for d in done if d.get("auto_add", {}).get("action") == "kept")
    assert kept["structure"]["effects"] == list(SEED_EFFECTS) + ["wind_yaw"]
    assert kept["stamp"] <= added["stamp"] + 2 * window
    assert kept["held_out_error"] <= 0.5 * named["held_out_error"]  # measured: 5.7 -> 1.5 noise floors
    after = done[done.index(added) + 1 : done.index(added) + 3]  # measured: 1.46, then 0.88 noise floors
    assert any(d["held_out_error"] < 1.25 * d["noise_floor"] for d in after)
    assert all(d["verdict"] != "missing_effect" for d in done[done.index(added) + 1 :])
    assert "missing_effect" not in events[-1][0].conditions


@pytest.mark.slow
def test_nothing_hidden_raises_no_missing_effect_in_a_15_minute_trip():
    """The model the boat has: 14 diagnoses over 15 min (a trip of ``bench onboard-diagnosis``, whose
    none trips hold 30 more), none missing_effect, nothing auto-added, the held-out error at the
    noise floor."""
    config = OnlineConfig(window_length=120.0, refit_period=30.0, diagnosis_period=60.0, auto_add_effects=True)
    sim = simulate("random", effects=SEED_EFFECTS, duration=900.0, seed=1)
    events = diagnosed(sim, config)
    done = [d for _, d in events if d["status"] == "done"]
    assert len(done) >= 12
    assert not [d["verdict_sentence"] for d in done if d["verdict"] == "missing_effect"]
    assert not any("auto_add" in d for d in done)
    assert not any("missing_effect" in r.conditions for r, _ in events)
    ratios = sorted(d["held_out_error"] / d["noise_floor"] for d in done)
    assert ratios[len(ratios) // 2] < 1.1


def windows(sim, length, count, model_effects, step=None):
    """``diagnose_window`` of ``count`` successive windows of ``length`` s (every ``step`` s)."""
    data, step = sim.dataset, step or length
    n, k = int(round(length / 0.1)), int(round(step / 0.1))
    return [
        diagnose_window(data.slice(i * k, i * k + n), "nomoto2", model_effects, float(data.time[i * k + n - 1]))
        for i in range(count)
    ]


@pytest.mark.slow
def test_auto_add_removes_an_effect_that_does_not_cut_the_held_out_error_and_the_model_resumes_its_evidence():
    """The gyro reads high (named three times in a row: added); then the gyro is recalibrated and a
    wind rises: with gyro_bias in the model the held-out error does not fall in two diagnoses, so
    auto-add removes it again and does not add it back. The model back in force goes on from its own
    three slices (the vessel did not change), and its verdict says the effect was tried."""
    gyro = simulate("random", effects=SEED_EFFECTS + ("gyro_bias",), duration=270.0, seed=1)
    wind = simulate("random", effects=SEED_EFFECTS + ("wind_yaw",), duration=400.0, seed=1)
    with_gyro = SEED_EFFECTS + ("gyro_bias",)
    before = OnlineConfig(window_length=90.0, auto_add_effects=True, auto_add_after=3)  # full windows
    after = before.changed(effects=with_gyro)
    diagnosis = OnlineDiagnosis()
    named = windows(gyro, 90.0, 3, SEED_EFFECTS)
    named_again = copy.deepcopy(named)
    assert [diagnosis.finish(d, before) for d in named] == [None, None, with_gyro]
    assert named[-1]["auto_add"]["action"] == "added" and named[-1]["candidates"][0]["effect"] == "gyro_bias"
    useless = windows(wind, 120.0, 2, with_gyro, step=60.0)
    assert all(d["held_out_error"] > 0.85 * named[-1]["held_out_error"] for d in useless)
    assert diagnosis.finish(useless[0], after) is None  # one diagnosis of grace
    assert diagnosis.finish(useless[1], after) == SEED_EFFECTS
    assert useless[1]["auto_add"]["action"] == "removed" and "did not fall" in useless[1]["auto_add"]["sentence"]
    for d in named_again:  # named again: not added again
        assert diagnosis.finish(d, before) is None
    assert named_again[-1]["verdict"] == "missing_effect" and "auto_add" not in named_again[-1]
    assert named_again[0]["pooled"]["since"] == "the start" and named_again[0]["pooled"]["slices"] == 4
    assert "auto-add tried it and removed it again" in named_again[-1]["verdict_sentence"]


def test_a_window_that_cannot_support_a_diagnosis_is_skipped_with_the_reason():
    sim = simulate("random", effects=SEED_EFFECTS, duration=120.0, seed=2)
    short = diagnose_window(sim.dataset.slice(0, 600), "nomoto2", SEED_EFFECTS, 60.0)
    assert short["status"] == "skipped" and "the window holds 60 s; a diagnosis needs 86 s" in short["reason"]
    still = simulate("random", effects=SEED_EFFECTS, duration=120.0, seed=2, amplitude=0.0)
    quiet = diagnose_window(still.dataset, "nomoto2", SEED_EFFECTS, 120.0)
    assert quiet["status"] == "skipped" and quiet["reason"].startswith("too little excitation")
    no_speed = diagnose_window(replace(sim.dataset, speed=None), "nomoto2", ("speed_dependence",), 120.0)
    assert no_speed["status"] == "skipped" and no_speed["reason"].startswith("fit failed: speed_dependence needs")


@pytest.mark.slow
def test_the_worker_diagnoses_in_a_child_process_one_at_a_time():
    sim = simulate("random", effects=SEED_EFFECTS + ("gyro_bias",), duration=100.0, seed=3)
    worker = DiagnosisWorker()
    try:
        worker.submit((sim.dataset, "nomoto2", SEED_EFFECTS, 100.0, -math.inf))
        assert worker.busy
        deadline = time.monotonic() + 120.0
        while (result := worker.poll()) is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not worker.busy
        assert result["status"] == "done" and result["candidates"][0]["effect"] == "gyro_bias"
        assert result["compute_seconds"] > 0
        assert result["held_out_slice"]["seconds"] == pytest.approx(35.0, abs=0.2)  # all of it is fresh
    finally:
        worker.close()
    assert not math.isnan(result["held_out_error"])


def test_a_ships_ten_minute_window_is_handed_to_a_child_that_cannot_read_yet_without_holding_the_refit():
    """A slow ship's 600 s window pickles to far more than a pipe holds (64 KiB): a child that cannot
    read yet (stopped here, as one still importing at low priority on a loaded machine is in
    effect) must not hold the refit thread that submits it. Once the child runs, it reads the whole
    window and its answer comes back: the ship held its rudder amidships, too little excitation (an
    answer the child gives at once, so the test does not wait on a diagnosis at low priority)."""
    ship = random_vessel(np.random.default_rng(3), "ship")
    sim = simulate("random", vessel=ship, duration=600.0, seed=3, amplitude=0.0)
    job = (sim.dataset, "nomoto2", (), 600.0, -math.inf)
    assert len(pickle.dumps(job)) > 4 * 65536
    worker = DiagnosisWorker()
    try:
        worker.start()
        os.kill(worker._process.pid, signal.SIGSTOP)
        submitting = threading.Thread(target=worker.submit, args=(job,), daemon=True)
        submitting.start()
        submitting.join(timeout=30.0)
        held = submitting.is_alive()
        os.kill(worker._process.pid, signal.SIGCONT)
        assert not held, "submit waited for the child to read the window"
        deadline = time.monotonic() + 300.0
        while (result := worker.poll()) is None and time.monotonic() < deadline:
            time.sleep(0.2)
        assert result is not None and result["stamp"] == 600.0 and result["status"] == "skipped"
        assert result["reason"].startswith("too little excitation")
        assert result["window"] == {"start": 0.0, "end": float(sim.dataset.time[-1])}
    finally:
        worker.close()


# --- the pooled evidence, on held-out errors drawn here --------------------------------------
NOISE = math.radians(0.2)  # rad/s, the yaw-rate noise floor of the drawn errors
SLICE = np.arange(600) * 0.1  # s, a minute of held-out samples at 10 Hz
TURNS = math.radians(3.0) * np.sin(2 * np.pi * SLICE / 45.0)  # rad/s, the yaw rate measured over the slice
DEFAULT_WINDOW_S = OnlineConfig().window_length  # s


def swell(period: float, amplitude: float = 2.0) -> np.ndarray:
    """A smooth yaw-rate error (rad/s) the model misses: ``amplitude`` noise levels, ``period`` s."""
    return amplitude * NOISE * np.sin(2 * np.pi * SLICE / period)


def drawn_diagnosis(
    stamp: float, missed, left: dict, rng, training_gain: float = 0.1, window_s: float = DEFAULT_WINDOW_S
) -> dict:
    """A finished diagnosis of nomoto2 without effects whose held-out slice, a minute ending at
    ``stamp`` (s), has the yaw-rate error ``missed`` (rad/s) beside the sensor noise (drawn here)
    with the model, and ``left[name]`` with each candidate, whose training free runs gain
    ``training_gain``; its window held ``window_s`` (s, the default configuration's full window)."""
    noise = NOISE * rng.standard_normal(len(SLICE))
    names = ["model", *left]
    rows = [noise + missed] + [noise + left[name] for name in left]
    piece = slice_sums(stamp - 60.0 + SLICE, 0.1, names, rows, [0.0] + [training_gain] * len(left), NOISE, TURNS)
    return finished(stamp, piece, window_s, held_out_error=float(np.sqrt(np.mean(rows[0] ** 2))), noise_floor=NOISE)


def finished(stamp: float, piece: dict, window_s: float, **figures) -> dict:
    """A finished diagnosis of nomoto2 without effects at ``stamp`` (s), its held-out slice's sums
    ``piece`` (its candidates the slice's rows after the model's), its window ``window_s`` (s) long."""
    return {
        "stamp": stamp,
        "status": "done",
        "structure": {"model": "nomoto2", "effects": []},
        "verdict": "unexplained",
        "verdict_sentence": "",
        "candidates": [{"effect": name, "significant": False, "evidence": "drawn"} for name in piece["names"][1:]],
        "pinned": [],
        "held_out_slice": piece,
        "window": {"start": stamp - window_s + 0.1, "end": stamp},
        **figures,
    }


def test_a_slice_where_a_candidate_runs_as_the_model_adds_no_evidence_either_way():
    rng = np.random.default_rng(1)
    shows = drawn_diagnosis(60.0, swell(20.0), {"cubic_yaw": 0.0}, rng)["held_out_slice"]  # cubic_yaw removes it
    quiet = drawn_diagnosis(120.0, 0.0, {"cubic_yaw": 0.0}, rng)["held_out_slice"]  # nothing to remove: alike
    pool = PooledEvidence(shows["names"])
    pool.add(shows)
    t, share = pool.t_statistic("model", "cubic_yaw"), pool.improvement("cubic_yaw")
    pool.add(quiet)
    assert pool.t_statistic("model", "cubic_yaw") == pytest.approx(t)
    assert t > 3 and pool.improvement("cubic_yaw") < share  # the share dilutes, the evidence stays
    assert pool.seconds == pytest.approx(120.0)


def test_an_effect_the_gyro_noise_half_hides_is_named_when_it_removes_most_of_the_error_above_the_floor():
    """The model misses a swell of 0.6 noise levels (its held-out error 1.09 times the floor): the
    effect that explains it removes 8 % of the total error, below the 15 % asked of the total, but
    most of the error above the floor (the floor's own sampling scatter keeps it from all). Named
    once its t holds, with a clear training gain; with a training gain of 5 % (as a candidate
    fitting the noise would show) not at t 4.6, only once its t is beyond doubt (measured 6.7 on
    two minutes)."""
    names, sentences = {}, {}
    for gain in (0.12, 0.05):
        rng = np.random.default_rng(3)
        diagnosis = OnlineDiagnosis()
        results = []
        for k in range(8):
            result = drawn_diagnosis(60.0 * (k + 1), swell(20.0, 0.6), {"cubic_yaw": 0.0}, rng, gain)
            diagnosis.finish(result, OnlineConfig(effects=()))
            results.append(result)
        names[gain] = [r["verdict"] == "missing_effect" for r in results]
        last = results[-1]
        sentences[gain] = last["verdict_sentence"]
        assert last["pooled"]["held_out_error"] / last["pooled"]["noise_floor"] == pytest.approx(1.09, abs=0.02)
        pooled = last["candidates"][0]["pooled"]
        assert pooled["improvement_yaw_rate"] < 0.15 and pooled["excess_removed"] > 0.7  # measured 8 %, 78 %
    assert names[0.12][-1] and "of what lies above the noise floor" in sentences[0.12]
    assert names[0.05][:2] == [False, True] and all(names[0.05][1:])


def test_the_named_effect_changes_only_when_the_pooled_evidence_reverses():
    """cubic_yaw explains the first two minutes; quiet minutes keep it named (no evidence against
    it); then minutes that quadratic_yaw explains and cubic_yaw does not: once they outweigh the
    first, the pooled evidence reverses, quadratic_yaw is named, once, and the sentence says why."""
    rng = np.random.default_rng(2)
    config = OnlineConfig(effects=())
    diagnosis = OnlineDiagnosis()
    first, second = swell(20.0), swell(30.0)
    plan = [(first, {"cubic_yaw": 0.0, "quadratic_yaw": 0.7 * first})] * 2
    plan += [(0.0, {"cubic_yaw": 0.0, "quadratic_yaw": 0.0})] * 3
    plan += [(second, {"cubic_yaw": second, "quadratic_yaw": 0.0})] * 6
    results = []
    for k, (missed, left) in enumerate(plan):
        result = drawn_diagnosis(60.0 * (k + 1), missed, left, rng)
        assert diagnosis.finish(result, config) is None  # auto-add is off
        results.append(result)
    names = [r["candidates"][0]["effect"] if r["verdict"] == "missing_effect" else None for r in results]
    print(names, [r["verdict_sentence"] for r in results])
    assert names[:5] == ["cubic_yaw"] * 5
    switch = names.index("quadratic_yaw")
    assert switch > 5 and set(names[switch:]) == {"quadratic_yaw"}
    assert "pooled evidence reversed" in results[switch]["verdict_sentence"]
    assert results[4]["verdict_sentence"].startswith("cubic_yaw is missing: on the 5.0 min of held-out data since")


def test_a_tankers_named_course_instability_stays_named_when_the_newest_window_lists_it_as_cubic_damping():
    """Minutes where course_instability removes the error the model misses name it. Then a window
    whose course_instability fit shows a course-stable hull lists it as cubic_yaw's model (cubic_yaw
    twice, course_instability not at all), and its slice counts course_instability with the model's
    errors: the name rests on the pooled minutes, the record lists it first with no refit of its
    own, and the diagnosis (on board, a refit's tick) goes through."""
    rng = np.random.default_rng(4)
    config = OnlineConfig(effects=())
    diagnosis = OnlineDiagnosis()
    missed = swell(20.0)
    for k in range(3):
        result = drawn_diagnosis(60.0 * (k + 1), missed, {"course_instability": 0.0, "cubic_yaw": 0.5 * missed}, rng)
        diagnosis.finish(result, config)
    assert result["verdict"] == "missing_effect" and result["candidates"][0]["effect"] == "course_instability"
    newest = drawn_diagnosis(240.0, missed, {"course_instability": missed, "cubic_yaw": 0.0}, rng)
    newest["candidates"] = [dict(newest["candidates"][1]), newest["candidates"][1]]  # cubic_yaw twice
    diagnosis.finish(newest, config)
    named = newest["candidates"][0]
    assert newest["verdict"] == "missing_effect" and named["effect"] == "course_instability"
    assert named["note"] == "not refitted here" and named["parameters"] is None
    assert newest["add_command"].endswith('effects "[course_instability]"')


@pytest.mark.slow
def test_a_quick_boat_whose_yaw_damping_grows_with_the_cube_of_the_turn_rate_is_named_once_and_fixed():
    """A 15-minute trip of random rudder steps on a boat whose yaw damping has a cubic part (K
    0.33 1/s, T1 8.7 s, T2 0.86 s, T3 2.1 s, alpha 17.8 s^2/rad^2), diagnosed every minute with
    nomoto2 + rudder_offset: the tight turns that show the cubic damping come seldom, and a
    window without them holds no evidence either way. Pooled since the start, cubic_yaw is named
    (measured at 360 s, on 4.7 min of held-out data), never another effect; auto-add adds it after
    three diagnoses and the next diagnosis' held-out error is at the noise floor."""
    boat = Vessel(
        "cubic damping",
        "a quick boat whose yaw damping grows with the cube of the turn rate",
        dict(K=0.33, T1=8.7, T2=0.86, T3=2.1, alpha=17.8),
        speed=3.0,
    )
    sim = simulate("random", boat, effects=("cubic_yaw",), duration=900.0, seed=1)
    config = OnlineConfig(effects=("rudder_offset",), diagnosis_period=60.0, auto_add_effects=True)
    done = [d for _, d in diagnosed(sim, config) if d["status"] == "done"]
    named = [d for d in done if d["verdict"] == "missing_effect"]
    print([(d["stamp"], d["verdict"], d["verdict_sentence"][:80]) for d in done])
    assert named and named[0]["stamp"] <= 600.0  # measured: 360 s
    assert {d["candidates"][0]["effect"] for d in named} == {"cubic_yaw"}
    assert "of held-out data since the start" in named[0]["verdict_sentence"]
    added = next(k for k, d in enumerate(done) if d.get("auto_add", {}).get("action") == "added")
    assert done[added]["auto_add"]["effects"] == ["rudder_offset", "cubic_yaw"]
    after = done[added + 1]
    assert after["structure"]["effects"] == ["rudder_offset", "cubic_yaw"] and after["verdict"] != "missing_effect"
    assert after["held_out_error"] <= 1.25 * after["noise_floor"]
    assert after["pooled"]["since"] == "rudder_offset+cubic_yaw came into force"


def alike_at_tight_turns(samples: int, squares: list) -> dict:
    """A slice's tight-turn sums (``tight_turns``) where every row misses as much at the tight turns as
    elsewhere: half the samples, half of each row's squared error."""
    return {"tight_samples": samples // 2, "tight_squares": [square / 2 for square in squares]}


def pooled(
    model_over_floor: float, candidate_over_floor: float, t: float, seconds: float = 60.0, weight: float = 1.0
) -> PooledEvidence:
    """A pool of one slice of ``seconds`` at 10 Hz whose model error and candidate error are the
    given multiples of a 0.01 rad/s noise floor, the candidate's t on the squared-error drop ``t``,
    the slice counting ``weight`` (its window's share of the configured length)."""
    samples, floor = int(round(10 * seconds)), 0.01
    model, candidate = (samples * (ratio * floor) ** 2 for ratio in (model_over_floor, candidate_over_floor))
    variance = ((model - candidate) / t) ** 2
    pool = PooledEvidence(["model", "cubic_yaw"])
    pool.add(
        {
            "start": 0.0,
            "samples": samples,
            "seconds": seconds,
            "squares": [model, candidate],
            "pair_variance": [[0.0, variance], [variance, 0.0]],
            "training_gain": [0.0, samples * 0.2],
            "noise_squares": samples * floor**2,
            **alike_at_tight_turns(samples, [model, candidate]),
        },
        weight,
    )
    return pool


def test_a_tankers_slice_held_out_by_a_window_two_minutes_into_ten_names_nothing_alone():
    """An MMG tanker's first diagnosis: its ten-minute window two minutes full holds out 42 s, where
    a candidate takes the error from 4.6 noise floors to 1.5 at t 3.2. A fit on a fifth of the window
    has not seen the hull's slow dynamics: nothing is named until the pool holds 30 s counted as from
    full windows. The same slice from a full window names it."""
    early = pooled(4.6, 1.5, 3.2, seconds=42.0, weight=0.2)
    assert early.full_window_seconds == pytest.approx(8.4)
    assert not early.determines and not early.significant("cubic_yaw")
    assert early.improvement("cubic_yaw") > 0.6 and early.t_statistic("model", "cubic_yaw") > 3.0
    assert pooled(4.6, 1.5, 3.2, seconds=42.0).significant("cubic_yaw")


def test_a_candidate_on_board_needs_a_t_of_three_however_close_to_the_floor_it_brings_the_error():
    """A model error 1.5 times the noise floor that the candidate takes to the floor: not significant
    at t 2.5 (on a hull that lacks nothing, several candidates each remove a quarter at t near 2);
    at t 3.1 it is, and so is one removing 19 % short of the floor."""
    assert not pooled(1.5, 1.0, 2.5).significant("cubic_yaw")
    assert pooled(1.5, 1.0, 3.1).significant("cubic_yaw")
    assert pooled(1.6, 1.3, 3.1).significant("cubic_yaw")
    assert not pooled(1.2, 1.15, 3.1).significant("cubic_yaw")  # 4 % removed: not enough


def test_a_near_equivalent_group_is_led_by_a_candidate_whose_parameters_the_data_determine():
    """A rudder offset on a zigzag about one heading: a wind moment runs as well (its heading
    harmonics fit the offset over that sector, and a little noise besides), but the window's fit
    leaves its harmonics undetermined. The pool names the offset; with the wind's parameters
    determined it names the wind, the better of the two."""
    rng = np.random.default_rng(3)
    floor = 0.01
    noise = floor * rng.standard_normal(600)
    errors = [noise + 0.02, noise + 0.001 * rng.standard_normal(600), noise]  # the model, rudder_offset, wind_yaw
    names = ["model", "rudder_offset", "wind_yaw"]
    pool = PooledEvidence(names)
    pool.add(slice_sums(SLICE, 0.1, names, errors, [0.0, 0.3, 0.3], floor, TURNS))
    assert pool.significant("rudder_offset") and pool.significant("wind_yaw")
    assert pool.equivalents("wind_yaw") == ["rudder_offset"]
    assert OnlineDiagnosis._determined_lead(pool, "wind_yaw", {"wind_yaw"}) == "rudder_offset"
    assert OnlineDiagnosis._determined_lead(pool, "wind_yaw", set()) == "wind_yaw"
    assert OnlineDiagnosis._determined_lead(pool, "wind_yaw", {"wind_yaw", "rudder_offset"}) == "wind_yaw"


def test_a_tanker_whose_first_short_window_fit_missed_widely_is_judged_on_every_minute_alike():
    """The first slice of a trip is held out by a window of two minutes, whose fit misses by six times
    what the later ten-minute fits do, and there the candidate runs a little worse; in every later
    minute it removes a third of the error. Each slice counting by its samples, the candidate is named
    within ten minutes; weighed by its squared errors, the first slice would hold it off."""
    rng = np.random.default_rng(4)
    diagnosis, config = OnlineDiagnosis(), OnlineConfig(effects=())
    plan = [(swell(20.0, 12.0), {"speed_dependence": swell(20.0, 13.0)})]
    plan += [(swell(20.0, 2.0), {"speed_dependence": swell(20.0, 1.2)})] * 9
    verdicts = []
    for k, (missed, left) in enumerate(plan):
        result = drawn_diagnosis(60.0 * (k + 2), missed, left, rng)
        diagnosis.finish(result, config)
        verdicts.append(result["verdict"])
    first_slice, later = drawn_diagnosis(0.0, *plan[0], rng), drawn_diagnosis(0.0, *plan[1], rng)
    squares = [piece["held_out_slice"]["squares"][0] for piece in (first_slice, later)]
    assert squares[0] > 20 * squares[1]  # the first slice's squared error outweighs a later one's 20 times
    assert "missing_effect" in verdicts[:9]
    assert result["candidates"][0]["effect"] == "speed_dependence"


def test_a_tanker_whose_candidate_ran_wild_in_one_held_out_minute_is_still_named():
    """A candidate fitted on a few minutes extrapolates far off in one held-out minute (three times
    the model's error there) and removes half of the error in each of the eight others. Its pooled
    share is a geometric mean of the minutes' error ratios, in which running at three times the
    model's error weighs as running at a third of it: named within the nine minutes. (The arithmetic
    mean of the ratios, which that one minute dominates, removes none.)"""
    rng = np.random.default_rng(5)
    diagnosis, config = OnlineDiagnosis(), OnlineConfig(effects=())
    plan = [(swell(20.0, 3.0), {"quadratic_yaw": swell(20.0, 1.5)})] * 4
    plan += [(swell(20.0, 3.0), {"quadratic_yaw": swell(20.0, 9.0)})]
    plan += [(swell(20.0, 3.0), {"quadratic_yaw": swell(20.0, 1.5)})] * 4
    ratios = []
    for k, (missed, left) in enumerate(plan):
        result = drawn_diagnosis(60.0 * (k + 2), missed, left, rng)
        squares = result["held_out_slice"]["squares"]
        ratios.append(squares[1] / squares[0])
        diagnosis.finish(result, config)
    assert np.mean(ratios) > 1.0  # averaged, the wild minute outweighs the eight
    assert result["verdict"] == "missing_effect" and result["candidates"][0]["effect"] == "quadratic_yaw"


def test_a_tanker_whose_stall_fit_runs_to_its_bound_is_named_by_the_determined_drag_that_removes_more():
    """A tanker's first two minutes: a rudder stall pinned at its bound removes 30 % of the pooled error
    at t 3.4; a cross-flow drag the data determine removes 46 % at t 2.3, not significant alone but not
    to be told from the stall: the group is named with the drag leading it. A determined candidate
    removing less than the stall, and not significant, does not lead."""
    samples, floor = 600, 0.01
    model = samples * (3.0 * floor) ** 2

    def pool(drag_share: float) -> PooledEvidence:
        squares = [model, model * 0.7**2, model * (1.0 - drag_share) ** 2]
        variance = np.zeros((3, 3))
        variance[0, 1] = variance[1, 0] = ((squares[0] - squares[1]) / 3.4) ** 2
        variance[0, 2] = variance[2, 0] = ((squares[0] - squares[2]) / 2.3) ** 2
        variance[1, 2] = variance[2, 1] = variance[0, 2]
        evidence = PooledEvidence(["model", "rudder_stall", "quadratic_yaw"])
        piece = {"start": 0.0, "samples": samples, "seconds": 60.0, "squares": squares}
        piece.update(pair_variance=variance.tolist(), training_gain=[0.0, 0.1 * samples, 0.4 * samples])
        evidence.add(dict(piece, noise_squares=samples * floor**2, **alike_at_tight_turns(samples, squares)))
        return evidence

    more, less = pool(0.46), pool(0.2)
    assert more.significant("rudder_stall") and not more.significant("quadratic_yaw")
    assert OnlineDiagnosis._determined_lead(more, "rudder_stall", {"rudder_stall"}) == "quadratic_yaw"
    assert OnlineDiagnosis._determined_lead(less, "rudder_stall", {"rudder_stall"}) == "rudder_stall"


def test_a_tanker_whose_first_minutes_fill_a_part_of_its_window_weighs_their_slices_by_that_part():
    """A tanker's window is ten minutes: in the held-out slices of its first four diagnoses (windows of
    two to five minutes) a quadratic damping refitted on so little runs 60 % above the model's
    error; in the four of full windows it removes half of it. Each slice weighs by the share of the
    window it held: named by the eighth diagnosis, about a third of the pooled error removed. Had
    every slice counted in full (each window full for its configuration), the early minutes would
    hold it at a tenth, not named."""
    shares, verdicts = {}, {}
    for name, window_length in (("share", 600.0), ("full", None)):
        rng = np.random.default_rng(7)
        diagnosis = OnlineDiagnosis()
        plan = [(60.0 * (k + 2), 1.7) for k in range(4)] + [(600.0, 0.3)] * 4
        for k, (window_s, over_model) in enumerate(plan):
            missed = swell(20.0, 3.0)
            result = drawn_diagnosis(60.0 * (k + 2), missed, {"quadratic_yaw": over_model * missed}, rng, 0.2, window_s)
            diagnosis.finish(result, OnlineConfig(effects=(), window_length=window_length or window_s))
        shares[name] = result["candidates"][0]["pooled"]["improvement_yaw_rate"]
        verdicts[name] = result["verdict"]
    assert verdicts == {"share": "missing_effect", "full": "unexplained"}
    assert shares["share"] == pytest.approx(0.32, abs=0.03) and shares["full"] < 0.12  # measured 32 %, 10 %


def test_a_tankers_named_rudder_offset_keeps_its_name_while_its_t_wavers_below_three():
    """A tanker's first held-out minute names a rudder offset (t 4, a third of the error removed); in
    the next the offset runs a little worse than the model (t -0.5) and a course instability removes
    a third (t 4.5), not significantly better than the offset over the two minutes. The offset's
    pooled t falls to 2.5: no evidence against it, and the name stays (held down to ``HOLD_T``);
    held only at t 3 it would pass to the instability on this one minute, and back when the
    offset's minutes return (a tanker with a hidden offset changed its name four times so)."""
    samples, model = 120, 9.0e-4

    def minute(stamp: float, offset: float, instability: float, t_offset: float, t_instability: float, t_between):
        squares = [model, offset, instability]
        variance = np.zeros((3, 3))
        for (i, j), t in {(0, 1): t_offset, (0, 2): t_instability, (1, 2): t_between}.items():
            if t:
                variance[i, j] = variance[j, i] = ((squares[i] - squares[j]) / t) ** 2
        piece = {"start": stamp - 60.0, "end": stamp, "samples": samples, "seconds": 60.0, "squares": squares}
        piece.update(names=["model", "rudder_offset", "course_instability"], pair_variance=variance.tolist())
        piece.update(training_gain=[0.0, 0.2 * samples, 0.2 * samples], noise_squares=samples * model / 9.0)
        piece.update(alike_at_tight_turns(samples, squares))
        return finished(stamp, piece, 600.0)

    config = OnlineConfig(effects=(), window_length=600.0)
    diagnosis = OnlineDiagnosis()
    first, second = minute(660.0, 4.0e-4, model, 4.0, 0.0, 4.0), minute(720.0, 9.9e-4, 4.0e-4, -0.5, 4.5, -2.0)
    for result in (first, second):
        diagnosis.finish(result, config)
    pool = diagnosis._pool
    assert 2.0 < pool.t_statistic("model", "rudder_offset") < 3.0 and pool.significant("course_instability")
    assert pool.t_statistic("rudder_offset", "course_instability") < 3.0
    assert [r["candidates"][0]["effect"] for r in (first, second)] == ["rudder_offset"] * 2
    assert second["verdict"] == "missing_effect" and "reversed" not in second["verdict_sentence"]


def test_a_quick_boat_whose_cubic_damping_refits_a_little_worse_than_the_quadratic_law_is_named_by_its_law():
    """A USV's cubic yaw damping: refitted apart, the quadratic law removes a little more of the held-out
    error than the cubic one (their searches, t beyond 3 between them), while the fits holding both
    laws put the damping's growth in the cubic term. The pool names the cubic law, with the quadratic
    one beside it, and keeps it: the quadratic law's lower error is no reversal. Without the law fits
    the quadratic law is named."""
    config = OnlineConfig(effects=())
    names = {}
    for laws in (["cubic_yaw"], []):
        rng = np.random.default_rng(6)
        diagnosis = OnlineDiagnosis()
        named = []
        for k in range(8):
            left = {"quadratic_yaw": swell(20.0, 0.6), "cubic_yaw": swell(20.0, 0.75)}
            result = dict(drawn_diagnosis(60.0 * (k + 2), swell(20.0, 2.0), left, rng), damping_laws=laws)
            diagnosis.finish(result, config)
            named.append(result["candidates"][0]["effect"] if result["verdict"] == "missing_effect" else None)
        pool = diagnosis._pool
        assert pool.significant("cubic_yaw") and pool.t_statistic("cubic_yaw", "quadratic_yaw") > 3
        names[bool(laws)] = named
        if laws:
            assert "quadratic_yaw" in result["near_equivalent"]
    assert set(names[True]) == {"cubic_yaw"} and set(names[False]) == {"quadratic_yaw"}


def test_a_quick_boats_quadratic_damping_that_the_cubic_laws_refits_credit_more_surely_is_named_by_its_law():
    """A USV's quadratic yaw damping, on a model without it: refitted apart, the cubic law removes 8 %
    of the pooled held-out error at t 7.7 (significant), the quadratic law nearly as much (7 %) at t
    3.3 (its refits scatter more), which alone credits no share under 15 %, while the fits holding
    both laws show the quadratic term. The pool names the quadratic law from the first diagnosis,
    the cubic one beside it; without the law fits, the cubic law."""
    config = OnlineConfig(effects=())
    for laws, named in ((["quadratic_yaw"], "quadratic_yaw"), ([], "cubic_yaw")):
        rng, scatter = np.random.default_rng(6), np.random.default_rng(7)
        diagnosis = OnlineDiagnosis()
        for k in range(3):
            left = {"quadratic_yaw": 0.27 * NOISE * scatter.standard_normal(len(SLICE)), "cubic_yaw": swell(20.0, 0.3)}
            result = dict(drawn_diagnosis(60.0 * (k + 2), swell(20.0, 0.7), left, rng), damping_laws=laws)
            diagnosis.finish(result, config)
            assert result["verdict"] == "missing_effect" and result["candidates"][0]["effect"] == named
            if k == 0:
                pool = diagnosis._pool
                assert pool.significant("cubic_yaw") and not pool.significant("quadratic_yaw")
                assert 3.0 < pool.t_statistic("model", "quadratic_yaw") < 6.0
                assert pool.improvement("quadratic_yaw") > 0.05
                assert result["near_equivalent"] == (["cubic_yaw"] if laws else [])


def test_a_tankers_damping_laws_the_fits_do_not_show_trade_no_places_on_their_searches():
    """An MMG tanker's damping: the fits holding both laws show the quadratic law, the cubic law is
    named on the first minute, and from the next one Norrbin's law (course_instability) runs below
    it at t 7 over the pool, its share 2.5 points above. Two laws the fits do not show differ by
    their searches: the cubic law stays named. One that removes 18 points more than the named law is
    named instead."""
    config = OnlineConfig(effects=())
    for later_cubic, names in ((0.6, ["cubic_yaw"] * 5), (1.5, ["cubic_yaw"] * 3 + ["course_instability"] * 2)):
        rng = np.random.default_rng(6)
        diagnosis = OnlineDiagnosis()
        named = []
        for k in range(5):
            cubic, norrbin = (0.3, 0.6) if k == 0 else (later_cubic, 0.2)
            left = {"cubic_yaw": swell(20.0, cubic), "course_instability": swell(20.0, norrbin)}
            result = dict(drawn_diagnosis(60.0 * (k + 2), swell(20.0, 2.0), left, rng), damping_laws=["quadratic_yaw"])
            diagnosis.finish(result, config)
            named.append(result["candidates"][0]["effect"] if result["verdict"] == "missing_effect" else None)
        pool = diagnosis._pool
        assert pool.t_statistic("cubic_yaw", "course_instability") > 7.0
        gap = pool.improvement("course_instability") - pool.improvement("cubic_yaw")
        assert (gap < 0.05) if later_cubic < 1.0 else (gap > 0.15)
        assert named == names


def test_a_tankers_group_is_led_by_the_effect_that_removes_most_at_the_tight_turns():
    """An MMG tanker's random steps: a rudder stall removes 28 % of the held-out error, evenly, and a
    quadratic damping 26 %, 40 % of it at the tight turns and 15 % at the gentle ones; the pool cannot
    tell the two apart over the whole error. The damping, which removes most where the turn is
    tightest, leads the group, the stall named beside it; where the damping's gain lay at the gentle
    turns instead, the stall leads."""
    tight = tight_turns(TURNS)
    for damping_better_at, leader in ((tight, "quadratic_yaw"), (~tight, "rudder_stall")):
        rng = np.random.default_rng(8)
        diagnosis = OnlineDiagnosis()
        for k in range(3):
            missed = swell(20.0, 4.0)
            left = {"rudder_stall": 0.72 * missed, "quadratic_yaw": np.where(damping_better_at, 0.6, 0.85) * missed}
            result = drawn_diagnosis(600.0 + 60.0 * k, missed, left, rng)
            diagnosis.finish(result, OnlineConfig(effects=()))
        pool = diagnosis._pool
        assert pool.improvement("rudder_stall") > pool.improvement("quadratic_yaw")
        assert result["verdict"] == "missing_effect"
        assert [result["candidates"][0]["effect"], *result["near_equivalent"]] == [
            leader,
            ({"rudder_stall", "quadratic_yaw"} - {leader}).pop(),
        ]
        assert "tightest half of the held-out turns" in result["verdict_sentence"]


COMPASS_NOISE = math.radians(0.1)  # rad, the heading noise of the drawn free runs
RUN_S = 30.0  # s, a drawn free run: two per held-out minute


def slow_ship_minute(stamp: float, candidate_drift: list, rng) -> dict:
    """A finished diagnosis of a slow ship's held-out minute ending at ``stamp`` (s): the model's
    yaw-rate error 1.02 times the noise floor, which the candidate takes a fifth of the way down
    with 1 % off its training free runs (not significant on the yaw rate), and two free runs whose
    heading drifts from the compass by a rate drawn about 0.06 deg/s with the model,
    ``candidate_drift[k]`` times that with the candidate."""
    result = drawn_diagnosis(stamp, swell(40.0, 0.3), {"cubic_yaw": swell(40.0, 0.24)}, rng, training_gain=0.01)
    runs = (SLICE // RUN_S).astype(int)
    since_start = SLICE - RUN_S * runs
    drift = math.radians(0.06) * np.abs(1.0 + 0.3 * rng.standard_normal(runs.max() + 1))[runs] * since_start
    model = drift + COMPASS_NOISE * rng.standard_normal(len(SLICE))
    candidate = np.asarray(candidate_drift)[runs] * drift + COMPASS_NOISE * rng.standard_normal(len(SLICE))
    result["held_out_slice"]["run_heading_squares"] = run_heading_squares([model, candidate], runs)
    return result


def slow_ship_trip(candidate_log_drift: float, seed: int) -> list[dict]:
    """Fifteen held-out minutes of ``slow_ship_minute`` pooled on board, the candidate's drift over the
    model's drawn per free run as exp(N(``candidate_log_drift``, 0.6))."""
    rng = np.random.default_rng(seed)
    diagnosis = OnlineDiagnosis()
    results = []
    for k in range(15):
        drift = np.exp(candidate_log_drift + 0.6 * rng.standard_normal(2))
        result = slow_ship_minute(60.0 * (k + 1), drift, rng)
        diagnosis.finish(result, OnlineConfig(effects=()))
        results.append(result)
    return results


def test_a_slow_ships_effect_the_gyro_noise_hides_is_named_on_the_heading_drift_of_its_free_runs():
    """A slow ship whose missing effect moves its yaw rate by less than the gyro's noise: the
    candidate removes a few per cent of the yaw-rate error, never significantly, while the heading of
    each free run drifts from the compass at half the rate with it (scattering run to run by a
    factor 1.8). Named on the heading once five free runs give a t of 3, and the sentence says
    the yaw rate sits at the floor and what the heading shows."""
    results = slow_ship_trip(math.log(0.5), seed=11)
    named = [r["verdict"] == "missing_effect" for r in results]
    first = named.index(True)
    pooled = results[first]["candidates"][0]["pooled"]
    assert 2 <= first <= 6 and all(named[first:])  # measured: from the fourth minute
    assert results[first]["candidates"][0]["effect"] == "cubic_yaw"
    assert pooled["improvement_yaw_rate"] < 0.15 and not results[first]["candidates"][0]["significant_in_window"]
    assert pooled["improvement_heading"] > 0.3 and pooled["heading_t"] >= 3.0
    assert results[first]["pooled"]["heading_runs"] >= 5
    assert "the heading of the free runs drifts from the compass" in results[first]["verdict_sentence"]


def test_a_slow_ship_that_lacks_nothing_names_nothing_from_the_scatter_of_its_free_runs_headings():
    """The same slow ship where the candidate's heading drift is the model's times a factor
    scattering about 1 (as refits of a hull that lacks nothing do): over fifteen minutes the draw
    has the candidate removing a fifth of the pooled heading error, more than the share asked, but
    run to run it scatters as much as it removes (t at most 2.7): nothing is named."""
    results = slow_ship_trip(0.0, seed=33)
    assert [r["verdict"] for r in results].count("missing_effect") == 0
    assert results[-1]["candidates"][0]["pooled"]["improvement_heading"] > 0.15  # measured 22 %
    assert max(r["candidates"][0]["pooled"]["heading_t"] for r in results) < 3.0  # measured 2.7
