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

from ..bag_replay import replay_bag
from ..errors import CommandError
from ..fleet import FleetError, add_fleet_arguments, run_fleet
from ..io import Topics
from ..jsonio import dumps_json
from ..online_config import OnlineConfig, spec
from .common import add_data_args, add_model_args, topics_from_args

DEFAULTS = OnlineConfig()


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "replay",
        help="run the online identifier over a bag, faster than real time",
        description=__doc__.split("\n\n", 1)[1],
    )
    parser.add_argument(
        "bag",
        metavar="BAG",
        nargs="+",
        help="rosbag2 directory, .mcap file or CSV file; several (or --jobs, --table, "
        "--dask): a fleet run into one table, see ship_ident/fleet.py",
    )
    add_data_args(parser)
    add_model_args(parser)
    parser.set_defaults(effects=",".join(DEFAULTS.effects), method=DEFAULTS.method)
    for name in ("window_length", "refit_period", "min_window_length", "gap_threshold", "change_ratio"):
        add_config_option(parser, name)
    add_config_option(parser, "rudder_limit", degrees=True)
    parser.add_argument(
        "--json", action="store_true", help="print one JSON object per refit on stdout, one per line (JSON lines)"
    )
    parser.add_argument("--out", metavar="OUT.mcap", help="write an MCAP with the input topics and the estimates")
    add_fleet_arguments(parser)
    parser.set_defaults(func=run)


def add_config_option(parser, name: str, degrees: bool = False) -> None:
    """``--NAME`` for the OnlineConfig field ``name``: its default, unit, range and description
    from the one definition (``online_config``); ``degrees``: an angle given in deg."""
    s = spec(OnlineConfig, name)
    scale = math.degrees(1.0) if degrees else 1.0
    unit = "deg" if degrees else s.unit
    low, high = (scale * limit for limit in s.limits)
    parser.add_argument(
        "--" + name.replace("_", "-"),
        type=float,
        default=scale * getattr(DEFAULTS, name),
        metavar="DEG" if degrees else (unit.upper() or "X"),
        help=f"{s.description}; {low:.4g} to {high:.4g}{' ' + unit if unit else ''} (default %(default).6g)",
    )


def config_from_args(args, topics: Topics, has_speed: bool) -> OnlineConfig:
    return OnlineConfig(
        rudder_topic=topics.rudder,
        heading_topic=topics.heading,
        yaw_rate_topic=topics.yaw_rate,
        speed_topic=topics.speed if has_speed else "",
        imu_topic=topics.imu,
        sample_time=args.sample_time,
        window_length=args.window_length,
        refit_period=args.refit_period,
        min_window_length=min(args.min_window_length, args.window_length),
        change_ratio=args.change_ratio,
        gap_threshold=args.gap_threshold,
        rudder_limit=math.radians(args.rudder_limit),
        model=args.model,
        effects=args.effects,
        method=args.method,
    ).validate()


def run(args) -> int:
    if len(args.bag) > 1 or args.jobs > 1 or args.table or args.dask:
        if args.out:
            raise CommandError("--out takes a single bag; for many bags use --table")
        topics = topics_from_args(args)
        try:
            return run_fleet(args, args.bag, topics, config_from_args(args, topics, has_speed=True))
        except FleetError as exc:
            raise CommandError(str(exc)) from None
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
        result = replay_bag(
            bag, topics, config_from_args(args, topics, has_speed=True), args.out, on_record, stop, sys.stderr.isatty()
        )
    finally:
        for signum, handler in handlers.items():
            signal.signal(signum, handler)
    if result.interrupted:
        kept = f"; {args.out} holds them" if args.out else ""
        print(
            f"ship-ident replay: interrupted at bag time {result.duration:.1f} s after "
            f"{len(result.records)} refits{kept}",
            file=sys.stderr,
        )
        return 128 + received[0]
    if not args.json:
        print_summary(result.records, result.duration, result.wall_seconds)
    return 0


def print_summary(records, duration: float, wall: float) -> None:
    """The last estimate, its fit and the replay speed, for people."""
    fitted = [r for r in records if r.new_estimate]
    print(
        f"{len(records)} refits over {duration:.0f} s of bag in {wall:.1f} s "
        f"({duration / max(wall, 1e-9):.0f}x real time); {len(fitted)} gave a new estimate"
    )
    if not records:
        return
    last = records[-1].to_json()
    print(
        f"last refit at {last['stamp']:.1f} s: {last['status']}"
        + "".join(f"\n  {c}: {m}" for c, m in last["conditions"].items())
    )
    if last["parameters"]:
        print(
            f"  {last['structure']['model']} + {', '.join(last['structure']['effects']) or 'no effects'}"
            f" ({last['method']}):"
        )
        for name, value in last["parameters"].items():
            std = last["std_errors"].get(name, math.nan)
            print(f"    {name:>8} = {value:12.5g}  +/- {std:.2g}")
        print(
            f"  free-run rmse: yaw rate {math.degrees(last['fit']['rmse_yaw_rate']):.3f} deg/s, "
            f"heading {math.degrees(last['fit']['rmse_heading']):.2f} deg"
        )
