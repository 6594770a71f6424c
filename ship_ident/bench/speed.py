"""``speed``: median wall time of one refit per method on windows of 1k, 6k and 60k samples.

Data: seed 001's vessel, the mixed manoeuvre with realistic noise, h =
0.1 s (so 100 s, 600 s and 6000 s windows). A refit is the full
``Estimator.fit``: differentiation, regression, solve (for rwlssvm the
particle swarm over weights and gamma), parameter map, std errors and the
in-sample free run. The first fit of each size is a warm-up and not timed.
``ms per 1k samples`` shows whether the cost is linear in the window.
"""

from __future__ import annotations

import time

import numpy as np

from ..estimators import make_estimator, method_names
from ..model.simulator import simulate
from . import progress, register
from .common import machine, machine_line, table

WINDOWS = (1_000, 6_000, 60_000)
METHODS = ("ols", "lssvm", "rlssvm", "rwlssvm", "tlssvm", "rwlssvm+oe", "rwlssvm+pem")


def median_fit_seconds(method: str, sim, repeats: int) -> float:
    estimator = make_estimator(method)
    estimator.fit(sim.structure, sim.dataset)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        estimator.fit(sim.structure, sim.dataset)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def run(quick: bool = False) -> dict:
    windows = (1_000, 2_000) if quick else WINDOWS
    assert set(METHODS) <= set(method_names())
    timings = {m: {} for m in METHODS}
    for n in windows:
        sim = simulate("mixed", noise=1.0, duration=(n - 1) * 0.1, seed=0)
        for method in METHODS:
            slow = "+" in method  # a refinement: free-run simulations
            repeats = 1 if quick or (slow and n > 10_000) else 3 if slow else 7
            progress(f"speed: {method} on {n} samples ({repeats} timed fits)")
            timings[method][str(n)] = median_fit_seconds(method, sim, repeats)
    return {
        "data": {
            "vessel": "seed001",
            "maneuver": "mixed",
            "noise": "realistic (factor 1)",
            "sample_time_s": 0.1,
            "windows": list(windows),
        },
        "machine": machine(),
        "median_seconds": timings,
    }


def render(result: dict) -> str:
    windows = [str(n) for n in result["data"]["windows"]]
    rows = []
    for method, t in result["median_seconds"].items():
        rows.append([method] + [1e3 * t[n] for n in windows] + [1e3 * t[n] / (int(n) / 1000) for n in windows])
    m = result["machine"]
    return table(
        ["method"] + [f"{n} samples ms" for n in windows] + [f"ms/1k @ {n}" for n in windows],
        rows,
        f"speed: median time of one refit (full fit), {machine_line(m)}, "
        f"OPENBLAS_NUM_THREADS={m['OPENBLAS_NUM_THREADS']}",
    )


register("speed", "median refit time per method on 1k, 6k and 60k sample windows", run, render)
