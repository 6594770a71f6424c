"""Each node parameter is defined once (``online_config``): the parameter file, the docs' table, the
node's descriptors, replay's options and the validation all follow that one definition."""

import math
import os
import re
from dataclasses import fields
from pathlib import Path

import pytest
import yaml

from ship_ident.cli import main as cli_main
from ship_ident.estimators import method_names
from ship_ident.model.effects import EFFECTS
from ship_ident.model.structure import BASE_MODELS, StructureError, parse_effects
from ship_ident.online.config import (
    NODE_PARAMETERS,
    TABLE_END,
    TABLE_START,
    ConfigError,
    NodeSettings,
    OnlineConfig,
    markdown_value,
    parameter_file,
    parameter_table,
    spec,
    specs,
)

ROOT = Path(__file__).resolve().parent.parent
BAG = ROOT / "bags" / "demo_seed001.mcap"
DEFINED = specs(*NODE_PARAMETERS)
BOUNDED = [(cls, f.name) for cls in NODE_PARAMETERS for f in fields(cls) if f.metadata["spec"].limits]


def test_every_node_parameter_is_defined_once_with_a_description():
    names = [f.name for cls in NODE_PARAMETERS for f in fields(cls)]
    assert len(names) == len(set(names)) == len(DEFINED) == 30
    assert all(s.description for _, s in DEFINED.values())
    assert spec(OnlineConfig, "window_length").limits == (10.0, 3600.0)


def test_parameter_file_holds_exactly_the_parameters_with_their_defaults():
    text = (ROOT / "config" / "ship_ident.yaml").read_text()
    assert text == parameter_file(), "config/ship_ident.yaml is stale: python -m ship_ident.online.config"
    values = yaml.safe_load(text)["/**"]["ros__parameters"]
    assert list(values) == list(DEFINED)
    for name, (default, _) in DEFINED.items():
        expected = list(default) if isinstance(default, tuple) else default
        assert values[name] == expected and type(values[name]) is type(expected), name  # rcl: 250.0, not 250


def table_rows(markdown: str) -> dict:
    """{name: [default, unit, range, description]} of the parameter table between the markers."""
    block = markdown[markdown.index(TABLE_START) : markdown.index(TABLE_END)]
    rows = [[cell.strip() for cell in re.split(r"(?<!\\)\|", line.strip()[1:-1])] for line in block.splitlines()[3:]]
    return {row[0].strip("`"): row[1:] for row in rows}


def test_docs_parameter_table_matches_the_definition():
    markdown = (ROOT / "docs" / "node.md").read_text()
    assert table_rows(markdown) == table_rows(parameter_table()), "docs/node.md: python -m ship_ident.online.config"
    rows = table_rows(markdown)
    assert list(rows) == list(DEFINED)
    for name, (default, s) in DEFINED.items():
        assert rows[name][:3] == [f"`{markdown_value(default)}`", s.unit, s.range_text()], name
    assert rows["window_length"][:3] == ["`180.0`", "s", "10 to 3600"]
    assert rows["effects"][2] == "any of " + ", ".join(EFFECTS)
    assert rows["method"][2] == "one of " + ", ".join(method_names())


def test_node_descriptors_carry_the_ranges_and_names():
    node = pytest.importorskip("ship_ident.ros.node")
    descriptors = node.parameter_descriptors()
    assert list(descriptors) == list(DEFINED)
    for name, (default, s) in DEFINED.items():
        value, descriptor = descriptors[name]
        assert value == (list(default) if isinstance(default, tuple) else default)
        assert descriptor.read_only == s.read_only and s.description in descriptor.description, name
        ranges = list(descriptor.floating_point_range) + list(descriptor.integer_range)
        if s.limits:
            assert [(r.from_value, r.to_value) for r in ranges] == [s.limits], name
        else:
            assert not ranges, name
    assert descriptors["model"][1].additional_constraints == "one of " + ", ".join(BASE_MODELS)
    assert set(node.RELIABILITY) == set(spec(NodeSettings, "qos_reliability").options())


