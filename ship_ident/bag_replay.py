"""One bag through the online identifier, the bag's time as its clock: ``ship-ident replay``'s engine.

The bag's (or CSV file's) samples go in time order through the same
``OnlineIdentifier`` as the node, with the node's refit schedule, as fast as
the machine allows. ``replay_bag`` optionally writes an MCAP as it goes: the
input topics and the node's outputs ``/ship_ident/estimate`` (the JSON
record) and ``/ship_ident/parameters`` at the refit times, and with
``diagnosis_period`` set ``/ship_ident/diagnosis`` (JSON) and
``/ship_ident/held_out_error`` (rad/s) at the refits where a diagnosis
finished (``online_diagnosis``, run inline: reproducible), complete even
when a ``stop`` event ends the replay early. One bag per call, so many-bag
replay (``fleet``) runs it per task. Bad input raises ``DataError`` or
``ConfigError`` (one line).
"""

from __future__ import annotations

import sys
import threading
import time
from dataclasses import dataclass

import numpy as np

from .dataset import DataError
from .io import FLOAT64, BagWriter, Sample, Topics, read_samples, typestore
from .jsonio import dumps_json
from .online import OnlineIdentifier, RefitRecord, run_schedule
from .online_config import OnlineConfig
from .online_diagnosis import OnlineDiagnosis

ESTIMATE_TOPIC = "/ship_ident/estimate"
PARAMETERS_TOPIC = "/ship_ident/parameters"
DIAGNOSIS_TOPIC = "/ship_ident/diagnosis"
HELD_OUT_ERROR_TOPIC = "/ship_ident/held_out_error"


class Progress:
    """A one-line progress bar on stderr (only when stderr is a terminal)."""

    def __init__(self, start: float, stop: float, enabled: bool):
        self.start, self.span, self.enabled = start, max(stop - start, 1e-9), enabled
        self.wall0 = self.last = time.perf_counter()

    def update(self, bag_time: float, force: bool = False) -> None:
        now = time.perf_counter()
        if not self.enabled or (now - self.last < 0.2 and not force):
            return
        self.last = now
        done = min(max((bag_time - self.start) / self.span, 0.0), 1.0)
        bar = "#" * int(30 * done)
        speed = (bag_time - self.start) / max(now - self.wall0, 1e-9)
        print(f"\rreplay [{bar:<30}] {100 * done:5.1f} %  {speed:6.0f}x real time", end="", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.enabled:
            print(file=sys.stderr)


@dataclass
class ReplayResult:
    """One bag's replay: its refit records in time order and how long it took."""

    bag: str
    records: list[RefitRecord]
    duration: float  # s of bag time replayed
    wall_seconds: float  # s of wall time of the identification loop
    interrupted: bool  # stopped early by ``stop``


def replay_bag(
    bag,
    topics: Topics,
    config: OnlineConfig,
    out=None,
    on_record=None,
    stop: threading.Event | None = None,
    progress: bool = False,
) -> ReplayResult:
    """Run one bag (or CSV) through the online identifier with the bag's time as the clock.

    ``config``: the online configuration (its speed topic is dropped when the
    bag has no speed). ``out``: MCAP written as the replay goes, complete even
    when ``stop`` ends it early. ``on_record(record)`` is called after each
    refit; ``stop`` is checked before every sample; ``progress`` draws a bar on
    stderr. Bad input raises DataError or ConfigError (one line).
    """
    samples = read_samples(bag, topics)
    if not samples:
        raise DataError(f"{bag} holds no input samples; check the topic names")
    if config.speed_topic and not any(s.role == "speed" for s in samples):
        config = config.changed(speed_topic="")
    identifier = OnlineIdentifier(config)
    bar = Progress(samples[0].time, samples[-1].time, progress)
    records, fed = [], []
    wall0 = time.perf_counter()
    with ReplayWriter(out, topics) if out else _NoWriter() as writer:
        for record in run_schedule(identifier, _feed(samples, writer, stop, fed), OnlineDiagnosis()):
            writer.write_record(record)
            records.append(record)
            bar.update(record.time)
            if on_record is not None:
                on_record(record)
    wall = time.perf_counter() - wall0
    end = fed[-1].time if fed else samples[0].time
    bar.update(end, force=True)
    bar.close()
    return ReplayResult(str(bag), records, end - samples[0].time, wall, len(fed) < len(samples))


def _feed(samples, writer, stop, fed: list):
    """The samples, each written to ``writer`` and appended to ``fed``, until ``stop`` is set."""
    for sample in samples:
        if stop is not None and stop.is_set():
            return
        writer.write_sample(sample)
        fed.append(sample)
        yield sample


class ReplayWriter:
    """The ``--out`` MCAP: inputs as Float64 topics, each refit's estimate and parameters."""

    def __init__(self, path, topics: Topics):
        types = typestore().types
        self._Float64, self._String = types[FLOAT64], types["std_msgs/msg/String"]
        self._MultiArray = types["std_msgs/msg/Float64MultiArray"]
        self._Layout = types["std_msgs/msg/MultiArrayLayout"]
        self._Dimension = types["std_msgs/msg/MultiArrayDimension"]
        self._topic_of = {
            "rudder": topics.rudder,
            "heading": topics.heading,
            "yaw_rate": topics.yaw_rate,
            "speed": topics.speed,
        }
        if topics.imu:  # the Imu was read as heading and yaw rate: write those as Float64
            self._topic_of.update(heading=Topics().heading, yaw_rate=Topics().yaw_rate)
        self._writer = BagWriter(path, "mcap")

    def write_sample(self, sample: Sample) -> None:
        self._writer.write(self._topic_of[sample.role], FLOAT64, self._Float64(data=float(sample.value)), sample.time)

    def write_record(self, record: RefitRecord) -> None:
        data = record.to_json()
        self._writer.write(ESTIMATE_TOPIC, "std_msgs/msg/String", self._String(data=dumps_json(data)), record.time)
        if data["parameters"]:
            names = list(data["parameters"])
            layout = self._Layout(
                dim=[self._Dimension(label=",".join(names), size=len(names), stride=len(names))], data_offset=0
            )
            values = np.array([data["parameters"][n] for n in names], dtype=np.float64)
            self._writer.write(
                PARAMETERS_TOPIC,
                "std_msgs/msg/Float64MultiArray",
                self._MultiArray(layout=layout, data=values),
                record.time,
            )
        if record.diagnosis is not None:
            text = self._String(data=dumps_json(record.diagnosis))
            self._writer.write(DIAGNOSIS_TOPIC, "std_msgs/msg/String", text, record.time)
            if record.diagnosis["status"] == "done":
                error = self._Float64(data=float(record.diagnosis["held_out_error"]))
                self._writer.write(HELD_OUT_ERROR_TOPIC, FLOAT64, error, record.time)

    def __enter__(self) -> ReplayWriter:
        return self

    def __exit__(self, *exc) -> None:
        self._writer.close()


class _NoWriter:
    """Stands in for ReplayWriter without ``--out``."""

    def write_sample(self, sample) -> None:
        pass

    def write_record(self, record) -> None:
        pass

    def __enter__(self) -> _NoWriter:
        return self

    def __exit__(self, *exc) -> None:
        pass
