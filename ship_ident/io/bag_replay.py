"""One bag through the online identifier, the bag's time as its clock: ``ship-ident replay``'s engine.

The bag's (or CSV file's) samples go in time order through the same
``OnlineIdentifier`` as the node, with the node's refit schedule, as fast as
the machine allows. ``replay_bag`` optionally writes an MCAP as it goes: the
input topics and the node's outputs ``/ship_ident/estimate`` (the JSON
record) and ``/ship_ident/parameters`` at the refit times, and with
``diagnosis_period`` set ``/ship_ident/diagnosis`` (JSON) and
``/ship_ident/held_out_error`` (rad/s, pooled as the verdict reads it) at the refits where a diagnosis
finished (``diagnosis.onboard``, run inline: reproducible), complete even
when a ``stop`` event ends the replay early. The MCAP also holds
``/ship_ident/predicted_yaw_rate`` at the yaw-rate samples' times
(``outputs.YawRatePrediction``), ``/ship_ident/gain_band``, ``/diagnostics``
and, with a diagnosis, ``/ship_ident/noise_floor``; ``/ship_ident/parameters``
holds only the estimates with status OK and is recorded latched (transient
local, depth 1), as the node offers it. One bag per call, so many-bag
replay (``fleet``) runs it per task. Bad input raises ``DataError`` or
``ConfigError`` (one line).
"""

from __future__ import annotations

import math
import sys
import threading
import time
from dataclasses import dataclass

import numpy as np

from ..diagnosis.onboard import OnlineDiagnosis
from ..model.dataset import DataError
from ..online.config import OnlineConfig
from ..online.identifier import OnlineIdentifier, RefitRecord, run_schedule
from ..online.outputs import (
    DIAGNOSTIC_NAME,
    GAIN_BAND_LABELS,
    PREDICTION_FRAME,
    YawRatePrediction,
    diagnostic_status,
    error_and_floor,
    gain_band,
    trusted_parameters,
)
from .files import FLOAT64, BagWriter, Sample, Topics, read_samples, typestore
from .jsonio import dumps_json

NODE = "/ship_ident"  # the node's default name: replay writes its topics as it publishes them
ESTIMATE_TOPIC = f"{NODE}/estimate"
PARAMETERS_TOPIC = f"{NODE}/parameters"
GAIN_BAND_TOPIC = f"{NODE}/gain_band"
PREDICTED_TOPIC = f"{NODE}/predicted_yaw_rate"
DIAGNOSIS_TOPIC = f"{NODE}/diagnosis"
HELD_OUT_ERROR_TOPIC = f"{NODE}/held_out_error"
NOISE_FLOOR_TOPIC = f"{NODE}/noise_floor"
DIAGNOSTICS_TOPIC = "/diagnostics"
MULTI_ARRAY, STRING = "std_msgs/msg/Float64MultiArray", "std_msgs/msg/String"
STAMPED_VECTOR, DIAGNOSTIC_ARRAY = "geometry_msgs/msg/Vector3Stamped", "diagnostic_msgs/msg/DiagnosticArray"


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
    start: float  # s, the bag's first stamp
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
    when ``stop`` ends it early. ``on_record(record, start)`` is called after each
    refit with the bag's first stamp (s); ``stop`` is checked before every sample; ``progress`` draws a bar on
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
    prediction = YawRatePrediction(config) if out else None
    with ReplayWriter(out, topics) if out else _NoWriter() as writer:
        for record in run_schedule(identifier, _feed(samples, writer, stop, fed, prediction), OnlineDiagnosis()):
            if prediction is not None:
                prediction.update(record, identifier.config)
            writer.write_record(record)
            records.append(record)
            bar.update(record.time)
            if on_record is not None:
                on_record(record, samples[0].time)
        if prediction is not None:
            writer.write_prediction(prediction.flush())
    wall = time.perf_counter() - wall0
    end = fed[-1].time if fed else samples[0].time
    bar.update(end, force=True)
    bar.close()
    start = samples[0].time
    return ReplayResult(str(bag), records, start, end - start, wall, len(fed) < len(samples))


def _feed(samples, writer, stop, fed: list, prediction: YawRatePrediction | None):
    """The samples, each written to ``writer`` (with the predicted yaw rates of a run it ends) and
    appended to ``fed``, until ``stop`` is set."""
    for sample in samples:
        if stop is not None and stop.is_set():
            return
        writer.write_sample(sample)
        if prediction is not None:
            writer.write_prediction(prediction.add(sample))
        fed.append(sample)
        yield sample


