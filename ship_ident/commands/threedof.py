"""The ``--model 3dof`` side of ``identify``, ``compare`` and ``simulate``: seed 000's 3-DOF model
(surge u, sway v, yaw rate r) from CSV files and bags, and its model files."""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import CommandError
from ..estimators.tlssvm import TRUNCATION_RULES
from ..io.jsonio import dumps_json
from ..threedof import DOFS, X_TERMS, YN_TERMS, Coefficients, Record, identify, predict, prediction_metrics
from ..threedof.data import DEFAULT_VELOCITY_TOPIC, load_records, write_record
from ..threedof.marin import approach_speed
from ..threedof.model import VESSELS, simulate_manoeuvre
from .common import say_columns, topics_from_args

MODEL = "3dof"
METHODS = ("tlssvm", "ols")  # the default first
DEFAULT_VESSEL = "dtc"
MANOEUVRES = {"zigzag10": ("zigzag", 10.0), "zigzag20": ("zigzag", 20.0), "turning": ("turning", 35.0)}
UNITS = {"surge": "m/s", "sway": "m/s", "yaw": "deg/s"}


def add_threedof_args(parser: argparse.ArgumentParser, fitting: bool = True) -> None:
    """Options of the 3-DOF model: ship length, reference speed and truncation rule (when fitting),
    and the velocity topic of bags."""
    group = parser.add_argument_group("3-DOF model (--model 3dof)")
    if fitting:
        group.add_argument(
            "--length", type=float, metavar="M", help="length between perpendiculars Lpp in m (needed by --model 3dof)"
        )
        group.add_argument(
            "--reference-speed",
            type=float,
            metavar="M/S",
            help="reference (approach) speed U0 in m/s of u' = (u - U0)/U (default: the "
            "mean surge speed over the first 3 s of the first recording)",
        )
        group.add_argument(
            "--truncation",
            default="gcv",
            choices=TRUNCATION_RULES,
            help="truncation rule of the tlssvm solver (default %(default)s)",
        )
    group.add_argument(
        "--velocity-topic",
        default=DEFAULT_VELOCITY_TOPIC,
        metavar="TOPIC",
        help="nav_msgs/Odometry or geometry_msgs/TwistStamped topic of the body-fixed "
        "velocity in bags (default %(default)s)",
    )


def read_records(args: argparse.Namespace, paths) -> list[Record]:
    """The 3-DOF Records of every recording (one per stretch between gaps), read at --sample-time."""
    topics = replace(topics_from_args(args), velocity=args.velocity_topic)
    records = []
    for path in paths:
        found = load_records(path, topics, args.sample_time)
        say_columns(args, path, found[0].meta.get("columns"))
        records += found
    return records


def solver(args: argparse.Namespace) -> str:
    """The 3-DOF solver name (``ols`` or ``tlssvm-RULE``) of --method and --truncation."""
    method = args.method or METHODS[0]
    if method not in METHODS:
        raise CommandError(
            f"--model 3dof fits with --method {' or '.join(METHODS)}, not {method!r} "
            "(the truncation rule is --truncation)"
        )
    return "ols" if method == "ols" else f"tlssvm-{args.truncation}"


def check_model_options(args: argparse.Namespace) -> None:
    if args.effects:
        raise CommandError("--model 3dof takes no --effects; its cubic terms are part of the model")
    if args.length is None or not (math.isfinite(args.length) and args.length > 0):
        raise CommandError("--model 3dof needs --length, the ship's length between perpendiculars in m (> 0)")
    if args.reference_speed is not None and not (math.isfinite(args.reference_speed) and args.reference_speed > 0):
        raise CommandError("--reference-speed must be a speed > 0 m/s")


def run_identify(args: argparse.Namespace) -> int:
    check_model_options(args)
    method = solver(args)
    records = read_records(args, args.data)
    speed = args.reference_speed or approach_speed(records[0])
    if not speed > 0:
        raise CommandError("the first recording does not start moving ahead; give --reference-speed")
    identification = identify(records, args.length, speed, method=method)
    fit = free_run_fit(identification.coefficients, records)
    record = {
        "structure": {"model": MODEL, "effects": []},
        **identification.to_json(),
        "fit": fit,
        "data": [str(p) for p in args.data] if len(args.data) > 1 else str(args.data[0]),
    }
    if args.save:
        Path(args.save).write_text(dumps_json(record, indent=2) + "\n")
    if args.json:
        print(dumps_json(record))
    else:
        print(
            f"3dof identified by {method} from {' + '.join(map(str, args.data))} "
            f"({identification.samples} samples, Lpp {args.length:g} m, U0 {speed:.4g} m/s)"
        )
        print(format_coefficients(identification.coefficients))
        print(format_fit(fit))
    return 0


