"""``realtime``: how many times faster than real time the online core runs, and the node's refit time.

Three figures, each in wall time and in CPU time (user + system of the processes measured): the
machine may be shared, and the CPU time is what the work costs whatever else runs beside it.

* **hour replay, whole process**: ``ship-ident replay BAG --json`` as a child process, start-up,
  imports and bag reading included, on a simulated 1-hour bag at 10 Hz on each input (the
  bundled bag's vessel, seed 001's, on the mixed manoeuvre with realistic noise; the noise drawn
  from the seed): the bag's duration over the process's time.
* **bundled bag, refit loop**: ``bags/demo_seed001.mcap`` (600 s) run in this process through the
  online core's schedule (``online.identifier.run_schedule``) after one untimed run (imports and
  compiled kernels loaded): the bag's duration over the loop's time (samples, refits, change
  watches), as ``replay`` runs it by default; and again with the diagnosis on board inline at its
  default period (``replay --diagnosis-period``; the node runs the diagnoses in a child process of
  their own, beside the refits).
* **node refit p95**: the real node (``bench onboard``'s measurement: DDS on a private domain,
  ``ship-ident play`` at real time, 10 Hz inputs) with the diagnosis on board on at its default
  period, on a USV drawn from the seed; the 95th percentile of the ``compute_seconds`` (wall time)
  of its refits after one full window, and the node's CPU share.
"""

from __future__ import annotations

import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ..online.config import OnlineConfig
from . import progress, register
from .common import machine, machine_line, table
from .onboard import QUICK, drawn_trip, measure

HOUR_S = 3600.0
BUNDLED_BAG = Path(__file__).resolve().parents[2] / "bags" / "demo_seed001.mcap"
NODE_MEASURE_S = 180.0  # s of node refits measured after the warm-up window


def children_cpu_seconds() -> float:
    """User + system CPU seconds of this process's finished children."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def own_cpu_seconds() -> float:
    """User + system CPU seconds of this process (every thread)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def hour_replay(seed: int, folder: str, duration: float) -> dict:
    """A simulated bag of ``duration`` s replayed by a ``ship-ident replay --json`` child: its wall
    and CPU seconds and the refits it printed."""
    from ..io.files import write_simulation
    from ..model.simulator import simulate

    bag = Path(folder) / "hour.mcap"
    write_simulation(simulate("mixed", duration=duration, seed=seed), bag, "mcap")
    progress(f"realtime: replaying a {duration:g} s bag at 10 Hz in a child process")
    cpu0, wall0 = children_cpu_seconds(), time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "ship_ident.cli", "replay", str(bag), "--json"], capture_output=True, text=True
    )
    wall, cpu = time.perf_counter() - wall0, children_cpu_seconds() - cpu0
    if done.returncode != 0:
        raise RuntimeError(f"replay of the simulated bag failed: {done.stderr.strip()}")
    return {"duration_s": duration, "wall_s": wall, "cpu_s": cpu, "refits": done.stdout.count('"stamp"')}


def bundled_loop(diagnosis: bool) -> dict:
    """The bundled bag's refit loop in this process (the bag read and one untimed run first), with
    the diagnosis on board inline at its default period or without: wall and CPU seconds."""
    from ..diagnosis.onboard import OnlineDiagnosis
    from ..io.files import DEFAULT_TOPICS, read_samples
    from ..online.identifier import OnlineIdentifier, run_schedule

    progress(f"realtime: the bundled bag's refit loop{' with the diagnosis inline' if diagnosis else ''}")
    samples = read_samples(BUNDLED_BAG, DEFAULT_TOPICS)
    config = OnlineConfig() if any(s.role == "speed" for s in samples) else OnlineConfig(speed_topic="")
    list(run_schedule(OnlineIdentifier(config), samples, OnlineDiagnosis() if diagnosis else None))
    cpu0, wall0 = own_cpu_seconds(), time.perf_counter()
    records = list(run_schedule(OnlineIdentifier(config), samples, OnlineDiagnosis() if diagnosis else None))
    wall, cpu = time.perf_counter() - wall0, own_cpu_seconds() - cpu0
    return {"duration_s": samples[-1].time - samples[0].time, "wall_s": wall, "cpu_s": cpu, "refits": len(records)}


def node_refits(seed: int, quick: bool, folder: str) -> dict:
    """The node's refit times at 10 Hz inputs with the diagnosis on (``onboard.measure``)."""
    window = QUICK["window_length"] if quick else OnlineConfig().window_length
    measure_s = QUICK["measure"] if quick else NODE_MEASURE_S
    period = QUICK["period"] if quick else OnlineConfig().diagnosis_period
    vessel, bag = drawn_trip(np.random.default_rng(seed), window + 5.0 + measure_s + 90.0, folder, 0)
    progress(f"realtime: the node on {vessel.name}, diagnosis every {period:g} s, {measure_s:g} s measured")
    row = measure(bag, period, window, measure_s, 101 + seed % 45, folder)
    return {"vessel": vessel.name, "window_length": window, "diagnosis_period": period, **row}


def run(quick: bool = False, seed: int = 0, count: int | None = None) -> dict:
    if count not in (None, 1):
        raise ValueError("realtime draws one bag and one vessel: --count does not apply")
    with tempfile.TemporaryDirectory() as folder:
        hour = hour_replay(seed, folder, 600.0 if quick else HOUR_S)
        loop = bundled_loop(diagnosis=False)
        diagnosed = bundled_loop(diagnosis=True)
        node = node_refits(seed, quick, folder)
    return {
        "machine": machine(),
        "hour_replay": hour,
        "bundled_loop": loop,
        "bundled_loop_diagnosed": diagnosed,
        "node": node,
    }


def render(result: dict) -> str:
    rows = []
    for label, key in (
        ("replay of a simulated bag, whole process", "hour_replay"),
        ("bundled bag, refit loop", "bundled_loop"),
        ("bundled bag, refit loop with the diagnosis inline", "bundled_loop_diagnosed"),
    ):
        r = result[key]
        rows.append(
            [
                label,
                f"{r['duration_s']:g}",
                r["refits"],
                r["wall_s"],
                r["duration_s"] / r["wall_s"],
                r["cpu_s"],
                r["duration_s"] / r["cpu_s"],
            ]
        )
    node = result["node"]
    return (
        table(
            ["run", "bag s", "refits", "wall s", "x real time (wall)", "CPU s", "x real time (CPU)"],
            rows,
            f"realtime: {machine_line(result['machine'])} at the end",
        )
        + f"\nnode at 10 Hz inputs, diagnosis every {node['diagnosis_period']:g} s ({node['vessel']}, window "
        f"{node['window_length']:g} s): refit p95 {node['refit_p95_ms']:.0f} ms wall (median "
        f"{node['refit_median_ms']:.0f}, max {node['refit_max_ms']:.0f}) over {node['refits']} refits; node CPU "
        f"{node['cpu_percent']:.1f} % of one core, {node['diagnoses_done']} diagnoses done"
    )


register(
    "realtime",
    "replay speed (1-hour bag, whole process; bundled bag's refit loop) and the node's refit p95 with the diagnosis on",
    run,
    render,
    randomised=True,
)
