"""``peers``: ship_ident against the online identifiers a user would otherwise pick, on the same data.

Peers (real libraries where one exists, not re-implementations):

* ``rls``: recursive least squares with exponential forgetting on the very
  same equation-error regression as ours (unit-scaled columns, P0 = 1e4 I);
  forgetting factor 1 - h/M for a memory of M seconds.
* ``ukf``: filterpy's ``UnscentedKalmanFilter`` on (psi, r, z, K, T1, T2,
  T3, delta_r, alpha) with random-walk parameters (per-sample std = drift x
  |parameter|), heading and yaw rate measured with their estimated noise,
  started from an OLS fit of the first 60 s.
* ``frols``: SysIdentPy's FROLS polynomial NARX model (yaw rate from rudder,
  lags 2, degree 3, information-criterion order), run free on held-out data
  (heading integrated); a black box without physical parameters.
* ``lssvm-dual``: the seed's plain LS-SVM solved in the N x N dual with
  bias (rows thinned to 3000: the dual is O(N^3)).
* ours: ``rwlssvm+pem`` (the node's default), ``rwlssvm+oe`` and ``rwlssvm``.

Accuracy: seed 001's vessel (nomoto2 + rudder offset + cubic yaw), mixed
manoeuvre, realistic sensor noise (``simulator.Noise()``), several noise
seeds; per parameter the RMS error over the seeds and its ratio to the
Cramer-Rao bound of the record (``crb.py``); free-run heading and yaw-rate
RMSE on a held-out random manoeuvre (``truth`` row: the true parameters, the
floor set by the noise). Every method sees the whole training record (RLS
with a memory of the record length, the UKF with drift 1e-4).

Tracking: K drops 30 % and T1 rises 30 % at a known time, in two scenarios
(``TRACKING_MANEUVERS``: random rudder steps throughout, and the mixed
manoeuvre, whose second half opens with a weakly exciting turning circle);
ours run through
``OnlineIdentifier`` with the node's default configuration (window W =
180 s, refit every 5 s); RLS and the UKF run sample by sample with a small
grid of memories and drifts, every setting reported. Recovery: seconds from
the change until K stays within 5 % of the new truth to the end of the run.

Speed: time per refit (ours: the online refit, warm-started, as on board;
FROLS and the dual: a fit of one window) or per sample (RLS, UKF), and the
CPU share of one core each needs at 10 Hz with the 5 s refit period.
Scaling: refit time of ours for 1k, 10k and 100k samples; replay throughput
of a 1-hour simulated bag (``fleet.identify_bag``, the replay loop).
"""
from __future__ import annotations

import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from ..estimators import DEFAULT_METHOD, make_estimator
from ..estimators.lssvm import lssvm_dual_with_bias
from ..integrate import advance, initial_z
from ..io import Sample, Topics, write_simulation
from ..online import OnlineConfig, OnlineIdentifier, run_schedule
from ..signals import compute_signals, noise_level
from ..simulator import Noise, simulate
from ..structure import Structure
from . import progress, register
from .common import table
from .efficiency import QUANTITIES, _with_derived, record_bound, summarise

STRUCTURE = Structure("nomoto2", ["rudder_offset", "cubic_yaw"])
PARAMETERS = STRUCTURE.parameter_names
ONLINE = OnlineConfig()                 # the node's defaults: window, refit period, method
OURS = (DEFAULT_METHOD, "rwlssvm+oe", "rwlssvm")
UKF_START_S = 60.0                      # s of data behind the UKF's initial OLS fit
DUAL_MAX_ROWS = 3000
INPUT_RATE_HZ = 10.0
RECOVERY_TOLERANCE = 0.05
TARGET_CRB_RATIO = 1.3
TARGET_CPU_SHARE = 0.10
TARGET_REPLAY_SPEED = 100.0
# Tracking scenarios: random rudder steps throughout (persistent excitation), and seed 001's mixed
# manoeuvre, whose second half starts with a turning circle (long constant rudder, weak excitation).
TRACKING_MANEUVERS = ("random", "mixed")


