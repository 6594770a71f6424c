"""Soak and load: the node fed 100 Hz on each input for 10 minutes of simulated time at up to 6x
real time (paced /clock), over real DDS. The feed waits whenever the clock runs more than two refit
periods and a timer tick past the node's newest refit, so a loaded machine slows the soak instead of
failing it. Figures are printed (``pytest -s``); docs/reliability.md."""

import math
import subprocess
import time

import numpy as np
import pytest
from test_node import domain_id, env  # noqa: F401  (fixtures)

from ship_ident.commands.play import Player
from ship_ident.model.simulator import simulate
from ship_ident.ros.demo import Listener, shut_down, start_node
from ship_ident.ros.node import TICKS_PER_REFIT

pytestmark = [pytest.mark.slow, pytest.mark.node]  # ten simulated minutes at 100 Hz through the node

SIM_SECONDS = 600.0  # s of simulated time
INPUT_RATE = 100.0  # Hz on each of rudder, heading, yaw rate
PACE = 6.0  # x real time: 1800 data messages/s plus 600 /clock messages/s
WARM_UP = 250.0  # s of simulated time: window full, compiled code loaded
REFIT_PERIOD = 5.0  # s
# s: /clock at most two refits and a tick past the node's newest (a refit due while the previous one
# still runs is skipped, so the next record can be two periods on)
MAX_LEAD = 2 * REFIT_PERIOD + REFIT_PERIOD / TICKS_PER_REFIT
CATCH_UP_TIMEOUT = 60.0  # s of wall time for the node to come within MAX_LEAD


def rss_mib(pid: int) -> float:
    with open(f"/proc/{pid}/status") as f:
        return next(int(line.split()[1]) / 1024 for line in f if line.startswith("VmRSS"))


def test_node_soak_at_100_hz_for_10_simulated_minutes(env, domain_id):  # noqa: F811
    d = simulate("mixed", duration=SIM_SECONDS, seed=11, sample_time=1.0 / INPUT_RATE).dataset
    heading = np.mod(d.heading + np.pi, 2 * np.pi) - np.pi
    # diagnosis off: the soak measures the input path at 6x real time, where a diagnosis of the window
    # every 60 s of simulated time would come every 10 s; its cost at real time is `bench onboard`'s
    node = start_node(
        env, "use_sim_time:=true", "diagnosis_period:=0.0", stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    listener = Listener(domain_id)
    player = Player(listener.node)
    rss = {}
    waited = 0.0  # s of wall time the feed waited for the node
    # a refit that overruns skips the ticks it covers, and with /clock held nothing is due again: after
    # a stall the lead grows by one period so that the clock moves on to the next refit
    pace_by_node = listener.pace_by_node(MAX_LEAD, CATCH_UP_TIMEOUT, skipped=REFIT_PERIOD, clock=player.republish_clock)
    try:
        assert player.wait_for_subscribers(20.0)
        listener.spin(1.0)
        wall0 = time.monotonic()
        for i, t in enumerate(d.time):
            player.publish_clock(float(t))
            player.publish("rudder", d.rudder[i])
            player.publish("heading", heading[i])
            player.publish("yaw_rate", d.yaw_rate[i])
            if i % 20 == 0:
                listener.executor.spin_once(timeout_sec=0)
                if "warm" not in rss and t >= WARM_UP:
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
        assert node.poll() is None
    finally:
        code, log = shut_down(node, listener)
    assert code == 0, log
    records = listener.estimates
    sent = 3 * len(d.time)
    counts = records[-1]["counts"]
    stamps = np.array([r["stamp"] for r in records])
    intervals = np.diff(stamps)
    latency = np.array([r["compute_seconds"] for r in records if r["new_estimate"]])
    overran = sum("refit_overran" in r["conditions"] for r in records)
    figures = {
        "simulated_s": SIM_SECONDS,
        "wall_s": wall,
        "x_real_time": SIM_SECONDS / wall,
        "waited_for_node_s": waited,
        "data_messages_per_s_sent": sent / wall,
        "accepted_per_s": counts["accepted"] / wall,
        "accepted_share": counts["accepted"] / sent,
        "duplicate_share": counts["duplicate"] / sent,
        "lost_share": 1 - sum(counts[k] for k in ("accepted", "duplicate", "out_of_order")) / sent,
        "rss_warm_mib": rss["warm"],
        "rss_end_mib": rss["end"],
        "refits": len(records),
        "new_estimates": int(len(latency)),
        "overran": overran,
        # the timer ticks TICKS_PER_REFIT times per period: a refit one tick late still keeps the schedule,
        # and one brought forward (a change found between refits is refitted at once, and followed at a
        # fifth of the period) keeps it too
        "period_kept_share": float(np.mean(intervals <= REFIT_PERIOD + REFIT_PERIOD / TICKS_PER_REFIT + 0.05)),
        "refit_ms_p50_p95_p99_max": [round(1000 * v, 1) for v in np.percentile(latency, [50, 95, 99, 100])],
    }
    print("\nsoak figures:", figures)
    assert rss["end"] - rss["warm"] < 30.0  # flat after warm-up
    # every message reaches the node and is used or counted as rejected; a node starved of CPU stamps
    # a backlog on arrival with one clock reading and rejects those as duplicates (0.95 used on a
    # quiet machine, 0.46 beside two busy processes on 2 cores), which its estimate record says
    assert figures["lost_share"] < 0.05
    assert stamps[-1] >= SIM_SECONDS - 2 * REFIT_PERIOD  # no backlog at the end
    # the schedule is kept though ticks come late on a loaded machine
    assert figures["period_kept_share"] >= 0.75 and len(records) >= 0.9 * SIM_SECONDS / REFIT_PERIOD
    assert len(latency) >= 0.5 * len(records) and math.isfinite(latency.max())
