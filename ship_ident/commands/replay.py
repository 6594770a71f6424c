"""``ship-ident replay BAG``: re-run the online node's identification on a recorded bag.

The bag's samples go in time order through the same ``OnlineIdentifier``
as the node, with the bag's time as the clock and the node's refit
schedule, as fast as the machine allows. ``--json`` prints one JSON object
per refit, one per line (JSON lines: the ``~/estimate`` record of the node).
``--out`` writes an MCAP with the input topics and the node's outputs
``/ship_ident/estimate`` and ``/ship_ident/parameters`` at the refit times,
as the replay goes, and the node's other outputs (the predicted yaw rate at
the yaw-rate samples' times, K's band, ``/diagnostics``; ``parameters`` only
for estimates with status OK): Ctrl-C or SIGTERM stop it after the refit in
progress and still leave a complete MCAP with every estimate up to then (exit
code 130 or 143). Times printed are from the bag's first stamp.
``--diagnosis-period S`` diagnoses the window every S seconds as the node
does (which effect the model misses, the held-out error against the noise
floor): each diagnosis goes into the JSON record of its refit and into the
MCAP (``/ship_ident/diagnosis``, ``/ship_ident/held_out_error``,
``/ship_ident/noise_floor``);
``--diagnosis-plot FILE.png`` draws the held-out error over the trip.
"""

from __future__ import annotations

import math
import signal
import sys
import threading
from pathlib import Path

from ..errors import CommandError
from ..io.bag_replay import replay_bag
from ..io.files import Topics
from ..io.fleet import FleetError, add_fleet_arguments, run_fleet
from ..io.jsonio import dumps_json
from ..online.config import OnlineConfig, spec
from ..online.outputs import error_and_floor
from . import SUMMARIES
from .common import add_data_args, add_model_args, topics_from_args

DEFAULTS = OnlineConfig()


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "replay",
        help=SUMMARIES["replay"],
        description=__doc__.split("\n\n", 1)[1],
    )
    parser.add_argument(
        "bag",
        metavar="BAG",
        nargs="+",
        help="rosbag2 directory, .mcap file or CSV file; several (or --jobs, --table, "
        "--dask): a fleet run into one table, see ship_ident/io/fleet.py",
    )
    add_data_args(parser)
    add_model_args(parser, effects=DEFAULTS.effects, method=DEFAULTS.method)
    for name in ("window_length", "refit_period", "min_window_length", "gap_threshold", "change_ratio"):
        add_config_option(parser, name)
    add_config_option(parser, "rudder_limit", degrees=True)
    add_config_option(parser, "diagnosis_period", default=0.0)
    parser.add_argument(
        "--auto-add-effects",
        action="store_true",
        help=spec(OnlineConfig, "auto_add_effects").description + " (default: off)",
    )
    parser.add_argument(
        "--auto-add-after",
        type=int,
        default=DEFAULTS.auto_add_after,
        metavar="N",
        help=spec(OnlineConfig, "auto_add_after").description + " (default %(default)s)",
    )
    parser.add_argument(
        "--diagnosis-plot",
        metavar="FILE.png",
        help="draw the held-out error of every diagnosis over the trip, the noise floor and the effects in force",
    )
    parser.add_argument(
        "--json", action="store_true", help="print one JSON object per refit on stdout, one per line (JSON lines)"
    )
    parser.add_argument("--out", metavar="OUT.mcap", help="write an MCAP with the input topics and the estimates")
    add_fleet_arguments(parser)
    parser.set_defaults(func=run)


def add_config_option(parser, name: str, degrees: bool = False, default: float | None = None) -> None:
    """``--NAME`` for the OnlineConfig field ``name``: its default (unless ``default``), unit, range
    and description from the one definition (``online.config``); ``degrees``: an angle given in deg."""
    s = spec(OnlineConfig, name)
    scale = math.degrees(1.0) if degrees else 1.0
    unit = "deg" if degrees else s.unit
    low, high = (scale * limit for limit in s.limits)
    parser.add_argument(
        "--" + name.replace("_", "-"),
        type=float,
        default=scale * (getattr(DEFAULTS, name) if default is None else default),
        metavar="DEG" if degrees else (unit.upper() or "X"),
        help=f"{s.description.replace('%', '%%')}; {low:.4g} to {high:.4g}{' ' + unit if unit else ''} "
        "(default %(default).6g)",
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
        diagnosis_period=args.diagnosis_period,
        auto_add_effects=args.auto_add_effects,
        auto_add_after=args.auto_add_after,
        model=args.model,
        effects=args.effects,
        method=args.method,
    ).validate()


def run(args) -> int:
    if args.diagnosis_plot and not args.diagnosis_period:
        raise CommandError("--diagnosis-plot needs --diagnosis-period S (the diagnoses it draws)")
    if len(args.bag) > 1 or args.jobs > 1 or args.table or args.dask:
        if args.out or args.diagnosis_plot:
            raise CommandError("--out and --diagnosis-plot take a single bag; for many bags use --table")
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

    def on_record(record, start):
        if args.json:
            print(dumps_json(record.to_json()), flush=True)
        elif record.diagnosis is not None:
            print(diagnosis_text(record.diagnosis, start), flush=True)

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
    if args.diagnosis_plot:
        try:
            plot_diagnoses(result.records, args.diagnosis_plot, Path(bag).name)
        except OSError as exc:
            raise CommandError(f"cannot write {args.diagnosis_plot}: {exc.strerror or exc}") from None
    if not args.json:
        print_summary(result.records, result.duration, result.wall_seconds, result.start)
        if args.diagnosis_plot:
            print(f"held-out error plot: {args.diagnosis_plot}")
    return 0


