"""``ship-ident compare``: run a saved model free on other data (cross-manoeuvre validation)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import CommandError
from ..metrics import free_run_fit
from ..structure import Structure, require_samples
from ..jsonio import dumps_json
from .common import add_data_args, add_json_arg, add_recordings_arg, load_recordings, sources
from .identify import data_field, format_fit


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "compare", help="run a saved model free on other data",
        description="Drive a model saved by `identify --save` with the measured rudder of other "
                    "data, starting from the measured heading and yaw rate, and compare the "
                    "free-run heading and yaw rate with the measurements.")
    parser.add_argument("model", metavar="MODEL.json", help="model file written by identify --save")
    add_recordings_arg(parser)
    add_json_arg(parser)
    add_data_args(parser)
    parser.set_defaults(func=run)


def load_model(path) -> tuple[Structure, dict]:
    """Structure and parameters (SI) of a model file written by ``identify --save``."""
    path = Path(path)
    try:
        record = json.loads(path.read_text())
        structure = Structure(record["structure"]["model"], record["structure"]["effects"])
        parameters = {name: float(record["parameters"][name]) for name in structure.parameter_names}
    except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError) as err:
        raise CommandError(f"{path} is not a model file written by `ship-ident identify --save` "
                           f"({type(err).__name__}: {err}); identify the model again with --save") from None
    if not all(np.isfinite(list(parameters.values()))):
        raise CommandError(f"{path} holds non-finite parameters; identify the model again")
    return structure, parameters


def run(args) -> int:
    structure, parameters = load_model(args.model)
    dataset = load_recordings(args, args.data)
    require_samples(dataset)
    heading, yaw_rate = structure.simulate(parameters, dataset)
    record = {"structure": structure.to_json(), "parameters": parameters, "model_file": str(args.model),
              "data": data_field(args.data), "recordings": dataset.meta["recordings"],
              "samples": dataset.n_samples,
              "fit": free_run_fit(dataset.heading, dataset.yaw_rate, heading, yaw_rate)}
    if args.json:
        print(dumps_json(record))
    else:
        print(f"{structure.label()} from {args.model} run free on {sources(args.data)} "
              f"({dataset.n_samples} samples, {dataset.duration:.1f} s)")
        print(format_fit(record["fit"]))
    return 0
