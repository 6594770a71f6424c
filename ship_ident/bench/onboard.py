"""``onboard``: what the diagnosis on board costs the node (randomised: the vessel is drawn).

The real node (``identifier_node``, default parameters, ``use_sim_time``) is fed a simulated trip
of a USV drawn with ``simulator.random_vessel`` (random rudder steps, realistic noise; ``--count``
vessels, one by default) by
``ship-ident play`` at real time, 10 Hz on each input, over DDS on a private domain restricted to
this machine; once with ``diagnosis_period`` 0 (off) and once with the default 60 s (on). After a
warm-up of one full window, for ``MEASURE_S``:

* **CPU**: the CPU time of the node and of every process it started (the diagnosis runs in a
  child) from ``/proc``, over the wall time: the average share of one core;
* **refit time**: the ``compute_seconds`` of every published estimate (median, p95, max): a
  diagnosis must never delay a refit (it runs in a low-priority child process);
* the diagnoses published (``~/diagnosis``) and their own CPU time.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

from ..model.simulator import random_vessel, simulate
from ..online.config import OnlineConfig
from . import progress, register
from .common import machine, machine_line, table

MODES = {"off": 0.0, "on": OnlineConfig().diagnosis_period}
FIGURES = ("cpu_percent", "refit_median_ms", "refit_p95_ms")  # averaged over the vessels
MEASURE_S = 180.0  # s of measurement after the warm-up (three diagnoses at the default period)
QUICK = {"window_length": 90.0, "measure": 40.0, "period": 20.0}  # smoke test: a short window


def process_tree_cpu_seconds(pid: int) -> float:
    """CPU time (user + system, s) of process ``pid`` and all its living descendants (from /proc)."""
    children: dict[int, list[int]] = {}
    stats: dict[int, list[str]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:  # ended meanwhile
            continue
        stats[int(entry)] = fields
        children.setdefault(int(fields[1]), []).append(int(entry))
    ticks, todo = 0, [pid]
    while todo:
        current = todo.pop()
        if current in stats:
            ticks += int(stats[current][11]) + int(stats[current][12])  # utime, stime
        todo += children.get(current, [])
    return ticks / os.sysconf("SC_CLK_TCK")


DEFAULT_EFFECTS = ("rudder_offset", "cubic_yaw")  # the node's default model: nothing hidden from it


def drawn_trip(rng: np.random.Generator, duration: float, folder: str, k: int) -> tuple:
    """A USV drawn with ``random_vessel`` (then a trip seed, from ``rng``), its random-step trip of
    ``duration`` s with the node's default effects written to ``folder/trip{k}.mcap``: (vessel, bag)."""
    from ..io.files import write_simulation

    vessel = random_vessel(rng, "usv")
    trip_seed = int(rng.integers(2**31))
    sim = simulate("random", vessel, effects=DEFAULT_EFFECTS, duration=duration, seed=trip_seed)
    bag = Path(folder) / f"trip{k}.mcap"
    write_simulation(sim, bag, "mcap")
    return vessel, bag


def measure(bag: Path, period: float, window: float, measure_s: float, domain_id: int, log_dir: str) -> dict:
    """One node run with ``diagnosis_period`` = ``period``: CPU share, refit times, diagnoses."""
    from ..ros.demo import quiet_trip, shut_down

    node, listener, play = quiet_trip(
        domain_id, log_dir, bag, 1.0, f"diagnosis_period:={period}", f"window_length:={window}"
    )
    try:
        warm = window + 5.0
        if not listener.spin(warm + 60.0, lambda: listener.estimates and listener.estimates[-1]["stamp"] >= warm):
            raise RuntimeError("the node published no estimate past its warm-up; is DDS working here?")
        first = len(listener.estimates)
        diagnoses_before = len(listener.diagnoses)
        cpu0, wall0 = process_tree_cpu_seconds(node.pid), time.monotonic()
        listener.spin(measure_s)
        cpu1, wall1 = process_tree_cpu_seconds(node.pid), time.monotonic()
    finally:
        shut_down(node, listener, play)
    refits = np.array([e["compute_seconds"] for e in listener.estimates[first:]])
    diagnoses = listener.diagnoses[diagnoses_before:]
    return {
        "diagnosis_period": period,
        "cpu_percent": float(100.0 * (cpu1 - cpu0) / (wall1 - wall0)),
        "refits": len(refits),
        "refit_median_ms": float(1e3 * np.median(refits)),
        "refit_p95_ms": float(1e3 * np.percentile(refits, 95)),
        "refit_max_ms": float(1e3 * refits.max()),
        "diagnoses": len(diagnoses),
        "diagnoses_done": sum(d["status"] == "done" for d in diagnoses),
        "diagnosis_cpu_seconds": [float(d["compute_seconds"]) for d in diagnoses if d["status"] == "done"],
    }


