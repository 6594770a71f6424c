"""Bags and CSV files: round trips, independent readers, Imu input, ros2-bag-style bags, bad input."""

import math
import shutil

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from ship_ident.io import files
from ship_ident.io.files import (
    BagWriter,
    Topics,
    load_dataset,
    parse_columns,
    read_samples,
    typestore,
    wrap_angle,
    write_simulation,
)
from ship_ident.io.mcap_float64 import float64_messages
from ship_ident.model.dataset import DataError, join_recordings
from ship_ident.model.simulator import simulate

FORMATS = {"rosbag2": "bag", "mcap": "run.mcap", "csv": "run.csv"}
STAMP_OFFSET = 1000.0  # s, header stamps of the Imu test (a zero stamp means "unstamped")
TOPICS = ("/usv/rudder", "/usv/heading", "/usv/yaw_rate", "/usv/speed")


@pytest.fixture(scope="module")
def written(clean_nomoto2, tmp_path_factory):
    """The clean simulation in every format: {fmt: path}."""
    folder = tmp_path_factory.mktemp("formats")
    paths = {fmt: folder / name for fmt, name in FORMATS.items()}
    for fmt, path in paths.items():
        write_simulation(clean_nomoto2, path, fmt)
    return paths


def float64(value):
    return typestore().types["std_msgs/msg/Float64"](data=float(value))


def assert_same_data(a, b):
    for name in ("time", "rudder", "heading", "yaw_rate", "speed"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=1e-9, err_msg=name)


@pytest.mark.parametrize("fmt", FORMATS)
def test_every_format_reads_back_the_simulation(written, clean_nomoto2, fmt):
    data = load_dataset(written[fmt])
    assert_same_data(data, clean_nomoto2.dataset)
    assert data.gaps == () and data.segments == ((0, clean_nomoto2.dataset.n_samples),)


def test_rosbag2_reads_with_rosbags_alone(written, clean_nomoto2):
    sim = clean_nomoto2.dataset
    with AnyReader([written["rosbag2"]]) as reader:
        assert sorted(c.topic for c in reader.connections) == sorted(TOPICS)
        assert {c.msgtype for c in reader.connections} == {"std_msgs/msg/Float64"}
        heading = [
            reader.deserialize(raw, c.msgtype).data for c, _, raw in reader.messages() if c.topic == "/usv/heading"
        ]
    np.testing.assert_array_equal(heading, sim.meta["wrapped_heading"])
    assert max(heading) <= math.pi and min(heading) > -math.pi


@pytest.mark.parametrize("fmt", ["rosbag2", "mcap"])
def test_mcap_reads_with_the_mcap_library_alone(written, clean_nomoto2, fmt):
    path = written[fmt]
    path = next(path.glob("*.mcap")) if path.is_dir() else path
    values = {t: [] for t in TOPICS}
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            assert schema.name == "std_msgs/msg/Float64"
            values[channel.topic].append((message.log_time * 1e-9, decoded.data))
    sim = clean_nomoto2.dataset
    time, rudder = np.array(values["/usv/rudder"]).T
    np.testing.assert_allclose(time, sim.time, atol=1e-9)
    np.testing.assert_array_equal(rudder, sim.rudder)
    np.testing.assert_array_equal(np.array(values["/usv/speed"])[:, 1], sim.speed)


def test_read_samples_is_time_ordered_with_roles(written):
    samples = read_samples(written["mcap"])
    assert [s.time for s in samples] == sorted(s.time for s in samples)
    assert {s.role for s in samples} == {"rudder", "heading", "yaw_rate", "speed"}


