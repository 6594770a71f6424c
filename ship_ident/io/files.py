"""Bags and CSV files in and out: the file adapter around the numeric core.

Reading accepts a rosbag2 directory (MCAP storage; ``metadata.yaml`` as
``ros2 bag record -s mcap`` or rosbags writes it), a directory holding
``.mcap`` files but no usable ``metadata.yaml`` (an interrupted recording,
a copied folder), a bare ``.mcap`` file, or a CSV file
``t,rudder,heading,yaw_rate[,speed]`` in SI units with a header line. CSV
columns are found by name: the canonical names, common synonyms
(``CSV_SYNONYMS``: e.g. ``surge_speed`` or ``u`` for the speed, ``delta`` for the
rudder), or the user's own mapping (``Topics.csv_columns``, ``--columns``).

Inputs are ``std_msgs/msg/Float64`` topics stamped with the bag's log time,
or a ``sensor_msgs/msg/Imu`` topic (ROS ENU convention) for heading and yaw
rate, converted to our NED convention: psi = pi/2 - yaw_enu, r = -omega_z.
For the 3-DOF model, the body-fixed velocity comes from a ``nav_msgs/msg/Odometry``
(its twist, in the child frame) or ``geometry_msgs/msg/TwistStamped`` topic in
ROS's body frame (x forward, y to port): surge u = linear.x, sway v = -linear.y
(our v is positive to starboard).

A single MCAP file of Float64 inputs is read straight from its chunks
(``mcap_float64``: an hour's 10 Hz bag in a quarter of a second); every other bag
through rosbags, which also words what is wrong with a bag it cannot read.

Every unusable input raises ``DataError`` with one sentence saying what is
wrong and what to do.
"""

from __future__ import annotations

import csv
import math
import shutil
import struct
import tempfile
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.errors import ReaderError
from rosbags.typesys import Stores, get_typestore

from ..model.dataset import DataError, Dataset, resample_series
from ..online.samples import ROLES, Sample, Topics
from .mcap_float64 import float64_messages

if TYPE_CHECKING:
    from rosbags.highlevel import AnyReader

CSV_COLUMNS = ("t", "rudder", "heading", "yaw_rate", "speed")  # speed optional
# Column names read as each role without --columns (matched case-insensitively, SI units only),
# the canonical name first; a public simulator's CSV names the speed surge_speed.
CSV_SYNONYMS = {
    "t": ("t", "time", "t_s", "time_s", "timestamp"),
    "rudder": ("rudder", "delta", "rudder_angle", "rudder_rad", "delta_rad"),
    "heading": ("heading", "psi", "yaw", "heading_rad", "psi_rad"),
    "yaw_rate": ("yaw_rate", "r", "yaw_rate_rad_s", "r_rad_s"),
    "speed": ("speed", "surge_speed", "u", "speed_mps", "u_mps"),
}
# The 3-DOF model's body-fixed velocity (m/s, sway positive to starboard).
VELOCITY_SYNONYMS = {"surge": ("surge_speed", "u", "surge", "u_mps"), "sway": ("sway_speed", "v", "sway", "v_mps")}
THREEDOF_SYNONYMS = dict({r: CSV_SYNONYMS[r] for r in CSV_COLUMNS[:4]}, **VELOCITY_SYNONYMS)
FLOAT64 = "std_msgs/msg/Float64"
IMU = "sensor_msgs/msg/Imu"
VELOCITY_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/TwistStamped")
TWIST_STAMPED = VELOCITY_TYPES[1]
MCAP_MAGIC = b"\x89MCAP0\r\n"
_INFINITE = QosTime(2147483647, 4294967295)  # rmw's "no deadline, no lifespan" as rosbag2 records it
# A latched topic as ``ros2 bag record`` stores its publisher's offer: reliable, transient local, keep last 1.
LATCHED_QOS = Qos(
    QosHistory.KEEP_LAST,
    1,
    QosReliability.RELIABLE,
    QosDurability.TRANSIENT_LOCAL,
    _INFINITE,
    _INFINITE,
    QosLiveliness.AUTOMATIC,
    _INFINITE,
    avoid_ros_namespace_conventions=False,
)
DEFAULT_TOPICS = Topics()  # the node's default topic names
# What a bag that is not readable raises in the general reader (with rosbags.highlevel's AnyReaderError,
# imported where the general reader runs: a plain bag is read without it)
BAD_BAG_ERRORS = (
    ReaderError,
    struct.error,
    EOFError,
    OSError,
    ValueError,
    KeyError,
    IndexError,
    AssertionError,
)


