"""Smoothed signals and their time derivatives for the equation-error regression.

Two differentiation methods, chosen by name like PySINDy's differentiation
objects:

* ``savgol``: Savitzky-Golay local polynomial fits (default). The same
  linear filter is applied to every term of the ODE, so the equation still
  holds for the filtered signals wherever the signals are locally polynomial.
* ``rts``: a Rauch-Tung-Striebel smoother (filterpy) on a constant-jerk
  model of (psi, r, r', r'') that fuses the heading and the yaw-rate
  measurements; the rudder goes through the same smoother as a single
  measured state. Better when the yaw rate is noisy.

Before smoothing, isolated outliers (a dropped bit, a glitching gyro) are
replaced by a running median (Hampel filter), so a spike does not smear
over a whole smoothing window of derivatives.

Rows within ``edge`` samples of a segment boundary are masked out, since
derivatives there are one-sided.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .dataset import DataError, Dataset
from .filters import savgol
from .noise import SENSOR_RESOLUTION, robust_std

DIFFERENTIATION_METHODS = ("savgol", "rts")


@dataclass
class Signals:
    """Signals on the dataset's grid, with derivatives (SI units)."""

    time: np.ndarray
    psi: np.ndarray  # rad
    r: np.ndarray  # rad/s, smoothed, corrected for known sensor effects
    r_dot: np.ndarray  # rad/s^2
    r_ddot: np.ndarray  # rad/s^3
    delta: np.ndarray  # rad
    delta_dot: np.ndarray  # rad/s
    r_measured: np.ndarray  # rad/s, as measured (raw)
    heading_rate: np.ndarray  # rad/s, derivative of the smoothed heading
    speed: np.ndarray | None  # m/s
    mask: np.ndarray  # rows usable for the regression
    sample_time: float
    base_column_scales: dict = field(default_factory=dict)

    @property
    def rows(self) -> np.ndarray:
        """The indices of the samples the regression uses (``mask``: inside a segment, away from its edges)."""
        return np.flatnonzero(self.mask)


def _savgol(values: np.ndarray, window: int, h: float, deriv: int) -> np.ndarray:
    if len(values) < window:
        window = len(values) if len(values) % 2 else len(values) - 1
    poly = min(4, window - 1)
    if window < 3:
        return np.zeros_like(values) if deriv else values.copy()
    return savgol(values, window, poly, deriv, h)


def _rts_segment(psi, r, h, heading_noise, yaw_rate_noise, jerk_psd):
    from filterpy.common import Q_discrete_white_noise
    from filterpy.kalman import KalmanFilter, rts_smoother

    kf = KalmanFilter(dim_x=4, dim_z=2)
    kf.F = np.array([[1, h, h * h / 2, h**3 / 6], [0, 1, h, h * h / 2], [0, 0, 1, h], [0, 0, 0, 1]], dtype=float)
    kf.H = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
    kf.R = np.diag([heading_noise**2, yaw_rate_noise**2])
    kf.Q = Q_discrete_white_noise(dim=4, dt=h, var=jerk_psd)
    kf.x = np.array([psi[0], r[0], 0.0, 0.0])
    kf.P = np.diag([heading_noise**2, yaw_rate_noise**2, 1e-2, 1e-2]) * 10
    zs = np.column_stack([psi, r])
    means, covs, _, _ = kf.batch_filter(zs)
    n = len(psi)
    xs, _, _, _ = rts_smoother(means, covs, [kf.F] * n, [kf.Q] * n)
    return xs


def despike(values: np.ndarray, floor: float, window: int = 7, threshold: float = 6.0) -> np.ndarray:
    """Hampel filter: samples more than ``threshold`` robust stds (at least ``floor``) from the
    running median of ``window`` samples are replaced by that median."""
    from scipy.ndimage import median_filter

    if len(values) < window:
        return values
    median = median_filter(values, size=window, mode="nearest")
    deviation = values - median
    limit = threshold * max(robust_std(deviation), floor)
    return np.where(np.abs(deviation) > limit, median, values)


def smoothing_window(yaw_rate_noise: float) -> float:
    """Savitzky-Golay window: 0.7 s on clean data, widening to 3 s at 0.2 deg/s yaw-rate noise.

    Parameters
    ----------
    yaw_rate_noise : float
        White-noise standard deviation of the measured yaw rate (rad/s).

    Returns
    -------
    float
        The window's length (s).
    """
    return float(0.7 + 2.3 * min(1.0, yaw_rate_noise / np.radians(0.2)))


