"""Rudder-sensor noise as input noise: its linear noise model and Kalman innovations.

A measured rudder angle d_m,k = d_k + n_k (n white, std s_delta, rad) drives
a free-run simulation with the wrong input. Between samples the rudder is
linear (first-order hold), so the simulated state's error obeys, for the
Nomoto model linearised at rest,

    x_{k+1} = A x_k + b0 n_k + b1 n_{k+1},    u_k = C x_k + v_k,

with x = (psi, r[, z]), A the one-sample transition, b0 and b1 the responses
to a unit rudder ramp down and up over one sample, C picking heading and yaw
rate, and v the white sensor noise of std (s_psi, s_r). The moving-average
input is made Markov by xi_k = x_k - b1 n_k:

    xi_{k+1} = A xi_k + g n_k,  g = A b1 + b0,    u_k = C xi_k + C b1 n_k + v_k,

a state-space model whose process and measurement noises are correlated.
Its steady-state Kalman predictor turns the free-run error series u into
white innovations e_k with covariance S; ``whiten`` returns S^-1/2 e_k.
The prediction-error estimator and the Cramer-Rao bound with a noisy rudder
both stand on this model.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit
from scipy.linalg import solve_discrete_are

from ..model.integrate import advance

FILTERS_KEPT = 32  # innovation filters remembered by their noise model (``innovation_filter``)


@dataclass(frozen=True)
class NoiseModel:
    """The linearised hull driven by rudder noise (see the module docstring; SI units)."""

    A: np.ndarray  # one-sample transition of (psi, r[, z])
    b0: np.ndarray  # state response to a unit rudder error at the start of a sample (FOH)
    b1: np.ndarray  # ... at its end
    rudder_noise: float  # rad
    heading_noise: float  # rad
    yaw_rate_noise: float  # rad/s

    @property
    def C(self) -> np.ndarray:
        return np.eye(2, self.A.shape[0])

    def transfer(self, omega: np.ndarray) -> np.ndarray:
        """Response H(e^{i omega}) of (heading, yaw rate) to the rudder noise, shape (len(omega), 2)."""
        n = self.A.shape[0]
        z = np.exp(1j * np.asarray(omega))
        resolvent = np.linalg.inv(z[:, None, None] * np.eye(n) - self.A)
        drive = self.b0[None, :] + z[:, None] * self.b1[None, :]
        return np.einsum("ij,wjk,wk->wi", self.C, resolvent, drive)


def noise_model(
    structure, params: dict, h: float, substeps: int, rudder_noise: float, heading_noise: float, yaw_rate_noise: float
) -> NoiseModel:
    """The linear noise model of a structure: its compiled integrator linearised at rest.

    One sample of length h is one step; only the linear terms are kept (a linear damping moved to
    the forcing in the acceleration form), since the effects' nonlinear terms vanish to first order
    at rest.

    Parameters
    ----------
    structure : Structure
        The model structure.
    params : dict
        Its parameters (SI).
    h : float
        Sample time (s).
    substeps : int
        RK4 steps per sample.
    rudder_noise, heading_noise, yaw_rate_noise : float
        White noise standard deviations of the rudder (rad), heading (rad) and yaw rate (rad/s).

    Returns
    -------
    NoiseModel
        State matrices of one sample and the noise levels.
    """
    order = structure.order
    (K, T1, T2, T3), terms = structure.kernel(params)
    linear = [t for t in terms if t.r_power == 1 and t.abs_power == 0 and t.harmonic == 0]
    forcing = (
        np.array([t.coefficient for t in linear], dtype=float),
        np.ones(len(linear), dtype=np.int64),
        *(np.zeros(len(linear), dtype=np.int64) for _ in range(3)),
    )
    n = 2 if order == 1 else 3

    def step(state, d0, d1):
        psi, r, z = (list(state) + [0.0])[:3]
        return np.array(advance(order, h, d0, d1, K, T1, T2, T3, psi, r, z, *forcing, substeps))[:n]

    zero = np.zeros(n)
    A = np.column_stack([step(np.eye(n)[i], 0.0, 0.0) for i in range(n)])
    return NoiseModel(
        A=A,
        b0=step(zero, 1.0, 0.0),
        b1=step(zero, 0.0, 1.0),
        rudder_noise=rudder_noise,
        heading_noise=heading_noise,
        yaw_rate_noise=yaw_rate_noise,
    )


@dataclass(frozen=True)
class InnovationFilter:
    """Steady-state Kalman predictor xi_{k+1} = A xi_k + L e_k, e_k = u_k - C xi_k, cov(e) = S."""

    A: np.ndarray
    gain: np.ndarray
    C: np.ndarray
    s_inv_sqrt: np.ndarray

    @property
    def log_det_covariance(self) -> float:
        """log det S: with the whitened squares, -2 log-likelihood per sample is |S^-1/2 e|^2 + log det S."""
        return float(-2.0 * np.linalg.slogdet(self.s_inv_sqrt)[1])

    def whiten(self, errors: np.ndarray) -> np.ndarray:
        """The whitened innovations S^-1/2 e_k of a free-run error series.

        The predictor starts at zero (the series starts from a known state).

        Parameters
        ----------
        errors : numpy.ndarray
            (N, 2) free-run errors of heading (rad) and yaw rate (rad/s).

        Returns
        -------
        numpy.ndarray
            (N, 2) the whitened innovations (dimensionless).
        """
        return _whiten(self.A, self.gain, self.C, self.s_inv_sqrt, np.ascontiguousarray(errors, dtype=float))

    def whiten_blocks(self, heading_error: np.ndarray, yaw_rate_error: np.ndarray, blocks: np.ndarray) -> np.ndarray:
        """The residual vector -S^-1/2 e_k of a free-run error series run free block by block.

        The predictor restarts at zero at each block's first sample (each block starts from a known
        state).

        Parameters
        ----------
        heading_error, yaw_rate_error : numpy.ndarray
            (N,) free-run errors of heading (rad) and yaw rate (rad/s).
        blocks : numpy.ndarray
            (blocks, 2) half-open sample-index ranges (int64).

        Returns
        -------
        numpy.ndarray
            (2 N,) the negated whitened innovations (dimensionless): every sample's heading
            component, then every sample's yaw-rate one.
        """
        return _whiten_blocks(self.A, self.gain, self.C, self.s_inv_sqrt, heading_error, yaw_rate_error, blocks)

    def whiten_blocks_rows(
        self, heading_errors: np.ndarray, yaw_rate_errors: np.ndarray, blocks: np.ndarray
    ) -> np.ndarray:
        """``whiten_blocks`` of every row of several free-run error series, in one compiled call.

        The runs of a Jacobian, two at a time: each row gets the very numbers ``whiten_blocks`` gives it.

        Parameters
        ----------
        heading_errors, yaw_rate_errors : numpy.ndarray
            (rows, N) free-run errors of heading (rad) and yaw rate (rad/s).
        blocks : numpy.ndarray
            (blocks, 2) half-open sample-index ranges (int64).

        Returns
        -------
        numpy.ndarray
            (rows, 2 N) each row's residual vector (dimensionless).
        """
        return _whiten_blocks_rows(self.A, self.gain, self.C, self.s_inv_sqrt, heading_errors, yaw_rate_errors, blocks)


def innovation_filter(model: NoiseModel) -> InnovationFilter:
    """The steady Kalman filter of the correlated-noise model (Riccati equation, scipy's DARE).

    The FILTERS_KEPT newest filters are kept by their model's exact numbers: the points of a cost's
    profile all weigh their residuals with the noise model at one estimate's parameters, and the
    Riccati equation is solved once for them.

    Parameters
    ----------
    model : NoiseModel
        The linear noise model (``noise_model``).

    Returns
    -------
    InnovationFilter
        Its gain and the whitening of its innovations (shared by the callers with the same model:
        read, never written).
    """
    noise = np.array([model.rudder_noise, model.heading_noise, model.yaw_rate_noise], dtype=float)
    return _filter_of_model(
        (model.A.tobytes(), model.A.shape[0], model.b0.tobytes(), model.b1.tobytes(), noise.tobytes())
    )


@lru_cache(maxsize=FILTERS_KEPT)
def _filter_of_model(numbers: tuple) -> InnovationFilter:
    """``innovation_filter`` of the noise model whose exact numbers are ``numbers`` (the bytes of A,
    its size, of b0, of b1 and of the noise levels)."""
    a_bytes, n, b0_bytes, b1_bytes, noise_bytes = numbers
    rudder_noise, heading_noise, yaw_rate_noise = np.frombuffer(noise_bytes)
    model = NoiseModel(
        A=np.frombuffer(a_bytes).reshape(n, n).copy(),
        b0=np.frombuffer(b0_bytes).copy(),
        b1=np.frombuffer(b1_bytes).copy(),
        rudder_noise=float(rudder_noise),
        heading_noise=float(heading_noise),
        yaw_rate_noise=float(yaw_rate_noise),
    )
    A, C, n = model.A, model.C, model.A.shape[0]
    s2 = model.rudder_noise**2
    g = A @ model.b1 + model.b0
    feedthrough = C @ model.b1
    R = np.diag([model.heading_noise**2, model.yaw_rate_noise**2]) + s2 * np.outer(feedthrough, feedthrough)
    cross = s2 * np.outer(g, feedthrough)
    if s2 == 0.0:  # sensor noise only: no state to track, the innovations are the errors
        P = np.zeros((n, n))
    else:
        P = solve_discrete_are(A.T, C.T, s2 * np.outer(g, g) + 1e-14 * np.eye(n), R, s=cross)
    S = C @ P @ C.T + R
    gain = (A @ P @ C.T + cross) @ np.linalg.inv(S)
    evals, evecs = np.linalg.eigh(S)
    return InnovationFilter(A=A, gain=gain, C=C, s_inv_sqrt=evecs @ np.diag(evals**-0.5) @ evecs.T)


@njit(cache=True)
def _whiten_span(A, gain, C, s_inv_sqrt, heading_error, yaw_rate_error, start, stop, sign, heading_out, yaw_rate_out):
    """The innovations of samples start..stop-1, the predictor started at zero there, times ``sign``
    (+1 or -1: exact), into ``heading_out`` and ``yaw_rate_out``."""
    m = A.shape[0]
    x = np.zeros(m)
    x_next = np.zeros(m)
    for k in range(start, stop):
        e0, e1 = heading_error[k], yaw_rate_error[k]
        for i in range(m):
            e0 -= C[0, i] * x[i]
            e1 -= C[1, i] * x[i]
        heading_out[k] = sign * (s_inv_sqrt[0, 0] * e0 + s_inv_sqrt[0, 1] * e1)
        yaw_rate_out[k] = sign * (s_inv_sqrt[1, 0] * e0 + s_inv_sqrt[1, 1] * e1)
        for i in range(m):
            v = gain[i, 0] * e0 + gain[i, 1] * e1
            for j in range(m):
                v += A[i, j] * x[j]
            x_next[i] = v
        x, x_next = x_next, x


@njit(cache=True)
def _whiten_span_pair(A, gain, C, s_inv_sqrt, errors_a, errors_b, start, stop, sign, out_a, out_b):
    """``_whiten_span`` of two series at once, ``errors_x = (heading, yaw rate)`` into ``out_x =
    (heading, yaw rate)``: each series' operations in ``_whiten_span``'s order, so the same numbers;
    two independent chains interleaved keep the processor busy where one waits on each result."""
    heading_a, yaw_rate_a = errors_a
    heading_b, yaw_rate_b = errors_b
    heading_out_a, yaw_rate_out_a = out_a
    heading_out_b, yaw_rate_out_b = out_b
    m = A.shape[0]
    xa, xa_next = np.zeros(m), np.zeros(m)
    xb, xb_next = np.zeros(m), np.zeros(m)
    for k in range(start, stop):
        a0, a1 = heading_a[k], yaw_rate_a[k]
        b0, b1 = heading_b[k], yaw_rate_b[k]
        for i in range(m):
            a0 -= C[0, i] * xa[i]
            a1 -= C[1, i] * xa[i]
            b0 -= C[0, i] * xb[i]
            b1 -= C[1, i] * xb[i]
        heading_out_a[k] = sign * (s_inv_sqrt[0, 0] * a0 + s_inv_sqrt[0, 1] * a1)
        yaw_rate_out_a[k] = sign * (s_inv_sqrt[1, 0] * a0 + s_inv_sqrt[1, 1] * a1)
        heading_out_b[k] = sign * (s_inv_sqrt[0, 0] * b0 + s_inv_sqrt[0, 1] * b1)
        yaw_rate_out_b[k] = sign * (s_inv_sqrt[1, 0] * b0 + s_inv_sqrt[1, 1] * b1)
        for i in range(m):
            va = gain[i, 0] * a0 + gain[i, 1] * a1
            vb = gain[i, 0] * b0 + gain[i, 1] * b1
            for j in range(m):
                va += A[i, j] * xa[j]
                vb += A[i, j] * xb[j]
            xa_next[i] = va
            xb_next[i] = vb
        xa, xa_next = xa_next, xa
        xb, xb_next = xb_next, xb


@njit(cache=True)
def _whiten_blocks_rows(A, gain, C, s_inv_sqrt, heading_errors, yaw_rate_errors, blocks):
    """``_whiten_blocks`` of every row of the (rows, N) errors: (rows, 2 N), two rows at a time."""
    rows, n = heading_errors.shape
    out = np.empty((rows, 2 * n))
    for row in range(0, rows - 1, 2):
        for b in range(blocks.shape[0]):
            _whiten_span_pair(
                A,
                gain,
                C,
                s_inv_sqrt,
                (heading_errors[row], yaw_rate_errors[row]),
                (heading_errors[row + 1], yaw_rate_errors[row + 1]),
                blocks[b, 0],
                blocks[b, 1],
                -1.0,
                (out[row, :n], out[row, n:]),
                (out[row + 1, :n], out[row + 1, n:]),
            )
    if rows % 2:
        for b in range(blocks.shape[0]):
            _whiten_span(
                A,
                gain,
                C,
                s_inv_sqrt,
                heading_errors[rows - 1],
                yaw_rate_errors[rows - 1],
                blocks[b, 0],
                blocks[b, 1],
                -1.0,
                out[rows - 1, :n],
                out[rows - 1, n:],
            )
    return out


@njit(cache=True)
def _whiten(A, gain, C, s_inv_sqrt, errors):
    n = errors.shape[0]
    out = np.empty((n, 2))
    _whiten_span(A, gain, C, s_inv_sqrt, errors[:, 0], errors[:, 1], 0, n, 1.0, out[:, 0], out[:, 1])
    return out


@njit(cache=True)
def _whiten_blocks(A, gain, C, s_inv_sqrt, heading_error, yaw_rate_error, blocks):
    n = heading_error.shape[0]
    out = np.empty(2 * n)
    for b in range(blocks.shape[0]):
        _whiten_span(
            A, gain, C, s_inv_sqrt, heading_error, yaw_rate_error, blocks[b, 0], blocks[b, 1], -1.0, out[:n], out[n:]
        )
    return out


def spectral_fisher_information(
    model: NoiseModel, slopes: list, n_samples: int, n_frequencies: int = 4096
) -> np.ndarray:
    """Whittle's Fisher information carried by the noise's spectrum alone.

        F_ij = (N / 2) mean_omega tr(Phi^-1 dPhi_i Phi^-1 dPhi_j),

    for the stationary error of (heading increment, yaw rate), Phi(omega) = s_delta^2 D H H^* D^*
    + diag(s_psi^2 |1 - e^{-i omega}|^2, s_r^2), D = diag(1 - e^{-i omega}, 1) (differencing the
    heading makes the rudder-noise walk stationary without changing the information).
    ``slopes`` holds, per parameter theta_j, (model at theta_j + step, model at theta_j - step,
    2 step): dPhi_j by central difference.

    Parameters
    ----------
    model : NoiseModel
        The noise model at the estimate.
    slopes : list
        Per parameter, (model at theta + step, model at theta - step, 2 step).
    n_samples : int
        Number of samples N of the record.
    n_frequencies : int
        Frequencies of the mean over omega.

    Returns
    -------
    numpy.ndarray
        The Fisher information matrix (one row and column per parameter).
    """
    omega = (np.arange(n_frequencies) + 0.5) * 2 * np.pi / n_frequencies
    diff = np.stack([1 - np.exp(-1j * omega), np.ones_like(omega)], axis=1)

    def spectrum(m: NoiseModel) -> np.ndarray:
        H = diff * m.transfer(omega)
        out = m.rudder_noise**2 * np.einsum("wi,wj->wij", H, H.conj())
        out[:, 0, 0] += m.heading_noise**2 * np.abs(diff[:, 0]) ** 2
        out[:, 1, 1] += m.yaw_rate_noise**2
        return out

    inverse = np.linalg.inv(spectrum(model))
    scaled = [inverse @ ((spectrum(plus) - spectrum(minus)) / width) for plus, minus, width in slopes]
    p = len(slopes)
    F = np.zeros((p, p))
    for i in range(p):
        for j in range(i, p):
            F[i, j] = F[j, i] = 0.5 * n_samples * float(np.mean(np.einsum("wij,wji->w", scaled[i], scaled[j]).real))
    return F
