"""``soak``: the node fed 100 Hz on each input for ten minutes of simulated time, over real DDS
(randomised: the trip's seed).

The real node (``identifier_node``, declared defaults, ``use_sim_time``, diagnosis off) is fed by an
rclpy publisher in this process: rudder, heading and yaw rate of a simulated mixed manoeuvre at
``INPUT_RATE`` each, with ``/clock`` before every sample, paced at ``PACE`` times real time (1800
data messages/s). The feed waits whenever the clock runs more than two refit periods and a timer
tick past the node's newest refit (``Listener.pace_by_node``), so a loaded machine slows the soak
instead of failing it; the waits are left out of the wall time. Figures: messages accepted per
second and their share, lost and duplicate shares, the node's resident memory after the warm-up
(``WARM_UP_S``: its window full, its compiled code loaded) and at the end, the refits' schedule
and their compute times. ``make test`` runs a shorter sample of it (``test_soak``).
"""

from __future__ import annotations

import math
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from . import progress, register
from .common import machine, machine_line, table

SIM_SECONDS = 600.0  # s of simulated time
QUICK_SIM_SECONDS = 300.0  # s: the window full, then its memory watched for 50 s
INPUT_RATE = 100.0  # Hz on each of rudder, heading, yaw rate
PACE = 6.0  # x real time: 1800 data messages/s plus 600 /clock messages/s
WARM_UP_S = 250.0  # s of simulated time: window full, compiled code loaded
CATCH_UP_TIMEOUT = 60.0  # s of wall time for the node to come within the pace's lead
DOMAIN_IDS = range(101, 146)  # apart from the tests' domains 1..100 and 150..199
NODE_LOG = "soak_node.log"  # the node's output, in the soak's log directory


def rss_mib(pid: int) -> float:
    """Resident memory of process ``pid`` (MiB)."""
    with open(f"/proc/{pid}/status") as f:
        return next(int(line.split()[1]) / 1024 for line in f if line.startswith("VmRSS"))


def soak(domain_id: int, log_dir, sim_seconds: float = SIM_SECONDS, seed: int = 11) -> dict:
    """Feed the node ``sim_seconds`` of a mixed manoeuvre (simulation seed ``seed``) at
    ``INPUT_RATE`` per input and ``PACE`` x real time on ROS domain ``domain_id``; returns the
    figures (see the module) and ``node_exit_code``; the node's output is in ``log_dir``/NODE_LOG."""
    from ..commands.play import Player
    from ..model.simulator import simulate
    from ..online.config import OnlineConfig
    from ..ros.demo import Listener, ros_environment, shut_down, start_node
    from ..ros.node import TICKS_PER_REFIT

    period = OnlineConfig().refit_period
    # /clock at most two refits and a tick past the node's newest (a refit due while the previous one
    # still runs is skipped, so the next record can be two periods on)
    max_lead = 2 * period + period / TICKS_PER_REFIT
    d = simulate("mixed", duration=sim_seconds, seed=seed, sample_time=1.0 / INPUT_RATE).dataset
    heading = np.mod(d.heading + np.pi, 2 * np.pi) - np.pi
    env = ros_environment(domain_id, log_dir)
    # diagnosis off: the soak measures the input path at 6x real time, where a diagnosis of the window
    # every 60 s of simulated time would come every 10 s; its cost at real time is `bench onboard`'s
    with open(Path(log_dir) / NODE_LOG, "w") as log:
        node = start_node(
            env, "use_sim_time:=true", "diagnosis_period:=0.0", params_file=None, stdout=log, stderr=subprocess.STDOUT
        )
    listener = Listener(domain_id)
    player = Player(listener.node)
    rss = {}
    waited = 0.0  # s of wall time the feed waited for the node
    pace_by_node = listener.pace_by_node(max_lead, CATCH_UP_TIMEOUT, skipped=period, clock=player.republish_clock)
    try:
        if not player.wait_for_subscribers(20.0):
            raise RuntimeError("the node did not subscribe within 20 s; is DDS working here?")
        listener.spin(1.0)
        wall0 = time.monotonic()
        for i, t in enumerate(d.time):
            player.publish_clock(float(t))
            player.publish("rudder", d.rudder[i])
            player.publish("heading", heading[i])
            player.publish("yaw_rate", d.yaw_rate[i])
            if i % 20 == 0:
                listener.executor.spin_once(timeout_sec=0)
                if "warm" not in rss and t >= WARM_UP_S:
                    rss["warm"] = rss_mib(node.pid)
                held = time.monotonic()
                pace_by_node(float(t))
                waited += time.monotonic() - held
                wall0 += time.monotonic() - held
            delay = wall0 + t / PACE - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        wall = time.monotonic() - wall0  # the waits for the node left out
        listener.spin(3.0)
        rss["end"] = rss_mib(node.pid)
        alive = node.poll() is None
    finally:
        code, _ = shut_down(node, listener)
    records = listener.estimates
    sent = 3 * len(d.time)
    counts = records[-1]["counts"]
    stamps = np.array([r["stamp"] for r in records])
    intervals = np.diff(stamps)
    latency = np.array([r["compute_seconds"] for r in records if r["new_estimate"]])
    return {
        "simulated_s": sim_seconds,
        "seed": seed,
        "refit_period_s": period,
        "wall_s": wall,
        "x_real_time": sim_seconds / wall,
        "waited_for_node_s": waited,
        "node_alive_at_the_end": alive,
        "node_exit_code": code,
        "data_messages_per_s_sent": sent / wall,
        "accepted_per_s": counts["accepted"] / wall,
        "accepted_share": counts["accepted"] / sent,
        "duplicate_share": counts["duplicate"] / sent,
        "lost_share": 1 - sum(counts[k] for k in ("accepted", "duplicate", "out_of_order")) / sent,
        "rss_warm_mib": rss["warm"],
        "rss_end_mib": rss["end"],
        "last_stamp_s": float(stamps[-1]),
        "refits": len(records),
        "new_estimates": int(len(latency)),
        "overran": sum("refit_overran" in r["conditions"] for r in records),
        # the timer ticks TICKS_PER_REFIT times per period: a refit one tick late still keeps the schedule,
        # and one brought forward (a change found between refits is refitted at once, and followed at a
        # fifth of the period) keeps it too
        "period_kept_share": float(np.mean(intervals <= period + period / TICKS_PER_REFIT + 0.05)),
        "refit_ms_p50_p95_p99_max": [round(1000 * v, 1) for v in np.percentile(latency, [50, 95, 99, 100])]
        if len(latency) and math.isfinite(latency.max())
        else [],
    }


