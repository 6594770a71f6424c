"""Smoke runs of every benchmark at tiny sizes (``--quick``), asserting sane numbers."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import ship_ident
from ship_ident.bench import benchmarks, onboard_diagnosis
from ship_ident.bench.crb import cramer_rao_bound
from ship_ident.bench.onboard_diagnosis import agreement, at_floor, median_shares, render, trip_line
from ship_ident.cli import main
from ship_ident.estimators import DEFAULT_METHOD
from ship_ident.model.dataset import Dataset
from ship_ident.model.simulator import simulate

pytestmark = pytest.mark.slow  # each test runs a benchmark's quick variant


def test_benchmarks_register_themselves_by_name():
    assert {"seed-table2", "efficiency", "speed"} <= set(benchmarks())


def test_seed_table2_quick_reproduces_the_failure_and_the_fix():
    bench = benchmarks()["seed-table2"]
    result = bench.run(True)
    errors = {m: r["relative_error_percent"] for m, r in result["methods"].items()}
    assert errors["lssvm"]["delta_r"] == -100.0
    for name in ("K", "T1", "delta_r"):
        assert abs(errors["rwlssvm+oe"][name]) < 0.5
    assert all(np.isfinite(v["heading_deg"]) for r in result["methods"].values() for v in r["rmse"].values())
    assert "paper reconstructed+APSO-WLSSVM" in bench.render(result)


def test_efficiency_quick_gives_bounded_errors_and_coverages():
    """Every method reports, for each fitted parameter, the fraction of its two quick runs whose 95 %
    interval covers the truth; the default method's intervals cover it in every run (measured: all
    1.0; rwlssvm+oe's cover K in one of two zigzag runs)."""
    result = benchmarks()["efficiency"].run(True)
    seeds = result["data"]["seeds"]
    parameters = ("K", "T1", "T2", "T3", "delta_r", "alpha")
    for maneuver in result["maneuvers"].values():
        for method, summary in maneuver["methods"].items():
            for q in parameters:
                coverage = summary[q]["coverage_95"]  # a KeyError is a failure, not 0.0
                assert coverage * seeds == pytest.approx(round(coverage * seeds)), (method, q)
                assert 0.0 <= coverage <= 1.0
            assert "coverage_95" not in summary["T1+T2-T3"]  # no standard error: no claim
        default = maneuver["methods"][DEFAULT_METHOD]
        assert all(default[q]["coverage_95"] == 1.0 for q in parameters), default
        oe = maneuver["methods"]["rwlssvm+oe"]
        assert all(s["crb_percent"] > 0 and np.isfinite(s["rms_percent"]) for s in oe.values())
        assert oe["K"]["rms_percent"] < 3.0


def test_crb_shrinks_with_the_noise_and_matches_its_scaling():
    sim = simulate("zigzag20", noise=0.0, duration=120.0, seed=0)
    d = sim.dataset
    exact = Dataset(time=d.time, rudder=sim.true_rudder, heading=sim.true_heading, yaw_rate=sim.true_yaw_rate)
    a = cramer_rao_bound(sim.structure, sim.truth, exact, [(0.0, 0.0, 0.0)], 1e-3, 2e-3)
    b = cramer_rao_bound(sim.structure, sim.truth, exact, [(0.0, 0.0, 0.0)], 2e-3, 4e-3)
    for name in a:
        assert b[name] == pytest.approx(2 * a[name], rel=1e-6)


