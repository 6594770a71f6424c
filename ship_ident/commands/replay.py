"""``ship-ident replay BAG``: re-run the online node's identification on a recorded bag.

The bag's samples go in time order through the same ``OnlineIdentifier``
as the node, with the bag's time as the clock and the node's refit
schedule, as fast as the machine allows. ``--json`` prints one JSON object
per refit, one per line (JSON lines: the ``~/estimate`` record of the node).
``--out`` writes an MCAP with the input topics and the node's outputs
``/ship_ident/estimate`` and ``/ship_ident/parameters`` at the refit times.
"""
from __future__ import annotations

import math
import sys
import time

import numpy as np

from ..errors import CommandError
from ..io import FLOAT64, BagWriter, Topics, read_samples, typestore
from ..online import OnlineConfig, OnlineIdentifier, run_schedule
from .common import add_data_args, add_model_args, dumps_json, topics_from_args

ESTIMATE_TOPIC = "/ship_ident/estimate"
PARAMETERS_TOPIC = "/ship_ident/parameters"
DEFAULTS = OnlineConfig()


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "replay", help="run the online identifier over a bag, faster than real time",
        description=__doc__.split("\n\n", 1)[1])
    parser.add_argument("bag", metavar="BAG", help="rosbag2 directory, .mcap file or CSV file")
    add_data_args(parser)
    add_model_args(parser)
    parser.set_defaults(effects=",".join(DEFAULTS.effects), method=DEFAULTS.method)
    parser.add_argument("--window-length", type=float, default=DEFAULTS.window_length, metavar="S",
                        help="s of data in each fit (default %(default)s)")
    parser.add_argument("--refit-period", type=float, default=DEFAULTS.refit_period, metavar="S",
                        help="s of bag time between refits (default %(default)s)")
    parser.add_argument("--min-window-length", type=float, default=DEFAULTS.min_window_length,
                        metavar="S", help="s of data before the first fit (default %(default)s)")
    parser.add_argument("--json", action="store_true",
                        help="print one JSON object per refit on stdout, one per line (JSON lines)")
    parser.add_argument("--out", metavar="OUT.mcap",
                        help="write an MCAP with the input topics and the estimates")
    parser.set_defaults(func=run)


def config_from_args(args, topics: Topics, has_speed: bool) -> OnlineConfig:
    return OnlineConfig(
        rudder_topic=topics.rudder, heading_topic=topics.heading, yaw_rate_topic=topics.yaw_rate,
        speed_topic=topics.speed if has_speed else "", imu_topic=topics.imu,
        sample_time=args.sample_time, window_length=args.window_length,
        refit_period=args.refit_period, min_window_length=min(args.min_window_length, args.window_length),
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


def run(args) -> int:
    topics = topics_from_args(args)
    samples = read_samples(args.bag, topics)
    if not samples:
        raise CommandError(f"{args.bag} holds no input samples; check the topic names")
    config = config_from_args(args, topics, any(s.role == "speed" for s in samples))
    identifier = OnlineIdentifier(config)
    progress = Progress(samples[0].time, samples[-1].time, sys.stderr.isatty())
    wall0 = time.perf_counter()
    records = []
    for record in run_schedule(identifier, samples):
        records.append(record)
        progress.update(record.time)
        if args.json:
            print(dumps_json(record.to_json()), flush=True)
    progress.update(samples[-1].time, force=True)
    progress.close()
    wall = time.perf_counter() - wall0
    if args.out:
        write_replay(args.out, samples, records, topics)
    if not args.json:
        print_summary(records, samples[-1].time - samples[0].time, wall)
    return 0


def write_replay(path, samples, records, topics: Topics) -> None:
    """MCAP with the inputs as Float64 topics and each refit's estimate and parameters."""
    types = typestore().types
    Float64, String = types[FLOAT64], types["std_msgs/msg/String"]
    MultiArray = types["std_msgs/msg/Float64MultiArray"]
    Layout, Dimension = types["std_msgs/msg/MultiArrayLayout"], types["std_msgs/msg/MultiArrayDimension"]
    topic_of = {"rudder": topics.rudder, "heading": topics.heading, "yaw_rate": topics.yaw_rate,
                "speed": topics.speed}
    if topics.imu:  # the Imu was read as heading and yaw rate: write those as Float64
        topic_of.update(heading=Topics().heading, yaw_rate=Topics().yaw_rate)
    events = [(s.time, 0, s) for s in samples] + [(r.time, 1, r) for r in records]
    events.sort(key=lambda e: (e[0], e[1]))
    with BagWriter(path, "mcap") as writer:
        for stamp, kind, item in events:
            if kind == 0:
                writer.write(topic_of[item.role], FLOAT64, Float64(data=float(item.value)), stamp)
                continue
            data = item.to_json()
            writer.write(ESTIMATE_TOPIC, "std_msgs/msg/String", String(data=dumps_json(data)), stamp)
            if data["parameters"]:
                names = list(data["parameters"])
                layout = Layout(dim=[Dimension(label=",".join(names), size=len(names), stride=len(names))],
                                data_offset=0)
                values = np.array([data["parameters"][n] for n in names], dtype=np.float64)
                writer.write(PARAMETERS_TOPIC, "std_msgs/msg/Float64MultiArray",
                             MultiArray(layout=layout, data=values), stamp)


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
