"""Linear filters of sampled signals: Savitzky-Golay smoothing and differentiation, and convolution.

Written on numpy alone: ``scipy.signal`` takes about a second to import (it loads scipy.stats and
scipy.interpolate), a second every replay and every start of the node would spend before its first
refit.
"""

from __future__ import annotations

import math

import numpy as np

DIRECT_LIMIT = 64  # kernels up to this many taps are applied directly, longer ones through the FFT


def _savgol_taps(window: int, polyorder: int, deriv: int, h: float) -> np.ndarray:
    """Taps of the Savitzky-Golay filter (arguments as ``savgol``'s): the ``deriv``-th derivative at
    the centre of the least-squares polynomial through the window, for convolution (the newest
    sample's tap first), in units of 1 / s^deriv."""
    half = window // 2
    offsets = np.arange(half, -half - 1, -1, dtype=float)  # reversed: taps for convolution
    powers = offsets[None, :] ** np.arange(polyorder + 1)[:, None]
    target = np.zeros(polyorder + 1)
    target[deriv] = math.factorial(deriv) / h**deriv
    taps, *_ = np.linalg.lstsq(powers, target, rcond=None)
    return taps


def savgol(values: np.ndarray, window: int, polyorder: int, deriv: int = 0, h: float = 1.0) -> np.ndarray:
    """Savitzky-Golay smoothing (``deriv`` 0) or derivative of ``values`` sampled every ``h`` s.

    Inside, each sample is the ``deriv``-th derivative of the degree-``polyorder`` least-squares
    polynomial through the ``window`` samples centred on it; within half a window of either end,
    that of the polynomial through the first (last) ``window`` samples, evaluated there.

    Parameters
    ----------
    values : numpy.ndarray
        The samples (at least ``window`` of them).
    window : int
        Samples in the window (odd).
    polyorder : int
        Degree of the local polynomial (below ``window``).
    deriv : int
        Order of the derivative.
    h : float
        Sample time (s).

    Returns
    -------
    numpy.ndarray
        The smoothed signal or its derivative (units of ``values`` per s^deriv).
    """
    values = np.asarray(values, dtype=float)
    half = window // 2
    out = np.convolve(values, _savgol_taps(window, polyorder, deriv, h), mode="same")
    positions = np.arange(window, dtype=float)
    for start, rows in ((0, slice(0, half)), (len(values) - window, slice(len(values) - half, len(values)))):
        polynomial = np.polyfit(positions, values[start : start + window], polyorder)
        if deriv:
            polynomial = np.polyder(polynomial, deriv)
        at = np.arange(rows.start, rows.stop, dtype=float) - start
        out[rows] = np.polyval(polynomial, at) / h**deriv
    return out


def convolve_columns(signals: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Each column of ``signals`` convolved with ``kernel`` (odd length), centred.

    The output has the rows of ``signals`` (zeros beyond its ends). Long kernels go through the FFT,
    whose cost grows with the rows, not with their product with the taps.

    Parameters
    ----------
    signals : numpy.ndarray
        (n, m) columns of samples.
    kernel : numpy.ndarray
        The taps (odd count).

    Returns
    -------
    numpy.ndarray
        (n, m) the convolved columns.
    """
    n, taps = signals.shape[0], len(kernel)
    first = (taps - 1) // 2
    if taps <= DIRECT_LIMIT:
        return np.stack([np.convolve(column, kernel)[first : first + n] for column in signals.T], axis=1)
    size = 1 << (n + taps - 2).bit_length()
    spectrum = np.fft.rfft(signals, size, axis=0) * np.fft.rfft(kernel, size)[:, None]
    return np.fft.irfft(spectrum, size, axis=0)[first : first + n]