def test_bench_speed_quick_json_is_one_object(capsys):
    assert main(["bench", "speed", "--quick", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["benchmark"] == "speed"
    for method, times in result["median_seconds"].items():
        assert all(0 < t < 60 for t in times.values()), method
    assert f"({result['machine']['processor']})" in benchmarks()["speed"].render(result)


@pytest.mark.node
def test_onboard_steady_quick_raises_no_missing_effect_over_dds(tmp_path):
    """The real node over DDS, five minutes of a drawn USV with nothing hidden at 8x (the 30-minute
    trips are ``bench onboard-steady``'s): its diagnoses run and none says missing_effect. The bench
    runs from the package alone, as installed without the repository around it."""
    shutil.copytree(Path(ship_ident.__file__).parent, tmp_path / "ship_ident")
    env = dict(os.environ, PYTHONPATH=str(tmp_path), OPENBLAS_NUM_THREADS="1")
    command = [sys.executable, "-m", "ship_ident.cli", "bench", "onboard-steady", "--quick", "--seed", "7", "--json"]
    done = subprocess.run(command, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-2000:]
    (row,) = json.loads(done.stdout)["rows"]
    assert row["node_exit"] == 0, row["node_log"]  # a node that died says why
    assert row["last_stamp"] >= 280.0  # the trip was played to its end
    # measured: 7 of 9 quiet, 2 of 9 at load average 5 (the child runs at low priority and skips when late)
    assert row["diagnoses_done"] >= 2, row
    assert row["missing_effect"] == [] and row["missing_effect_warnings"] == 0
    assert row["held_out_over_noise_median"] < 1.5  # measured 1.05


def test_onboard_diagnosis_quick_names_a_hidden_rudder_offset_once():
    """A 7-minute trip replayed with the diagnosis on board (the 15-minute trips of the ten kinds and
    the trips with nothing hidden are ``bench onboard-diagnosis``'s; a trip with nothing hidden is
    ``test_onboard_steady_quick_raises_no_missing_effect_over_dds``'s and test_online_diagnosis'): a
    USV zigzagging with a hidden rudder offset."""
    result = benchmarks()["onboard-diagnosis"].run(True, seed=1, none_trips=0)
    (offset,) = result["rows"]
    assert offset["hidden"] == "rudder_offset" and offset["fair"]
    assert offset["named_first_in_time"] and offset["changes"] == 0
    assert offset["added"] == "rudder_offset" and at_floor(offset, "pooled")
    assert result["skipped"].keys() <= {"the window holds 60 s", "too little excitation"}


def test_a_tankers_judge_takes_the_median_share_of_three_training_spans_so_one_fit_decides_nothing():
    """An MMG tanker's shares of the turning circle's heading error on 540, 600 and 660 s of its random
    steps: the course instability removes 51, 49 and 62 %, a half by its median, not by the 600 s fit
    alone; the cubic law's fit on 660 s failed (it scores 0 there, as a candidate not fitted does) and
    its median is its 540 s share; the speed dependence, not fitted on 540 s, counts 0 there."""
    by_span = [
        {"course_instability": 0.515, "cubic_yaw": 0.415},
        {"course_instability": 0.489, "cubic_yaw": 0.684, "speed_dependence": 0.58},
        {"course_instability": 0.62, "cubic_yaw": 0.0, "speed_dependence": 0.233},
    ]
    shares = median_shares(by_span)
    assert shares == {"course_instability": 0.515, "cubic_yaw": 0.415, "speed_dependence": 0.233}
    assert list(shares) == ["course_instability", "cubic_yaw", "speed_dependence"]
    row = {"seed": 1, "hidden": "mmg", "vessel": "KVLCC2(x)", "manoeuvre": "steps", "first_named": "300 s"}
    row.update(missing_effect=3, done=9, changes=0, added=None, after_add=[], named_by_deadline="course_instability")
    row.update(halving={"course_instability": 0.515}, named_share=0.515, judge_spans_seconds=[540.0, 600.0, 660.0])
    row["judge_shares"] = {effect: [s.get(effect, 0.0) for s in by_span] for effect in shares}
    assert "course_instability (52 %: 52, 49, 62 % fitted on 540, 600, 660 s)" in trip_line(row)


def test_tankers_whose_halving_law_is_named_beside_the_leader_count_apart_from_the_target():
    """Three MMG tankers: the first names its halving course instability; the second names the
    quadratic law (41 %) with the cubic one (55 %, halving) beside it as near-equivalent; the third
    names a speed law that removes 24 % alone. The target counts the leader only (1 of 3); the
    group named with it holds a halving effect on 2 of 3, printed beside it."""

    def tanker(seed, halving, leader, share, group_halves):
        row = {"seed": seed, "hidden": "mmg", "vessel": "kvlcc2(x)", "vessel_kind": "kvlcc2", "manoeuvre": "steps"}
        row.update(changes=0, after_add=[], added=None, missing_effect=3, done=14, skipped=[])
        row.update(diagnosis_cpu_percent=3.0, halving=halving, named_by_deadline=leader, named_share=share)
        row.update(named_halves=leader in halving, group_halves=group_halves)
        return row

    rows = [
        tanker(1, {"course_instability": 0.58}, "course_instability", 0.58, True),
        tanker(2, {"cubic_yaw": 0.55}, "quadratic_yaw", 0.41, True),
        tanker(3, {"cubic_yaw": 0.55}, "speed_dependence", 0.24, False),
    ]
    result = dict(onboard_diagnosis.summary(rows), seed=5, trip_seconds=900.0, named_by_seconds=600.0)
    assert result["mmg_named_halves"] == pytest.approx(1 / 3)
    assert result["mmg_group_halves"] == pytest.approx(2 / 3)
    assert "halves it in 33 % of them (target >= 90 %; one in the near-equivalent group named with it: 67 %)" in render(
        result
    )


def test_a_dds_trip_from_which_no_diagnosis_arrived_is_reported_as_silent_not_as_a_disagreement():
    """The replay named and added a rudder offset; over DDS, one node's diagnoses arrived and agree,
    another's never came (its estimates did): that trip is counted apart, not as a disagreement."""
    named = {"status": "done", "verdict": "missing_effect", "candidates": [{"effect": "rudder_offset"}]}
    added = dict(named, auto_add={"action": "added", "effect": "rudder_offset", "effects": ["rudder_offset"]})
    replay = [dict(named, stamp=120.0), dict(added, stamp=180.0)]
    heard = agreement(replay, [dict(named, stamp=121.0), dict(added, stamp=181.0)], 600.0)
    silent = agreement(replay, [], 600.0)
    assert heard["agrees"] and heard["same_verdict"] == 1.0 and heard["received"] == 2
    assert not silent["agrees"] and silent["received"] == 0 and np.isnan(silent["same_verdict"])
    rows = []
    for k, dds in enumerate((heard, silent)):
        row = {"seed": k, "hidden": "rudder_offset", "vessel": "usv(x)", "manoeuvre": "zigzag", "first_named": None}
        row.update(missing_effect=2, done=2, changes=0, added="rudder_offset", after_add=[], skipped=[])
        row.update(fair=False, true_improvement=0.0, vessel_kind="usv")
        row.update(dds=dict(dds, node_exit=0, node_log="", estimates_node=180), diagnosis_cpu_percent=1.0)
        rows.append(row)
    assert "no diagnosis reached the listener (180 estimate records did" in trip_line(rows[1])
    assert {
        k: onboard_diagnosis.summary(rows)[k] for k in ("dds_trips", "dds_silent", "dds_agree", "dds_same_verdict")
    } == {
        "dds_trips": 2,
        "dds_silent": 1,
        "dds_agree": 1,
        "dds_same_verdict": 1.0,
    }


def test_realtime_times_the_replay_of_a_usv_bag_as_a_whole_process(tmp_path):
    """``bench realtime``'s replay figure on a 2-minute bag of seed 001's USV: a child ``replay``
    process prints its 24 refits (one every 5 s), and its wall and CPU seconds are measured."""
    from ship_ident.bench.realtime import hour_replay

    replay = hour_replay(3, str(tmp_path), 120.0)
    assert replay["refits"] == 24
    assert replay["duration_s"] == 120.0 and replay["wall_s"] > 0.3 and replay["cpu_s"] > 0.3


def test_every_timing_names_the_processor_it_ran_on():
    """Timings move by half and more between processors: the benchmarks that time print the CPUs,
    the processor's model (Linux's /proc/cpuinfo) and the load average beside their figures."""
    from ship_ident.bench.common import CPU_INFO, machine, machine_line

    m = machine()
    assert m["cpus"] >= 1 and m["processor"] and m["load_average"] >= 0.0
    if CPU_INFO.exists():
        assert f": {m['processor']}" in CPU_INFO.read_text()
    assert machine_line(m) == f"{m['cpus']} CPUs ({m['processor']}), load average {m['load_average']:.1f}"
