"""Least squares and the LS-SVM family with a linear kernel.

LS-SVM (Suykens and Vandewalle, "Least squares support vector machine classifiers", 1999):
min 1/2 w'w + gamma/2 sum v_i e_i^2, e_i = y_i - x_i'w - b. Seed 001 is "Identification of Unmanned
Surface Vehicle Maneuverability Parameters Based on Improved WLSSVM" (Journal of Unmanned Undersea
Systems, doi:10.11993/j.issn.2096-3920.2022-0044), whose vessel and Table 2 the tests use.

* ``lssvm`` is seed 001's original form: the bias b is in the model and the
  constant regressor of the rudder offset sits inside the kernel. Its dual

      [ 0   1'              ] [b]   [0]
      [ 1   X X' + I/gamma  ] [a] = [y],   w = X' a,

  carries the constraint sum(a) = 0, so the weight of any constant column
  of X is w_c = c * sum(a) = 0 exactly: delta_r comes out 0 (-100 %) and
  the offset ends in b, which is no physical parameter. This is the
  failure of seed 001's Table 2, reproduced on purpose.
* ``rlssvm`` is the reconstructed form. The seed paper's own "cosine
  processing" is not available to us; our reconstruction follows its
  diagnosis: drop the bias b, so that every physical parameter owns a
  coefficient (the constant column's weight is K*delta_r; the cubic column
  no longer competes with b), and scale every column to unit RMS so that
  the ridge term 1/(2 gamma) w'w treats all parameters alike. It is solved
  in the primal, (X_s' V X_s + I/gamma) w_s = X_s' V y, at O(N p^2) cost,
  which equals the bias-free dual (X_s X_s' + (gamma V)^-1) a = y, w_s = X_s' a
  (tested).
"""

from __future__ import annotations

import numpy as np

from .base import RegressionEstimator, Solution, column_scales

DUAL_MAX_SAMPLES = 1500  # the N x N dual (O(N^3)) is solved up to this size; beyond, its exact primal twin


def ridge_primal(X: np.ndarray, y: np.ndarray, gamma: float, weights: np.ndarray | None = None):
    """Weighted ridge regression on unit-RMS columns, without a bias.

    Parameters
    ----------
    X : ndarray
        Regression matrix, samples by columns.
    y : ndarray
        Targets.
    gamma : float
        Regularisation: the ridge term is 1 / (2 gamma) w'w on the scaled columns.
    weights : ndarray or None
        Per-sample weights v (default 1).

    Returns
    -------
    w : ndarray
        Coefficients, in the units of the original columns.
    covariance : ndarray
        A^-1 X_s' V^2 X_s A^-1 with A = X_s' V X_s + I / gamma, in the original columns' units: the
        coefficients' covariance per unit noise variance.
    """
    scale = column_scales(X)
    Xs = X / scale
    v = np.ones(len(y)) if weights is None else weights
    A = Xs.T @ (Xs * v[:, None]) + np.eye(X.shape[1]) / gamma
    A_inv = np.linalg.inv(A)
    ws = A_inv @ (Xs.T @ (v * y))
    cov = A_inv @ (Xs.T @ (Xs * (v**2)[:, None])) @ A_inv
    return ws / scale, cov / np.outer(scale, scale)


def lssvm_dual_bias_free(X: np.ndarray, y: np.ndarray, gamma: float, weights: np.ndarray | None = None) -> np.ndarray:
    """Bias-free dual on unit-RMS columns; returns w in original units (tests prove primal == dual)."""
    scale = column_scales(X)
    Xs = X / scale
    v = np.ones(len(y)) if weights is None else weights
    alpha = np.linalg.solve(Xs @ Xs.T + np.diag(1.0 / (gamma * v)), y)
    return (Xs.T @ alpha) / scale


def lssvm_dual_with_bias(X: np.ndarray, y: np.ndarray, gamma: float) -> tuple[np.ndarray, float, np.ndarray]:
    """Seed 001's LS-SVM dual with a bias.

    Parameters
    ----------
    X : ndarray
        Regression matrix, samples by columns.
    y : ndarray
        Targets.
    gamma : float
        Regularisation.

    Returns
    -------
    w : ndarray
        Coefficients (the weight of a constant column is exactly 0).
    b : float
        The bias.
    a : ndarray
        The dual variables (sum(a) == 0).
    """
    n = len(y)
    M = np.empty((n + 1, n + 1))
    M[0, 0] = 0.0
    M[0, 1:] = 1.0
    M[1:, 0] = 1.0
    M[1:, 1:] = X @ X.T + np.eye(n) / gamma
    sol = np.linalg.solve(M, np.concatenate(([0.0], y)))
    b, alpha = sol[0], sol[1:]
    return X.T @ alpha, float(b), alpha


