"""The bad-input catalogue of docs/reliability.md: replay's one-line errors, heading wraps, and that
every test the catalogue names exists."""

import os
import re
from pathlib import Path

import numpy as np
import pytest
from test_io import BAD_INPUTS, make_bad_input, written  # noqa: F401  (fixture)

from ship_ident.cli import main
from ship_ident.io.files import Sample
from ship_ident.model.simulator import simulate
from ship_ident.online.config import OnlineConfig
from ship_ident.online.identifier import OnlineIdentifier, run_schedule
from ship_ident.online.samples import dataset_samples

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("kind", BAD_INPUTS)
def test_replay_of_bad_input_is_one_line_and_exit_2(kind, tmp_path, written, capsys):  # noqa: F811
    path = make_bad_input(kind, tmp_path, written["mcap"])
    assert main(["replay", str(path)]) == 2
    err = capsys.readouterr().err
    assert BAD_INPUTS[kind] in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_heading_wrapping_through_pi_both_ways_is_plausible(direction):
    """Turning circles to starboard and to port: the wrapped heading crosses +-pi many times."""
    d = simulate("turning", duration=150.0, seed=1).dataset
    wrapped = np.mod(direction * d.heading + np.pi, 2 * np.pi) - np.pi
    assert np.sum(np.abs(np.diff(wrapped)) > np.pi) >= 2
    samples = [
        Sample(float(t), role, float(v))
        for i, t in enumerate(d.time)
        for role, v in (
            ("rudder", direction * d.rudder[i]),
            ("heading", wrapped[i]),
            ("yaw_rate", direction * d.yaw_rate[i]),
        )
    ]
    records = list(
        run_schedule(
            OnlineIdentifier(OnlineConfig(window_length=60.0, min_window_length=30.0, method="rwlssvm")), samples
        )
    )
    seen = {c for r in records for c in r.conditions}
    assert not seen & {"heading_in_degrees", "yaw_rate_sign", "rejected_samples", "clock_jump"}


def test_every_test_the_catalogue_names_exists():
    table = (ROOT / "docs" / "reliability.md").read_text()
    named = set(re.findall(r"`(test_\w+)::(test_\w+)`", table))
    assert len(named) >= 20
    for module, test in named:
        source = (ROOT / "test" / f"{module}.py").read_text()
        assert f"def {test}(" in source, f"{module}::{test}"


def test_a_refit_that_waited_behind_a_slow_one_keeps_the_window(tmp_path, monkeypatch):
    """A real node (its own context and ROS domain, never spun) takes 90 s of a USV's samples stamped up
    to its clock's present, as a worker starved of CPU finds them when a refit its timer submitted
    1.5 s earlier finally runs. The refit reads the clock then: the window stays and is fitted, no
    clock jump. Handed the tick's time instead, the identifier reads a clock stepping back beyond
    ``clock_jump_threshold`` (a bag looping) and empties the window."""
    rclpy = pytest.importorskip("rclpy")
    node_module = pytest.importorskip("ship_ident.ros.node")
    monkeypatch.setenv("ROS_LOG_DIR", str(tmp_path))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    sim = simulate("random", "seed001", duration=90.0, seed=31)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=150 + (os.getpid() + 3) % 50)
    try:
        node = node_module.IdentifierNode(context=context)
        try:
            present = node._now()
            for sample in dataset_samples(sim.dataset):
                node._take(Sample(present - sim.dataset.time[-1] + sample.time, sample.role, sample.value))
            tick = present - 1.5
            node._refit()
            assert node.identifier.counts["clock_jumps"] == 0
            assert node.identifier.window_dataset(node._now()).n_samples > 800
            stale = node.identifier.refit(tick)
            assert "clock_jump" in stale.conditions and "no_data" in stale.conditions
        finally:
            node.shutdown()
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
