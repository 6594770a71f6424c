"""``ship-ident identify``: fit a model to a bag or CSV file and print (or save) the estimate."""

from __future__ import annotations

import math
from pathlib import Path

from ..errors import CommandError
from ..estimators import DEFAULT_METHOD, make_estimator
from ..estimators.base import excitation_shortfall
from ..io.jsonio import dumps_json
from ..model.structure import require_samples
from . import SUMMARIES
from .common import (
    add_data_args,
    add_json_arg,
    add_model_args,
    add_recordings_arg,
    load_recordings,
    sources,
    structure_from_args,
)
from .threedof import METHODS as THREEDOF_METHODS
from .threedof import add_threedof_args, run_identify


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "identify",
        help=SUMMARIES["identify"],
        description="Fit a Nomoto model (plus effects), or seed 000's 3-DOF model, to recorded or "
        "simulated data and report parameters, standard errors and the free-run fit.",
    )
    add_recordings_arg(parser)
    add_model_args(parser, threedof_methods=THREEDOF_METHODS)
    parser.add_argument(
        "--save", metavar="MODEL.json", help="write the estimate as a model file for `ship-ident compare`"
    )
    add_json_arg(parser)
    add_data_args(parser)
    add_threedof_args(parser)
    parser.set_defaults(func=run)


def run(args) -> int:
    if args.model == "3dof":
        return run_identify(args)
    structure = structure_from_args(args)
    estimator = make_estimator(args.method or DEFAULT_METHOD)
    dataset = load_recordings(args, args.data)
    require_samples(dataset)
    require_excitation(dataset)
    estimate = estimator.fit(structure, dataset)
    record = dict(estimate.to_json(), data=data_field(args.data), recordings=dataset.meta["recordings"])
    if args.save:
        Path(args.save).write_text(dumps_json(record, indent=2) + "\n")
    print(dumps_json(record) if args.json else format_estimate(estimate, sources(args.data)))
    return 0


def data_field(paths) -> str | list[str]:
    """The JSON ``data`` field: the one path, or the list of paths fitted together."""
    return str(paths[0]) if len(paths) == 1 else [str(p) for p in paths]


def require_excitation(dataset) -> None:
    """Refuse data where the rudder hardly moves or the boat hardly turns: no model can be identified."""
    shortfall = excitation_shortfall(dataset)
    if shortfall:
        raise CommandError(f"{shortfall}; record a manoeuvre such as a zigzag or turns")


def format_estimate(estimate, source) -> str:
    """A readable table of an Estimate: angles in degrees, other units SI."""
    lines = [
        f"{estimate.structure.label()} identified by {estimate.method} from {source} "
        f"({estimate.samples} samples, {estimate.window[1] - estimate.window[0]:.1f} s)",
        f"  {'parameter':<10} {'value':>12} {'std error':>12}  unit",
    ]
    values, errors = estimate.published()
    for name in values:
        known = name in estimate.structure.parameter_names
        unit, scale = display_unit(estimate.structure.parameter(name)) if known else (NOMOTO_UNITS[name], 1.0)
        lines.append(
            f"  {name:<10} {values[name] * scale:>12.5g} {errors[name] * scale:>12.3g}  {unit}"
            + ("" if known else "  (from the fitted ones)")
        )
    stability = estimate.course_stability()
    if stability:
        lines.append(stability["sentence"])
    lines.append(format_fit(estimate.fit))
    if estimate.flags:
        lines.append(f"flags: {', '.join(estimate.flags)}")
    return "\n".join(lines)


NOMOTO_UNITS = {"K": "1/s", "T": "s", "T1": "s", "T2": "s", "T3": "s"}


def display_unit(parameter) -> tuple[str, float]:
    """(unit shown, SI-to-shown factor) of a parameter."""
    if parameter.display_unit:
        return parameter.display_unit, parameter.display_scale
    return parameter.unit, 1.0


def format_fit(fit: dict) -> str:
    """The free-run fit figures, heading in deg and yaw rate in deg/s."""
    deg = math.degrees(1.0)
    return (
        f"free-run fit: heading RMSE {fit['rmse_heading'] * deg:.3g} deg, "
        f"R {fit['r_heading']:.4f}, fit {fit['fit_percent_heading']:.1f} %; "
        f"yaw rate RMSE {fit['rmse_yaw_rate'] * deg:.3g} deg/s, "
        f"R {fit['r_yaw_rate']:.4f}, fit {fit['fit_percent_yaw_rate']:.1f} %"
        + (" (diverged)" if fit.get("diverged") else "")
    )