class UnreadableBag(DataError):
    """A bag whose files cannot be parsed (corrupt, truncated, unsupported metadata)."""


@lru_cache(maxsize=1)
def typestore():
    """The ROS 2 Kilted message types (rosbags) used for writing and as reading fallback."""
    return get_typestore(Stores.ROS2_KILTED)


# --- reading -----------------------------------------------------------------


def read_samples(path, topics: Topics = DEFAULT_TOPICS, csv_roles: dict = CSV_SYNONYMS) -> list[Sample]:
    """All input samples of a bag or CSV file, time-ordered (see module docstring); a CSV file's
    columns are those of the roles in ``csv_roles`` (role -> synonyms; all but speed required)."""
    path = Path(path)
    if not path.exists():
        raise DataError(f"{path} does not exist; give a rosbag2 directory, a .mcap file or a CSV file")
    if path.name == "metadata.yaml":
        path = path.parent
    if path.is_dir():
        samples = _read_bag_dir(path, topics)
    elif path.suffix.lower() == ".mcap" or _starts_with_mcap_magic(path):
        samples = _read_bag([path], topics)
    elif path.suffix.lower() in (".csv", ".txt"):
        samples = _read_csv(path, dict(topics.csv_columns), csv_roles)
    else:
        raise DataError(
            f"{path} is neither a bag (rosbag2 directory or .mcap file) nor a CSV file (.csv); convert it or rename it"
        )
    _check_not_all_nan(path, samples)
    samples.sort(key=lambda s: s.time)
    return samples


def load_dataset(path, topics: Topics = DEFAULT_TOPICS, sample_time: float = 0.1) -> Dataset:
    """A bag or CSV file resampled onto a uniform grid (gaps split segments, heading unwrapped);
    for a CSV file ``meta["columns"]`` maps each role to the column read."""
    samples = read_samples(path, topics)
    series = {}
    for role in ROLES:
        picked = [(s.time, s.value) for s in samples if s.role == role]
        if picked:
            series[role] = tuple(np.array(column) for column in zip(*picked))
    meta = {"source": str(path)}
    if Path(path).suffix.lower() in (".csv", ".txt"):
        meta["columns"] = csv_column_map(path, dict(topics.csv_columns))
    return resample_series(series, sample_time, meta=meta)


def _starts_with_mcap_magic(path: Path) -> bool:
    with path.open("rb") as f:
        return f.read(len(MCAP_MAGIC)) == MCAP_MAGIC


def _read_bag_dir(path: Path, topics: Topics) -> list[Sample]:
    """A rosbag2 directory; without a readable metadata.yaml, its .mcap files directly."""
    mcaps = sorted(path.glob("*.mcap"))
    if (path / "metadata.yaml").exists():
        try:
            return _read_bag([path], topics)
        except UnreadableBag:
            if not mcaps:
                raise
    if not mcaps:
        raise DataError(
            f"{path} is a directory without metadata.yaml or .mcap files; "
            "give a rosbag2 directory recorded with MCAP storage"
        )
    return _read_bag(mcaps, topics)


def _read_bag(paths: list[Path], topics: Topics) -> list[Sample]:
    name = paths[0] if len(paths) == 1 else paths[0].parent
    plain = _plain_float64_samples(paths, topics)
    if plain is not None:
        return plain
    from rosbags.highlevel import AnyReader, AnyReaderError

    try:
        with AnyReader(paths, default_typestore=typestore()) as reader:
            return _bag_samples(reader, name, topics)
    except DataError:
        raise
    except (AnyReaderError, *BAD_BAG_ERRORS) as err:
        raise UnreadableBag(
            f"{name} is not a readable MCAP bag ({err}); it is corrupt or truncated "
            "(an interrupted recording): re-record or re-export it"
        ) from None


def _plain_float64_samples(paths: list[Path], topics: Topics) -> list[Sample] | None:
    """The samples of a single MCAP file of Float64 inputs read straight from its chunks
    (``mcap_float64``), or None where the general reader must read the bag: a directory or several
    files, Imu or velocity topics, anything not plain, an input without a message."""
    if len(paths) != 1 or not paths[0].is_file() or topics.imu or topics.velocity:
        return None
    role_of = {topic: role for role, topic in _wanted_topics(topics).items()}
    messages = float64_messages(paths[0], set(role_of))
    if messages is None or not {"rudder", "heading", "yaw_rate"} <= {role_of[m[1]] for m in messages}:
        return None
    return [Sample(log_time * 1e-9, role_of[topic], value) for log_time, topic, value in messages]


