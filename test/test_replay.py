"""ship-ident replay: a simulated bag through the online identifier, JSON lines and the --out MCAP."""

import json
import math
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from ship_ident.commands.replay import replay_bag
from ship_ident.io.files import Topics, typestore, write_simulation
from ship_ident.model.simulator import simulate
from ship_ident.online.config import OnlineConfig
from ship_ident.ros.demo import BAG as DEMO_BAG


def replay(*args):
    return subprocess.run(
        [sys.executable, "-m", "ship_ident.cli", "replay", *map(str, args)], capture_output=True, text=True, timeout=120
    )


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    sim = simulate("mixed", duration=300.0, seed=4)
    path = tmp_path_factory.mktemp("replay") / "sim.mcap"
    write_simulation(sim, path, "mcap")
    return path, sim.truth


@pytest.mark.slow
def test_replay_json_lines_recover_truth(bag):
    path, truth = bag
    result = replay(path, "--json")
    assert result.returncode == 0, result.stderr
    records = [json.loads(line) for line in result.stdout.splitlines()]
    assert [r["stamp"] for r in records] == pytest.approx([5.0 * k for k in range(1, 61)])
    final = records[-1]
    assert final["status"] == "OK" and final["new_estimate"]
    assert final["structure"] == {"model": "nomoto2", "effects": ["rudder_offset", "cubic_yaw"]}
    assert final["parameters"]["K"] == pytest.approx(truth["K"], rel=0.05)
    assert final["parameters"]["T1"] == pytest.approx(truth["T1"], rel=0.10)
    assert final["parameters"]["delta_r"] == pytest.approx(truth["delta_r"], rel=0.15)
    assert final["window"]["end"] - final["window"]["start"] == pytest.approx(180.0, abs=0.5)


def read_topics(path) -> tuple[dict, dict]:
    """{topic: [(log time s, message)]} of an MCAP and {topic: offered QoS profiles}."""
    with AnyReader([Path(path)], default_typestore=typestore()) as reader:
        messages = {c.topic: [] for c in reader.connections}
        for c, stamp, raw in reader.messages():
            messages[c.topic].append((stamp * 1e-9, reader.deserialize(raw, c.msgtype)))
        return messages, {c.topic: c.ext.offered_qos_profiles for c in reader.connections}


@pytest.mark.slow
def test_replay_out_mcap_holds_what_the_node_publishes(bag, tmp_path):
    """Inputs, every refit's estimate and /diagnostics status, the parameters of exactly the OK
    estimates (recorded latched), K's band, and the predicted yaw rate at the yaw-rate samples'
    times for nearly every sample after the first estimate, close to the measurement."""
    path, truth = bag
    out = tmp_path / "identified.mcap"
    result = replay(path, "--out", out, "--effects", "rudder_offset", "--refit-period", "10.0")
    assert result.returncode == 0, result.stderr
    assert "real time" in result.stdout and "K =" in result.stdout
    written, qos = read_topics(out)
    assert {"/usv/rudder", "/usv/heading", "/usv/yaw_rate", "/ship_ident/gain_band", "/diagnostics"} <= set(written)
    estimates = [json.loads(m.data) for _, m in written["/ship_ident/estimate"]]
    assert len(estimates) == 30  # every 10 s of 0 .. 300 s
    assert estimates[-1]["structure"]["effects"] == ["rudder_offset"]
    ok = [e for e in estimates if e["status"] == "OK"]
    parameters = written["/ship_ident/parameters"]
    assert 0 < len(ok) < len(estimates) and [t for t, _ in parameters] == [e["stamp"] for e in ok]
    assert [list(m.data) for _, m in parameters] == [list(e["parameters"].values()) for e in ok]
    assert parameters[-1][1].layout.dim[0].label == "K,T1,T2,T3,delta_r"
    assert parameters[-1][1].data[0] == pytest.approx(truth["K"], rel=0.05)
    (latched,) = qos["/ship_ident/parameters"]
    assert (latched.durability.name, latched.history.name, latched.depth) == ("TRANSIENT_LOCAL", "KEEP_LAST", 1)
    statuses = [m.status[0] for _, m in written["/diagnostics"]]
    assert [s.level for s in statuses] == [{"OK": 0, "WARN": 1, "ERROR": 2}[e["status"]] for e in estimates]
    low, gain, high = written["/ship_ident/gain_band"][-1][1].data
    last = estimates[-1]
    assert gain == last["parameters"]["K"] and high - low == pytest.approx(2 * 1.96 * last["std_errors"]["K"], rel=1e-3)
    first = min(e["stamp"] for e in estimates if e["parameters"])
    yaw_rate = {t: m.data for t, m in written["/usv/yaw_rate"] if t >= first}
    predicted = written["/ship_ident/predicted_yaw_rate"]
    assert all(t in yaw_rate for t, _ in predicted) and len(predicted) >= 0.9 * len(yaw_rate)
    assert all(m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec == pytest.approx(t) for t, m in predicted)
    error = np.array([m.vector.z - yaw_rate[t] for t, m in predicted])
    assert math.degrees(np.sqrt(np.mean(error**2))) < 0.5  # deg/s: 10 s free runs of a right model