def _regression(dataset):
    return STRUCTURE.regression(compute_signals(dataset))


class RecursiveLeastSquares:
    """RLS with forgetting 1 - h/memory on unit-scaled regression columns."""

    def __init__(self, memory_s: float):
        self.memory_s = memory_s

    def run(self, dataset, record_every: int = 10):
        """Final parameters, K every ``record_every`` rows (times, values), seconds per sample."""
        reg = _regression(dataset)
        scale = np.sqrt(np.mean(reg.X ** 2, axis=0))
        X, y = reg.X / scale, reg.y
        k_column = reg.columns.index("delta")
        forgetting = 1.0 - dataset.sample_time / self.memory_s
        w = np.zeros(X.shape[1])
        P = np.eye(X.shape[1]) * 1e4
        times = reg.signals.time[reg.signals.rows]
        trace_t, trace_k = [], []
        start = time.perf_counter()
        for i in range(len(y)):
            x = X[i]
            Px = P @ x
            gain = Px / (forgetting + x @ Px)
            w = w + gain * (y[i] - x @ w)
            P = (P - np.outer(gain, Px)) / forgetting
            if i % record_every == 0:
                trace_t.append(times[i])
                trace_k.append(w[k_column] / scale[k_column])
        per_sample = (time.perf_counter() - start) / len(y)
        params, _ = STRUCTURE.parameters_from_coefficients(w / scale, reg)
        return STRUCTURE.clip_to_bounds(params), np.array(trace_t), np.array(trace_k), per_sample


class ParameterUKF:
    """filterpy UKF with the parameters in the state (random walk of relative std ``drift`` per sample)."""

    PARAMETER_FLOOR = np.array([0.05, 0.1, 0.02, 0.02, 0.005, 0.05])  # scale of a parameter near 0

    def __init__(self, drift: float = 1e-4):
        self.drift = drift

    def run(self, dataset, start: dict, record_every: int = 10):
        """Final parameters, K every ``record_every`` samples (times, values), seconds per sample."""
        from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

        one = np.ones(1)
        cubic = np.array([3]), np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64)

        def fx(x, dt, d0=0.0, d1=0.0):
            K, T1, T2, T3 = max(x[3], 1e-3), max(x[4], 1e-2), max(x[5], 1e-3), max(x[6], 0.0)
            out = x.copy()
            out[:3] = advance(2, dt, d0 + x[7], d1 + x[7], K, T1, T2, T3, x[0], x[1], x[2],
                              -x[8] * one, *cubic, 2)
            return out

        def hx(x):
            return x[:2]

        ukf = UnscentedKalmanFilter(dim_x=9, dim_z=2, dt=dataset.sample_time, fx=fx, hx=hx,
                                    points=MerweScaledSigmaPoints(9, alpha=1e-3, beta=2.0, kappa=0.0))
        p0 = np.array([start[n] for n in PARAMETERS])
        scale = np.maximum(np.abs(p0), self.PARAMETER_FLOOR)
        ukf.x = np.concatenate([[dataset.heading[0], dataset.yaw_rate[0],
                                 initial_z(p0[0], p0[1], p0[2], p0[3], dataset.yaw_rate[0], 0.0,
                                           dataset.rudder[0])], p0])
        ukf.P = np.diag(np.concatenate([[1e-4, 1e-4, 1e-3], (0.2 * scale) ** 2]))
        ukf.R = np.diag([noise_level(dataset.heading, np.radians(0.01)) ** 2,
                         noise_level(dataset.yaw_rate, np.radians(0.01)) ** 2])
        ukf.Q = np.diag(np.concatenate([[1e-8, 1e-7, 1e-7], (self.drift * scale) ** 2]))
        trace_t, trace_k = [], []
        start_clock = time.perf_counter()
        for k in range(1, dataset.n_samples):
            ukf.predict(d0=dataset.rudder[k - 1], d1=dataset.rudder[k])
            ukf.update(np.array([dataset.heading[k], dataset.yaw_rate[k]]))
            if k % record_every == 0:
                trace_t.append(dataset.time[k])
                trace_k.append(ukf.x[3])
        per_sample = (time.perf_counter() - start_clock) / (dataset.n_samples - 1)
        params = STRUCTURE.clip_to_bounds(dict(zip(PARAMETERS, map(float, ukf.x[3:]))))
        return params, np.array(trace_t), np.array(trace_k), per_sample