def write_imu_bag(path, sim, stamped: bool):
    """Heading and yaw rate as ENU sensor_msgs/Imu stamped t + 1000 s, logged 50 ms later; or unstamped."""
    types = typestore().types
    Imu, Header, Time = types["sensor_msgs/msg/Imu"], types["std_msgs/msg/Header"], types["builtin_interfaces/msg/Time"]
    Quaternion, Vector3 = types["geometry_msgs/msg/Quaternion"], types["geometry_msgs/msg/Vector3"]
    d, offset, delay = sim.dataset, STAMP_OFFSET if stamped else 0.0, 0.05 if stamped else 0.0
    with BagWriter(path, "rosbag2") as writer:
        for t, rudder, psi, r in zip(d.time, d.rudder, d.meta["wrapped_heading"], d.yaw_rate):
            yaw_enu = math.pi / 2 - psi
            ns = int(round((t + offset) * 1e9)) if stamped else 0
            msg = Imu(
                header=Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="imu"),
                orientation=Quaternion(x=0.0, y=0.0, z=math.sin(yaw_enu / 2), w=math.cos(yaw_enu / 2)),
                orientation_covariance=np.zeros(9),
                angular_velocity=Vector3(x=0.0, y=0.0, z=-r),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=Vector3(x=0.0, y=0.0, z=9.81),
                linear_acceleration_covariance=np.zeros(9),
            )
            writer.write("/imu/data", "sensor_msgs/msg/Imu", msg, t + offset + delay)
            writer.write("/usv/rudder", "std_msgs/msg/Float64", float64(rudder), t + offset)


@pytest.mark.parametrize("stamped", [True, False], ids=["header_stamp", "log_time"])
def test_imu_in_enu_reads_as_ned_heading_and_yaw_rate(clean_nomoto2, tmp_path, stamped):
    write_imu_bag(tmp_path / "imu", clean_nomoto2, stamped)
    data = load_dataset(tmp_path / "imu", Topics(imu="/imu/data"))
    sim = clean_nomoto2.dataset
    np.testing.assert_allclose(data.time - (STAMP_OFFSET if stamped else 0.0), sim.time, atol=1e-6)
    np.testing.assert_allclose(data.heading, sim.heading, atol=1e-12)
    np.testing.assert_allclose(data.yaw_rate, sim.yaw_rate, atol=1e-12)
    heading = [s.value for s in read_samples(tmp_path / "imu", Topics(imu="/imu/data")) if s.role == "heading"]
    assert max(heading) <= math.pi and min(heading) > -math.pi


@pytest.mark.parametrize("angle", [0.0, math.pi, -math.pi, 3 * math.pi, 1.0 - 4 * math.pi, 7.5])
def test_wrap_angle_lands_in_half_open_interval(angle):
    wrapped = wrap_angle(angle)
    assert -math.pi < wrapped <= math.pi
    assert math.isclose(math.cos(wrapped), math.cos(angle), abs_tol=1e-12)
    assert math.isclose(math.sin(wrapped), math.sin(angle), abs_tol=1e-12)


def test_directory_with_mcap_but_no_metadata_reads(written, clean_nomoto2, tmp_path):
    folder = tmp_path / "copied"
    shutil.copytree(written["rosbag2"], folder)
    (folder / "metadata.yaml").unlink()
    assert_same_data(load_dataset(folder), clean_nomoto2.dataset)