def run(quick: bool = False, seed: int = 0, count: int | None = None) -> dict:
    rng = np.random.default_rng(seed)
    window = QUICK["window_length"] if quick else OnlineConfig().window_length
    measure_s = QUICK["measure"] if quick else MEASURE_S
    modes = {"off": 0.0, "on": QUICK["period"]} if quick else MODES
    duration = window + 5.0 + measure_s + 90.0  # warm-up, measurement, and slack for the start-up
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(count or 1):
            vessel, bag = drawn_trip(rng, duration, tmp, k)
            for mode, period in modes.items():
                progress(f"onboard: {vessel.name}, diagnosis {mode}: {window:g} s warm-up, {measure_s:g} s measured")
                domain_id = 101 + (seed + len(rows)) % 45  # apart from the tests' domains 1..100 and 150..199
                row = {"vessel": vessel.name, "mode": mode, **measure(bag, period, window, measure_s, domain_id, tmp)}
                progress(
                    f"onboard: diagnosis {mode}: CPU {row['cpu_percent']:.1f} % of one core, refit p95 "
                    f"{row['refit_p95_ms']:.0f} ms, {row['diagnoses_done']} diagnoses"
                )
                rows.append(row)
    mean = {
        mode: {key: float(np.mean([r[key] for r in rows if r["mode"] == mode])) for key in FIGURES} for mode in modes
    }
    return {
        "window_length": window,
        "measure_seconds": measure_s,
        "input_rate_hz": 10.0,
        "machine": machine(),
        "rows": rows,
        "mean": mean,
        "refit_p95_ratio": mean["on"]["refit_p95_ms"] / mean["off"]["refit_p95_ms"],
    }


def render(result: dict) -> str:
    rows = [
        [
            r["vessel"],
            r["mode"],
            f"{r['diagnosis_period']:g}",
            r["cpu_percent"],
            r["refits"],
            r["refit_median_ms"],
            r["refit_p95_ms"],
            r["refit_max_ms"],
            f"{r['diagnoses_done']} of {r['diagnoses']}",
            float(np.mean(r["diagnosis_cpu_seconds"])) if r["diagnosis_cpu_seconds"] else float("nan"),
        ]
        for r in result["rows"]
    ]
    mean = result["mean"]
    return table(
        [
            "vessel",
            "diagnosis",
            "period (s)",
            "node CPU (% of one core)",
            "refits",
            "refit median (ms)",
            "refit p95 (ms)",
            "refit max (ms)",
            "diagnoses done",
            "CPU per diagnosis (s)",
        ],
        rows,
        title=(
            f"onboard (seed {result['seed']}): the node at {result['input_rate_hz']:g} Hz inputs in real time, "
            f"{result['window_length']:g} s window, measured {result['measure_seconds']:g} s after one window; "
            f"{machine_line(result['machine'])}"
        ),
    ) + (
        f"\nmean: CPU {mean['off']['cpu_percent']:.1f} % off / {mean['on']['cpu_percent']:.1f} % on; refit p95 "
        f"{mean['off']['refit_p95_ms']:.0f} / {mean['on']['refit_p95_ms']:.0f} ms "
        f"(on/off {result['refit_p95_ratio']:.2f})"
    )


register(
    "onboard",
    "node CPU and refit times at 10 Hz inputs, diagnosis on board off and on (real node over DDS, real time)",
    run,
    render,
    randomised=True,
)
