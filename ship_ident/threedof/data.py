"""3-DOF records in and out of CSV files and bags (the file adapter of the 3-DOF model).

A CSV file holds ``t,rudder,heading,yaw_rate,surge_speed,sway_speed`` (SI units, columns found by
name or synonym as for the Nomoto model: ``u``/``v`` also work, ``--columns`` names others). A bag
holds the Float64 rudder, heading and yaw-rate topics (or an Imu topic) and the body-fixed velocity
as a ``nav_msgs/msg/Odometry`` or ``geometry_msgs/msg/TwistStamped`` topic (``io.velocity_samples``).
"""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..io.files import (
    FLOAT64,
    THREEDOF_SYNONYMS,
    TWIST_STAMPED,
    BagWriter,
    Topics,
    csv_column_map,
    read_samples,
    typestore,
)
from ..model.dataset import DataError, resample_signals
from .model import Record

DEFAULT_VELOCITY_TOPIC = "/usv/velocity"
VELOCITY_TOPICS = Topics(velocity=DEFAULT_VELOCITY_TOPIC)  # the default topics with the velocity input
SIGNALS = ("rudder", "heading", "yaw_rate", "surge", "sway")
CSV_HEADER = ("t", "rudder", "heading", "yaw_rate", "surge_speed", "sway_speed")
SIGNALS_CSV = tuple(THREEDOF_SYNONYMS)  # t and the signals
MIN_RECORD_S = 5.0  # s: a stretch between gaps shorter than this is too short to smooth and fit


def load_records(path, topics: Topics = VELOCITY_TOPICS, sample_time: float = 0.1) -> list[Record]:
    """A bag or CSV file as 3-DOF Records on a uniform grid, one per stretch between gaps (heading
    unwrapped); each Record's meta names its source and, for a CSV, the columns read."""
    if not topics.velocity:
        topics = replace(topics, velocity=DEFAULT_VELOCITY_TOPIC)
    samples = read_samples(path, topics, THREEDOF_SYNONYMS)
    series = {}
    for role in SIGNALS:
        picked = [(s.time, s.value) for s in samples if s.role == role]
        if picked:
            series[role] = tuple(np.array(column) for column in zip(*picked))
    time, values, segments, _ = resample_signals(series, sample_time, required=SIGNALS)
    meta = {"source": str(path)}
    if Path(path).suffix.lower() in (".csv", ".txt"):
        meta["columns"] = csv_column_map(path, dict(topics.csv_columns), THREEDOF_SYNONYMS, SIGNALS_CSV)
    records = [
        Record(
            time=time[a:b],
            surge=values["surge"][a:b],
            sway=values["sway"][a:b],
            yaw_rate=values["yaw_rate"][a:b],
            heading=values["heading"][a:b],
            rudder=values["rudder"][a:b],
            meta=meta,
        )
        for a, b in segments
        if (b - a - 1) * sample_time >= MIN_RECORD_S
    ]
    if not records:
        raise DataError(f"{path} has no stretch of {MIN_RECORD_S:g} s without gaps; record longer runs")
    return records


def write_record(record: Record, path, fmt: str = "csv", velocity_topic: str = DEFAULT_VELOCITY_TOPIC) -> None:
    """Write a Record as CSV (``CSV_HEADER``) or as a bag (``rosbag2`` directory or ``mcap`` file):
    the Float64 rudder, heading (wrapped) and yaw-rate topics of ``Topics()`` and the velocity as
    ``geometry_msgs/msg/TwistStamped`` in ROS's body frame (y to port, so linear.y = -v)."""
    path = Path(path)
    heading = np.mod(record.heading + np.pi, 2 * np.pi) - np.pi
    if fmt == "csv":
        if path.exists():
            raise DataError(f"{path} exists already; remove it or choose another output path")
        with path.open("w", newline="") as f:
            out = csv.writer(f)
            out.writerow(CSV_HEADER)
            columns = (record.time, record.rudder, heading, record.yaw_rate, record.surge, record.sway)
            out.writerows(zip(*(map(repr, map(float, c)) for c in columns)))
        return
    types = typestore().types
    Float64, Twist, Header = types[FLOAT64], types[TWIST_STAMPED], types["std_msgs/msg/Header"]
    Time, Vector3 = types["builtin_interfaces/msg/Time"], types["geometry_msgs/msg/Vector3"]
    topics = Topics()
    with BagWriter(path, fmt) as writer:
        for i, t in enumerate(record.time):
            for topic, value in (
                (topics.rudder, record.rudder[i]),
                (topics.heading, heading[i]),
                (topics.yaw_rate, record.yaw_rate[i]),
            ):
                writer.write(topic, FLOAT64, Float64(data=float(value)), float(t))
            sec, nanosec = divmod(int(round(float(t) * 1e9)), 1_000_000_000)
            header = Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id="base_link")
            twist = types["geometry_msgs/msg/Twist"](
                linear=Vector3(x=float(record.surge[i]), y=-float(record.sway[i]), z=0.0),
                angular=Vector3(x=0.0, y=0.0, z=-float(record.yaw_rate[i])),
            )
            writer.write(velocity_topic, TWIST_STAMPED, Twist(header=header, twist=twist), float(t))
