"""Exact sample-to-sample steps of the Nomoto models without state-dependent forcing.

Where every effect acts through the rudder (offset, delay, stall) or the sensor (gyro bias) and
none scales with the speed, the model is linear and time-invariant in the state (psi, r, z) of
``integrate``:

    x' = A x + B d(t)

and with the rudder linear between samples (first-order hold) one sample of length h is exactly

    x(h) = Phi x(0) + G_d d0 + G_v (d1 - d0) / h,

the blocks of exp(M h) for the augmented state (x, d, d') (Van Loan, 1978). One step per sample
whatever the poles: RK4 needs 56 substeps per sample for the stability of a ship's 10 ms fast pole
at 0.37 s samples. ``Structure.simulate_runs`` takes it where RK4 would need EXACT_STEP_SUBSTEPS or
more; both agree there to 1e-9 of the yaw rate.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .integrate import lane_starts, store_lanes

AUGMENTED = 5  # psi, r, z, the rudder d and its rate d'
TAYLOR_TERMS = 12  # of exp(M h / 2^s) with its norm <= 1/4: truncation below 1e-16
SCALED_NORM = 0.25


@njit(cache=True)
def _product(a, b):
    """The matrix product a b of two small square matrices (loops: no BLAS call to compile)."""
    n = a.shape[0]
    out = np.zeros((n, n))
    for i in range(n):
        for k in range(n):
            aik = a[i, k]
            if aik != 0.0:
                for j in range(n):
                    out[i, j] += aik * b[k, j]
    return out


@njit(cache=True)
def _matrix_exponential(M):
    """exp(M) by scaling and squaring of its Taylor series (a small dense matrix)."""
    n = M.shape[0]
    norm = 0.0
    for i in range(n):
        row = 0.0
        for j in range(n):
            row += abs(M[i, j])
        norm = max(norm, row)
    squarings = 0
    while norm > SCALED_NORM:
        norm *= 0.5
        squarings += 1
    scaled = M * 0.5**squarings
    result, term = np.eye(n), np.eye(n)
    for k in range(1, TAYLOR_TERMS + 1):
        term = _product(term, scaled) / k
        result += term
    for _ in range(squarings):
        result = _product(result, result)
    return result


@njit(cache=True)
def sample_transition(order, h, K, T1, T2, T3):
    """exp(M h) of one sample: the exact step of the linear model x' = A x + B d.

    Parameters
    ----------
    order : int
        1 (T r' + r = K d, T = T1) or 2 (nomoto2 in the state z of ``integrate``).
    h : float
        Sample time (s).
    K, T1, T2, T3 : float
        Gain (1/s) and time constants (s).

    Returns
    -------
    numpy.ndarray
        (5, 5) exp(M h) of the augmented state (psi, r, z, d, d'): its first three rows give the
        state after one sample from the state, the rudder at the start and its rate.
    """
    M = np.zeros((AUGMENTED, AUGMENTED))
    M[0, 1] = 1.0
    if order == 1:
        M[1, 1] = -1.0 / T1
        M[1, 3] = K / T1
    else:
        M[1, 1] = -(T1 + T2) / (T1 * T2)
        M[1, 2] = 1.0 / (T1 * T2)
        M[1, 3] = K * T3 / (T1 * T2)
        M[2, 1] = -1.0
        M[2, 3] = K
    M[3, 4] = 1.0
    return _matrix_exponential(M * h)


@njit(cache=True, error_model="numpy")
def simulate_linear_kernel(order, h, rudder, constants, bounds, initial):
    """``integrate.simulate_kernel`` for models without forcing terms, each sample one exact step.

    Parameters
    ----------
    order, h, rudder, constants, bounds, initial
        As ``integrate.simulate_kernel``'s: the model's order, the sample time (s), each run's
        effective rudder (rad) and K, T1, T2, T3 (1/s, s), the segments and each lane's initial
        heading, yaw rate and yaw acceleration (rad, rad/s, rad/s^2).

    Returns
    -------
    heading, yaw_rate : numpy.ndarray
        (m, n) of every run, as ``integrate.simulate_kernel`` returns them (rad, rad/s; NaN outside
        the segments and after a blow-up).
    """
    runs, n = rudder.shape
    unscaled = np.ones((runs, n))
    psi_out, r_out, run, first, last, alive, psi, r, z, longest = lane_starts(
        rudder, unscaled, unscaled, constants, bounds, initial
    )
    lanes = run.shape[0]
    steps = np.empty((runs, 3, AUGMENTED))  # each run's exact step: exp(M h)'s first three rows
    for j in range(runs):
        K, T1, T2, T3 = constants[j, 0], constants[j, 1], constants[j, 2], constants[j, 3]
        steps[j] = sample_transition(order, h, K, T1, T2, T3)[:3]
    E = np.empty((3, AUGMENTED, lanes))
    for lane in range(lanes):
        E[:, :, lane] = steps[run[lane]]
    # the lanes advance one sample together, in loops over the lanes (vector instructions); a lane
    # past its segment's end repeats its last sample, unwritten (z is unused by nomoto1: its row and
    # column of exp(M h) are the identity's)
    d0, rate = np.empty(lanes), np.empty(lanes)
    for step in range(longest - 1):
        for lane in range(lanes):
            j, k = run[lane], min(first[lane] + step, last[lane])
            d0[lane] = rudder[j, k]
            rate[lane] = (rudder[j, min(k + 1, n - 1)] - d0[lane]) / h
        for lane in range(lanes):  # psi feeds neither r nor z: exp(M h)'s first column is (1, 0, 0, ...)
            p, q, w, d, v = psi[lane], r[lane], z[lane], d0[lane], rate[lane]
            psi[lane] = p + E[0, 1, lane] * q + E[0, 2, lane] * w + E[0, 3, lane] * d + E[0, 4, lane] * v
            r[lane] = E[1, 1, lane] * q + E[1, 2, lane] * w + E[1, 3, lane] * d + E[1, 4, lane] * v
            z[lane] = E[2, 1, lane] * q + E[2, 2, lane] * w + E[2, 3, lane] * d + E[2, 4, lane] * v
        store_lanes(step, run, first, last, alive, psi, r, psi_out, r_out)
    return psi_out, r_out
