"""``ship-ident diagnose``: where the model fails on held-out data and which effect it misses."""

from __future__ import annotations

import math
import sys
import time

from ..diagnosis.diagnose import DEFAULT_METHOD, covered, diagnose
from ..io.jsonio import dumps_json
from ..model.structure import parse_effects, require_samples
from . import SUMMARIES
from .common import add_data_args, add_json_arg, add_model_args, add_recordings_arg, load_recordings, sources
from .identify import data_field

DEG = math.degrees(1.0)


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "diagnose",
        help=SUMMARIES["diagnose"],
        description="Fit the model on the first part of the data, run it free on the held-out rest, "
        "show the worst segments and residual tests, and refit with every effect not "
        "yet in the model to rank what is missing. With --effects, the error before "
        "and after the last listed effect is shown.",
    )
    add_recordings_arg(parser)
    add_model_args(parser, method=DEFAULT_METHOD)
    parser.add_argument(
        "--validate",
        metavar="OTHER",
        action="append",
        help="hold out this other recording (bag or CSV) instead of the tail of DATA, "
        "and fit on all of DATA: cross-manoeuvre validation (repeat for more "
        "recordings: each is its own set of free runs, the test pools them)",
    )
    parser.add_argument("--report", metavar="DIR", help="write an HTML report with plots to DIR/index.html")
    parser.add_argument(
        "--workers", type=int, default=None, metavar="N", help="processes for the candidate refits (default: CPU count)"
    )
    add_json_arg(parser)
    add_data_args(parser)
    parser.set_defaults(func=run)


def run(args) -> int:
    start = time.monotonic()

    def progress(message: str) -> None:
        print(f"diagnose [{time.monotonic() - start:5.1f} s]: {message}", file=sys.stderr, flush=True)

    dataset = load_recordings(args, args.data)
    require_samples(dataset)
    validation = load_recordings(args, args.validate) if args.validate else None
    result = diagnose(
        dataset,
        args.model,
        parse_effects(args.effects),
        args.method,
        progress=progress,
        workers=args.workers,
        validation=validation,
    )
    if args.report:
        from ..diagnosis.report import write_report

        progress(f"writing the report to {args.report}")
        held_out = f" (held out: {', '.join(args.validate)})" if args.validate else ""
        path = write_report(result, args.report, source=f"{sources(args.data)}{held_out}")
        progress(f"report: {path}")
    record = dict(result.to_json(), data=data_field(args.data), validate=list(args.validate or ()))
    options = "".join([f" --validate {v}" for v in args.validate or ()] + [f" --sample-time {args.sample_time:g}"])
    print(dumps_json(record) if args.json else format_diagnosis(result, " ".join(args.data), options))
    return 0


