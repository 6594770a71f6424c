"""``ship-ident simulate``: a manoeuvre of a vessel preset, written as a bag or CSV with its truth.

The bundled demo bag is made with (see docs/cli.md)::

    ship-ident simulate --maneuver mixed --vessel seed001 --duration 600 --seed 1 \\
        --out bags/demo_seed001.mcap --truth-out bags/demo_seed001.truth.json
"""

from __future__ import annotations

import json
from pathlib import Path

from ..errors import CommandError
from ..io.files import DEFAULT_TOPICS, write_simulation
from ..model.simulator import MANEUVERS, VESSELS, simulate
from ..model.structure import parse_effects
from ..threedof import VESSELS as THREEDOF_VESSELS
from . import SUMMARIES
from .threedof import DEFAULT_VESSEL as THREEDOF_VESSEL
from .threedof import add_threedof_args, run_simulate

FORMATS = ("rosbag2", "mcap", "csv")
MIN_SAMPLE_TIME = 0.01  # s, the simulator's internal integration step
DEFAULT_VESSEL = "seed001"
TOPICS = ", ".join((DEFAULT_TOPICS.rudder, DEFAULT_TOPICS.heading, DEFAULT_TOPICS.yaw_rate, DEFAULT_TOPICS.speed))


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "simulate",
        help=SUMMARIES["simulate"],
        description="Simulate a manoeuvre of a vessel preset with sensor noise and write the "
        f"measurements (std_msgs/Float64 on the node's input topics {TOPICS}; heading wrapped) "
        "with the true parameters.",
    )
    parser.add_argument("--maneuver", required=True, choices=MANEUVERS)
    parser.add_argument(
        "--out", required=True, metavar="PATH", help="output: rosbag2 directory, .mcap file or .csv file"
    )
    parser.add_argument(
        "--format", choices=FORMATS, help="output format (default: from the --out suffix, .mcap, .csv, else rosbag2)"
    )
    parser.add_argument(
        "--model",
        default="nomoto2",
        choices=("nomoto2", "3dof"),
        help="simulated model (default %(default)s); 3dof: seed 000's surge-sway-yaw model "
        "(manoeuvres zigzag10, zigzag20, turning; vessel dtc)",
    )
    parser.add_argument(
        "--vessel",
        default=None,
        choices=sorted(VESSELS) + sorted(THREEDOF_VESSELS),
        help=f"vessel preset (default {DEFAULT_VESSEL}; with --model 3dof: {THREEDOF_VESSEL})",
    )
    parser.add_argument(
        "--effects",
        default=None,
        metavar="A,B",
        help="effects in the true model (default: the vessel's own; '' for none)",
    )
    parser.add_argument(
        "--noise",
        type=float,
        default=1.0,
        metavar="FACTOR",
        help="multiple of the realistic sensor noise (default %(default)s; 0: none)",
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed (default %(default)s)")
    parser.add_argument(
        "--duration", type=float, default=600.0, metavar="S", help="duration in s (default %(default)s)"
    )
    parser.add_argument(
        "--sample-time", type=float, default=0.1, metavar="S", help="sample time in s (default %(default)s)"
    )
    parser.add_argument(
        "--truth-out",
        metavar="FILE",
        help="write the true model as JSON to FILE (with --model 3dof a model file for `compare`)",
    )
    add_threedof_args(parser, fitting=False)
    parser.set_defaults(func=run)


def output_format(path: str, fmt: str | None) -> str:
    """The --format, or the one the output path's suffix implies."""
    if fmt:
        return fmt
    return {".mcap": "mcap", ".csv": "csv"}.get(Path(path).suffix.lower(), "rosbag2")


def run(args) -> int:
    if args.duration <= 0 or args.sample_time < MIN_SAMPLE_TIME or args.noise < 0:
        raise CommandError(
            f"--duration must be > 0, --sample-time at least {MIN_SAMPLE_TIME} s "
            "(the simulator's internal step) and --noise >= 0"
        )
    if Path(args.out).exists():
        raise CommandError(f"{args.out} exists already; remove it or choose another --out")
    fmt = output_format(args.out, args.format)
    if args.model == "3dof":
        return run_simulate(args, fmt)
    vessel = args.vessel or DEFAULT_VESSEL
    if vessel not in VESSELS:
        raise CommandError(
            f"the vessel {vessel!r} has a 3dof model only; add --model 3dof or choose {', '.join(sorted(VESSELS))}"
        )
    effects = None if args.effects is None else parse_effects(args.effects)
    sim = simulate(
        args.maneuver,
        vessel,
        effects,
        duration=args.duration,
        sample_time=args.sample_time,
        noise=args.noise,
        seed=args.seed,
    )
    write_simulation(sim, args.out, fmt)
    if args.truth_out:
        Path(args.truth_out).write_text(json.dumps(sim.truth_json(), indent=2) + "\n")
    print(
        f"wrote {args.out} ({fmt}, {sim.dataset.n_samples} samples, {sim.dataset.duration:.1f} s, "
        f"{sim.structure.label()})"
    )
    return 0