def bag_time(stamp: float, start: float) -> str:
    """'65 s' from the bag's first stamp ``start`` (s), with the bag's clock when that is not the
    start (a bag stamped in Unix time: '65 s, bag clock 1.7e9 s' written out in full)."""
    return f"{stamp - start:.0f} s" + (f", bag clock {stamp:.0f} s" if start else "")


def diagnosis_text(diagnosis: dict, start: float = 0.0) -> str:
    """A finished diagnosis in a few lines, for people (angles in deg; its time from the bag's first
    stamp ``start``, s)."""
    effects = "+".join(diagnosis["structure"]["effects"]) or "no effects"
    head = f"diagnosis at {bag_time(diagnosis['stamp'], start)} ({effects}):"
    if diagnosis["status"] != "done":
        return f"{head} skipped: {diagnosis['reason']}"
    error, floor = error_and_floor(diagnosis)
    pooled = diagnosis.get("pooled")
    lines = [
        f"{head} {diagnosis['verdict']}; held-out yaw-rate error {math.degrees(error):.3f} deg/s, noise floor "
        f"{math.degrees(floor):.3f} deg/s"
        + (
            f" (pooled over {pooled['seconds'] / 60.0:.1f} min; this window's own "
            f"{math.degrees(diagnosis['held_out_error']):.3f} deg/s)"
            if pooled
            else ""
        ),
        f"  {diagnosis['verdict_sentence']}",
    ]
    if diagnosis.get("add_command"):
        lines.append(f"  add it: {diagnosis['add_command']}")
    if diagnosis.get("auto_add"):
        lines.append(f"  auto-add: {diagnosis['auto_add']['sentence']}")
    return "\n".join(lines)


def plot_diagnoses(records, path, title: str) -> None:
    """PNG of the held-out yaw-rate error of every finished diagnosis over the trip (deg/s): pooled
    since the model or vessel last changed (what the verdict is read from, ``~/held_out_error``)
    against the pooled noise floor, each window's own as faint dots; the diagnoses that found an
    effect missing (the effect named where it first appears), and the effects in force as shaded
    bands."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    diagnoses = [r.diagnosis for r in records if r.diagnosis is not None]
    done = [d for d in diagnoses if d["status"] == "done"]
    fig, ax = plt.subplots(figsize=(9, 4))
    if done:
        t = [d["stamp"] for d in done]
        figures = [error_and_floor(d) for d in done]
        error = [math.degrees(f[0]) for f in figures]
        own = [math.degrees(d["held_out_error"]) for d in done]
        ax.plot(t, error, "o-", ms=4, label="held-out yaw-rate error (pooled)")
        ax.plot(t, own, ".", ms=4, color="tab:blue", alpha=0.35, label="a window's own")
        ax.plot(t, [math.degrees(f[1]) for f in figures], "--", color="grey", label="noise floor")
        missing = [
            (d["stamp"], e, d["candidates"][0]["effect"])
            for d, e in zip(done, error)
            if d["verdict"] == "missing_effect"
        ]
        ax.plot(
            [m[0] for m in missing],
            [m[1] for m in missing],
            "o",
            ms=9,
            mfc="none",
            color="tab:red",
            label="missing_effect",
        )
        named = None
        for stamp, e, effect in missing:
            if effect != named:
                ax.annotate(
                    effect,
                    (stamp, e),
                    textcoords="offset points",
                    xytext=(0, 9),
                    ha="center",
                    fontsize=8,
                    color="tab:red",
                )
            named = effect
        ax.set_ylim(0.0, 1.3 * max(error + own))
    spans = []  # [start, end, effects in force]: changed by auto-add at its diagnosis, or from outside
    for d in diagnoses:
        effects = "+".join(d["structure"]["effects"]) or "no effects"
        added = d.get("auto_add")
        if not spans or spans[-1][2] != effects:
            spans.append([records[0].time if not spans else d["stamp"], d["stamp"], effects])
        if added and added["action"] != "kept":
            spans.append([d["stamp"], d["stamp"], "+".join(added["effects"]) or "no effects"])
    if spans:
        spans[-1][1] = records[-1].time
    for k, (start, _, effects) in enumerate(spans):
        end = spans[k + 1][0] if k + 1 < len(spans) else spans[-1][1]
        ax.axvspan(start, end, color=f"C{k % 10}", alpha=0.1, lw=0)
        ax.text(start, 0.98, " " + effects, transform=ax.get_xaxis_transform(), va="top", fontsize=7)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("deg/s")
    ax.set_title(f"{title}: held-out free-run error pooled since the model changed; effects shaded", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left", fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def print_summary(records, duration: float, wall: float, start: float = 0.0) -> None:
    """The last estimate, its fit and the replay speed, for people (times from the bag's first
    stamp ``start``, s)."""
    fitted = [r for r in records if r.new_estimate]
    print(
        f"{len(records)} refits over {duration:.0f} s of bag in {wall:.1f} s "
        f"({duration / max(wall, 1e-9):.0f}x real time); {len(fitted)} gave a new estimate"
    )
    if not records:
        return
    last = records[-1].to_json()
    print(
        f"last refit at {bag_time(last['stamp'], start)}: {last['status']}"
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
