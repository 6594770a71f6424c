"""Measurements as the online core receives them: plain data, nothing of ROS or files.

A ``Sample`` is one measured value of one role (``ROLES``: rudder angle in rad,
heading in rad, yaw rate in rad/s, speed in m/s; NED, time in s). ``Topics``
names where each role comes from: bag topics, or the user's CSV columns. The
bag and CSV adapter (``io``) and the ROS node produce samples; the online
identifier consumes them.
"""

from __future__ import annotations

from dataclasses import dataclass

ROLES = ("rudder", "heading", "yaw_rate", "speed")


@dataclass(frozen=True)
class Topics:
    """Input names: bag topics, and the column names of CSV files.

    When ``imu`` is set, heading and yaw rate come from that Imu topic; for CSV files the user's
    (role, column) pairs are ``csv_columns`` (see ``io.parse_columns``).
    """

    rudder: str = "/usv/rudder"
    heading: str = "/usv/heading"
    yaw_rate: str = "/usv/yaw_rate"
    speed: str = "/usv/speed"
    imu: str = ""
    velocity: str = ""  # Odometry or TwistStamped topic of the body-fixed velocity (3-DOF model)
    csv_columns: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class Sample:
    """One measurement: time in s, role in ROLES, value in SI units (NED)."""

    time: float
    role: str
    value: float


def dataset_samples(dataset) -> list[Sample]:
    """A recording as the node would receive it: time-ordered rudder, heading and yaw-rate samples.

    Parameters
    ----------
    dataset : Dataset
        A uniformly sampled recording (s, rad, rad/s); its ``wrapped_heading`` when it has one
        (the heading wrapped, as a compass gives it).

    Returns
    -------
    list of Sample
        Per sample time, the rudder, heading and yaw-rate samples, oldest first.
    """
    heading = dataset.meta.get("wrapped_heading", dataset.heading)
    return [
        Sample(float(t), role, float(v))
        for i, t in enumerate(dataset.time)
        for role, v in (("rudder", dataset.rudder[i]), ("heading", heading[i]), ("yaw_rate", dataset.yaw_rate[i]))
    ]
