"""Prediction-error refinement: the free-run error whitened by a Kalman innovation filter.

Noise on the measured rudder (s_delta) is input noise: driven through the
hull, it makes the free-run heading and yaw rate wander in a coloured way
that the white-noise weighting of the output-error stage ignores (it fights
the wander with restarts instead). Here the free-run error of each segment,

    u_k = y_k - y_sim,k(theta),   y = (heading, measured yaw rate),

is modelled as the response of the linearised hull to the rudder noise plus
white sensor noise,

    xi_{k+1} = A xi_k + b n_k,  u_k = C xi_k + v_k,  n ~ N(0, s_delta^2), v ~ N(0, R),

with A and b the one-sample transition of the Nomoto model at rest (from the
same compiled integrator) and R = diag(s_psi^2, s_r^2). The steady-state
Kalman predictor of that model (discrete Riccati equation) turns u into its
innovations e_k = u_k - C xi_hat_k, white with covariance S, and the
refinement minimises sum_k |S^-1/2 e_k|^2: the prediction-error (maximum-
likelihood) criterion of the output-error model with coloured noise. One
free run per segment replaces the shooting intervals; the filter is fixed at
the starting estimate (its dependence on theta is second order). With a
noise-free rudder the gain vanishes and this is the plain output-error fit.
"""
from __future__ import annotations

import numpy as np
from numba import njit
from scipy.linalg import solve_discrete_are

from ..integrate import advance
from ..signals import noise_level
from .output_error import OutputError

_NO_FORCING = (np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64),
               np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))


def linear_transition(order: int, params: dict, h: float, substeps: int) -> tuple[np.ndarray, np.ndarray]:
    """One-sample transition matrix A and rudder input vector b of the Nomoto model at rest,
    on the states (psi, r[, z]), by differences of the compiled integrator (exact: it is linear)."""
    K = params["K"]
    T1 = params["T"] if order == 1 else params["T1"]
    T2 = 0.0 if order == 1 else params["T2"]
    T3 = 0.0 if order == 1 else params["T3"]
    n = 2 if order == 1 else 3

    def step(state, rudder):
        psi, r, z = (list(state) + [0.0])[:3]
        return np.array(advance(order, h, rudder, rudder, K, T1, T2, T3, psi, r, z, *_NO_FORCING,
                                substeps))[:n]

    zero = np.zeros(n)
    A = np.column_stack([step(np.eye(n)[i], 0.0) for i in range(n)])
    b = step(zero, 1.0)
    return A, b


def innovation_filter(A: np.ndarray, b: np.ndarray, rudder_noise: float, heading_noise: float,
                      yaw_rate_noise: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Steady-state Kalman predictor: returns A - L C, L, C and S^-1/2 (innovation whitening)."""
    n = A.shape[0]
    C = np.eye(2, n)
    Q = rudder_noise ** 2 * np.outer(b, b) + 1e-14 * np.eye(n)
    R = np.diag([heading_noise ** 2, yaw_rate_noise ** 2])
    P = solve_discrete_are(A.T, C.T, Q, R)
    S = C @ P @ C.T + R
    L = A @ P @ C.T @ np.linalg.inv(S)
    evals, evecs = np.linalg.eigh(S)
    return A - L @ C, L, C, evecs @ np.diag(evals ** -0.5) @ evecs.T


@njit(cache=True)
def whiten(closed_loop, gain, C, s_inv_sqrt, errors):
    """Whitened innovations (N x 2) of the error series ``errors`` (N x 2), filter state from zero."""
    n = errors.shape[0]
    x = np.zeros(closed_loop.shape[0])
    out = np.empty((n, 2))
    for k in range(n):
        e = errors[k] - C @ x
        out[k] = s_inv_sqrt @ e
        x = closed_loop @ x + gain @ errors[k]
    return out


class PredictionError(OutputError):
    """Refine a starting estimate by the prediction-error criterion (rudder noise as input noise)."""

    def __init__(self, start, max_iterations: int = 30):
        super().__init__(start, max_iterations=max_iterations)
        self.name = f"{start.name}+pem"

    def intervals(self, dataset):
        return tuple(dataset.segments)

    @staticmethod
    def residual_weighting(structure, dataset, params0, s_psi, s_r, intervals):
        from .base import fit_substeps

        h = dataset.sample_time
        s_delta = noise_level(dataset.rudder, np.radians(0.001))
        A, b = linear_transition(structure.order, params0, h, fit_substeps(h, params0))
        closed_loop, gain, C, s_inv_sqrt = innovation_filter(A, b, s_delta, s_psi, s_r)

        def weigh(psi_err, r_err):
            errors = np.column_stack([psi_err, r_err])
            out = np.empty_like(errors)
            for a, z in intervals:
                out[a:z] = whiten(closed_loop, gain, C, s_inv_sqrt, np.ascontiguousarray(errors[a:z]))
            return -out.T.ravel()

        return weigh

    @staticmethod
    def bandwidth(intervals) -> int:
        return 10  # innovations are white: a short lag window only guards against model error
