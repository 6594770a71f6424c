"""The shipped Foxglove and PlotJuggler layouts plot what the node publishes and ``replay --out``
writes: every topic they name is one of the node's (a real rclpy node, never spun) and is in a
replay's MCAP, with the same message type, and every field path reaches a number there."""

import json
import math
import os
import re
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader

from ship_ident.io.bag_replay import replay_bag
from ship_ident.io.files import Topics, typestore, write_simulation
from ship_ident.model.simulator import simulate
from ship_ident.online.config import OnlineConfig

ROOT = Path(__file__).resolve().parent.parent
FOXGLOVE = ROOT / "config" / "foxglove_layout.json"
PLOTJUGGLER = ROOT / "config" / "plotjuggler_layout.xml"


def foxglove_paths() -> list[str]:
    """Message paths of the Foxglove layout's panels (``/topic.field.sub[0]``), and the topics they
    render whole (``/diagnostics``)."""
    panels = json.loads(FOXGLOVE.read_text())["configById"].values()
    paths = [p["value"] for panel in panels for p in panel.get("paths", [])]
    return paths + [panel["topicToRender"] for panel in panels if "topicToRender" in panel]


def plotjuggler_curves() -> list[str]:
    """Curve names of the PlotJuggler layout: ``/topic/field/sub[0]``."""
    return [curve.get("name") for curve in ElementTree.parse(PLOTJUGGLER).getroot().iter("curve")]


def split_foxglove(path: str) -> tuple[str, list[str]]:
    topic, _, fields = path.partition(".")
    return topic, [f for f in re.split(r"\.|(?=\[)", fields) if f]


def split_plotjuggler(curve: str, topics) -> tuple[str, list[str]]:
    """The longest known topic the curve name starts with, and the field path after it."""
    topic = max((t for t in topics if curve.startswith(t + "/")), key=len, default="")
    assert topic, f"{curve} names no topic written"
    return topic, [f for f in re.split(r"/|(?=\[)", curve[len(topic) :]) if f]


def field(message, names: list[str]):
    for name in names:
        message = message[int(name[1:-1])] if name.startswith("[") else getattr(message, name)
    return message


@pytest.fixture(scope="module")
def replayed(tmp_path_factory):
    """{topic: (message type, last message)} of a replay's MCAP, diagnosed so that its error and
    noise floor are written."""
    folder = tmp_path_factory.mktemp("layouts")
    bag, out = folder / "trip.mcap", folder / "replayed.mcap"
    write_simulation(simulate("mixed", duration=150.0, seed=4), bag, "mcap")
    config = OnlineConfig(window_length=90.0, min_window_length=30.0, diagnosis_period=30.0)
    replay_bag(bag, Topics(), config, out)
    with AnyReader([out], default_typestore=typestore()) as reader:
        last = {}
        for connection, _, raw in reader.messages():
            last[connection.topic] = (connection.msgtype, reader.deserialize(raw, connection.msgtype))
    return last


@pytest.fixture(scope="module")
def node_topics(tmp_path_factory):
    """{topic: message type} of what a real node publishes and subscribes to."""
    rclpy = pytest.importorskip("rclpy")
    node_module = pytest.importorskip("ship_ident.ros.node")
    os.environ.setdefault("ROS_LOG_DIR", str(tmp_path_factory.mktemp("ros_log")))
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=150 + (os.getpid() + 2) % 50)
    try:
        node = node_module.IdentifierNode(context=context)
        try:
            ends = list(node.publishers) + list(node.subscriptions)
            return {
                end.topic_name: end.msg_type.__module__.split(".")[0] + "/msg/" + end.msg_type.__name__ for end in ends
            }
        finally:
            node.shutdown()
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_the_layouts_plot_the_core_quantities():
    paths = foxglove_paths()
    curves = plotjuggler_curves()
    for wanted in ("/usv/yaw_rate", "/ship_ident/predicted_yaw_rate", "/usv/heading", "/ship_ident/held_out_error"):
        assert any(p.startswith(wanted + ".") for p in paths) and any(c.startswith(wanted + "/") for c in curves)
    for wanted in ("/ship_ident/noise_floor", "/ship_ident/gain_band"):
        assert any(p.startswith(wanted + ".") for p in paths) and any(c.startswith(wanted + "/") for c in curves)


def test_every_topic_a_layout_names_is_written_by_the_node_and_by_replay(replayed, node_topics):
    named = [split_foxglove(p) for p in foxglove_paths()]
    named += [split_plotjuggler(c, replayed) for c in plotjuggler_curves()]
    for topic, fields in named:
        assert topic in replayed, f"{topic}: not in replay's MCAP"
        assert topic in node_topics, f"{topic}: the node neither publishes nor subscribes to it"
        msgtype, message = replayed[topic]
        assert node_topics[topic] == msgtype, (topic, node_topics[topic], msgtype)
        if fields:
            value = field(message, fields)
            assert isinstance(value, float) and math.isfinite(value), (topic, fields, value)