def _wanted_topics(topics: Topics) -> dict[str, str]:
    """The bag topic read for each role (the Imu and the velocity where set)."""
    wanted = {"rudder": topics.rudder, "speed": topics.speed}
    if topics.imu:
        wanted["imu"] = topics.imu
    else:
        wanted.update(heading=topics.heading, yaw_rate=topics.yaw_rate)
    if topics.velocity:
        wanted["velocity"] = topics.velocity
    return wanted


def _bag_samples(reader: AnyReader, name: Path, topics: Topics) -> list[Sample]:
    if reader.message_count == 0:
        raise DataError(f"{name} holds no messages; record the rudder, heading and yaw-rate topics")
    found = {c.topic: c.msgtype for c in reader.connections}
    wanted = _wanted_topics(topics)
    missing = [t for role, t in wanted.items() if role != "speed" and t not in found]
    if missing:
        have = ", ".join(f"{t} ({m})" for t, m in sorted(found.items())) or "none"
        raise DataError(
            f"{name} has no topic {', '.join(missing)}; topics in it: {have}; "
            "choose the topics with the --*-topic options"
        )
    for role, topic in wanted.items():
        expected = {"imu": (IMU,), "velocity": VELOCITY_TYPES}.get(role, (FLOAT64,))
        if topic in found and found[topic] not in expected:
            raise DataError(
                f"{name}: topic {topic} carries {found[topic]}, expected {' or '.join(expected)}; choose another topic"
            )
    role_of = {t: role for role, t in wanted.items() if t in found}
    samples = []
    connections = [c for c in reader.connections if c.topic in role_of]
    count = 0
    for connection, log_time, raw in reader.messages(connections=connections):
        role = role_of[connection.topic]
        if role in ("imu", "velocity"):
            msg = reader.deserialize(raw, connection.msgtype)
            samples.extend((imu_samples if role == "imu" else velocity_samples)(msg, log_time * 1e-9))
        else:
            samples.append(Sample(log_time * 1e-9, role, float64_data(raw, reader, connection.msgtype)))
        count += 1
    indexed = sum(c.msgcount for c in connections)
    if count < indexed:
        raise UnreadableBag(
            f"{name} is corrupt or truncated: only {count} of its {indexed} indexed "
            "messages are readable; re-record or re-export it"
        )
    return samples


# A std_msgs/Float64 message in little-endian CDR: the encapsulation header, then the double
LITTLE_ENDIAN_FLOAT64 = struct.Struct("<4sd")
LITTLE_ENDIAN_CDR = b"\x00\x01\x00\x00"


def float64_data(raw: bytes, reader: AnyReader, msgtype: str) -> float:
    """The ``data`` of a serialized std_msgs/Float64 message: read straight from a little-endian CDR
    message (what ROS 2 records on the machines it runs on), else through the bag's deserializer."""
    if len(raw) == LITTLE_ENDIAN_FLOAT64.size:
        header, value = LITTLE_ENDIAN_FLOAT64.unpack(raw)
        if header == LITTLE_ENDIAN_CDR:
            return value
    return float(reader.deserialize(raw, msgtype).data)


def header_time(msg, log_time: float) -> float:
    """A stamped message's header time in s, or its log time where the header stamp is zero."""
    stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
    return stamp if stamp > 0 else log_time


def imu_samples(msg, log_time: float) -> tuple[Sample, Sample]:
    """Heading and yaw rate (NED) from an ENU Imu message, stamped by its header when set."""
    time = header_time(msg, log_time)
    q = msg.orientation
    yaw_enu = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    return (
        Sample(time, "heading", wrap_angle(math.pi / 2 - yaw_enu)),
        Sample(time, "yaw_rate", -float(msg.angular_velocity.z)),
    )


def velocity_samples(msg, log_time: float) -> tuple[Sample, Sample]:
    """Surge u and sway v (m/s, v positive to starboard) from an Odometry or TwistStamped message
    in ROS's body frame (y to port), stamped by its header when set."""
    time = header_time(msg, log_time)
    twist = msg.twist.twist if hasattr(msg, "child_frame_id") else msg.twist
    return Sample(time, "surge", float(twist.linear.x)), Sample(time, "sway", -float(twist.linear.y))


def wrap_angle(angle: float) -> float:
    """Angle wrapped to (-pi, pi] (rad)."""
    wrapped = math.remainder(angle, 2 * math.pi)
    return math.pi if wrapped == -math.pi else wrapped


