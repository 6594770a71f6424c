"""The experiments of ``bench peers``: accuracy, tracking, speed (see ``peers`` for what each measures).

Ours runs through ``OnlineIdentifier`` with the node's defaults (``ONLINE``);
the peers come from ``peer_models``. Each experiment returns a JSON-ready dict.
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np

from ..estimators import DEFAULT_METHOD, make_estimator
from ..io.files import write_simulation
from ..model.simulator import Noise, simulate
from ..online.config import OnlineConfig
from ..online.identifier import OnlineIdentifier, run_schedule
from ..online.samples import Topics, dataset_samples
from . import progress
from .efficiency import QUANTITIES, _with_derived, record_bound, summarise
from .peer_models import (
    STRUCTURE,
    ParameterUKF,
    RecursiveLeastSquares,
    fit_dual,
    fit_frols,
    frols_held_out_rmse,
    held_out_rmse,
    ukf_start,
)

ONLINE = OnlineConfig()  # the node's defaults: window, refit period, method
OURS = (DEFAULT_METHOD, "rwlssvm+oe", "rwlssvm")
INPUT_RATE_HZ = 10.0
RECOVERY_TOLERANCE = 0.05
# Tracking scenarios: random rudder steps throughout (persistent excitation), and seed 001's mixed
# manoeuvre, whose second half starts with a turning circle (long constant rudder, weak excitation).
TRACKING_MANEUVERS = ("random", "mixed")


def _timed(fn, *args):
    t0 = time.perf_counter()
    out = fn(*args)
    return out, time.perf_counter() - t0


def accuracy(quick: bool = False) -> dict:
    """Parameter errors over noise seeds (vs the CRB) and held-out free-run RMSE of every method."""
    seeds = range(1) if quick else range(10)
    duration = 300.0 if quick else 600.0
    noise = Noise()
    errors, rmse, seconds, bounds = {}, {}, {}, []
    truth = None
    for seed in seeds:
        progress(f"peers accuracy: seed {seed}")
        sim = simulate("mixed", "seed001", duration=duration, noise=noise, seed=100 + seed)
        train, test = sim.dataset, simulate("random", "seed001", duration=300.0, noise=noise, seed=200 + seed).dataset
        truth = _with_derived(sim.truth)
        bounds.append(record_bound(sim, noise))
        fits = {"truth": (sim.truth, 0.0)}
        for method in OURS:
            est, s = _timed(make_estimator(method).fit, STRUCTURE, train)
            fits[f"ship_ident {method}"] = (est.parameters, s)
        fits["lssvm-dual (seed)"] = _timed(fit_dual, train)
        rls, s = _timed(RecursiveLeastSquares(duration).run, train)
        fits["rls"] = (rls[0], s)
        ukf, s = _timed(ParameterUKF(1e-4).run, train, ukf_start(train))
        fits["ukf (filterpy)"] = (ukf[0], s)
        for name, (params, s) in fits.items():
            p = _with_derived(params)
            errors.setdefault(name, []).append({q: p[q] - truth[q] for q in QUANTITIES})
            rmse.setdefault(name, []).append(held_out_rmse(params, test))
            seconds.setdefault(name, []).append(s)
        model, s = _timed(fit_frols, train)
        rmse.setdefault("frols (SysIdentPy)", []).append(frols_held_out_rmse(model, test))
        seconds.setdefault("frols (SysIdentPy)", []).append(s)
    methods = {}
    for name in rmse:
        heading, yaw_rate = np.degrees(np.mean(rmse[name], axis=0))
        methods[name] = {
            "rmse_heading_deg": float(heading),
            "rmse_yaw_rate_deg_s": float(yaw_rate),
            "fit_seconds": float(np.median(seconds[name])),
            "quantities": summarise(errors[name], [], bounds, truth) if name in errors else None,
        }
    return {
        "data": {
            "vessel": "seed001",
            "effects": STRUCTURE.to_json()["effects"],
            "train": "mixed",
            "train_duration_s": duration,
            "held_out": "random",
            "held_out_duration_s": 300.0,
            "seeds": len(seeds),
            "noise": {
                "rudder_deg": float(np.degrees(noise.rudder)),
                "heading_deg": float(np.degrees(noise.heading)),
                "yaw_rate_deg_s": float(np.degrees(noise.yaw_rate)),
            },
        },
        "truth": truth,
        "methods": methods,
    }


def recovery_time(times, k_trace, change_time: float, k_new: float) -> float:
    """Seconds from the change to the first K that stays within 5 % of the new truth to the end (inf: never)."""
    times, k_trace = np.asarray(times), np.asarray(k_trace)
    after = np.flatnonzero(times > change_time)
    if not len(after):
        return float("inf")
    outside = np.flatnonzero(np.abs(k_trace[after] - k_new) > RECOVERY_TOLERANCE * k_new)
    first_settled = outside[-1] + 1 if len(outside) else 0
    if first_settled == len(after):
        return float("inf")
    return float(times[after[first_settled]] - change_time)


def online_trace(method: str, samples) -> tuple[np.ndarray, np.ndarray, dict]:
    """K in force after each record of the node's online core (the K in force until the next one:
    a scheduled refit, or a gain refit while a change is followed), and the compute: the time (s)
    of each window refit (not the gain refits after a change, a few ms each) and the share of one
    core the whole core took over the run (inputs, refits, gain refits, change watches)."""
    identifier = OnlineIdentifier(ONLINE.changed(method=method))
    times, ks, refits = [], [], []
    started = time.perf_counter()
    for record in run_schedule(identifier, samples):
        if "vessel_changed" not in record.conditions:
            refits.append(record.compute_seconds)
        if record.estimate:
            times.append(record.time)
            ks.append(record.estimate["parameters"]["K"])
    span = samples[-1].time - samples[0].time if samples else math.nan
    return np.array(times), np.array(ks), {"refit_seconds": refits, "cpu_share": (time.perf_counter() - started) / span}


def tracking(quick: bool = False, maneuver: str = "random") -> dict:
    """K -30 % and T1 +30 % at a known time; recovery time and error before the change per method."""
    change_time = 240.0 if quick else 600.0
    window = ONLINE.window_length
    sim = simulate(
        maneuver,
        "seed001",
        duration=2 * change_time,
        noise=1.0,
        seed=31,
        change=(change_time, {"K": 0.7 * 0.5883, "T1": 1.3 * 1.4397}),
    )
    data = sim.dataset
    k0, k_new = sim.truth["K"], sim.info["truth_after"]["K"]
    out = {
        "maneuver": maneuver,
        "change_time_s": change_time,
        "duration_s": 2 * change_time,
        "K_before": k0,
        "K_after": k_new,
        "T1_before": sim.truth["T1"],
        "T1_after": sim.info["truth_after"]["T1"],
        "window_s": window,
        "refit_period_s": ONLINE.refit_period,
        "methods": {},
        "compute_seconds": {},
    }

    def row(name, times, ks):
        before = (times > change_time - 120.0) & (times <= change_time)
        out["methods"][name] = {
            "recovery_s": recovery_time(times, ks, change_time, k_new),
            "error_before_percent": float(100 * np.sqrt(np.mean(((ks[before] - k0) / k0) ** 2)))
            if before.any()
            else float("nan"),
            "times": times.tolist(),
            "K": ks.tolist(),
        }

    samples = dataset_samples(data)
    for method in OURS:
        progress(f"peers tracking ({maneuver}): ship_ident {method} (online core)")
        times, ks, compute = online_trace(method, samples)
        row(f"ship_ident {method}", times, ks)
        out["compute_seconds"][method] = compute
    for memory in (window, window / 3):
        progress(f"peers tracking ({maneuver}): rls, memory {memory:.0f} s")
        _, times, ks, _ = RecursiveLeastSquares(memory).run(data, record_every=1)
        row(f"rls (memory {memory:.0f} s)", times, ks)
    start = ukf_start(data)
    for drift in (1e-4, 1e-3, 1e-2):
        progress(f"peers tracking ({maneuver}): ukf, drift {drift:g}")
        _, times, ks, _ = ParameterUKF(drift).run(data, start, record_every=1)
        row(f"ukf (drift {drift:g}/sample)", times, ks)
    return out


def speed_and_scaling(compute_seconds: dict, quick: bool = False) -> dict:
    """Time per refit or sample and CPU share at 10 Hz; refit time against window; replay throughput."""
    window_samples = int(ONLINE.window_length * INPUT_RATE_HZ)
    period = ONLINE.refit_period
    data = simulate("mixed", "seed001", duration=window_samples / INPUT_RATE_HZ, noise=1.0, seed=41).dataset
    cost = {}
    for method, compute in compute_seconds.items():
        cost[f"ship_ident {method}"] = {
            "seconds": float(np.median(compute["refit_seconds"])),
            "per": "refit (online)",
            "cpu_share": compute["cpu_share"],
        }
    for name, fit in (("frols (SysIdentPy)", fit_frols), ("lssvm-dual (seed)", fit_dual)):
        fit(data)
        _, s = _timed(fit, data)
        cost[name] = {"seconds": s, "per": "refit (window)", "cpu_share": s / period}
    _, _, _, s = RecursiveLeastSquares(ONLINE.window_length).run(data)
    cost["rls"] = {"seconds": s, "per": "sample", "cpu_share": s * INPUT_RATE_HZ}
    _, _, _, s = ParameterUKF().run(data, ukf_start(data))
    cost["ukf (filterpy)"] = {"seconds": s, "per": "sample", "cpu_share": s * INPUT_RATE_HZ}

    sizes = (1_000, 10_000) if quick else (1_000, 10_000, 100_000)
    long = simulate("mixed", "seed001", duration=max(sizes) / INPUT_RATE_HZ, noise=1.0, seed=42).dataset
    scaling = {}
    for method in OURS:
        estimator = make_estimator(method)
        estimator.fit(STRUCTURE, long.slice(0, 1000))  # compile and warm up
        for n in sizes:
            progress(f"peers scaling: {method} on {n} samples")
            _, scaling.setdefault(method, {})[str(n)] = _timed(estimator.fit, STRUCTURE, long.slice(0, n))
    return {
        "window_samples": window_samples,
        "refit_period_s": period,
        "input_rate_hz": INPUT_RATE_HZ,
        "cost": cost,
        "refit_seconds": scaling,
        "replay": replay_throughput(300.0 if quick else 3600.0),
    }


def replay_throughput(duration: float) -> dict:
    """Replay a simulated bag of ``duration`` s with the node's default configuration (fleet's per-bag task)."""
    from ..io.fleet import BagJob, identify_bag

    progress(f"peers replay: simulating and writing a {duration:.0f} s bag")
    sim = simulate("mixed", "seed001", duration=duration, noise=1.0, seed=43)
    with tempfile.TemporaryDirectory() as tmp:
        bag = str(Path(tmp) / "trip.mcap")
        write_simulation(sim, bag, "mcap")
        progress("peers replay: replaying")
        result = identify_bag(BagJob(bag, "sim", Topics(), ONLINE))
    return {
        "bag_seconds": result.bag_seconds,
        "read_seconds": result.read_seconds,
        "loop_seconds": result.loop_seconds,
        "estimates": len(result.rows),
        "refits": result.refits,
        "speed_loop": result.bag_seconds / result.loop_seconds,
        "speed_total": result.bag_seconds / (result.loop_seconds + result.read_seconds),
    }
