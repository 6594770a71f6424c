"""Identification of the 3-DOF model by equation error: Savitzky-Golay smoothed states and
accelerations, one regression per DOF (OLS or truncated LS-SVM), free-run prediction and its metrics."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..estimators.lssvm import OLS
from ..estimators.tlssvm import TLSSVM, TRUNCATION_RULES
from ..model.filters import savgol
from ..model.metrics import effective_sample_fraction, signal_metrics
from .model import DOFS, Coefficients, Record, _regression_matrices, run_model

METHODS = ("ols",) + tuple(f"tlssvm-{rule}" for rule in TRUNCATION_RULES)  # equation-error solvers


@dataclass
class Smoothed:
    """Savitzky-Golay smoothed states (SI) and their time derivatives on the usable rows."""

    surge: np.ndarray
    sway: np.ndarray
    yaw_rate: np.ndarray
    rudder: np.ndarray
    surge_dot: np.ndarray
    sway_dot: np.ndarray
    yaw_rate_dot: np.ndarray


def smooth(record: Record, window_time: float, trim: bool = True) -> Smoothed:
    """Cubic Savitzky-Golay fit over ``window_time`` (s); rows within half a window of the ends dropped."""
    h = record.sample_time
    window = max(5, int(round(window_time / h)) | 1)
    window = min(window, len(record) - (1 - len(record) % 2))
    half = window // 2 if trim else 0
    keep = slice(half, len(record) - half)

    def fit(x, deriv=0):
        return savgol(x, window, 3, deriv, h)[keep]

    return Smoothed(
        fit(record.surge),
        fit(record.sway),
        fit(record.yaw_rate),
        fit(record.rudder),
        fit(record.surge, 1),
        fit(record.sway, 1),
        fit(record.yaw_rate, 1),
    )


@dataclass
class Identification:
    """Identified coefficients with standard errors and per-DOF solver facts."""

    coefficients: Coefficients
    method: str
    samples: int
    info: dict

    def to_json(self) -> dict:
        return {
            "method": self.method,
            "samples": self.samples,
            "info": self.info,
            "coefficients": self.coefficients.to_json(),
        }


def default_window_time(length: float, speed: float) -> float:
    """Smoothing window (s): a quarter of the time L / U0 the ship takes to run its own length."""
    return 0.25 * length / speed


def regression(records: list[Record], length: float, speed: float, window_time: float) -> dict:
    """Stack the three per-DOF regressions (prime accelerations on the left) over all records."""
    rows = {"surge": ([], []), "sway": ([], []), "yaw": ([], [])}
    for record in records:
        s = smooth(record, window_time)
        phi_x, phi_yn, q = _regression_matrices(s.surge, s.sway, s.yaw_rate, s.rudder, length, speed)
        for dof, phi, acc, scale in (
            ("surge", phi_x, s.surge_dot, q),
            ("sway", phi_yn, s.sway_dot, q),
            ("yaw", phi_yn, s.yaw_rate_dot, q / length),
        ):
            rows[dof][0].append(phi)
            rows[dof][1].append(acc / scale)
    return {dof: (np.vstack(X), np.concatenate(y)) for dof, (X, y) in rows.items()}


def _solver(method: str):
    if method == "ols":
        return OLS()
    if method.startswith("tlssvm-") and method[7:] in TRUNCATION_RULES:
        return TLSSVM(rule=method[7:])
    raise ValueError(f"unknown 3-DOF method {method!r}; choose from {', '.join(METHODS)}")


def identify(
    records: Record | list[Record],
    length: float,
    speed: float,
    method: str = "tlssvm-gcv",
    window_time: float | None = None,
) -> Identification:
    """Identify a, b, c by equation error on one or more records (each smoothed on its own).

    ``speed`` is the reference speed U0 (m/s) of u' = (u - U0)/U. Standard
    errors: sqrt(diag(sigma^2 C)) with C the solver's coefficient covariance
    and sigma^2 the residual variance, inflated for residual autocorrelation.
    """
    records = [records] if isinstance(records, Record) else list(records)
    window_time = default_window_time(length, speed) if window_time is None else window_time
    solver = _solver(method)
    vectors, std_errors, info = {}, {}, {}
    for dof, (X, y) in regression(records, length, speed, window_time).items():
        solution = solver.solve(X, y)
        residual = y - X @ solution.w
        sigma2 = float(residual @ residual) / max(len(y) - len(solution.w), 1)
        sigma2 /= effective_sample_fraction(residual)
        vectors[dof] = solution.w
        std_errors[dof] = np.sqrt(np.clip(np.diag(solution.cov), 0.0, None) * sigma2)
        info[dof] = {
            "residual_std": float(np.sqrt(sigma2)),
            **{k: v for k, v in solution.info.items() if k in ("truncation", "of", "rule")},
        }
    coefficients = Coefficients(length=length, speed=speed, std_errors=std_errors, **vectors)
    return Identification(coefficients, method, int(sum(len(r) for r in records)), dict(info, window_time=window_time))


def predict(coefficients: Coefficients, record: Record, window_time: float | None = None) -> Record:
    """Free run: the model driven by the measured rudder from the measured (smoothed) initial state."""
    window_time = default_window_time(coefficients.length, coefficients.speed) if window_time is None else window_time
    s = smooth(record, window_time, trim=False)
    initial = (s.surge[0], s.sway[0], s.yaw_rate[0], record.heading[0])
    return run_model(coefficients, record.time, record.rudder, initial)


def prediction_metrics(measured: Record, predicted: Record) -> dict:
    """Per DOF (surge u, sway v, yaw rate r): metrics.signal_metrics plus the measured STD (SI)."""
    return {
        dof: dict(signal_metrics(measured.dof(dof), predicted.dof(dof)), std_measured=float(np.std(measured.dof(dof))))
        for dof in DOFS
    }