def write_ros2_bag_record_style(folder, sim, version):
    """What ``ros2 bag record -s mcap`` leaves: zstd chunks, QoS in channel metadata, metadata.yaml."""
    folder.mkdir()
    d = sim.dataset
    columns = {"/usv/rudder": d.rudder, "/usv/heading": d.meta["wrapped_heading"], "/usv/yaw_rate": d.yaw_rate}
    qos = (
        "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n  deadline:\n    sec: 0\n"
        "    nsec: 0\n  lifespan:\n    sec: 0\n    nsec: 0\n  liveliness: 1\n"
        "  liveliness_lease_duration:\n    sec: 0\n    nsec: 0\n  avoid_ros_namespace_conventions: false"
    )
    msgdef, _ = typestore().generate_msgdef("std_msgs/msg/Float64", ros_version=2)
    start_ns = 1_700_000_000 * 10**9
    with (folder / "trip_0.mcap").open("wb") as f:
        writer = McapWriter(f, compression=CompressionType.ZSTD, chunk_size=4096)
        writer.start(profile="ros2", library="rosbag2 (imitated)")
        schema = writer.register_schema("std_msgs/msg/Float64", "ros2msg", msgdef.encode())
        channels = {
            topic: writer.register_channel(topic, "cdr", schema, {"offered_qos_profiles": qos, "topic_type_hash": ""})
            for topic in columns
        }
        for i, t in enumerate(d.time):
            for topic, values in columns.items():
                ns = start_ns + int(round(t * 1e9))
                writer.add_message(
                    channels[topic],
                    ns,
                    typestore().serialize_cdr(float64(values[i]), "std_msgs/msg/Float64"),
                    ns,
                    sequence=i,
                )
        writer.finish()
    n, duration = len(d.time), int(round(d.time[-1] * 1e9))
    topics = "".join(
        f"    - topic_metadata:\n        name: {topic}\n        type: std_msgs/msg/Float64\n"
        f"        serialization_format: cdr\n        offered_qos_profiles:\n"
        f"          - history: keep_last\n            depth: 10\n            reliability: reliable\n"
        f"            durability: volatile\n            deadline:\n              sec: 9223372036\n"
        f"              nsec: 854775807\n            lifespan:\n              sec: 9223372036\n"
        f"              nsec: 854775807\n            liveliness: automatic\n"
        f"            liveliness_lease_duration:\n              sec: 9223372036\n"
        f"              nsec: 854775807\n            avoid_ros_namespace_conventions: false\n"
        f"        type_description_hash: RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18\n"
        f"      message_count: {n}\n"
        for topic in columns
    )
    (folder / "metadata.yaml").write_text(
        "rosbag2_bagfile_information:\n"
        f"  version: {version}\n  storage_identifier: mcap\n"
        f"  duration:\n    nanoseconds: {duration}\n"
        f"  starting_time:\n    nanoseconds_since_epoch: {start_ns}\n"
        f"  message_count: {3 * n}\n  topics_with_message_count:\n{topics}"
        '  compression_format: ""\n  compression_mode: ""\n  relative_file_paths:\n    - trip_0.mcap\n'
        f"  files:\n    - path: trip_0.mcap\n      starting_time:\n        nanoseconds_since_epoch: {start_ns}\n"
        f"      duration:\n        nanoseconds: {duration}\n      message_count: {3 * n}\n"
        "  custom_data: ~\n  ros_distro: kilted\n"
    )


@pytest.mark.parametrize("version", [9, 10], ids=["v9", "v10_unknown_to_rosbags"])
def test_ros2_bag_record_style_bag_reads_like_a_rosbags_bag(written, clean_nomoto2, tmp_path, version):
    write_ros2_bag_record_style(tmp_path / "trip", clean_nomoto2, version)
    data = load_dataset(tmp_path / "trip")
    ours = load_dataset(written["rosbag2"])
    np.testing.assert_allclose(data.time - data.time[0], ours.time, atol=1e-6)
    for name in ("rudder", "heading", "yaw_rate"):  # epoch stamps: float64 time resolves ~0.2 us
        np.testing.assert_allclose(getattr(data, name), getattr(ours, name), rtol=0, atol=1e-6)
    assert data.speed is None


def write_float64_mcap(path, compression, chunked: bool = True, imu_heading: bool = False):
    """Three Float64 inputs with the mcap library: 256-byte chunks, stamps out of order within a
    chunk (in order without chunks) and equal across topics (the reader must keep file order at
    ties); the heading as an Imu topic's type when ``imu_heading``."""
    msgdef, _ = typestore().generate_msgdef("std_msgs/msg/Float64", ros_version=2)
    with path.open("wb") as f:
        writer = McapWriter(f, compression=compression, chunk_size=256, use_chunking=chunked)
        writer.start(profile="ros2", library="test")
        schema = writer.register_schema("std_msgs/msg/Float64", "ros2msg", msgdef.encode())
        imu = writer.register_schema("sensor_msgs/msg/Imu", "ros2msg", b"")
        channels = [
            writer.register_channel(topic, "cdr", imu if imu_heading and topic == "/usv/heading" else schema)
            for topic in TOPICS[:3]
        ]
        for k in (0, 2, 1, 3, 5, 4, *range(6, 40)) if chunked else range(40):
            for i, channel in enumerate(channels):
                data = typestore().serialize_cdr(float64(10 * k + i), "std_msgs/msg/Float64")
                writer.add_message(channel, k * 10**8, data, k * 10**8)
        writer.finish()


