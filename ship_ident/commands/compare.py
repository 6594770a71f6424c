"""``ship-ident compare``: run a saved model free on other data (cross-manoeuvre validation)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import CommandError
from ..io.jsonio import dumps_json
from ..model.metrics import free_run_fit
from ..model.structure import Structure, require_samples
from . import SUMMARIES
from .common import add_data_args, add_json_arg, add_recordings_arg, load_recordings, sources
from .identify import data_field, format_fit
from .threedof import add_threedof_args, run_compare


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "compare",
        help=SUMMARIES["compare"],
        description="Drive a model saved by `identify --save` with the measured rudder of other "
        "data, starting from the measured heading and yaw rate, and compare the "
        "free-run heading and yaw rate with the measurements.",
    )
    parser.add_argument("model", metavar="MODEL.json", help="model file written by identify --save")
    add_recordings_arg(parser)
    add_json_arg(parser)
    add_data_args(parser)
    add_threedof_args(parser, fitting=False)
    parser.set_defaults(func=run)


def model_file_error(path, err: Exception) -> CommandError:
    return CommandError(
        f"{path} is not a model file written by `ship-ident identify --save` "
        f"({type(err).__name__}: {err}); identify the model again with --save"
    )


def read_model_file(path) -> dict:
    """The JSON record of a model file."""
    try:
        record = json.loads(Path(path).read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise model_file_error(path, err) from None
    if not isinstance(record, dict):
        raise model_file_error(path, TypeError("not a JSON object"))
    return record


def load_model(path, record: dict | None = None) -> tuple[Structure, dict]:
    """Structure and parameters (SI) of a Nomoto model file written by ``identify --save``."""
    record = read_model_file(path) if record is None else record
    try:
        structure = Structure(record["structure"]["model"], record["structure"]["effects"])
        parameters = {name: float(record["parameters"][name]) for name in structure.parameter_names}
    except (KeyError, TypeError) as err:
        raise model_file_error(path, err) from None
    if not all(np.isfinite(list(parameters.values()))):
        raise CommandError(f"{path} holds non-finite parameters; identify the model again")
    return structure, parameters


def run(args) -> int:
    record = read_model_file(args.model)
    if isinstance(record.get("structure"), dict) and record["structure"].get("model") == "3dof":
        return run_compare(args, record)
    structure, parameters = load_model(args.model, record)
    dataset = load_recordings(args, args.data)
    require_samples(dataset)
    heading, yaw_rate = structure.simulate(parameters, dataset)
    record = {
        "structure": structure.to_json(),
        "parameters": parameters,
        "model_file": str(args.model),
        "data": data_field(args.data),
        "recordings": dataset.meta["recordings"],
        "samples": dataset.n_samples,
        "fit": free_run_fit(dataset.heading, dataset.yaw_rate, heading, yaw_rate),
    }
    if args.json:
        print(dumps_json(record))
    else:
        print(
            f"{structure.label()} from {args.model} run free on {sources(args.data)} "
            f"({dataset.n_samples} samples, {dataset.duration:.1f} s)"
        )
        print(format_fit(record["fit"]))
    return 0
