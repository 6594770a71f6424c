"""ship-ident replay: a simulated bag through the online identifier, JSON lines and the --out MCAP."""
import json
import subprocess
import sys

import pytest
from rosbags.highlevel import AnyReader

from ship_ident.io import typestore, write_simulation
from ship_ident.simulator import simulate


def replay(*args):
    return subprocess.run([sys.executable, "-m", "ship_ident.cli", "replay", *map(str, args)],
                          capture_output=True, text=True, timeout=120)


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    sim = simulate("mixed", duration=300.0, seed=4)
    path = tmp_path_factory.mktemp("replay") / "sim.mcap"
    write_simulation(sim, path, "mcap")
    return path, sim.truth


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


def test_replay_out_mcap_reads_back_with_estimates(bag, tmp_path):
    path, truth = bag
    out = tmp_path / "identified.mcap"
    result = replay(path, "--out", out, "--effects", "rudder_offset", "--refit-period", "10.0")
    assert result.returncode == 0, result.stderr
    assert "real time" in result.stdout and "K =" in result.stdout
    with AnyReader([out], default_typestore=typestore()) as reader:
        topics = {c.topic for c in reader.connections}
        assert {"/usv/rudder", "/usv/heading", "/usv/yaw_rate", "/ship_ident/estimate",
                "/ship_ident/parameters"} <= topics
        estimates = [json.loads(reader.deserialize(raw, c.msgtype).data)
                     for c, _, raw in reader.messages([c for c in reader.connections
                                                       if c.topic == "/ship_ident/estimate"])]
        parameters = [reader.deserialize(raw, c.msgtype)
                      for c, _, raw in reader.messages([c for c in reader.connections
                                                        if c.topic == "/ship_ident/parameters"])]
    assert len(estimates) == 30  # every 10 s of 0 .. 300 s
    assert estimates[-1]["structure"]["effects"] == ["rudder_offset"]
    assert parameters[-1].layout.dim[0].label == "K,T1,T2,T3,delta_r"
    assert parameters[-1].data[0] == pytest.approx(truth["K"], rel=0.05)


@pytest.mark.parametrize("args, message", [
    (["/nonexistent/bag.mcap"], "does not exist"),
    (["{bag}", "--effects", "barnacles"], "unknown effect"),
    (["{bag}", "--window-length", "-5"], "window_length"),
])
def test_replay_bad_input_is_one_line(bag, args, message):
    result = replay(*[a.format(bag=bag[0]) for a in args])
    assert result.returncode == 2
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1