@pytest.mark.parametrize("compression", list(CompressionType), ids=lambda c: c.name.lower())
def test_a_float64_mcap_reads_as_the_general_reader_reads_it(tmp_path, compression):
    path = tmp_path / "inputs.mcap"
    write_float64_mcap(path, compression)
    with AnyReader([path], default_typestore=typestore()) as reader:
        general = files._bag_samples(reader, path, Topics())
    plain = read_samples(path)
    assert plain == general and len(plain) == 120
    assert [s.value for s in plain[:6]] == [0.0, 1.0, 2.0, 10.0, 11.0, 12.0]  # by stamp, ties in file order


@pytest.mark.parametrize("chunked, imu_heading", [(False, False), (True, True)], ids=["unchunked", "imu_type"])
def test_a_bag_the_plain_reading_does_not_handle_goes_to_the_general_reader(tmp_path, chunked, imu_heading):
    path = tmp_path / "inputs.mcap"
    write_float64_mcap(path, CompressionType.ZSTD, chunked, imu_heading)
    assert float64_messages(path, set(TOPICS[:3])) is None
    if imu_heading:
        with pytest.raises(DataError, match="carries sensor_msgs/msg/Imu, expected std_msgs/msg/Float64"):
            read_samples(path)
    else:
        assert len(read_samples(path)) == 120


@pytest.mark.parametrize("fmt", ["rosbag2", "mcap"])
def test_bag_writer_writes_output_types_and_closes_on_interrupt(tmp_path, fmt):
    types = typestore().types
    path = tmp_path / ("out" if fmt == "rosbag2" else "out.mcap")
    layout = types["std_msgs/msg/MultiArrayLayout"](
        dim=[types["std_msgs/msg/MultiArrayDimension"](label="K,T", size=2, stride=2)], data_offset=0
    )
    status = types["diagnostic_msgs/msg/DiagnosticStatus"](
        level=0,
        name="ship_ident",
        message="ok",
        hardware_id="usv",
        values=[types["diagnostic_msgs/msg/KeyValue"](key="K", value="0.5")],
    )
    with pytest.raises(KeyboardInterrupt), BagWriter(path, fmt) as writer:
        for i in range(3):
            writer.write(
                "/ship_ident/estimate",
                "std_msgs/msg/String",
                types["std_msgs/msg/String"](data=f'{{"i": {i}}}'),
                i * 1.0,
            )
            writer.write(
                "/ship_ident/parameters",
                "std_msgs/msg/Float64MultiArray",
                types["std_msgs/msg/Float64MultiArray"](layout=layout, data=np.array([0.5, 1.5])),
                i * 1.0,
            )
            writer.write(
                "/diagnostics",
                "diagnostic_msgs/msg/DiagnosticArray",
                types["diagnostic_msgs/msg/DiagnosticArray"](
                    header=types["std_msgs/msg/Header"](
                        stamp=types["builtin_interfaces/msg/Time"](sec=i, nanosec=0), frame_id=""
                    ),
                    status=[status],
                ),
                i * 1.0,
            )
        raise KeyboardInterrupt
    mcap_file = next(path.glob("*.mcap")) if path.is_dir() else path
    with mcap_file.open("rb") as f:
        decoded = [
            (c.topic, m) for _, c, _, m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()
        ]
    assert len(decoded) == 9
    last = {topic: msg for topic, msg in decoded}
    assert last["/ship_ident/estimate"].data == '{"i": 2}'
    assert last["/ship_ident/parameters"].layout.dim[0].label == "K,T"
    assert list(last["/ship_ident/parameters"].data) == [0.5, 1.5]
    assert last["/diagnostics"].status[0].values[0].key == "K"
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporary folder left


def test_bag_writer_rejects_a_second_type_on_a_topic(tmp_path):
    with BagWriter(tmp_path / "b.mcap", "mcap") as writer:
        writer.write("/x", "std_msgs/msg/Float64", float64(1.0), 0.0)
        with pytest.raises(ValueError, match="/x"):
            writer.write("/x", "std_msgs/msg/String", typestore().types["std_msgs/msg/String"](data=""), 1.0)


# --- bad input: every case raises DataError with one sentence naming the problem ----------------