def free_run_fit(coefficients: Coefficients, records: list[Record]) -> dict:
    """Per DOF: the free-run metrics (``prediction_metrics``) pooled over the records."""
    runs = [(record, predict(coefficients, record)) for record in records]
    return prediction_metrics(*(joined([run[i] for run in runs]) for i in (0, 1)))


def joined(records: list[Record]) -> Record:
    """Records one after another (for pooled metrics only: the time axis is not continued)."""
    fields = ("time", "surge", "sway", "yaw_rate", "heading", "rudder")
    return Record(**{f: np.concatenate([getattr(r, f) for r in records]) for f in fields})


def format_coefficients(coefficients: Coefficients) -> str:
    """The coefficients a (surge), b (sway), c (yaw) with standard errors, one DOF per block."""
    record = coefficients.to_json()
    lines = []
    for dof in DOFS:
        lines.append(f"  {dof:<6} {'term':<5} {'value':>12} {'std error':>12}")
        lines += [f"  {'':<6} {t:<5} {v['value']:>12.5g} {v['std_error']:>12.3g}" for t, v in record[dof].items()]
    return "\n".join(lines)


def format_fit(fit: dict) -> str:
    def shown(dof, value):
        return math.degrees(value) if dof == "yaw" else value

    return "free-run fit: " + "; ".join(
        f"{dof} RMSE {shown(dof, m['rmse']):.3g} {UNITS[dof]}, R {m['r']:.4f}"
        + (" (diverged)" if m.get("diverged") else "")
        for dof, m in fit.items()
    )


def coefficients_from_json(record: dict) -> Coefficients:
    """The Coefficients of a model file written by ``identify --model 3dof --save`` (or a truth file)."""
    c = record["coefficients"]
    vectors = {
        dof: np.array([float(c[dof][t]["value"]) for t in (X_TERMS if dof == "surge" else YN_TERMS)]) for dof in DOFS
    }
    coefficients = Coefficients(length=float(c["length"]), speed=float(c["speed"]), **vectors)
    if not all(np.all(np.isfinite(v)) for v in vectors.values()) or coefficients.length <= 0:
        raise ValueError("non-finite coefficients or a length <= 0")
    return coefficients


def run_compare(args: argparse.Namespace, record: dict) -> int:
    """Run a 3-DOF model file free on other recordings."""
    try:
        coefficients = coefficients_from_json(record)
    except (KeyError, TypeError, ValueError) as err:
        raise CommandError(
            f"{args.model} is not a 3dof model file ({type(err).__name__}: {err}); identify "
            "the model again with --model 3dof --save"
        ) from None
    records = read_records(args, args.data)
    fit = free_run_fit(coefficients, records)
    out = {
        "structure": {"model": MODEL, "effects": []},
        "model_file": str(args.model),
        "data": [str(p) for p in args.data] if len(args.data) > 1 else str(args.data[0]),
        "samples": int(sum(len(r) for r in records)),
        "fit": fit,
    }
    if args.json:
        print(dumps_json(out))
    else:
        print(f"3dof from {args.model} run free on {' + '.join(map(str, args.data))} ({out['samples']} samples)")
        print(format_fit(fit))
    return 0


def run_simulate(args: argparse.Namespace, fmt: str) -> int:
    """Simulate a 3-DOF manoeuvre of a preset and write it (CSV or bag) and its truth."""
    vessel = args.vessel or DEFAULT_VESSEL
    if vessel not in VESSELS or not VESSELS[vessel].derivatives:
        usable = [name for name, v in VESSELS.items() if v.derivatives]
        raise CommandError(f"--model 3dof simulates the vessel {' or '.join(usable)}, not {vessel!r}")
    if args.maneuver not in MANOEUVRES:
        raise CommandError(f"--model 3dof simulates {', '.join(MANOEUVRES)}, not {args.maneuver!r}")
    if args.effects:
        raise CommandError("--model 3dof takes no --effects")
    manoeuvre, amplitude = MANOEUVRES[args.maneuver]
    noisy, _ = simulate_manoeuvre(
        vessel,
        manoeuvre,
        amplitude,
        duration=args.duration,
        sample_time=args.sample_time,
        noise=args.noise,
        seed=args.seed,
    )
    write_record(noisy, args.out, fmt, args.velocity_topic)
    if args.truth_out:
        truth = {
            "structure": {"model": MODEL, "effects": []},
            "vessel": vessel,
            "maneuver": args.maneuver,
            "coefficients": VESSELS[vessel].coefficients().to_json(),
        }
        Path(args.truth_out).write_text(json.dumps(truth, indent=2) + "\n")
    print(f"wrote {args.out} ({fmt}, {len(noisy)} samples, {noisy.time[-1] - noisy.time[0]:.1f} s, 3dof {vessel})")
    return 0