def parse_columns(text: str) -> tuple[tuple[str, str], ...]:
    """``speed=surge_speed,rudder=delta`` as ((role, column), ...); an unknown role, a pair without
    ``=`` or a role named twice raises DataError."""
    pairs = []
    for item in filter(None, (part.strip() for part in text.split(","))):
        role, sep, column = (x.strip() for x in item.partition("="))
        if not sep or not role or not column:
            raise DataError(
                f"--columns item {item!r} is not ROLE=COLUMN; e.g. --columns speed=surge_speed,rudder=delta"
            )
        if role not in CSV_SYNONYMS and role not in VELOCITY_SYNONYMS:
            raise DataError(
                f"--columns: unknown role {role!r}; roles are {', '.join([*CSV_SYNONYMS, *VELOCITY_SYNONYMS])}"
            )
        if role in dict(pairs):
            raise DataError(f"--columns names the role {role!r} twice; give each role once")
        pairs.append((role, column))
    return tuple(pairs)


def resolve_columns(
    header: list[str], chosen: dict[str, str], synonyms: dict[str, tuple[str, ...]], required, source
) -> dict[str, str]:
    """Which header column each role of ``synonyms`` is read from: the user's ``chosen`` column
    (which must exist), else the first synonym present (case-insensitive). A ``required`` role
    without a column, or one column for two roles, raises DataError naming the columns found."""
    by_name = {h.lower(): h for h in header}
    found = ", ".join(header) or "none"
    mapping = {}
    for role, column in chosen.items():
        if role not in synonyms:
            raise DataError(
                f"--columns {role}={column}: this model reads no {role}; its roles are {', '.join(synonyms)}"
            )
        if column not in header:
            raise DataError(f"{source} has no column {column!r} (--columns {role}={column}); its columns: {found}")
        mapping[role] = column
    for role, names in synonyms.items():
        if role not in mapping:
            match = next((by_name[n] for n in names if n in by_name and by_name[n] not in mapping.values()), None)
            if match is not None:
                mapping[role] = match
    missing = [role for role in required if role not in mapping]
    for role in missing:
        taken = next((by_name[n] for n in synonyms[role] if by_name.get(n) in mapping.values()), None)
        if taken is not None:
            other = next(r for r, c in mapping.items() if c == taken)
            raise DataError(
                f"{source}: column {taken!r} is read as {other} (--columns), so {role} has "
                f"none; name its column with --columns {role}=NAME"
            )
    if missing:
        raise DataError(
            f"{source} has no column for {', '.join(missing)}; its columns: {found}; "
            f"name them with --columns, e.g. --columns {missing[0]}=NAME (SI units)"
        )
    twice = sorted({c for c in mapping.values() if list(mapping.values()).count(c) > 1})
    if twice:
        raise DataError(f"{source}: column {twice[0]!r} is named for two roles; give each role its own column")
    return mapping


def _csv_header(path: Path) -> list[str]:
    with path.open(newline="") as f:
        return [h.strip() for h in next(csv.reader(f), [])]


def csv_column_map(
    path, chosen: dict[str, str] | None = None, synonyms=CSV_SYNONYMS, required=CSV_COLUMNS[:4]
) -> dict[str, str]:
    """Role -> CSV column read for the roles of ``synonyms`` (default: the Nomoto model's) of
    ``path`` (see ``resolve_columns``)."""
    path = Path(path)
    return resolve_columns(_csv_header(path), chosen or {}, synonyms, required, path)


def is_canonical(mapping: dict[str, str]) -> bool:
    """True when every role is read from its canonical column (the first of its synonyms)."""
    canonical = {role: names[0] for role, names in {**CSV_SYNONYMS, **VELOCITY_SYNONYMS}.items()}
    return all(canonical[role] == column for role, column in mapping.items())


def read_csv_columns(path: Path, mapping: dict[str, str]) -> dict[str, np.ndarray]:
    """The mapped columns of a CSV file as float arrays {role: values}; a row that is not numbers
    raises DataError naming its line."""
    header = _csv_header(path)
    index = {role: header.index(column) for role, column in mapping.items()}
    rows = []
    with path.open(newline="") as f:
        lines = csv.reader(f)
        next(lines, None)
        for line, row in enumerate(lines, start=2):
            if not row:
                continue
            try:
                rows.append([float(row[i]) for i in index.values()])
            except (ValueError, IndexError):
                raise DataError(
                    f"{path} line {line} is not {len(header)} numbers: {','.join(row)!r}; fix or delete that line"
                ) from None
    if not rows:
        raise DataError(f"{path} holds a header but no data rows; export the data again")
    return dict(zip(index, np.array(rows).T))


