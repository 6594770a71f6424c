"""ship_ident against the alternatives a user would otherwise pick, on the same data.

Peers (real libraries, not re-implementations, where one exists):

* ``rls``: recursive least squares with exponential forgetting on the very
  same equation-error regression as ours; forgetting factor 1 - h/W, so its
  memory equals our window W.
* ``ukf``: filterpy's UnscentedKalmanFilter with the Nomoto parameters in the
  state (random-walk parameters), heading and yaw rate measured, started
  from a batch least-squares fit of the first 60 s.
* ``frols``: SysIdentPy's FROLS polynomial NARX model (yaw rate from rudder),
  free-run simulated; a black box with no physical parameters.
* ``lssvm-dual``: the seed's plain LS-SVM, solved in the N x N dual.
* ours: ``rwlssvm`` and ``rwlssvm+oe`` on a sliding window.

Accuracy: error per parameter on a training run and the free-run heading
RMSE on a held-out run. Tracking: K drops 30 % and T1 rises 30 % mid-run;
time until each method's K is within 5 % of the new truth. Speed: time per
refit or per sample and the CPU share at 10 Hz. Scaling: refit time against
window length.
"""
from __future__ import annotations

import time

import numpy as np

from ..estimators import make_estimator
from ..estimators.lssvm import lssvm_dual_with_bias
from ..integrate import advance, initial_z
from ..signals import compute_signals, noise_level
from ..simulator import simulate
from ..structure import Structure

STRUCTURE = Structure("nomoto2", ["rudder_offset", "cubic_yaw"])
PARAMETERS = STRUCTURE.parameter_names
WINDOW_S = 300.0
REFIT_PERIOD_S = 10.0


def _regression(dataset):
    return STRUCTURE.regression(compute_signals(dataset))


class RecursiveLeastSquares:
    """RLS with forgetting on unit-scaled regression columns; ``K_trace`` holds K after each row."""

    def __init__(self, forgetting: float):
        self.forgetting = forgetting

    def run(self, dataset, record_every: int = 10):
        reg = _regression(dataset)
        scale = np.sqrt(np.mean(reg.X ** 2, axis=0))
        X, y = reg.X / scale, reg.y
        p = X.shape[1]
        w = np.zeros(p)
        P = np.eye(p) * 1e4
        lam = self.forgetting
        trace_t, trace_k = [], []
        times = reg.signals.time[reg.signals.rows]
        start = time.perf_counter()
        for i in range(len(y)):
            x = X[i]
            Px = P @ x
            gain = Px / (lam + x @ Px)
            w = w + gain * (y[i] - x @ w)
            P = (P - np.outer(gain, Px)) / lam
            if i % record_every == 0:
                trace_t.append(times[i])
                trace_k.append(w[reg.columns.index("delta")] / scale[reg.columns.index("delta")])
        per_sample = (time.perf_counter() - start) / len(y)
        params, _ = STRUCTURE.parameters_from_coefficients(w / scale, reg)
        return params, np.array(trace_t), np.array(trace_k), per_sample


class ParameterUKF:
    """filterpy UKF on (psi, r, z, K, T1, T2, T3, delta_r, alpha) with random-walk parameters."""

    def __init__(self, parameter_drift: float = 1e-4):
        self.parameter_drift = parameter_drift  # relative std of the parameter random walk per sample

    def run(self, dataset, start: dict, record_every: int = 10):
        from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

        h = dataset.sample_time
        one = np.ones(1)
        powers = np.array([3]), np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64)

        def fx(x, dt, d0=0.0, d1=0.0):
            K, T1, T2, T3 = max(x[3], 1e-3), max(x[4], 1e-2), max(x[5], 1e-3), max(x[6], 0.0)
            psi, r, z = advance(2, dt, d0 + x[7], d1 + x[7], K, T1, T2, T3, x[0], x[1], x[2],
                                -x[8] * one, *powers, 2)
            out = x.copy()
            out[:3] = psi, r, z
            return out

        def hx(x):
            return x[:2]

        points = MerweScaledSigmaPoints(9, alpha=1e-3, beta=2.0, kappa=0.0)
        ukf = UnscentedKalmanFilter(dim_x=9, dim_z=2, dt=h, fx=fx, hx=hx, points=points)
        p0 = np.array([start[n] for n in PARAMETERS])
        ukf.x = np.concatenate([[dataset.heading[0], dataset.yaw_rate[0],
                                 initial_z(p0[0], p0[1], p0[2], p0[3], dataset.yaw_rate[0], 0.0,
                                           dataset.rudder[0])], p0])
        spread = np.maximum(np.abs(p0) * 0.2, [0.05, 0.1, 0.02, 0.02, 0.005, 0.05])
        ukf.P = np.diag(np.concatenate([[1e-4, 1e-4, 1e-3], spread ** 2]))
        s_psi = noise_level(dataset.heading, np.radians(0.01))
        s_r = noise_level(dataset.yaw_rate, np.radians(0.01))
        ukf.R = np.diag([s_psi ** 2, s_r ** 2])
        drift = self.parameter_drift * np.maximum(np.abs(p0), [0.05, 0.1, 0.02, 0.02, 0.005, 0.05])
        ukf.Q = np.diag(np.concatenate([[1e-8, 1e-7, 1e-7], drift ** 2]))
        trace_t, trace_k = [], []
        start_clock = time.perf_counter()
        n = dataset.n_samples
        for k in range(1, n):
            ukf.predict(d0=dataset.rudder[k - 1], d1=dataset.rudder[k])
            ukf.update(np.array([dataset.heading[k], dataset.yaw_rate[k]]))
            if k % record_every == 0:
                trace_t.append(dataset.time[k])
                trace_k.append(ukf.x[3])
        per_sample = (time.perf_counter() - start_clock) / (n - 1)
        return dict(zip(PARAMETERS, ukf.x[3:])), np.array(trace_t), np.array(trace_k), per_sample