@pytest.mark.parametrize(
    "args, message",
    [
        (["/nonexistent/bag.mcap"], "does not exist"),
        (["{bag}", "--effects", "barnacles"], "unknown effect"),
        (["{bag}", "--window-length", "-5"], "window_length"),
        (["{bag}", "--diagnosis-plot", "p.png"], "--diagnosis-plot needs --diagnosis-period"),
        (["{bag}", "--diagnosis-period", "2"], "diagnosis_period must be 0 (off) or >= refit_period"),
    ],
)
@pytest.mark.slow
def test_replay_bad_input_is_one_line(bag, args, message):
    result = replay(*[a.format(bag=bag[0]) for a in args])
    assert result.returncode == 2
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_replay_diagnoses_the_trip_into_the_records_the_mcap_and_a_plot(bag, tmp_path):
    """Nothing hidden: every diagnosis in the record of its refit and on its own MCAP topics, the
    held-out error at the noise floor, no missing_effect; printed for people; the plot is written."""
    path, _ = bag
    out, plot = tmp_path / "diagnosed.mcap", tmp_path / "held_out.png"
    args = ["--window-length", 120, "--refit-period", 10, "--diagnosis-period", 60, "--out", out]
    result = replay(path, *args, "--diagnosis-plot", plot)
    assert result.returncode == 0, result.stderr
    assert "diagnosis at 120 s (rudder_offset+cubic_yaw): " in result.stdout and "noise floor" in result.stdout
    with AnyReader([out], default_typestore=typestore()) as reader:
        written = {
            topic: [
                reader.deserialize(raw, c.msgtype).data
                for c, _, raw in reader.messages([c for c in reader.connections if c.topic == topic])
            ]
            for topic in (
                "/ship_ident/estimate",
                "/ship_ident/diagnosis",
                "/ship_ident/held_out_error",
                "/ship_ident/noise_floor",
            )
        }
    records = [json.loads(text) for text in written["/ship_ident/estimate"]]
    diagnoses = [r["diagnosis"] for r in records if "diagnosis" in r]
    assert [d["stamp"] for d in diagnoses] == [r["stamp"] for r in records if "diagnosis" in r]
    assert [d["stamp"] for d in diagnoses] == pytest.approx([60, 120, 180, 240, 300])
    assert diagnoses[0]["status"] == "skipped" and "the window holds 60 s" in diagnoses[0]["reason"]
    done = diagnoses[1:]
    assert all(d["status"] == "done" and d["verdict"] != "missing_effect" for d in done)
    assert all(d["held_out_error"] < 1.25 * d["noise_floor"] for d in done)
    assert not any("missing_effect" in r["conditions"] for r in records)
    assert [json.loads(text) for text in written["/ship_ident/diagnosis"]] == diagnoses
    # the curve the crew reads the verdict from: the error pooled since the start against the pooled floor
    assert all("pooled" in d for d in done)
    assert written["/ship_ident/held_out_error"] == [d["pooled"]["held_out_error"] for d in done]
    assert written["/ship_ident/noise_floor"] == [d["pooled"]["noise_floor"] for d in done]
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def estimates_in(path) -> list[dict]:
    with AnyReader([path], default_typestore=typestore()) as reader:
        connections = [c for c in reader.connections if c.topic == "/ship_ident/estimate"]
        return [json.loads(reader.deserialize(raw, c.msgtype).data) for c, _, raw in reader.messages(connections)]


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_interrupted_replay_leaves_a_readable_mcap_with_every_estimate(tmp_path, signum):
    out = tmp_path / "partial.mcap"
    # unbuffered: readline takes exactly one line from the pipe, so communicate() gets the rest
    # (a buffered reader may hold the next lines where communicate, reading the pipe, misses them)
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "ship_ident.cli",
            "replay",
            str(DEMO_BAG),
            "--json",
            "--out",
            str(out),
            "--refit-period",
            "1.0",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        bufsize=0,
    )
    try:
        printed = [json.loads(process.stdout.readline()) for _ in range(20)]
        process.send_signal(signum)
        rest, err = (text.decode() for text in process.communicate(timeout=30))
    finally:
        if process.poll() is None:
            process.kill()
    printed += [json.loads(line) for line in rest.splitlines()]
    assert process.returncode == 128 + signum, err
    assert "interrupted at bag time" in err and len(err.strip().splitlines()) == 1
    written = estimates_in(out)
    assert 20 <= len(printed) == len(written) < 600  # stopped early, nothing printed is missing
    assert [e["stamp"] for e in written] == [e["stamp"] for e in printed]