def make_bad_input(kind: str, folder, good_mcap):
    """Create one kind of bad input in ``folder``; return its path."""
    if kind == "missing":
        return folder / "nope.mcap"
    if kind == "not_a_bag":
        path = folder / "photo.png"
        path.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(100))
        return path
    if kind == "empty_dir":
        (folder / "empty").mkdir()
        return folder / "empty"
    if kind == "zero_bytes":
        (folder / "zero.mcap").write_bytes(b"")
        return folder / "zero.mcap"
    if kind == "corrupt":
        data = bytearray(good_mcap.read_bytes())
        data[200:20000] = np.random.default_rng(0).integers(0, 256, 19800, dtype=np.uint8).tobytes()
        (folder / "corrupt.mcap").write_bytes(bytes(data))
        return folder / "corrupt.mcap"
    if kind == "truncated":
        data = good_mcap.read_bytes()
        (folder / "cut.mcap").write_bytes(data[: len(data) // 2])
        return folder / "cut.mcap"
    if kind == "no_messages":
        with BagWriter(folder / "silent", "rosbag2"):
            pass
        return folder / "silent"
    if kind == "missing_topics":
        with BagWriter(folder / "other.mcap", "mcap") as writer:
            writer.write("/usv/rudder", "std_msgs/msg/Float64", float64(0.1), 0.0)
            writer.write("/gps/fix_heading", "std_msgs/msg/Float64", float64(1.0), 0.0)
        return folder / "other.mcap"
    if kind == "wrong_type":
        with BagWriter(folder / "typed.mcap", "mcap") as writer:
            for topic in ("/usv/rudder", "/usv/yaw_rate"):
                writer.write(topic, "std_msgs/msg/Float64", float64(0.1), 0.0)
            writer.write("/usv/heading", "std_msgs/msg/String", typestore().types["std_msgs/msg/String"](data="N"), 0.0)
        return folder / "typed.mcap"
    csv_text = {
        "csv_missing_column": "t,rudder,heading\n0,0,0\n0.1,0,0\n",
        "csv_text_in_number": "t,rudder,heading,yaw_rate\n0,0,0,0\n0.1,zero,0,0\n",
        "csv_nan_only": "t,rudder,heading,yaw_rate\n0,nan,0,0\n0.1,nan,0,0\n0.2,nan,0,0\n",
        "csv_header_only": "t,rudder,heading,yaw_rate\n",
    }[kind]
    (folder / f"{kind}.csv").write_text(csv_text)
    return folder / f"{kind}.csv"


BAD_INPUTS = {  # kind: words the message must contain
    "missing": "does not exist",
    "not_a_bag": "neither a bag",
    "empty_dir": "without metadata.yaml",
    "zero_bytes": "corrupt or truncated",
    "corrupt": "corrupt or truncated",
    "truncated": "corrupt or truncated",
    "no_messages": "no messages",
    "missing_topics": "/gps/fix_heading",
    "wrong_type": "std_msgs/msg/String",
    "csv_missing_column": "yaw_rate",
    "csv_text_in_number": "line 3",
    "csv_nan_only": "every rudder sample is NaN",
    "csv_header_only": "no data rows",
}


@pytest.mark.parametrize("kind", BAD_INPUTS)
def test_bad_input_raises_one_clear_data_error(kind, tmp_path, written):
    path = make_bad_input(kind, tmp_path, written["mcap"])
    with pytest.raises(DataError) as caught:
        load_dataset(path)
    message = str(caught.value)
    assert BAD_INPUTS[kind] in message
    assert "\n" not in message and str(path.name) in message


# --- several recordings, CSV columns by name ------------------------------------------------


def test_joined_recordings_are_named_and_resampled_to_one_step():
    """Two recordings of different steps: the second is resampled onto the first's 0.1 s, each keeps
    its own segment, and meta["recordings"] gives each one's name and sample range."""
    fine = simulate("zigzag10", "seed001", (), duration=30.0, noise=0, seed=1).dataset
    coarse = simulate("turning", "seed001", (), duration=20.0, sample_time=0.2, noise=0, seed=2).dataset
    joined = join_recordings([fine, coarse], ["zigzag.csv", "turning.mcap"])
    n = fine.n_samples
    assert joined.sample_time == pytest.approx(0.1)
    assert joined.n_samples == n + 201  # 20 s at 0.1 s, both ends included
    assert joined.segments == ((0, n), (n, n + 201))  # never bridged
    assert joined.meta["recordings"] == [
        {"name": "zigzag.csv", "start": 0, "stop": n},
        {"name": "turning.mcap", "start": n, "stop": n + 201},
    ]
    assert np.all(np.diff(joined.time) > 0) and len(joined.gaps) == 1
    np.testing.assert_array_equal(joined.yaw_rate[:n], fine.yaw_rate)
    np.testing.assert_allclose(joined.yaw_rate[n::2], coarse.yaw_rate, rtol=0, atol=1e-12)  # 0.2 s samples kept
    midpoints = 0.5 * (coarse.yaw_rate[:-1] + coarse.yaw_rate[1:])
    np.testing.assert_allclose(joined.yaw_rate[n + 1 :: 2], midpoints, rtol=0, atol=1e-12)
    tail = joined.slice(n - 10, joined.n_samples)  # e.g. a held-out tail
    assert tail.meta["recordings"] == [
        {"name": "zigzag.csv", "start": 0, "stop": 10},
        {"name": "turning.mcap", "start": 10, "stop": 211},
    ]
    assert joined.slice(0, 5).meta["recordings"] == [{"name": "zigzag.csv", "start": 0, "stop": 5}]
    on_coarse = join_recordings([fine, coarse], sample_time=0.2)
    assert on_coarse.sample_time == pytest.approx(0.2) and on_coarse.n_samples == (n + 1) // 2 + 101


def test_a_single_recording_gets_its_entry_too(written):
    data = load_dataset(written["mcap"])
    joined = join_recordings([data])
    assert joined.meta["recordings"] == [{"name": str(written["mcap"]), "start": 0, "stop": data.n_samples}]
    assert_same_data(joined, data)


SYNONYM_HEADERS = {  # a header of synonyms: the columns in the canonical order t,rudder,heading,yaw_rate,speed
    "public simulator": "time,delta,psi,r,surge_speed",
    "units in names": "t_s,rudder_angle,heading_rad,yaw_rate_rad_s,speed_mps",
    "capitals": "Time,Delta,Yaw,R,U",
}


def renamed_csv(source, header: str, target):
    lines = source.read_text().splitlines()
    target.write_text("\n".join([header] + lines[1:]) + "\n")
    return target


@pytest.mark.parametrize("header", SYNONYM_HEADERS.values(), ids=SYNONYM_HEADERS)
def test_csv_synonyms_are_read_without_options(written, tmp_path, header):
    path = renamed_csv(written["csv"], header, tmp_path / "renamed.csv")
    data = load_dataset(path)
    assert_same_data(data, load_dataset(written["csv"]))  # the speed too: surge_speed is the speed
    assert data.meta["columns"] == dict(zip(("t", "rudder", "heading", "yaw_rate", "speed"), header.split(",")))


def test_csv_columns_by_name(written, tmp_path):
    path = renamed_csv(written["csv"], "clock,helm,compass,gyro,log", tmp_path / "own.csv")
    columns = parse_columns("t=clock, rudder=helm,heading=compass,yaw_rate=gyro,speed=log")
    data = load_dataset(path, Topics(csv_columns=columns))
    assert_same_data(data, load_dataset(written["csv"]))
    assert data.meta["columns"]["speed"] == "log"


@pytest.mark.parametrize(
    "columns, words",
    [
        ("speed=surge", "has no column 'surge'"),
        ("sped=speed", "unknown role 'sped'"),
        ("speed", "is not ROLE=COLUMN"),
        ("speed=log,speed=u", "twice"),
        ("rudder=heading", "so heading has none"),
    ],
)
def test_bad_columns_are_one_clear_data_error(written, columns, words):
    with pytest.raises(DataError) as caught:
        load_dataset(written["csv"], Topics(csv_columns=parse_columns(columns)))
    assert words in str(caught.value) and "\n" not in str(caught.value)


def test_a_csv_without_a_rudder_column_names_what_it_has(written, tmp_path):
    path = renamed_csv(written["csv"], "t,helm,heading,yaw_rate,speed", tmp_path / "helm.csv")
    with pytest.raises(DataError, match="no column for rudder; its columns: t, helm, heading"):
        load_dataset(path)
