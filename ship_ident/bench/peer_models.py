"""The peers of ``bench peers``: online identifiers a user would otherwise pick (see ``peers``).

Recursive least squares with forgetting (``RecursiveLeastSquares``) on the very
regression ours fits, filterpy's unscented Kalman filter with the parameters
in the state (``ParameterUKF``), SysIdentPy's FROLS NARX model (``fit_frols``)
and the seed's plain LS-SVM in the dual (``fit_dual``), all on seed 001's
model (nomoto2 + rudder offset + cubic yaw), and the held-out free-run RMSE
(rad, rad/s) that judges them.
"""

from __future__ import annotations

import time

import numpy as np

from ..estimators import make_estimator
from ..estimators.lssvm import lssvm_dual_with_bias
from ..model.integrate import advance, initial_z
from ..model.signals import compute_signals
from ..model.structure import Structure

STRUCTURE = Structure("nomoto2", ["rudder_offset", "cubic_yaw"])
PARAMETERS = STRUCTURE.parameter_names
UKF_START_S = 60.0  # s of data behind the UKF's initial OLS fit
DUAL_MAX_ROWS = 3000


def _regression(dataset):
    return STRUCTURE.regression(compute_signals(dataset))


class RecursiveLeastSquares:
    """RLS with forgetting 1 - h/memory on unit-scaled regression columns."""

    def __init__(self, memory_s: float):
        self.memory_s = memory_s

    def run(self, dataset, record_every: int = 10):
        """Final parameters, K every ``record_every`` rows (times, values), seconds per sample."""
        reg = _regression(dataset)
        scale = np.sqrt(np.mean(reg.X**2, axis=0))
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
            out[:3] = advance(2, dt, d0 + x[7], d1 + x[7], K, T1, T2, T3, x[0], x[1], x[2], -x[8] * one, *cubic, 2)
            return out

        def hx(x):
            return x[:2]

        ukf = UnscentedKalmanFilter(
            dim_x=9,
            dim_z=2,
            dt=dataset.sample_time,
            fx=fx,
            hx=hx,
            points=MerweScaledSigmaPoints(9, alpha=1e-3, beta=2.0, kappa=0.0),
        )
        p0 = np.array([start[n] for n in PARAMETERS])
        scale = np.maximum(np.abs(p0), self.PARAMETER_FLOOR)
        ukf.x = np.concatenate(
            [
                [
                    dataset.heading[0],
                    dataset.yaw_rate[0],
                    initial_z(p0[0], p0[1], p0[2], p0[3], dataset.yaw_rate[0], 0.0, dataset.rudder[0]),
                ],
                p0,
            ]
        )
        ukf.P = np.diag(np.concatenate([[1e-4, 1e-4, 1e-3], (0.2 * scale) ** 2]))
        ukf.R = np.diag(
            [
                dataset.noise_std("heading") ** 2,
                dataset.noise_std("yaw_rate") ** 2,
            ]
        )
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
