"""``ship-ident replay BAG``: re-run the online node's identification on a recorded bag.

The bag's samples go in time order through the same ``OnlineIdentifier``
as the node, with the bag's time as the clock and the node's refit
schedule, as fast as the machine allows. ``--json`` prints one JSON object
per refit, one per line (JSON lines: the ``~/estimate`` record of the node).
``--out`` writes an MCAP with the input topics and the node's outputs
``/ship_ident/estimate`` and ``/ship_ident/parameters`` at the refit times,
as the replay goes: Ctrl-C or SIGTERM stop it after the refit in progress
and still leave a complete MCAP with every estimate up to then (exit code
130 or 143).
"""
from __future__ import annotations

import math
import signal
import sys
import threading
import time
from dataclasses import dataclass

import numpy as np

from ..errors import CommandError
from ..fleet import add_fleet_arguments, run_fleet
from ..io import FLOAT64, BagWriter, Sample, Topics, read_samples, typestore
from ..online import OnlineConfig, OnlineIdentifier, RefitRecord, run_schedule
from ..jsonio import dumps_json
from .common import add_data_args, add_model_args, topics_from_args

ESTIMATE_TOPIC = "/ship_ident/estimate"
PARAMETERS_TOPIC = "/ship_ident/parameters"
DEFAULTS = OnlineConfig()


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "replay", help="run the online identifier over a bag, faster than real time",
        description=__doc__.split("\n\n", 1)[1])
    parser.add_argument("bag", metavar="BAG", nargs="+",
                        help="rosbag2 directory, .mcap file or CSV file; several (or --jobs, --table, "
                             "--dask): a fleet run into one table, see ship_ident/fleet.py")
    add_data_args(parser)
    add_model_args(parser)
    parser.set_defaults(effects=",".join(DEFAULTS.effects), method=DEFAULTS.method)
    parser.add_argument("--window-length", type=float, default=DEFAULTS.window_length, metavar="S",
                        help="s of data in each fit (default %(default)s)")
    parser.add_argument("--refit-period", type=float, default=DEFAULTS.refit_period, metavar="S",
                        help="s of bag time between refits (default %(default)s)")
    parser.add_argument("--min-window-length", type=float, default=DEFAULTS.min_window_length,
                        metavar="S", help="s of data before the first fit (default %(default)s)")
    parser.add_argument("--gap-threshold", type=float, default=DEFAULTS.gap_threshold, metavar="S",
                        help="s without a sample that splits the window; 0: five sample times "
                             "(default %(default)s)")
    parser.add_argument("--rudder-limit", type=float, default=math.degrees(DEFAULTS.rudder_limit),
                        metavar="DEG", help="the steering gear's limit in deg: a rudder held there is "
                                            "rudder_saturated (default %(default).0f)")
    parser.add_argument("--change-ratio", type=float, default=DEFAULTS.change_ratio, metavar="R",
                        help="restart the window where the vessel changed, when the newest 30 s are "
                             "mispredicted R times worse (mean squares) than usual; 0: never "
                             "(default %(default)s)")
    parser.add_argument("--json", action="store_true",
                        help="print one JSON object per refit on stdout, one per line (JSON lines)")
    parser.add_argument("--out", metavar="OUT.mcap",
                        help="write an MCAP with the input topics and the estimates")
    add_fleet_arguments(parser)
    parser.set_defaults(func=run)


