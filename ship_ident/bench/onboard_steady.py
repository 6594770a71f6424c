"""``onboard-steady``: the diagnosis on board raises no false alarm over a long trip (randomised).

The real node (``identifier_node``, default parameters, ``use_sim_time``) is fed, over DDS on a
private domain restricted to this machine, ``MINUTES`` of a trip of a USV drawn with
``simulator.random_vessel`` (random rudder steps, realistic noise; ``--count`` vessels, one by
default) whose true model is the node's own default (``rudder_offset``, ``cubic_yaw``): nothing is
hidden. ``ship-ident play`` paces it at ``PACE`` times real time. Counted: the diagnoses the node
publishes on ``~/diagnosis`` (done and skipped), those whose verdict is ``missing_effect``, the
``missing_effect`` WARNs in ``/diagnostics``, and the held-out error against the noise floor.
The figure: no ``missing_effect`` at all.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from ..online.config import OnlineConfig
from . import progress, register
from .common import table
from .onboard import drawn_trip

MINUTES = 30.0  # of simulated trip per vessel
PACE = 4.0  # x real time: 30 minutes in 7.5 minutes of wall time
QUICK = {"minutes": 5.0, "pace": 8.0, "window_length": 120.0, "diagnosis_period": 30.0}
DOMAIN_IDS = range(146, 150)  # apart from the tests' domains (1..100, 150..199) and bench onboard's


def diagnose_trip(bag: Path, duration: float, pace: float, window: float, period: float, domain_id: int, log_dir):
    """Play ``bag`` (``duration`` s) at ``pace`` to a node diagnosing its ``window`` s window every
    ``period`` s; return the diagnoses it published and the missing_effect WARNs it raised."""
    from ..ros.demo import node_log_tail, quiet_trip, shut_down

    node, listener, play = quiet_trip(
        domain_id, log_dir, bag, pace, f"window_length:={window}", f"diagnosis_period:={period}"
    )
    try:
        wall = time.monotonic()
        listener.spin(duration / pace + 30.0, lambda: play.poll() is not None)
        listener.spin(5.0)  # the last refit's outputs
        wall = time.monotonic() - wall
    finally:
        code, _ = shut_down(node, listener, play)
    warnings = [kv.value for s in listener.diagnostics for kv in s.values if kv.key == "condition/missing_effect"]
    done = [d for d in listener.diagnoses if d["status"] == "done"]
    return {
        "node_exit": code,
        "node_log": node_log_tail(log_dir) if code else "",  # what a node that died said last
        "wall_seconds": wall,
        "last_stamp": listener.estimates[-1]["stamp"] if listener.estimates else float("nan"),
        "diagnoses": len(listener.diagnoses),
        "diagnoses_done": len(done),
        "missing_effect": [d["verdict_sentence"] for d in done if d["verdict"] == "missing_effect"],
        "missing_effect_warnings": len(warnings),
        "verdicts": sorted({d["verdict"] for d in done}),
        "held_out_over_noise_median": (
            float(np.median([d["held_out_error"] / d["noise_floor"] for d in done])) if done else float("nan")
        ),
    }


def run(quick: bool = False, seed: int = 0, count: int | None = None) -> dict:
    rng = np.random.default_rng(seed)
    settings = QUICK if quick else {"minutes": MINUTES, "pace": PACE}
    defaults = OnlineConfig()
    window = settings.get("window_length", defaults.window_length)
    period = settings.get("diagnosis_period", defaults.diagnosis_period)
    duration = 60.0 * settings["minutes"]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(count or 1):
            vessel, bag = drawn_trip(rng, duration, tmp, k)
            progress(
                f"onboard-steady: {vessel.name}: {settings['minutes']:g} min at {settings['pace']:g}x, "
                f"window {window:g} s, diagnosis every {period:g} s"
            )
            domain_id = DOMAIN_IDS[(seed + k) % len(DOMAIN_IDS)]
            trip = diagnose_trip(bag, duration, settings["pace"], window, period, domain_id, tmp)
            row = {"vessel": vessel.name, **trip}
            progress(
                f"onboard-steady: {row['diagnoses_done']} diagnoses done of {row['diagnoses']}, "
                f"missing_effect in {len(row['missing_effect'])}"
            )
            rows.append(row)
    done = sum(r["diagnoses_done"] for r in rows)
    false_alarms = sum(len(r["missing_effect"]) for r in rows)
    return {
        "minutes": settings["minutes"],
        "pace": settings["pace"],
        "window_length": window,
        "diagnosis_period": period,
        "rows": rows,
        "diagnoses_done": done,
        "missing_effect": false_alarms,
        "missing_effect_share": false_alarms / done if done else float("nan"),
    }


def render(result: dict) -> str:
    rows = [
        [
            r["vessel"],
            f"{r['diagnoses_done']} of {r['diagnoses']}",
            len(r["missing_effect"]),
            r["missing_effect_warnings"],
            ", ".join(r["verdicts"]),
            r["held_out_over_noise_median"],
            r["node_exit"],
        ]
        for r in result["rows"]
    ]
    return table(
        [
            "vessel",
            "diagnoses done",
            "missing_effect",
            "missing_effect WARNs",
            "verdicts",
            "held-out error / noise floor (median)",
            "node exit",
        ],
        rows,
        title=(
            f"onboard-steady (seed {result['seed']}): nothing hidden, {result['minutes']:g} min per vessel "
            f"at {result['pace']:g}x over DDS, window {result['window_length']:g} s, diagnosis every "
            f"{result['diagnosis_period']:g} s"
        ),
    ) + (
        f"\nmissing_effect in {result['missing_effect']} of {result['diagnoses_done']} diagnoses "
        f"({100 * result['missing_effect_share']:.1f} %)"
    )


register(
    "onboard-steady",
    "no false missing_effect from the diagnosis on board: the real node over DDS, a long trip with nothing hidden",
    run,
    render,
    randomised=True,
)