class ReplayWriter:
    """The ``--out`` MCAP: inputs as Float64 topics and the node's outputs, each message of the same
    type as the node publishes and ``/ship_ident/parameters`` recorded latched as the node offers it."""

    def __init__(self, path, topics: Topics):
        self._types = typestore().types
        self._topic_of = {
            "rudder": topics.rudder,
            "heading": topics.heading,
            "yaw_rate": topics.yaw_rate,
            "speed": topics.speed,
        }
        if topics.imu:  # the Imu was read as heading and yaw rate: write those as Float64
            self._topic_of.update(heading=Topics().heading, yaw_rate=Topics().yaw_rate)
        self._writer = BagWriter(path, "mcap")

    def _float64(self, value: float):
        return self._types[FLOAT64](data=float(value))

    def _multi_array(self, names, values):
        dimension = self._types["std_msgs/msg/MultiArrayDimension"](
            label=",".join(names), size=len(names), stride=len(names)
        )
        layout = self._types["std_msgs/msg/MultiArrayLayout"](dim=[dimension], data_offset=0)
        return self._types[MULTI_ARRAY](layout=layout, data=np.array(values, dtype=np.float64))

    def _header(self, stamp: float, frame_id: str = ""):
        seconds = int(np.floor(stamp))
        nanoseconds = min(int(round((stamp - seconds) * 1e9)), 999_999_999)
        time_msg = self._types["builtin_interfaces/msg/Time"](sec=seconds, nanosec=nanoseconds)
        return self._types["std_msgs/msg/Header"](stamp=time_msg, frame_id=frame_id)

    def write_sample(self, sample: Sample) -> None:
        self._writer.write(self._topic_of[sample.role], FLOAT64, self._float64(sample.value), sample.time)

    def write_prediction(self, predicted: list[tuple[float, float]]) -> None:
        """``/ship_ident/predicted_yaw_rate`` at each yaw-rate sample's time (rad/s in vector.z)."""
        vector, stamped = self._types["geometry_msgs/msg/Vector3"], self._types[STAMPED_VECTOR]
        for stamp, value in predicted:
            header = self._header(stamp, PREDICTION_FRAME)
            message = stamped(header=header, vector=vector(x=math.nan, y=math.nan, z=value))
            self._writer.write(PREDICTED_TOPIC, STAMPED_VECTOR, message, stamp)

    def write_record(self, record: RefitRecord) -> None:
        data = record.to_json()
        self._writer.write(ESTIMATE_TOPIC, STRING, self._types[STRING](data=dumps_json(data)), record.time)
        trusted = trusted_parameters(record)
        if trusted is not None:
            self._writer.write(PARAMETERS_TOPIC, MULTI_ARRAY, self._multi_array(*trusted), record.time, latched=True)
        band = gain_band(record)
        if band is not None:
            self._writer.write(GAIN_BAND_TOPIC, MULTI_ARRAY, self._multi_array(GAIN_BAND_LABELS, band), record.time)
        self._write_diagnostics(record)
        if record.diagnosis is not None:
            text = self._types[STRING](data=dumps_json(record.diagnosis))
            self._writer.write(DIAGNOSIS_TOPIC, STRING, text, record.time)
            finished = error_and_floor(record.diagnosis)
            if finished is not None:
                self._writer.write(HELD_OUT_ERROR_TOPIC, FLOAT64, self._float64(finished[0]), record.time)
                self._writer.write(NOISE_FLOOR_TOPIC, FLOAT64, self._float64(finished[1]), record.time)

    def _write_diagnostics(self, record: RefitRecord) -> None:
        level, message, values = diagnostic_status(record)
        pair = self._types["diagnostic_msgs/msg/KeyValue"]
        status = self._types["diagnostic_msgs/msg/DiagnosticStatus"](
            level=level,
            name=DIAGNOSTIC_NAME,
            message=message,
            hardware_id=NODE,
            values=[pair(key=k, value=v) for k, v in values],
        )
        array = self._types[DIAGNOSTIC_ARRAY](header=self._header(record.time), status=[status])
        self._writer.write(DIAGNOSTICS_TOPIC, DIAGNOSTIC_ARRAY, array, record.time)

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

    def write_prediction(self, predicted) -> None:
        pass

    def __enter__(self) -> _NoWriter:
        return self

    def __exit__(self, *exc) -> None:
        pass