def _read_csv(path: Path, chosen: dict[str, str], roles: dict) -> list[Sample]:
    mapping = csv_column_map(path, chosen, roles, [r for r in roles if r != "speed"])
    columns = read_csv_columns(path, mapping)
    return [
        Sample(float(t), role, float(columns[role][i]))
        for i, t in enumerate(columns["t"])
        for role in columns
        if role != "t"
    ]


def _check_not_all_nan(path: Path, samples: list[Sample]) -> None:
    with_finite = {s.role for s in samples if math.isfinite(s.value)}
    for role in dict.fromkeys(s.role for s in samples):
        if role not in with_finite:
            raise DataError(f"{path}: every {role} sample is NaN or Inf; check the sensor or the export")


# --- writing -----------------------------------------------------------------


class BagWriter:
    """Write ROS 2 messages to a rosbag2 directory (``fmt='rosbag2'``) or a bare ``.mcap`` file.

    A context manager; ``write(topic, msgtype, msg, time_s)`` takes a rosbags
    message object of ``typestore()`` and its log time in s. Messages are
    buffered in 1 MiB chunks and the file is completed on ``close``. Leaving
    the ``with`` block by any exception, Ctrl-C (KeyboardInterrupt) included,
    closes the bag: it is complete and readable. A killed process (SIGKILL,
    power loss) leaves no readable bag.
    """

    def __init__(self, path, fmt: str = "rosbag2"):
        if fmt not in ("rosbag2", "mcap"):
            raise ValueError(f"unknown bag format {fmt!r}; use rosbag2 or mcap")
        self.path = Path(path)
        if self.path.exists():
            raise DataError(f"{self.path} exists already; remove it or choose another output path")
        self.fmt = fmt
        # A bare .mcap is the storage file of a rosbag2 directory written beside it.
        self._bag_dir = (
            self.path
            if fmt == "rosbag2"
            else Path(tempfile.mkdtemp(prefix=f".{self.path.name}.", dir=self.path.parent)) / "bag"
        )
        self._writer = Writer(self._bag_dir, version=9, storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        self._connections: dict[str, object] = {}

    def write(self, topic: str, msgtype: str, msg, time_s: float, latched: bool = False) -> None:
        """``latched`` (taken at a topic's first message): recorded as offered with transient-local
        durability, depth 1, so that ``ros2 bag play`` republishes it latched."""
        connection = self._connections.get(topic)
        if connection is None:
            qos = [LATCHED_QOS] if latched else []
            connection = self._writer.add_connection(topic, msgtype, typestore=typestore(), offered_qos_profiles=qos)
            self._connections[topic] = connection
        elif connection.msgtype != msgtype:
            raise ValueError(f"topic {topic} was opened as {connection.msgtype}, not {msgtype}")
        self._writer.write(connection, int(round(time_s * 1e9)), typestore().serialize_cdr(msg, msgtype))

    def close(self) -> None:
        if self._writer is None:
            return
        self._writer.close()
        self._writer = None
        if self.fmt == "mcap":
            next(self._bag_dir.glob("*.mcap")).replace(self.path)
            shutil.rmtree(self._bag_dir.parent)

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def write_simulation(sim, path, fmt: str = "rosbag2") -> None:
    """Write a Simulation's measurements as Float64 on the node's default input topics (or CSV),
    heading wrapped."""
    d = sim.dataset
    columns = {"rudder": d.rudder, "heading": d.meta["wrapped_heading"], "yaw_rate": d.yaw_rate, "speed": d.speed}
    columns = {role: values for role, values in columns.items() if values is not None}
    if fmt == "csv":
        path = Path(path)
        if path.exists():
            raise DataError(f"{path} exists already; remove it or choose another output path")
        with path.open("w", newline="") as f:
            out = csv.writer(f)
            out.writerow(["t", *columns])
            out.writerows(zip(*(map(repr, map(float, v)) for v in (d.time, *columns.values()))))
        return
    if fmt not in ("rosbag2", "mcap"):
        raise ValueError(f"unknown format {fmt!r}; use rosbag2, mcap or csv")
    Float64 = typestore().types[FLOAT64]
    topics = Topics()
    with BagWriter(path, fmt) as writer:
        for i, t in enumerate(d.time):
            for role, values in columns.items():
                writer.write(getattr(topics, role), FLOAT64, Float64(data=float(values[i])), float(t))