def ukf_start(dataset) -> dict:
    return make_estimator("ols").fit(STRUCTURE, dataset.slice(0, int(UKF_START_S / dataset.sample_time))).parameters


def fit_dual(dataset) -> dict:
    """The seed's plain LS-SVM in the dual (rows thinned to DUAL_MAX_ROWS)."""
    reg = _regression(dataset)
    step = max(1, -(-len(reg.y) // DUAL_MAX_ROWS))
    w, _, _ = lssvm_dual_with_bias(reg.X[::step], reg.y[::step], 1e4)
    params, _ = STRUCTURE.parameters_from_coefficients(w, reg)
    return STRUCTURE.clip_to_bounds(params)


def fit_frols(dataset):
    """SysIdentPy FROLS NARX model of yaw rate from rudder."""
    from sysidentpy.basis_function import Polynomial
    from sysidentpy.model_structure_selection import FROLS

    model = FROLS(order_selection=True, n_info_values=12, ylag=2, xlag=2, basis_function=Polynomial(degree=3))
    model.fit(X=dataset.rudder[:, None], y=dataset.yaw_rate[:, None])
    return model


def frols_held_out_rmse(model, test) -> tuple[float, float]:
    """Free-run heading (integrated) and yaw-rate RMSE (rad, rad/s) of a FROLS model."""
    r = model.predict(X=test.rudder[:, None], y=test.yaw_rate[:2, None])[:, 0]
    psi = test.heading[0] + np.concatenate([[0.0], np.cumsum((r[1:] + r[:-1]) / 2 * test.sample_time)])
    return float(np.sqrt(np.mean((psi - test.heading) ** 2))), float(np.sqrt(np.mean((r - test.yaw_rate) ** 2)))


def held_out_rmse(params: dict, test) -> tuple[float, float]:
    """Free-run heading and yaw-rate RMSE (rad, rad/s) from the measured initial state."""
    psi, r = STRUCTURE.simulate(params, test)
    return float(np.sqrt(np.mean((psi - test.heading) ** 2))), float(np.sqrt(np.mean((r - test.yaw_rate) ** 2)))


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
        methods[name] = {"rmse_heading_deg": float(heading), "rmse_yaw_rate_deg_s": float(yaw_rate),
                         "fit_seconds": float(np.median(seconds[name])),
                         "quantities": summarise(errors[name], [], bounds, truth) if name in errors else None}
    return {"data": {"vessel": "seed001", "effects": STRUCTURE.to_json()["effects"], "train": "mixed",
                     "train_duration_s": duration, "held_out": "random", "held_out_duration_s": 300.0,
                     "seeds": len(seeds), "noise": {"rudder_deg": float(np.degrees(noise.rudder)),
                                                    "heading_deg": float(np.degrees(noise.heading)),
                                                    "yaw_rate_deg_s": float(np.degrees(noise.yaw_rate))}},
            "truth": truth, "methods": methods}


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


def dataset_samples(dataset) -> list[Sample]:
    """The dataset as time-ordered input samples (heading wrapped, as a compass gives it)."""
    heading = dataset.meta.get("wrapped_heading", dataset.heading)
    return [Sample(float(t), role, float(v)) for i, t in enumerate(dataset.time)
            for role, v in (("rudder", dataset.rudder[i]), ("heading", heading[i]), ("yaw_rate", dataset.yaw_rate[i]))]


def online_trace(method: str, samples) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """K in force after each refit of the node's online core, and each refit's compute time (s)."""
    identifier = OnlineIdentifier(ONLINE.changed(method=method))
    times, ks, compute = [], [], []
    for record in run_schedule(identifier, samples):
        compute.append(record.compute_seconds)
        if record.estimate:
            times.append(record.time)
            ks.append(record.estimate["parameters"]["K"])
    return np.array(times), np.array(ks), compute


def tracking(quick: bool = False, maneuver: str = "random") -> dict:
    """K -30 % and T1 +30 % at a known time; recovery time and error before the change per method."""
    change_time = 240.0 if quick else 600.0
    window = ONLINE.window_length
    sim = simulate(maneuver, "seed001", duration=2 * change_time, noise=1.0, seed=31,
                   change=(change_time, {"K": 0.7 * 0.5883, "T1": 1.3 * 1.4397}))
    data = sim.dataset
    k0, k_new = sim.truth["K"], sim.info["truth_after"]["K"]
    out = {"maneuver": maneuver, "change_time_s": change_time, "duration_s": 2 * change_time,
           "K_before": k0, "K_after": k_new, "T1_before": sim.truth["T1"], "T1_after": sim.info["truth_after"]["T1"],
           "window_s": window, "refit_period_s": ONLINE.refit_period, "methods": {}, "compute_seconds": {}}

    def row(name, times, ks):
        before = (times > change_time - 120.0) & (times <= change_time)
        out["methods"][name] = {
            "recovery_s": recovery_time(times, ks, change_time, k_new),
            "error_before_percent": float(100 * np.sqrt(np.mean(((ks[before] - k0) / k0) ** 2))) if before.any()
            else float("nan"),
            "times": times.tolist(), "K": ks.tolist()}

    samples = dataset_samples(data)
    for method in OURS:
        progress(f"peers tracking ({maneuver}): ship_ident {method} (online core)")
        times, ks, compute = online_trace(method, samples)
        row(f"ship_ident {method}", times, ks)
        out["compute_seconds"][method] = compute
    for memory in (window, window / 3):
        progress(f"peers tracking ({maneuver}): rls, memory {memory:.0f} s")
        _, times, ks, _ = RecursiveLeastSquares(memory).run(data)
        row(f"rls (memory {memory:.0f} s)", times, ks)
    start = ukf_start(data)
    for drift in (1e-4, 1e-3, 1e-2):
        progress(f"peers tracking ({maneuver}): ukf, drift {drift:g}")
        _, times, ks, _ = ParameterUKF(drift).run(data, start)
        row(f"ukf (drift {drift:g}/sample)", times, ks)
    return out


def speed_and_scaling(compute_seconds: dict, quick: bool = False) -> dict:
    """Time per refit or sample and CPU share at 10 Hz; refit time against window; replay throughput."""
    window_samples = int(ONLINE.window_length * INPUT_RATE_HZ)
    period = ONLINE.refit_period
    data = simulate("mixed", "seed001", duration=window_samples / INPUT_RATE_HZ, noise=1.0, seed=41).dataset
    cost = {}
    for method, compute in compute_seconds.items():
        cost[f"ship_ident {method}"] = {"seconds": float(np.median(compute)), "per": "refit (online)",
                                        "cpu_share": float(np.mean(compute)) / period}
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
    return {"window_samples": window_samples, "refit_period_s": period, "input_rate_hz": INPUT_RATE_HZ,
            "cost": cost, "refit_seconds": scaling, "replay": replay_throughput(300.0 if quick else 3600.0)}


def replay_throughput(duration: float) -> dict:
    """Replay a simulated bag of ``duration`` s with the node's default configuration (fleet's per-bag task)."""
    from ..fleet import BagJob, identify_bag

    progress(f"peers replay: simulating and writing a {duration:.0f} s bag")
    sim = simulate("mixed", "seed001", duration=duration, noise=1.0, seed=43)
    with tempfile.TemporaryDirectory() as tmp:
        bag = str(Path(tmp) / "trip.mcap")
        write_simulation(sim, bag, "mcap")
        progress("peers replay: replaying")
        result = identify_bag(BagJob(bag, "sim", Topics(), ONLINE))
    return {"bag_seconds": result.bag_seconds, "read_seconds": result.read_seconds,
            "loop_seconds": result.loop_seconds, "estimates": len(result.rows), "refits": result.refits,
            "speed_loop": result.bag_seconds / result.loop_seconds,
            "speed_total": result.bag_seconds / (result.loop_seconds + result.read_seconds)}


def run(quick: bool = False, plot_dir: str | None = None) -> dict:
    scenarios = {maneuver: tracking(quick, maneuver) for maneuver in TRACKING_MANEUVERS}
    result = {"machine": {"cpus": os.cpu_count(), "processor": platform.processor() or platform.machine(),
                          "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "unset")},
              "online_config": {"method": ONLINE.method, "window_s": ONLINE.window_length,
                                "refit_period_s": ONLINE.refit_period},
              "accuracy": accuracy(quick), "tracking": scenarios,
              "speed": speed_and_scaling(scenarios[TRACKING_MANEUVERS[0]]["compute_seconds"], quick)}
    for scenario in scenarios.values():
        del scenario["compute_seconds"]
    if plot_dir:
        result["plots"] = plot(result, plot_dir)
    return result


def plot(result: dict, plot_dir: str) -> list[str]:
    """peers_tracking.png (K against time per method, truth step) and peers_accuracy.png (bars)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    Path(plot_dir).mkdir(parents=True, exist_ok=True)
    scenarios = result["tracking"]
    fig, axes = plt.subplots(len(scenarios), 1, figsize=(9, 4.2 * len(scenarios)), squeeze=False)
    for ax, track in zip(axes[:, 0], scenarios.values()):
        change = track["change_time_s"]
        ax.step([0, change, track["duration_s"]], [track["K_before"], track["K_after"], track["K_after"]],
                where="post", color="k", lw=2, label="truth")
        ax.fill_between([change, track["duration_s"]], track["K_after"] * (1 - RECOVERY_TOLERANCE),
                        track["K_after"] * (1 + RECOVERY_TOLERANCE), color="0.85", label="new truth +-5 %")
        for name, m in track["methods"].items():
            ax.plot(m["times"], m["K"], lw=2.2 if name.startswith("ship_ident") else 1.0,
                    label=f"{name}: {_seconds(m['recovery_s'])}")
        ax.set_ylim(0.5 * track["K_after"], 1.4 * track["K_before"])
        ax.set_xlabel("time (s)")
        ax.set_ylabel("K (1/s)")
        ax.set_title(f"{track['maneuver']} manoeuvre: K -30 %, T1 +30 % at {change:.0f} s; ours: window "
                     f"{track['window_s']:.0f} s, refit every {track['refit_period_s']:.0f} s "
                     "(legend: recovery time)", fontsize=9)
        ax.legend(fontsize=7, loc="upper right")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    paths = [str(Path(plot_dir) / "peers_tracking.png")]
    fig.savefig(paths[0], dpi=100)
    plt.close(fig)

    methods = {n: m for n, m in result["accuracy"]["methods"].items()}
    names = list(methods)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    ax1.barh(names, [methods[n]["rmse_heading_deg"] for n in names], color="tab:blue")
    ax1.set_xscale("log")
    ax1.set_xlabel("held-out free-run heading RMSE (deg, log scale)")
    ax1.invert_yaxis()
    shown = [n for n in names if methods[n]["quantities"] and n != "truth"]
    quantities = ("K", "T1", "delta_r", "T1+T2-T3")
    width = 0.8 / len(shown)
    for i, name in enumerate(shown):
        values = [methods[name]["quantities"][q]["rms_percent"] for q in quantities]
        ax2.bar(np.arange(len(quantities)) + i * width, values, width, label=name)
    ax2.set_xticks(np.arange(len(quantities)) + 0.4 - width / 2, quantities)
    ax2.set_yscale("log")
    ax2.set_ylabel("RMS error over seeds (%)")
    ax2.legend(fontsize=7)
    fig.tight_layout()
    paths.append(str(Path(plot_dir) / "peers_accuracy.png"))
    fig.savefig(paths[1], dpi=100)
    plt.close(fig)
    return paths


def _seconds(value: float) -> str:
    return f"{value:.0f} s" if np.isfinite(value) else "never"


def _best(values: dict) -> str:
    """The key of the smallest finite value."""
    finite = {k: v for k, v in values.items() if np.isfinite(v)}
    return min(finite, key=finite.get)


OURS_LABEL = f"ship_ident {OURS[0]}"
ACCURACY_COLUMNS = ("K", "T1", "T2", "T3", "delta_r", "alpha", "T1+T2-T3")
CRB_COLUMNS = ("K", "T1", "delta_r", "T1+T2-T3")


def _better_than_ours(figures: dict, ours: dict) -> str:
    """The names of the figures (smaller is better) where a peer beats ours."""
    return ", ".join(k for k, v in figures.items() if v < ours[k]) or "-"


def _render_accuracy(acc: dict) -> list[str]:
    d, methods = acc["data"], acc["methods"]

    def figures(v):
        out = {"heading RMSE": v["rmse_heading_deg"]}
        out.update({q: v["quantities"][q]["rms_percent"] for q in ACCURACY_COLUMNS} if v["quantities"] else {})
        return out

    ours = figures(methods[OURS_LABEL])
    best = _best({n: v["rmse_heading_deg"] for n, v in methods.items() if n != "truth"})
    rows = []
    for name, v in methods.items():
        q = v["quantities"]
        peer = name not in ("truth", OURS_LABEL)
        rows.append([name + (" (best)" if name == best else ""), v["rmse_heading_deg"], v["rmse_yaw_rate_deg_s"]]
                    + [q[p]["rms_percent"] if q else "-" for p in ACCURACY_COLUMNS] + [v["fit_seconds"]]
                    + [_better_than_ours(figures(v), ours) if peer else ""])
    noise = d["noise"]
    title = (f"accuracy: seed001 vessel + {', '.join(d['effects'])}, {d['train']} {d['train_duration_s']:.0f} s "
             f"training, {d['held_out']} {d['held_out_duration_s']:.0f} s held out, {d['seeds']} noise seeds, noise "
             f"std rudder {noise['rudder_deg']:.2g} deg, heading {noise['heading_deg']:.2g} deg, yaw rate "
             f"{noise['yaw_rate_deg_s']:.2g} deg/s; parameter columns: RMS error over seeds; RMSE: mean over "
             "seeds, free run from the measured initial state")
    out = [table(["method", "held-out heading RMSE deg", "yaw rate RMSE deg/s"] + [f"{p} %" for p in ACCURACY_COLUMNS]
                 + ["fit s", f"better than {OURS_LABEL} on"], rows, title)]
    rows = []
    for name, v in methods.items():
        if v["quantities"] and name != "truth":
            ratios = {p: v["quantities"][p]["rms_over_crb"] for p in CRB_COLUMNS}
            beyond = [p for p in ("K", "T1", "delta_r") if ratios[p] > TARGET_CRB_RATIO]
            rows.append([name] + list(ratios.values()) + [", ".join(beyond) or "all within"])
    crb = methods["truth"]["quantities"]
    title = "ratio to the Cramer-Rao bound (CRB % of truth: " + ", ".join(
        f"{p} {crb[p]['crb_percent']:.3g}" for p in CRB_COLUMNS) + ")"
    out.append(table(["method"] + [f"{p} RMS/CRB" for p in CRB_COLUMNS] + [f"beyond {TARGET_CRB_RATIO}x CRB"],
                     rows, title))
    return out


def _render_tracking(track: dict) -> str:
    ours = track["methods"][OURS_LABEL]
    ours = {"recovery": ours["recovery_s"], "error before": ours["error_before_percent"]}
    rows = [[name, _seconds(v["recovery_s"]), v["error_before_percent"],
             _better_than_ours({"recovery": v["recovery_s"], "error before": v["error_before_percent"]}, ours)
             if not name.startswith("ship_ident") else ""]
            for name, v in track["methods"].items()]
    title = (f"tracking, {track['maneuver']} manoeuvre: K {track['K_before']:.4g} -> {track['K_after']:.4g} 1/s, "
             f"T1 {track['T1_before']:.4g} -> {track['T1_after']:.4g} s at {track['change_time_s']:.0f} s of "
             f"{track['duration_s']:.0f} s; target for ours: < window + refit period = "
             f"{track['window_s'] + track['refit_period_s']:.0f} s; error before: the last 120 s")
    return table(["method", "K back within 5 %", "K RMS error before change %", f"better than {OURS_LABEL} on"],
                 rows, title)


def _render_speed(speed: dict) -> list[str]:
    ours = speed["cost"][OURS_LABEL]["cpu_share"]
    rows = [[name, 1e3 * v["seconds"], v["per"], 100 * v["cpu_share"],
             ("yes" if v["cpu_share"] < ours else "-") if not name.startswith("ship_ident") else ""]
            for name, v in speed["cost"].items()]
    out = [table(["method", "ms", "per", "CPU % of one core at 10 Hz", f"cheaper than {OURS_LABEL}"], rows,
                 f"speed: window {speed['window_samples']} samples, refit every {speed['refit_period_s']:.0f} s, "
                 f"inputs at {speed['input_rate_hz']:.0f} Hz (target for ours: < {100 * TARGET_CPU_SHARE:.0f} %)")]
    sizes = list(next(iter(speed["refit_seconds"].values())))
    steps = list(zip(sizes, sizes[1:]))
    rows = [[method] + [1e3 * t[n] for n in sizes]
            + [1e3 * (t[b] - t[a]) / ((int(b) - int(a)) / 1000) for a, b in steps]
            for method, t in speed["refit_seconds"].items()]
    out.append(table(["method"] + [f"{n} samples ms" for n in sizes] + [f"ms per extra 1k, {a}->{b}" for a, b in steps],
                     rows, "scaling: one cold refit (Estimator.fit) against window length; linear growth = the same "
                     "ms per extra 1k samples at every step (the 1k figure also holds the fixed cost)"))
    r = speed["replay"]
    out.append(f"replay of a {r['bag_seconds'] / 60:.0f} min simulated bag (node defaults): "
               f"{r['speed_loop']:.0f}x real time for the loop ({r['loop_seconds']:.1f} s), "
               f"{r['speed_total']:.0f}x with reading the bag ({r['read_seconds']:.1f} s); "
               f"{r['estimates']} accepted estimates from {r['refits']} refits "
               f"(target >= {TARGET_REPLAY_SPEED:.0f}x)")
    return out


def render(result: dict) -> str:
    m, online = result["machine"], result["online_config"]
    out = [f"peers: {m['cpus']} CPUs ({m['processor']}), OPENBLAS_NUM_THREADS={m['OPENBLAS_NUM_THREADS']}; "
           f"ours online: {online['method']}, window {online['window_s']:.0f} s, "
           f"refit every {online['refit_period_s']:.0f} s"]
    out += _render_accuracy(result["accuracy"])
    out += [_render_tracking(track) for track in result["tracking"].values()]
    out += _render_speed(result["speed"])
    return "\n\n".join(out)


register("peers", "ship_ident against RLS, filterpy UKF, SysIdentPy FROLS and the dual LS-SVM: "
         "accuracy, tracking, speed, scaling", run, render, plots=True)