def run(quick: bool = False, seed: int = 0, count: int | None = None) -> dict:
    if count is not None:
        raise ValueError("soak feeds one trip: --count does not apply")
    sim_seconds = QUICK_SIM_SECONDS if quick else SIM_SECONDS
    progress(
        f"soak: {sim_seconds:g} s simulated at {INPUT_RATE:g} Hz per input, {PACE:g}x real time "
        f"(about {sim_seconds / PACE:.0f} s)"
    )
    with tempfile.TemporaryDirectory() as tmp:
        figures = soak(DOMAIN_IDS[seed % len(DOMAIN_IDS)], tmp, sim_seconds, seed)
        if figures["node_exit_code"] != 0:
            raise RuntimeError(
                f"the node exited with code {figures['node_exit_code']}: " + (Path(tmp) / NODE_LOG).read_text()[-2000:]
            )
    return {"machine": machine(), **figures}


def render(result: dict) -> str:
    p50, p95, p99, worst = result["refit_ms_p50_p95_p99_max"] or [float("nan")] * 4
    rows = [
        [
            "simulated / wall time",
            f"{result['simulated_s']:g} s in {result['wall_s']:.0f} s ({result['x_real_time']:.1f}x real time)",
        ],
        ["waited for the node", f"{result['waited_for_node_s']:.1f} s (left out of the wall time)"],
        ["data messages sent", f"{result['data_messages_per_s_sent']:.0f} /s (plus /clock)"],
        ["accepted by the node", f"{result['accepted_per_s']:.0f} /s ({100 * result['accepted_share']:.0f} %)"],
        [
            "rejected as duplicate stamps / lost",
            f"{100 * result['duplicate_share']:.1f} % / {100 * result['lost_share']:.1f} %",
        ],
        ["RSS after warm-up / at the end", f"{result['rss_warm_mib']:.1f} / {result['rss_end_mib']:.1f} MiB"],
        ["refits / new estimates / overran", f"{result['refits']} / {result['new_estimates']} / {result['overran']}"],
        ["intervals within one timer tick of the period", f"{100 * result['period_kept_share']:.0f} %"],
        ["refit compute time p50 / p95 / p99 / max", f"{p50:.0f} / {p95:.0f} / {p99:.0f} / {worst:.0f} ms"],
    ]
    return table(
        ["figure", "value"],
        rows,
        title=(
            f"soak (seed {result['seed']}): the node at {INPUT_RATE:g} Hz per input over DDS, diagnosis off; "
            f"{machine_line(result['machine'])}"
        ),
    )


register(
    "soak",
    "the node fed 100 Hz per input for 10 simulated minutes at 6x real time over DDS: messages, memory, refit times",
    run,
    render,
    randomised=True,
)