def test_replay_bag_is_callable_per_bag(bag):
    """The per-bag function that ``ship-ident replay`` (and many-bag replay) runs."""
    path, truth = bag
    config = OnlineConfig(method="rwlssvm", refit_period=20.0, speed_topic="/usv/speed")
    result = replay_bag(path, Topics(), config)
    assert not result.interrupted and result.duration == pytest.approx(300.0)
    assert [r.time for r in result.records] == pytest.approx([20.0 * k for k in range(1, 16)])
    assert result.records[-1].estimate["parameters"]["K"] == pytest.approx(truth["K"], rel=0.05)


KVLCC2_ZIGZAG = (
    Path(__file__).resolve().parents[2] / "shared" / "data" / "kvlcc2_marin" / "MARIN_FREE_KVLCC2_zz_20_m.csv"
)


@pytest.mark.skipif(
    not KVLCC2_ZIGZAG.exists(), reason="kvlcc2_marin: measured MARIN model tests, not shipped with the package"
)
@pytest.mark.slow
def test_kvlcc2_zigzag_uncertainty_covers_the_scatter_and_is_not_saturated():
    """The measured 20/20 zigzag of a slow ship: successive published K within 3 joint standard
    errors of each other (they were 12-19 apart), no rudder_saturated for the zigzag's +-20 deg,
    and a 1 s sample time runs (the gap threshold follows it)."""
    args = [
        KVLCC2_ZIGZAG,
        "--json",
        "--model",
        "nomoto1",
        "--effects",
        "cubic_yaw",
        "--window-length",
        400,
        "--refit-period",
        20,
    ]
    out = replay(*args, "--sample-time", 0.5)
    assert out.returncode == 0, out.stderr
    records = [json.loads(line) for line in out.stdout.splitlines()]
    published = [(r["parameters"]["K"], r["std_errors"]["K"]) for r in records if r["new_estimate"]]
    assert len(published) >= 4  # 6 on 120 s shooting intervals; on 3 T (225 s) two late windows are refused
    apart = [abs(k2 - k1) / math.hypot(s1, s2) for (k1, s1), (k2, s2) in zip(published, published[1:])]
    assert max(apart) < 3.0, apart
    assert not any("rudder_saturated" in r["conditions"] for r in records)
    coarse = replay(*args, "--sample-time", 1)
    assert coarse.returncode == 0 and any(json.loads(line)["new_estimate"] for line in coarse.stdout.splitlines())
    bad = replay(*args, "--sample-time", 1, "--gap-threshold", 0.5)
    assert bad.returncode == 2 and "gap_threshold must be 0" in bad.stderr


def test_replay_prints_times_from_the_bags_start():
    """A bag with absolute stamps: times from its first stamp, the bag's clock beside them."""
    from ship_ident.commands.replay import bag_time, diagnosis_text

    assert bag_time(130.0, 0.0) == "130 s"
    start = 1_700_000_000.0
    diagnosis = {
        "stamp": start + 65.0,
        "status": "skipped",
        "reason": "the window holds 65 s",
        "structure": {"model": "nomoto2", "effects": ["rudder_offset"]},
    }
    assert diagnosis_text(diagnosis, start) == (
        "diagnosis at 65 s, bag clock 1700000065 s (rudder_offset): skipped: the window holds 65 s"
    )
