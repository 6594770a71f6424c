"""Prediction-error refinement: the free-run error whitened by a Kalman innovation filter.

Noise on the measured rudder (s_delta) is input noise: driven through the
hull, it makes the free-run heading and yaw rate wander in a coloured way
that the white-noise weighting of the output-error stage ignores (it fights
the wander with restarts alone). Here the free-run error of each shooting
interval,

    u_k = y_k - y_sim,k(theta),   y = (heading, measured yaw rate),

is modelled as the response of the linearised hull to the rudder noise plus
white sensor noise,

    xi_{k+1} = A xi_k + b n_k,  u_k = C xi_k + v_k,  n ~ N(0, s_delta^2), v ~ N(0, R),

with A and b the one-sample transition of the Nomoto model at rest (from the
same compiled integrator; b is in fact a two-tap moving average, since the
rudder is linear between samples: ``innovations.py``) and R = diag(s_psi^2, s_r^2). The steady-state
Kalman predictor of that model (discrete Riccati equation) turns u into its
innovations e_k = u_k - C xi_hat_k, white with covariance S, and the
refinement minimises sum_k |S^-1/2 e_k|^2: the prediction-error (maximum-
likelihood) criterion of the output-error model with coloured noise. The
filter restarts with each shooting interval (120 s, each from its own
estimated state; ``+oe`` needs 30 s because it has no filter): within an
interval the filter discounts the rudder-noise walk, and the restarts keep
the search out of the local minima that one long free run of an
approximately right model has (KVLCC2 with cubic_yaw: one free run over the
whole record ended at alpha = -1.4e4 s^2/rad^2; 30, 60 and 120 s intervals
all find the damping that grows in turns). At 120 s the efficiency is that
of one free run per record (RMS / CRB 0.8-1.05, ``bench efficiency``) and
the held-out free run of ``bench peers`` is the best of all methods. The filter is
fixed at the starting estimate (its dependence on theta is second order).
With a noise-free rudder the gain vanishes and this is the plain output-error
fit.
"""

from __future__ import annotations

import numpy as np

from .innovations import InnovationFilter, innovation_filter, noise_model
from .output_error import OutputError


class Whitening:
    """The residual vector of free-run errors: their innovations through ``kalman``, the predictor
    restarted at each shooting interval's first sample (``InnovationFilter.whiten_blocks``); called
    on one run's (heading errors rad, yaw-rate errors rad/s), or on the rows of several (``rows``)."""

    def __init__(self, kalman: InnovationFilter, blocks: np.ndarray):
        self.kalman = kalman
        self.blocks = blocks

    def __call__(self, psi_err: np.ndarray, r_err: np.ndarray) -> np.ndarray:
        return self.kalman.whiten_blocks(psi_err, r_err, self.blocks)

    def rows(self, psi_errs: np.ndarray, r_errs: np.ndarray) -> np.ndarray:
        """The residual vectors of the rows of (runs, N) heading and yaw-rate errors, (runs, 2 N)."""
        return self.kalman.whiten_blocks_rows(psi_errs, r_errs, self.blocks)


class PredictionError(OutputError):
    """Refine a starting estimate by the prediction-error criterion (rudder noise as input noise).

    The free-run error whitened by a steady-state Kalman predictor (Kalman 1960) of the rudder
    noise's walk, the maximum-likelihood criterion of the output-error model with coloured noise
    (Ljung, "System Identification: Theory for the User", 1999).
    """

    walk_limited = False  # the innovation filter takes in the rudder noise's walk

    def __init__(self, start, max_iterations: int = 30, shooting_s: float = 120.0, explore: bool = True):
        super().__init__(start, max_iterations=max_iterations, shooting_s=shooting_s, explore=explore)
        self.name = f"{start.name}+pem"

    @staticmethod
    def residual_weighting(structure, dataset, params0, s_psi, s_r, intervals):
        """Map free-run errors to their whitened Kalman innovations S^-1/2 e_k, interval by interval.

        The log-determinant of the innovations' covariance S per sample depends on the parameters
        (through the noise model linearised at ``params0``); with the squared residuals it makes
        -2 log-likelihood.

        Parameters
        ----------
        structure : Structure
            The model.
        dataset : Dataset
            The data (its rudder noise sets the input-noise model).
        params0 : dict
            The parameters the noise model is linearised at (SI units).
        s_psi, s_r : float
            White noise levels of the heading (rad) and the yaw rate (rad/s).
        intervals : list of (int, int)
            The shooting intervals, half-open sample-index ranges.

        Returns
        -------
        weigh : callable
            (heading errors rad, yaw-rate errors rad/s) -> the residual vector (dimensionless).
        log_det : float
            Log-determinant of the residual covariance per sample in those units.
        """
        from .base import fit_substeps

        h = dataset.sample_time
        s_delta = dataset.noise_std("rudder", np.radians(0.001))
        kalman = innovation_filter(noise_model(structure, params0, h, fit_substeps(h, params0), s_delta, s_psi, s_r))

        return Whitening(kalman, np.array(intervals, dtype=np.int64).reshape(-1, 2)), kalman.log_det_covariance

    @staticmethod
    def bandwidth(intervals) -> int:
        """Newey-West lag window: innovations are white, so a short window only guards against model error.

        Parameters
        ----------
        intervals : list of (int, int)
            The shooting intervals (unused: the window is fixed).

        Returns
        -------
        int
            The lag window (samples): 10.
        """
        return 10  # innovations are white: a short lag window only guards against model error