def format_diagnosis(result, source, options: str = "") -> str:
    """Readable summary: held-out fit, before/after, worst segments, residual tests, candidates;
    ``options`` are repeated in the suggested next command."""
    fit = result.run.fit
    lines = [
        f"{result.structure.label()} fitted on {covered(result.training):.0f} s of {source}, "
        f"run free on {covered(result.held_out):.0f} s held out "
        f"({'other recordings; ' if result.cross_manoeuvre else ''}"
        f"{len(result.held_out.segments)} free runs from the measured state)",
        f"  held-out free-run: heading RMSE {fit['rmse_heading'] * DEG:.3g} deg "
        f"(fit {fit['fit_percent_heading']:.1f} %), yaw rate RMSE {fit['rmse_yaw_rate'] * DEG:.3g} deg/s "
        f"(fit {fit['fit_percent_yaw_rate']:.1f} %); yaw-rate noise floor "
        f"{result.noise['yaw_rate'] * DEG:.3g} deg/s",
    ]
    if result.before is not None:
        b = result.before_run.fit
        lines.append(
            f"  before ({result.before.structure.label()}): heading RMSE "
            f"{b['rmse_heading'] * DEG:.3g} -> {fit['rmse_heading'] * DEG:.3g} deg, yaw rate RMSE "
            f"{b['rmse_yaw_rate'] * DEG:.3g} -> {fit['rmse_yaw_rate'] * DEG:.3g} deg/s"
        )
    stability = result.estimate.course_stability()
    if stability:
        lines.append(f"  {stability['sentence']}")
    lines.append("worst segments (short free runs from the measured state):")
    for seg in result.worst_segments:
        c = seg["conditions"]
        was = (
            (f" (before: {seg['rmse_heading_before'] * DEG:.3g} deg, {seg['rmse_yaw_rate_before'] * DEG:.3g} deg/s)")
            if "rmse_heading_before" in seg
            else ""
        )
        lines.append(
            f"  {seg['recording']}{' (held out)' if seg['held_out'] and 'held out' not in seg['recording'] else ''} "
            f"{seg['start']:7.1f}-{seg['end']:7.1f} s: heading {seg['rmse_heading'] * DEG:.3g} deg, "
            f"yaw rate {seg['rmse_yaw_rate'] * DEG:.3g} deg/s{was}; turning {c['turning']}, "
            f"|r| {c['mean_abs_yaw_rate_deg_s']:.2f} deg/s, heading {c['heading_sector']}, "
            f"rudder std {c['rudder_std_deg']:.1f} deg" + (f", speed {c['speed']:.2f} m/s" if "speed" in c else "")
        )
    tests = result.residual_tests
    lines.append(
        f"residual: {100 * tests['autocorrelation_outside']:.0f} % of autocorrelation lags and "
        f"{100 * tests['cross_correlation_outside']:.0f} % of rudder cross-correlation lags "
        f"outside +-{tests['bound']:.3f} (95 %), RMS {tests['noise_ratio']:.2f} times the noise floor"
        + (
            ""
            if tests["white"] and tests["independent_of_rudder"]
            else f": the residual still carries structure the model lacks; it follows {tests['follows']}"
        )
    )
    lines += [f"  {w['message']}" for w in result.parameter_warnings]
    lines.append(f"verdict: {result.verdict}: {result.verdict_sentence}")
    for c in result.candidates:
        lines.append(
            f"  {c.effect:<17} improvement {100 * c.improvement:5.1f} % "
            f"(heading {100 * c.improvement_heading:.0f} %, yaw rate {100 * c.improvement_yaw_rate:.0f} %), "
            f"{'significant' if c.significant else 'not significant'} (t {c.t_statistic:.1f})"
            f"{'; ' + c.note if c.note else ''}"
        )
        lines.append(f"      {c.evidence.sentence}")
        if c.extrapolation:
            lines.append(f"      much worse held out: {c.extrapolation}")
        if c.second_order:
            lines.append(
                f"      fitted on {c.estimate.structure.model}: on nomoto2 {', '.join(c.second_order['undetermined'])} "
                f"undetermined (improvement {100 * c.second_order['improvement']:.1f} % there)"
            )
        if c.preferred_over:
            other = c.preferred_over
            lines.append(f"      ranked before {other['effect']}: its {', '.join(other['undetermined'])} undetermined")
        if c.near_equivalent:
            lines.append(f"      near-equivalent on these data: {', '.join(c.near_equivalent)}")
        if c.together:
            pair = c.together
            lines.append(
                f"      with {pair.effect} as well: improvement {100 * pair.improvement:.1f} % (heading "
                f"{100 * pair.improvement_heading:.0f} %, yaw rate {100 * pair.improvement_yaw_rate:.0f} %), "
                f"significant (t {pair.t_statistic:.1f})"
            )
    recommendation = result.recommendation
    if recommendation is not None:
        effects = ",".join(recommendation["effects"])
        lines.append(
            f"next: ship-ident diagnose {source} --model {recommendation['model']} --effects {effects}{options}"
        )
    return "\n".join(lines)
