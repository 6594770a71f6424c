"""Truncated LS-SVM (seed 000): solve through the SVD and drop small singular values.

Seed 000 is Xu and Guedes Soares, "Data-Driven Parameter Estimation of Nonlinear Ship Manoeuvring
Model in Shallow Water Using Truncated Least Squares Support Vector Machines" (2023).

With unit-RMS columns X_s = U S V', the bias-free linear LS-SVM with
gamma -> infinity is w_s = V S^-1 U' y; multicollinearity shows as tiny
singular values whose terms amplify noise. The truncated solution keeps the
k largest: w_s = sum_{i<=k} v_i (u_i'y) / s_i, with k chosen by

* ``gcv``: minimise ||y - X w_k||^2 / (N - k)^2 (generalised cross-validation);
* ``lcurve``: the corner of maximum curvature of (log ||r_k||, log ||w_k||);
* ``picard``: the largest k for which the Fourier coefficients |u_i'y| still
  decay faster than s_i (discrete Picard condition), i.e. |u_i'y| / s_i
  stops growing beyond the noise level.

The chosen k and the rule are reported in the estimate's info.
"""

from __future__ import annotations

import numpy as np

from .base import RegressionEstimator, Solution, column_scales

TRUNCATION_RULES = ("gcv", "lcurve", "picard")


def truncation_level(s: np.ndarray, beta: np.ndarray, n: int, residual_floor: float, rule: str) -> int:
    """Number of singular values kept, by ``rule`` (s descending, beta = U'y)."""
    p = len(s)
    res2 = np.array([residual_floor + np.sum(beta[k:] ** 2) for k in range(1, p + 1)])
    if rule == "gcv":
        gcv = res2 / (n - np.arange(1, p + 1)) ** 2
        return int(np.argmin(gcv)) + 1
    if rule == "lcurve":
        if p < 3:
            return p
        norms = np.array([np.sqrt(np.sum((beta[:k] / s[:k]) ** 2)) for k in range(1, p + 1)])
        x, y = np.log(np.sqrt(res2)), np.log(norms)
        curvature = np.zeros(p)
        for k in range(1, p - 1):
            a, b, c = np.array([x[k - 1], y[k - 1]]), np.array([x[k], y[k]]), np.array([x[k + 1], y[k + 1]])
            ab, bc, ca = np.linalg.norm(b - a), np.linalg.norm(c - b), np.linalg.norm(a - c)
            area2 = abs((b - a)[0] * (c - a)[1] - (b - a)[1] * (c - a)[0])
            curvature[k] = 2 * area2 / max(ab * bc * ca, 1e-300)
        return int(np.argmax(curvature)) + 1
    if rule == "picard":
        noise = np.sqrt(residual_floor / max(n - p, 1))
        keep = np.abs(beta) > 2.0 * noise
        return max(1, int(np.flatnonzero(keep)[-1]) + 1) if keep.any() else 1
    raise ValueError(f"unknown truncation rule {rule!r}; choose from {', '.join(TRUNCATION_RULES)}")


class TLSSVM(RegressionEstimator):
    """Truncated LS-SVM of seed 000 (SVD of the scaled regression matrix)."""

    name = "tlssvm"

    def __init__(self, rule: str = "gcv", differentiation: str = "savgol"):
        super().__init__(differentiation)
        if rule not in TRUNCATION_RULES:
            raise ValueError(f"unknown truncation rule {rule!r}; choose from {', '.join(TRUNCATION_RULES)}")
        self.rule = rule

    def solve(self, X, y, sample_time=None):
        """The truncated LS-SVM (Xu and Guedes Soares 2023): SVD of the scaled regression, small values dropped.

        The number of singular values kept is chosen by ``rule`` (generalised cross-validation or the
        L-curve, ``truncation_level``).

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
        scale = column_scales(X)
        U, s, Vt = np.linalg.svd(X / scale, full_matrices=False)
        beta = U.T @ y
        floor = float(y @ y - beta @ beta)
        k = truncation_level(s, beta, len(y), max(floor, 0.0), self.rule)
        ws = Vt[:k].T @ (beta[:k] / s[:k])
        cov = (Vt[:k].T / s[:k] ** 2) @ Vt[:k]
        return Solution(
            w=ws / scale,
            cov=cov / np.outer(scale, scale),
            info={"truncation": k, "of": len(s), "rule": self.rule, "singular_values": [float(v) for v in s]},
        )