def frols_free_run(train, test):
    """SysIdentPy FROLS NARX (yaw rate from rudder), free-run on the test run; heading integrated."""
    from sysidentpy.basis_function import Polynomial
    from sysidentpy.model_structure_selection import FROLS

    model = FROLS(order_selection=True, n_info_values=12, ylag=2, xlag=2,
                  basis_function=Polynomial(degree=3))
    start = time.perf_counter()
    model.fit(X=train.rudder[:, None], y=train.yaw_rate[:, None])
    fit_time = time.perf_counter() - start
    r = model.predict(X=test.rudder[:, None], y=test.yaw_rate[:2, None])[:, 0]
    h = test.sample_time
    psi = test.heading[0] + np.concatenate([[0.0], np.cumsum((r[1:] + r[:-1]) / 2 * h)])
    return psi, r, fit_time


def _held_out_rmse(params, test):
    psi, r = STRUCTURE.simulate(params, test)
    return float(np.sqrt(np.nanmean((psi - test.heading) ** 2))), float(np.sqrt(np.nanmean((r - test.yaw_rate) ** 2)))


def _errors(params, truth):
    return {n: float(100 * (params[n] - truth[n]) / truth[n]) for n in PARAMETERS}


def accuracy(quick: bool = False, progress=print) -> dict:
    """Parameter errors and held-out free-run RMSE of every method on the same data."""
    duration = 300.0 if quick else 600.0
    train = simulate("mixed", "seed001", duration=duration, noise=1.0, seed=21)
    test = simulate("random", "seed001", duration=300.0, noise=1.0, seed=22).dataset
    truth = train.truth
    rows = {}
    for method in ("rwlssvm+oe", "rwlssvm"):
        progress(f"accuracy: {method}")
        t0 = time.perf_counter()
        est = make_estimator(method).fit(STRUCTURE, train.dataset)
        rows[f"ship_ident {method}"] = {"parameters": est.parameters, "seconds": time.perf_counter() - t0,
                                        "std_errors": est.std_errors}
    progress("accuracy: lssvm-dual")
    reg = _regression(train.dataset)
    step = max(1, len(reg.y) // 3000)  # the N x N dual; beyond 3000 rows it is thinned
    t0 = time.perf_counter()
    w, _, _ = lssvm_dual_with_bias(reg.X[::step], reg.y[::step], 1e4)
    params, _ = STRUCTURE.parameters_from_coefficients(w, reg)
    rows["lssvm-dual (seed)"] = {"parameters": STRUCTURE.clip_to_bounds(params), "seconds": time.perf_counter() - t0}
    progress("accuracy: rls")
    forgetting = 1 - train.dataset.sample_time / WINDOW_S
    params, _, _, per_sample = RecursiveLeastSquares(forgetting).run(train.dataset)
    rows["rls (forgetting)"] = {"parameters": STRUCTURE.clip_to_bounds(params), "seconds_per_sample": per_sample}
    progress("accuracy: ukf")
    first = train.dataset.slice(0, int(60 / train.dataset.sample_time))
    start = make_estimator("ols").fit(STRUCTURE, first).parameters
    params, _, _, per_sample = ParameterUKF().run(train.dataset, start)
    rows["ukf (filterpy)"] = {"parameters": STRUCTURE.clip_to_bounds(params), "seconds_per_sample": per_sample}
    for row in rows.values():
        row["errors_percent"] = _errors(row["parameters"], truth)
        row["rmse_heading_deg"], row["rmse_yaw_rate_deg_s"] = map(np.degrees, _held_out_rmse(row["parameters"], test))
    progress("accuracy: frols")
    psi, r, seconds = frols_free_run(train.dataset, test)
    rows["frols (SysIdentPy)"] = {"parameters": None, "errors_percent": None, "seconds": seconds,
                                  "rmse_heading_deg": float(np.degrees(np.sqrt(np.nanmean((psi - test.heading) ** 2)))),
                                  "rmse_yaw_rate_deg_s": float(np.degrees(np.sqrt(np.nanmean((r - test.yaw_rate) ** 2))))}
    return {"truth": truth, "train": {"maneuver": "mixed", "duration_s": duration},
            "held_out": {"maneuver": "random", "duration_s": 300.0}, "methods": rows}


def _recovery_time(times, k_trace, change_time, k_new, tolerance=0.05):
    """Seconds after the change until K stays within tolerance of the new truth (inf if never)."""
    after = times > change_time
    inside = np.abs(k_trace - k_new) <= tolerance * k_new
    bad = np.flatnonzero(after & ~inside)
    if len(bad) and bad[-1] == len(times) - 1:
        return float("inf")
    last_bad = times[bad[-1]] if len(bad) else change_time
    return float(last_bad - change_time)


def tracking(quick: bool = False, progress=print) -> dict:
    """K drops 30 % and T1 rises 30 % at a known time; recovery time per method."""
    change_time = 600.0 if not quick else 400.0
    total = 2 * change_time
    k0, t10 = 0.5883, 1.4397
    sim = simulate("mixed", "seed001", duration=total, noise=1.0, seed=31,
                   change=(change_time, {"K": 0.7 * k0, "T1": 1.3 * t10}))
    data = sim.dataset
    k_new = 0.7 * k0
    h = data.sample_time
    out = {"change_time_s": change_time, "K_before": k0, "K_after": k_new, "window_s": WINDOW_S,
           "refit_period_s": REFIT_PERIOD_S, "methods": {}}
    for method in ("rwlssvm", "rwlssvm+oe"):
        progress(f"tracking: {method}")
        estimator = make_estimator(method)
        times, ks = [], []
        for end in np.arange(WINDOW_S, total + 1e-9, REFIT_PERIOD_S):
            a, b = int((end - WINDOW_S) / h), int(end / h)
            ks.append(estimator.fit(STRUCTURE, data.slice(a, b)).parameters["K"])
            times.append(end)
        times, ks = np.array(times), np.array(ks)
        out["methods"][f"ship_ident {method}"] = _tracking_row(times, ks, change_time, k0, k_new)
    for memory in (WINDOW_S, WINDOW_S / 3):
        progress(f"tracking: rls, memory {memory:.0f} s")
        _, times, ks, _ = RecursiveLeastSquares(1 - h / memory).run(data)
        out["methods"][f"rls (memory {memory:.0f} s)"] = _tracking_row(times, ks, change_time, k0, k_new)
    start = make_estimator("ols").fit(STRUCTURE, data.slice(0, int(60 / h))).parameters
    for drift in (1e-4, 1e-3):
        progress(f"tracking: ukf, drift {drift:g}")
        _, times, ks, _ = ParameterUKF(drift).run(data, start)
        out["methods"][f"ukf (drift {drift:g}/sample)"] = _tracking_row(times, ks, change_time, k0, k_new)
    return out


def _tracking_row(times, ks, change_time, k0, k_new):
    before = (times > change_time - 200) & (times <= change_time)
    return {"recovery_s": _recovery_time(times, ks, change_time, k_new),
            "error_before_percent": float(100 * np.sqrt(np.mean(((ks[before] - k0) / k0) ** 2))) if before.any() else None,
            "times": times.tolist(), "K": ks.tolist()}


def speed_and_scaling(quick: bool = False, progress=print) -> dict:
    """Time per refit against window length; CPU share at 10 Hz for the default configuration."""
    sizes = (1000, 10000) if quick else (1000, 10000, 100000)
    long = simulate("mixed", "seed001", duration=max(sizes) * 0.1 + 10, noise=1.0, seed=41).dataset
    out = {"refit_seconds": {}}
    for method in ("rwlssvm", "rwlssvm+oe"):
        estimator = make_estimator(method)
        estimator.fit(STRUCTURE, long.slice(0, 1000))  # compile and warm up
        for n in sizes:
            if method.endswith("+oe") and n > 10000 and quick:
                continue
            progress(f"scaling: {method} on {n} samples")
            t0 = time.perf_counter()
            estimator.fit(STRUCTURE, long.slice(0, n))
            out["refit_seconds"].setdefault(method, {})[str(n)] = time.perf_counter() - t0
    window = int(WINDOW_S / 0.1)
    t0 = time.perf_counter()
    make_estimator("rwlssvm+oe").fit(STRUCTURE, long.slice(0, window))
    refit = time.perf_counter() - t0
    out["default"] = {"window_samples": window, "refit_s": refit, "refit_period_s": REFIT_PERIOD_S,
                      "cpu_share_at_10Hz": refit / REFIT_PERIOD_S}
    return out


def run(quick: bool = False, progress=print) -> dict:
    return {"accuracy": accuracy(quick, progress), "tracking": tracking(quick, progress),
            "speed": speed_and_scaling(quick, progress)}