def config_from_args(args, topics: Topics, has_speed: bool) -> OnlineConfig:
    return OnlineConfig(
        rudder_topic=topics.rudder, heading_topic=topics.heading, yaw_rate_topic=topics.yaw_rate,
        speed_topic=topics.speed if has_speed else "", imu_topic=topics.imu,
        sample_time=args.sample_time, window_length=args.window_length,
        refit_period=args.refit_period, min_window_length=min(args.min_window_length, args.window_length),
        change_ratio=args.change_ratio, gap_threshold=args.gap_threshold,
        rudder_limit=math.radians(args.rudder_limit),
        model=args.model, effects=args.effects, method=args.method).validate()


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
        print(f"\rreplay [{bar:<30}] {100 * done:5.1f} %  {speed:6.0f}x real time", end="",
              file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.enabled:
            print(file=sys.stderr)


@dataclass
class ReplayResult:
    """One bag's replay: its refit records in time order and how long it took."""

    bag: str
    records: list[RefitRecord]
    duration: float        # s of bag time replayed
    wall_seconds: float    # s of wall time of the identification loop
    interrupted: bool      # stopped early by ``stop``


def replay_bag(bag, topics: Topics, config: OnlineConfig, out=None, on_record=None,
               stop: threading.Event | None = None, progress: bool = False) -> ReplayResult:
    """Run one bag (or CSV) through the online identifier with the bag's time as the clock.

    ``config`` as from ``config_from_args`` (its speed topic is dropped when the
    bag has no speed). ``out``: MCAP written as the replay goes, complete even
    when ``stop`` ends it early. ``on_record(record)`` is called after each
    refit; ``stop`` is checked before every sample; ``progress`` draws a bar on
    stderr. Bad input raises DataError, ConfigError or CommandError (one line).
    """
    samples = read_samples(bag, topics)
    if not samples:
        raise CommandError(f"{bag} holds no input samples; check the topic names")
    if config.speed_topic and not any(s.role == "speed" for s in samples):
        config = config.changed(speed_topic="")
    identifier = OnlineIdentifier(config)
    bar = Progress(samples[0].time, samples[-1].time, progress)
    records, fed = [], []
    wall0 = time.perf_counter()
    with (ReplayWriter(out, topics) if out else _NoWriter()) as writer:
        for record in run_schedule(identifier, _feed(samples, writer, stop, fed)):
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


def run(args) -> int:
    if len(args.bag) > 1 or args.jobs > 1 or args.table or args.dask:
        if args.out:
            raise CommandError("--out takes a single bag; for many bags use --table")
        return run_fleet(args, args.bag)
    bag = args.bag[0]
    stop, received = threading.Event(), []

    def on_signal(signum, _frame):
        received.append(signum)
        stop.set()

    def on_record(record):
        if args.json:
            print(dumps_json(record.to_json()), flush=True)

    topics = topics_from_args(args)
    handlers = {signum: signal.signal(signum, on_signal) for signum in (signal.SIGINT, signal.SIGTERM)}
    try:
        result = replay_bag(bag, topics, config_from_args(args, topics, has_speed=True),
                            args.out, on_record, stop, sys.stderr.isatty())
    finally:
        for signum, handler in handlers.items():
            signal.signal(signum, handler)
    if result.interrupted:
        kept = f"; {args.out} holds them" if args.out else ""
        print(f"ship-ident replay: interrupted at bag time {result.duration:.1f} s after "
              f"{len(result.records)} refits{kept}", file=sys.stderr)
        return 128 + received[0]
    if not args.json:
        print_summary(result.records, result.duration, result.wall_seconds)
    return 0


class ReplayWriter:
    """The ``--out`` MCAP: inputs as Float64 topics, each refit's estimate and parameters."""

    def __init__(self, path, topics: Topics):
        types = typestore().types
        self._Float64, self._String = types[FLOAT64], types["std_msgs/msg/String"]
        self._MultiArray = types["std_msgs/msg/Float64MultiArray"]
        self._Layout = types["std_msgs/msg/MultiArrayLayout"]
        self._Dimension = types["std_msgs/msg/MultiArrayDimension"]
        self._topic_of = {"rudder": topics.rudder, "heading": topics.heading,
                          "yaw_rate": topics.yaw_rate, "speed": topics.speed}
        if topics.imu:  # the Imu was read as heading and yaw rate: write those as Float64
            self._topic_of.update(heading=Topics().heading, yaw_rate=Topics().yaw_rate)
        self._writer = BagWriter(path, "mcap")

    def write_sample(self, sample: Sample) -> None:
        self._writer.write(self._topic_of[sample.role], FLOAT64,
                           self._Float64(data=float(sample.value)), sample.time)

    def write_record(self, record: RefitRecord) -> None:
        data = record.to_json()
        self._writer.write(ESTIMATE_TOPIC, "std_msgs/msg/String", self._String(data=dumps_json(data)),
                           record.time)
        if data["parameters"]:
            names = list(data["parameters"])
            layout = self._Layout(dim=[self._Dimension(label=",".join(names), size=len(names),
                                                       stride=len(names))], data_offset=0)
            values = np.array([data["parameters"][n] for n in names], dtype=np.float64)
            self._writer.write(PARAMETERS_TOPIC, "std_msgs/msg/Float64MultiArray",
                               self._MultiArray(layout=layout, data=values), record.time)

    def __enter__(self) -> "ReplayWriter":
        return self

    def __exit__(self, *exc) -> None:
        self._writer.close()


class _NoWriter:
    """Stands in for ReplayWriter without ``--out``."""

    def write_sample(self, sample) -> None:
        pass

    def write_record(self, record) -> None:
        pass

    def __enter__(self) -> "_NoWriter":
        return self

    def __exit__(self, *exc) -> None:
        pass


def print_summary(records, duration: float, wall: float) -> None:
    """The last estimate, its fit and the replay speed, for people."""
    fitted = [r for r in records if r.new_estimate]
    print(f"{len(records)} refits over {duration:.0f} s of bag in {wall:.1f} s "
          f"({duration / max(wall, 1e-9):.0f}x real time); {len(fitted)} gave a new estimate")
    if not records:
        return
    last = records[-1].to_json()
    print(f"last refit at {last['stamp']:.1f} s: {last['status']}"
          + "".join(f"\n  {c}: {m}" for c, m in last["conditions"].items()))
    if last["parameters"]:
        print(f"  {last['structure']['model']} + {', '.join(last['structure']['effects']) or 'no effects'}"
              f" ({last['method']}):")
        for name, value in last["parameters"].items():
            std = last["std_errors"].get(name, math.nan)
            print(f"    {name:>8} = {value:12.5g}  +/- {std:.2g}")
        print(f"  free-run rmse: yaw rate {math.degrees(last['fit']['rmse_yaw_rate']):.3f} deg/s, "
              f"heading {math.degrees(last['fit']['rmse_heading']):.2f} deg")