def lssvm_primal_with_bias(X: np.ndarray, y: np.ndarray, gamma: float) -> tuple[np.ndarray, float]:
    """Exact primal twin of the dual with bias: ridge on w, b free (the mean is removed)."""
    xm, ym = X.mean(axis=0), y.mean()
    Xc = X - xm
    w = np.linalg.solve(Xc.T @ Xc + np.eye(X.shape[1]) / gamma, Xc.T @ (y - ym))
    return w, float(ym - xm @ w)


class OLS(RegressionEstimator):
    """Ordinary least squares on the equation-error regression (reference)."""

    name = "ols"

    def solve(self, X, y, sample_time=None):
        """Ordinary least squares: w = argmin |y - X w|^2, covariance (X'X)^-1.

        Parameters
        ----------
        X : numpy.ndarray
            The (n, p) regression matrix: one row per sample, one column per regression coefficient.
        y : numpy.ndarray
            The (n,) regression target (the yaw acceleration, rad/s^2, or what the structure regresses).
        sample_time : float or None
            Time between rows (s), for solvers that hold out blocks of time.

        Returns
        -------
        Solution
            The coefficients w, their covariance up to the noise variance, and solver facts.
        """
        w, *_ = np.linalg.lstsq(X, y, rcond=None)
        return Solution(w=w, cov=np.linalg.pinv(X.T @ X))


class LSSVM(RegressionEstimator):
    """Seed 001's original LS-SVM: linear kernel with bias, constant regressor in the kernel."""

    name = "lssvm"

    def __init__(self, gamma: float = 1e4, differentiation: str = "savgol"):
        super().__init__(differentiation)
        self.gamma = gamma

    def solve(self, X, y, sample_time=None):
        """The LS-SVM with bias (Suykens and Vandewalle 1999), its dual or, for a long window, its primal twin.

        Parameters
        ----------
        X : numpy.ndarray
            The (n, p) regression matrix: one row per sample, one column per regression coefficient.
        y : numpy.ndarray
            The (n,) regression target (the yaw acceleration, rad/s^2, or what the structure regresses).
        sample_time : float or None
            Time between rows (s), for solvers that hold out blocks of time.

        Returns
        -------
        Solution
            The coefficients w, their covariance up to the noise variance, and solver facts.
        """
        if len(y) <= DUAL_MAX_SAMPLES:
            w, b, alpha = lssvm_dual_with_bias(X, y, self.gamma)
            solver = "dual"
        else:
            w, b = lssvm_primal_with_bias(X, y, self.gamma)
            solver = "primal-equivalent"
        constant = np.all(X == X[:1], axis=0)
        w[constant] = 0.0  # sum(a) = 0 makes them zero; remove the round-off (~1e-13)
        Xc = X - X.mean(axis=0)
        cov = np.linalg.pinv(Xc.T @ Xc + np.eye(X.shape[1]) / self.gamma)
        return Solution(w=w, cov=cov, info={"gamma": self.gamma, "bias": b, "solver": solver}, residual=y - X @ w - b)


class RLSSVM(RegressionEstimator):
    """Reconstructed LS-SVM: bias-free, unit-scaled columns, solved in the primal."""

    name = "rlssvm"

    def __init__(self, gamma: float = 1e6, differentiation: str = "savgol"):
        super().__init__(differentiation)
        self.gamma = gamma

    def solve(self, X, y, sample_time=None):
        """The bias-free LS-SVM on unit-scaled columns, solved in the primal: a ridge regression with 1/gamma.

        Parameters
        ----------
        X : numpy.ndarray
            The (n, p) regression matrix: one row per sample, one column per regression coefficient.
        y : numpy.ndarray
            The (n,) regression target (the yaw acceleration, rad/s^2, or what the structure regresses).
        sample_time : float or None
            Time between rows (s), for solvers that hold out blocks of time.

        Returns
        -------
        Solution
            The coefficients w, their covariance up to the noise variance, and solver facts.
        """
        w, cov = ridge_primal(X, y, self.gamma)
        return Solution(w=w, cov=cov, info={"gamma": self.gamma, "solver": "primal"})
