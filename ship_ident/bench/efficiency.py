"""``efficiency``: scatter of the estimates over noise seeds against the Cramer-Rao bound.

Data: seed 001's vessel, 20/20 zigzag and random-step manoeuvres of 600 s
at h = 0.1 s, sensor noise std rudder 0.1 deg, heading 0.1 deg, yaw rate
0.2 deg/s (``simulator.Noise()``), 20 noise seeds each. Per parameter: RMS
error, bias, the Cramer-Rao lower bound for the same record (``crb.py``,
with the rudder-sensor noise in it, averaged as sqrt(mean CRB^2) over the
seeds since the random manoeuvre differs per seed), their ratio, the worst
single-run error, and the fraction of runs whose 95 % interval
(estimate +- 1.96 std error) covers the truth. The bound with a known
rudder is printed beside it; a control repeats the default method with an
exact rudder and is judged against that bound.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..estimators import DEFAULT_METHOD, make_estimator
from ..estimators.base import Z_95
from ..model.dataset import Dataset
from ..model.simulator import Noise, simulate
from . import progress, register
from .common import table
from .crb import cramer_rao_bound

MANEUVERS = ("zigzag20", "random")
METHODS = ("rwlssvm", "rwlssvm+oe", "rwlssvm+pem")
CONTROL = f"{DEFAULT_METHOD} (exact rudder)"
QUANTITIES = ("K", "T1", "T2", "T3", "delta_r", "alpha", "T1+T2-T3")
SINGLE_RUN_TARGET_PERCENT = {"K": 1.0, "T1": 3.0, "delta_r": 3.0, "T1+T2-T3": 2.0}


def _with_derived(params: dict) -> dict:
    return dict(params, **{"T1+T2-T3": params["T1"] + params["T2"] - params["T3"]})


def record_bound(sim, noise: Noise) -> dict:
    """CRB of the simulation's record (true initial state at rest) with the record's rudder noise."""
    d = sim.dataset
    exact = Dataset(
        time=d.time, rudder=sim.true_rudder, heading=sim.true_heading, yaw_rate=sim.true_yaw_rate, meta=d.meta
    )
    return cramer_rao_bound(
        sim.structure, sim.truth, exact, [(0.0, 0.0, 0.0)], noise.heading, noise.yaw_rate, noise.rudder
    )


def _pooled(bounds: list[dict], q: str) -> float:
    return float(np.sqrt(np.mean([b[q] ** 2 for b in bounds])))


def summarise(
    errors: list[dict],
    covered: list[dict],
    bounds: list[dict],
    truth: dict,
    known_rudder_bounds: list[dict] | None = None,
) -> dict:
    """Per quantity: RMS error, bias, CRB and their ratio, worst run (all % of truth), coverage."""
    out = {}
    for q in QUANTITIES:
        e = np.array([err[q] for err in errors])
        crb = _pooled(bounds, q)
        rms = float(np.sqrt(np.mean(e**2)))
        scale = 100.0 / abs(truth[q])
        row = {
            "rms_percent": rms * scale,
            "bias_percent": float(np.mean(e)) * scale,
            "crb_percent": crb * scale,
            "rms_over_crb": rms / crb if crb > 0 else float("inf"),
            "worst_percent": float(np.max(np.abs(e))) * scale,
        }
        if known_rudder_bounds:
            row["crb_known_rudder_percent"] = _pooled(known_rudder_bounds, q) * scale
        if covered and q in covered[0]:
            row["coverage_95"] = float(np.mean([c[q] for c in covered]))
        out[q] = row
    return out


def run(quick: bool = False) -> dict:
    seeds = range(2) if quick else range(20)
    duration = 120.0 if quick else 600.0
    noise = Noise()
    result = {
        "data": {
            "vessel": "seed001",
            "maneuvers": list(MANEUVERS),
            "duration_s": duration,
            "sample_time_s": 0.1,
            "seeds": len(seeds),
            "noise": {
                "rudder_deg": float(np.degrees(noise.rudder)),
                "heading_deg": float(np.degrees(noise.heading)),
                "yaw_rate_deg_s": float(np.degrees(noise.yaw_rate)),
            },
        },
        "maneuvers": {},
    }
    for maneuver in MANEUVERS:
        runs = {m: ([], []) for m in METHODS + (CONTROL,)}
        bounds, known_rudder = [], []
        truth = None
        for seed in seeds:
            progress(f"efficiency: {maneuver} seed {seed}")
            sim = simulate(maneuver, noise=noise, duration=duration, seed=1000 + seed)
            truth = _with_derived(sim.truth)
            bounds.append(record_bound(sim, noise))
            known_rudder.append(record_bound(sim, replace(noise, rudder=0.0)))
            exact = simulate(maneuver, noise=Noise(rudder=0.0), duration=duration, seed=1000 + seed)
            for method, data in [(m, sim.dataset) for m in METHODS] + [(CONTROL, exact.dataset)]:
                est = make_estimator(method.split(" ")[0]).fit(sim.structure, data)
                p = _with_derived(est.parameters)
                runs[method][0].append({q: p[q] - truth[q] for q in QUANTITIES})
                runs[method][1].append(
                    {
                        q: bool(abs(p[q] - truth[q]) <= Z_95 * est.std_errors[q])
                        for q in QUANTITIES
                        if q in est.std_errors
                    }
                )
        result["maneuvers"][maneuver] = {
            "truth": truth,
            "methods": {
                m: summarise(e, c, known_rudder if m == CONTROL else bounds, truth, known_rudder)
                for m, (e, c) in runs.items()
            },
        }
    return result


def render(result: dict) -> str:
    d = result["data"]
    n = d["noise"]
    out = [
        f"efficiency: seed001 vessel, {d['duration_s']:.0f} s per run, h = {d['sample_time_s']} s, "
        f"{d['seeds']} noise seeds; noise std rudder {n['rudder_deg']} deg, heading {n['heading_deg']} deg, "
        f"yaw rate {n['yaw_rate_deg_s']} deg/s. CRB: with the rudder noise (for the exact-rudder control: "
        "the known-rudder bound, also shown as 'CRB known rudder %')."
    ]
    for maneuver, res in result["maneuvers"].items():
        rows = []
        for method, summary in res["methods"].items():
            for q, s in summary.items():
                target = SINGLE_RUN_TARGET_PERCENT.get(q)
                rows.append(
                    [
                        method,
                        q,
                        s["rms_percent"],
                        s["bias_percent"],
                        s["crb_percent"],
                        s["crb_known_rudder_percent"],
                        s["rms_over_crb"],
                        s["worst_percent"],
                        "" if target is None else target,
                        s.get("coverage_95", ""),
                    ]
                )
        out.append(
            table(
                [
                    "method",
                    "quantity",
                    "RMS %",
                    "bias %",
                    "CRB %",
                    "CRB known rudder %",
                    "RMS/CRB",
                    "worst %",
                    "single-run target %",
                    "95% coverage",
                ],
                rows,
                f"manoeuvre {maneuver}",
            )
        )
    return "\n\n".join(out)


register("efficiency", "RMS error over noise seeds vs the Cramer-Rao bound, 95 % interval coverage", run, render)