def test_a_real_node_refuses_a_window_beyond_its_range(tmp_path, monkeypatch):
    """The descriptors on a real rclpy node (its own context and ROS domain, never spun): a 5000 s
    window is refused by its range, 600 s is taken."""
    rclpy = pytest.importorskip("rclpy")
    node_module = pytest.importorskip("ship_ident.ros.node")
    from rclpy.parameter import Parameter

    monkeypatch.setenv("ROS_LOG_DIR", str(tmp_path))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=150 + os.getpid() % 50)
    try:
        node = node_module.IdentifierNode(context=context)
        try:
            refused, taken = node.set_parameters(
                [Parameter("window_length", value=5000.0), Parameter("window_length", value=600.0)]
            )
            assert not refused.successful and "window_length" in refused.reason
            assert taken.successful and node.identifier.config.window_length == 600.0
            assert node.describe_parameter("sample_time").floating_point_range[0].to_value == 1.0
        finally:
            node.shutdown()
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_a_namespaced_node_takes_its_values_from_the_parameter_file(tmp_path, monkeypatch):
    """The shipped file is keyed /**: with -r __ns:=/boat1 (a namespaced or launched node) a value
    in it is taken, not silently left for the default."""
    rclpy = pytest.importorskip("rclpy")
    node_module = pytest.importorskip("ship_ident.ros.node")
    text = parameter_file()
    assert "    window_length: 180.0\n" in text
    params = tmp_path / "boat1.yaml"
    params.write_text(text.replace("    window_length: 180.0\n", "    window_length: 120.0\n"))
    monkeypatch.setenv("ROS_LOG_DIR", str(tmp_path))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = rclpy.Context()
    arguments = ["identifier_node", "--ros-args", "-r", "__ns:=/boat1", "--params-file", str(params)]
    rclpy.init(args=arguments, context=context, domain_id=150 + (os.getpid() + 1) % 50)
    try:
        node = node_module.IdentifierNode(context=context)
        try:
            assert node.get_fully_qualified_name() == "/boat1/ship_ident"
            assert node.identifier.config.window_length == 120.0
        finally:
            node.shutdown()
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_replay_refuses_a_window_beyond_the_nodes_range_in_one_line(capsys):
    too_long = spec(OnlineConfig, "window_length").limits[1] + 1.0
    assert cli_main(["replay", str(BAG), "--window-length", f"{too_long:g}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "window_length must be in [10, 3600] s" in err[0] and "3601" in err[0]


def test_replay_options_take_their_range_and_help_from_the_definition(capsys):
    with pytest.raises(SystemExit):
        cli_main(["replay", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "data in each fit; 10 to 3600 s (default 180)" in text
    assert "0.573 to 90 deg (default 35)" in text  # rudder_limit, in deg on the command line


def bad_values(cls, name):
    low, high = spec(cls, name).limits
    integer = isinstance(low, int)
    below = low - 1 if integer else low - max(abs(low), 1.0) * 0.5
    above = high + 1 if integer else high * 1.5
    return [below, above] + ([high + 0.5] if integer else [math.nan, math.inf])


@pytest.mark.parametrize("cls, name", BOUNDED, ids=[name for _, name in BOUNDED])
def test_a_value_out_of_range_is_refused_for_every_bounded_field(cls, name):
    low, high = spec(cls, name).limits
    for value in (low, high):  # the ends are in range (a field may still clash with another)
        try:
            cls(**{name: value}).validate()
        except ConfigError as exc:
            assert not str(exc).startswith(f"{name} must be in"), exc
    for value in bad_values(cls, name):
        with pytest.raises(ConfigError, match=f"^{name} must be"):
            cls(**{name: value}).validate()


@pytest.mark.parametrize(
    "cls, name, value",
    [(OnlineConfig, "model", "nomoto3"), (OnlineConfig, "method", "magic"), (NodeSettings, "qos_reliability", "lossy")],
)
def test_a_name_outside_its_registry_is_refused_naming_the_valid_ones(cls, name, value):
    with pytest.raises(
        ConfigError, match=re.escape(f"unknown {name} '{value}'; choose from {', '.join(spec(cls, name).options())}")
    ):
        cls(**{name: value}).validate()


def test_one_effect_parser_for_text_and_lists():
    assert parse_effects(" rudder_offset, cubic_yaw ,") == ("rudder_offset", "cubic_yaw")
    assert parse_effects(["rudder_offset", "cubic_yaw"]) == ("rudder_offset", "cubic_yaw")
    assert parse_effects("") == parse_effects(None) == parse_effects([]) == ()
    with pytest.raises(StructureError, match="unknown effect 'barnacles'; choose from " + ", ".join(EFFECTS)):
        parse_effects("rudder_offset,barnacles")
    with pytest.raises(StructureError, match="listed twice"):
        parse_effects(["cubic_yaw", "cubic_yaw"])
    assert OnlineConfig(effects="rudder_offset, cubic_yaw").effects == OnlineConfig().effects
    with pytest.raises(ConfigError, match="unknown effect 'barnacles'"):
        OnlineConfig(effects=["barnacles"])


def test_model_effect_and_method_lists_in_the_help_come_from_the_registries(capsys):
    with pytest.raises(SystemExit):
        cli_main(["identify", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "{" + ",".join(BASE_MODELS) in text
    assert "any of " + ", ".join(EFFECTS) in text
    assert ", ".join(method_names()) in text