def compute_signals(
    dataset: Dataset, method: str = "savgol", window_s: float | None = None, jerk_psd: float = 1e-3
) -> Signals:
    """Smooth and differentiate a dataset segment by segment.

    Computed once per dataset and arguments (``Dataset.derived``), each caller given its own copy (an
    effect's ``prepare`` sets its fields).

    Savitzky-Golay (Savitzky and Golay 1964) local polynomials, or a Rauch-Tung-Striebel smoother
    (Rauch, Tung and Striebel 1965) of a constant-jerk yaw model fusing heading and yaw rate.
    ``window_s`` defaults to ``smoothing_window`` of the yaw-rate noise
    estimated from the data; the RTS smoother uses the estimated heading and
    yaw-rate noise levels as its measurement noise.

    Parameters
    ----------
    dataset : Dataset
        The data (rad, rad/s).
    method : str
        'savgol' or 'rts' (DIFFERENTIATION_METHODS).
    window_s : float or None
        Savitzky-Golay window (s); None: from the yaw-rate noise.
    jerk_psd : float
        The RTS model's yaw-jerk power spectral density ((rad/s^3)^2 s).

    Returns
    -------
    Signals
        Heading, smoothed yaw rate and its first two derivatives (rad, rad/s, rad/s^2, rad/s^3) on
        the dataset's grid, with the regression's row mask.

    Raises
    ------
    DataError
        For an unknown method or non-finite data.
    """
    key = ("signals", method, window_s, jerk_psd)
    if key not in dataset.derived:
        dataset.derived[key] = _smoothed_signals(dataset, method, window_s, jerk_psd)
    return replace(dataset.derived[key])


def _smoothed_signals(dataset: Dataset, method: str, window_s: float | None, jerk_psd: float) -> Signals:
    """The signals ``compute_signals`` returns, computed afresh."""
    if method not in DIFFERENTIATION_METHODS:
        raise DataError(f"unknown differentiation method {method!r}; choose from {', '.join(DIFFERENTIATION_METHODS)}")
    dataset.check_finite()
    h = dataset.sample_time
    n = dataset.n_samples
    heading_noise = dataset.noise_std("heading")
    yaw_rate_noise = dataset.noise_std("yaw_rate")
    window_s = smoothing_window(yaw_rate_noise) if window_s is None else window_s
    window = max(5, int(round(window_s / h)) | 1)
    edge = window // 2 + 1
    out = {k: np.zeros(n) for k in ("psi", "r", "r_dot", "r_ddot", "delta", "delta_dot", "heading_rate")}
    mask = np.zeros(n, dtype=bool)
    for a, b in dataset.segments:
        if b - a < 2 * edge + 3:
            continue
        psi = despike(dataset.heading[a:b], SENSOR_RESOLUTION)
        r = despike(dataset.yaw_rate[a:b], SENSOR_RESOLUTION)
        d = despike(dataset.rudder[a:b], SENSOR_RESOLUTION)
        out["delta"][a:b] = _savgol(d, window, h, 0)
        out["delta_dot"][a:b] = _savgol(d, window, h, 1)
        out["heading_rate"][a:b] = _savgol(psi, window, h, 1)
        if method == "savgol":
            out["psi"][a:b] = _savgol(psi, window, h, 0)
            out["r"][a:b] = _savgol(r, window, h, 0)
            out["r_dot"][a:b] = _savgol(r, window, h, 1)
            out["r_ddot"][a:b] = _savgol(r, window, h, 2)
        else:
            xs = _rts_segment(psi, r, h, heading_noise, yaw_rate_noise, jerk_psd)
            out["psi"][a:b], out["r"][a:b], out["r_dot"][a:b], out["r_ddot"][a:b] = xs.T
        mask[a + edge : b - edge] = True
    if not mask.any():
        raise DataError(f"too few samples: every segment is shorter than {2 * edge + 3} samples")
    return Signals(
        time=dataset.time,
        psi=out["psi"],
        r=out["r"],
        r_dot=out["r_dot"],
        r_ddot=out["r_ddot"],
        delta=out["delta"],
        delta_dot=out["delta_dot"],
        r_measured=dataset.yaw_rate,
        heading_rate=out["heading_rate"],
        speed=dataset.speed,
        mask=mask,
        sample_time=h,
    )
