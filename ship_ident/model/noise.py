"""Sensor noise: the resolution floor, a robust spread, and the white-noise level of a sampled signal.

Numpy only, so that ``Dataset`` can estimate (and keep) the noise of its own signals.
"""

from __future__ import annotations

import numpy as np

# The finest angle (rad) or turn rate (rad/s) a compass or rate gyro resolves: the floor under
# every estimate of their noise.
SENSOR_RESOLUTION = float(np.radians(0.01))
MAD_TO_STD = 1.4826  # std of Gaussian noise / its median absolute deviation

# residual of a local quadratic fit over 11 samples, as one convolution kernel (symmetric): the
# sample less the Savitzky-Golay smoothing weights (267 - 15 k^2) / 1287, k = -5..5
_QUADRATIC_RESIDUAL = -(267.0 - 15.0 * np.arange(-5, 6) ** 2) / 1287.0
_QUADRATIC_RESIDUAL[5] += 1.0
# The residual keeps 1 - 89/429 = 0.79 of white noise's variance (the kernel's squared sum); the
# thresholds built on this level (excitation, diagnosis noise floors, change test) were set with
# 0.5874, which puts the level at 1.16 times the noise's std. Kept until they are re-measured.
_RESIDUAL_VARIANCE_SHARE = 1 - 0.4126


def median(values: np.ndarray) -> np.float64:
    """The median of a 1-D array, the very number ``numpy.median`` gives, without its general machinery.

    The same partition (the middle value or values, and the largest last, where a NaN sorts) and
    the same mean of the two middle values of an even count; NaN when a value is NaN. The online
    core takes tens of thousands of medians of short arrays, where numpy's dispatch costs more than
    the partition.

    Parameters
    ----------
    values : numpy.ndarray
        A 1-D array of floats.

    Returns
    -------
    numpy.float64
        The median (NaN for an empty array or one holding a NaN).
    """
    n = len(values)
    if n == 0:
        return np.median(values)
    middle = n // 2
    part = np.partition(values, [middle - 1, middle, -1] if n % 2 == 0 else [middle, -1])
    if np.isnan(part[-1]):
        return np.float64(np.nan)
    # numpy's mean of the middle value(s): a sum started at 0.0 (a median of zeros is +0.0), over their count
    return 0.0 + part[middle] if n % 2 else (0.0 + part[middle - 1] + part[middle]) / 2


def robust_std(values: np.ndarray) -> float:
    """The std of Gaussian noise, blind to a few outliers: MAD_TO_STD (1.4826) times the median absolute deviation.

    Parameters
    ----------
    values : numpy.ndarray
        The samples.

    Returns
    -------
    float
        The std, in the samples' unit.
    """
    return float(MAD_TO_STD * median(np.abs(values - median(values))))


def noise_level(values: np.ndarray, floor: float) -> float:
    """Std of white measurement noise, at least ``floor``.

    The robust residual of a local quadratic fit over 11 samples (interior samples only), corrected
    for its smoothing: a turning hull's signal is smooth over 11 samples, the sensor's noise is not.

    Parameters
    ----------
    values : numpy.ndarray
        A measured signal on a uniform grid.
    floor : float
        The smallest value returned (the signal's unit).

    Returns
    -------
    float
        The noise std (the signal's unit); ``floor`` for fewer than 15 samples.
    """
    if len(values) < 15:
        return floor
    residual = np.convolve(values, _QUADRATIC_RESIDUAL, mode="valid")
    return max(robust_std(residual) / np.sqrt(_RESIDUAL_VARIANCE_SHARE), floor)
