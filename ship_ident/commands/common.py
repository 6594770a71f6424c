"""Argument helpers shared by the subcommands: data input, model choice, JSON output."""

from __future__ import annotations

import argparse
import sys

from ..estimators import DEFAULT_METHOD, method_names
from ..io.files import Topics, is_canonical, load_dataset, parse_columns
from ..model.dataset import Dataset, join_recordings
from ..model.effects import EFFECTS
from ..model.structure import BASE_MODELS, Structure

DEFAULT_TOPICS = Topics()


def add_data_args(parser: argparse.ArgumentParser) -> None:
    """Topic names and the resampling step for reading bags and CSV files."""
    group = parser.add_argument_group("data input (bags and CSV)")
    for role in ("rudder", "heading", "yaw_rate", "speed"):
        flag = role.replace("_", "-")
        group.add_argument(
            f"--{flag}-topic",
            default=getattr(DEFAULT_TOPICS, role),
            metavar="TOPIC",
            help=f"std_msgs/Float64 {role.replace('_', ' ')} topic (default %(default)s)",
        )
    group.add_argument(
        "--imu-topic",
        default="",
        metavar="TOPIC",
        help="sensor_msgs/Imu topic (ENU) for heading and yaw rate instead of the two Float64 topics",
    )
    group.add_argument(
        "--sample-time", type=float, default=0.1, metavar="S", help="resampling step in s (default %(default)s)"
    )
    group.add_argument(
        "--columns",
        default="",
        metavar="ROLE=NAME,...",
        help="CSV columns by name, e.g. speed=surge_speed,rudder=delta (roles t, rudder, "
        "heading, yaw_rate, speed; SI units); without it the canonical names and "
        "common synonyms (surge_speed, u; delta; psi, yaw; r; time) are recognised",
    )


def topics_from_args(args: argparse.Namespace) -> Topics:
    return Topics(
        rudder=args.rudder_topic,
        heading=args.heading_topic,
        yaw_rate=args.yaw_rate_topic,
        speed=args.speed_topic,
        imu=args.imu_topic,
        csv_columns=parse_columns(args.columns),
    )


def load_data(args: argparse.Namespace, path) -> Dataset:
    """The Dataset of a bag or CSV file, read with the topics, columns and sample time of ``args``;
    a CSV column mapping other than the canonical one is said on stderr (one line)."""
    dataset = load_dataset(path, topics_from_args(args), args.sample_time)
    say_columns(args, path, dataset.meta.get("columns"))
    return dataset


def say_columns(args: argparse.Namespace, path, mapping: dict | None) -> None:
    """One stderr line naming the CSV columns read, when they are not the canonical names."""
    if mapping and not is_canonical(mapping):
        pairs = ",".join(f"{role}={column}" for role, column in mapping.items())
        print(f"ship-ident {args.command}: {path}: reading columns {pairs}", file=sys.stderr)


def load_recordings(args: argparse.Namespace, paths) -> Dataset:
    """Several bags or CSV files as one Dataset on ``--sample-time``, each recording its own
    segment(s), never bridged; ``meta["recordings"]`` names each one's sample range."""
    return join_recordings([load_data(args, path) for path in paths], [str(p) for p in paths], args.sample_time)


def add_recordings_arg(parser: argparse.ArgumentParser, name: str = "data") -> None:
    """One or more recordings fitted (or judged) together."""
    parser.add_argument(
        name,
        metavar="DATA",
        nargs="+",
        help="rosbag2 directories, .mcap files or CSV files; several recordings make "
        "one dataset, each its own segment (never bridged)",
    )


def sources(paths) -> str:
    """The recordings' names for a heading line: ``a.csv`` or ``a.csv + b.mcap``."""
    return " + ".join(str(p) for p in paths)


def add_model_args(
    parser: argparse.ArgumentParser, effects=(), method: str = DEFAULT_METHOD, threedof_methods: tuple = ()
) -> None:
    """``--model``, ``--effects`` and ``--method``, their defaults the ``effects`` and ``method`` the
    command runs with (its help shows those very values). With ``threedof_methods`` (its methods,
    its default first) the model may be seed 000's ``3dof``, and an unset --method is None (the
    command picks ``method`` or the 3-DOF default)."""
    parser.add_argument(
        "--model",
        default="nomoto2",
        choices=tuple(BASE_MODELS) + (("3dof",) if threedof_methods else ()),
        help="base model (default %(default)s)"
        + ("; 3dof: seed 000's surge-sway-yaw model" if threedof_methods else ""),
    )
    parser.add_argument(
        "--effects",
        default=",".join(effects),
        metavar="A,B",
        help=f"comma-separated effects, any of {', '.join(EFFECTS)} (default: {','.join(effects) or 'none'})",
    )
    threedof = (
        f"; with --model 3dof: {' or '.join(threedof_methods)}, default {threedof_methods[0]}"
        if threedof_methods
        else ""
    )
    parser.add_argument(
        "--method",
        default=None if threedof_methods else method,
        metavar="NAME",
        help=f"estimator: {', '.join(method_names())} (default {method}{threedof})",
    )


def structure_from_args(args: argparse.Namespace) -> Structure:
    return Structure(args.model, args.effects)


def add_json_arg(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout and nothing else there")
