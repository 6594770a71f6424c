"""Output-error refinement: minimise the free-run simulation error.

Equation-error regressions are biased when the yaw rate is noisy (the
noise sits in the regressors) and by the smoothing of derivatives. The
output-error stage starts from any regression estimate and solves

    min_theta  sum_k [(psi_sim_k - psi_k) / s_psi]^2 + [(r_sim_k - r_k) / s_r]^2

with bounded Gauss-Newton (scipy ``least_squares``, trust region
reflective) over the free physical parameters within their physical bounds
(K > 0, T1, T2 > 0, T3 >= 0, ...) and, per segment, the initial heading and
yaw rate. s_psi and s_r are the measurement noise levels estimated from
the high-frequency part of each signal. Using heading as well as yaw rate
makes the estimate the maximum-likelihood one under white output noise.
Standard errors come from the Jacobian, s^2 (J'J)^-1, inflated for any
residual autocorrelation.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import savgol_filter

from ..dataset import Dataset
from ..metrics import effective_sample_fraction
from ..structure import Structure
from .base import Estimate, Estimator, finish_estimate

MAX_SEGMENT_STATES = 12  # initial states are estimated for at most this many segments


def noise_level(values: np.ndarray, floor: float) -> float:
    """Std of white measurement noise: the residual of a local quadratic fit, corrected for its smoothing."""
    if len(values) < 15:
        return floor
    window = 11
    resid = values - savgol_filter(values, window, 2)
    # a quadratic over 11 points passes a fraction of white noise; undo that loss of variance
    return max(float(np.std(resid) / np.sqrt(1 - 0.4126)), floor)


class OutputError(Estimator):
    """Refine a starting estimator's result by minimising the free-run error."""

    def __init__(self, start: Estimator, max_iterations: int = 60, estimate_initial_states: bool = True):
        self.start = start
        self.max_iterations = max_iterations
        self.estimate_initial_states = estimate_initial_states
        self.name = f"{start.name}+oe"

    def fit(self, structure: Structure, dataset: Dataset) -> Estimate:
        first = self.start.fit(structure, dataset)
        return self.refine(structure, dataset, first)

    def refine(self, structure: Structure, dataset: Dataset, first: Estimate) -> Estimate:
        names = structure.free_names
        lower, upper = structure.bounds(names)
        params0 = structure.clip_to_bounds(first.parameters)
        x0 = np.array([params0[n] for n in names])
        segments = list(dataset.segments)
        with_states = self.estimate_initial_states and len(segments) <= MAX_SEGMENT_STATES
        bias0 = structure.measured_yaw_rate(np.zeros(1), params0)[0]
        if with_states:
            states0 = np.array([[dataset.heading[a], dataset.yaw_rate[a] - bias0] for a, _ in segments]).ravel()
            x0 = np.concatenate([x0, states0])
            lower = np.concatenate([lower, np.full(len(states0), -np.inf)])
            upper = np.concatenate([upper, np.full(len(states0), np.inf)])
        x0 = np.clip(x0, lower, upper)
        s_psi = noise_level(dataset.heading, np.radians(0.01))
        s_r = noise_level(dataset.yaw_rate, np.radians(0.01))
        fixed = {n: params0[n] for n in structure.fixed_names}

        def unpack(x):
            p = dict(fixed)
            p.update(zip(names, x[:len(names)]))
            if not with_states:
                return p, None
            st = x[len(names):].reshape(-1, 2)
            return p, [(psi0, r0, 0.0) for psi0, r0 in st]

        def residual(x):
            p, initial = unpack(x)
            psi, r = structure.simulate(p, dataset, initial=initial)
            res = np.concatenate([(psi - dataset.heading) / s_psi, (r - dataset.yaw_rate) / s_r])
            return np.where(np.isfinite(res), res, 1e6)

        result = least_squares(residual, x0, bounds=(lower, upper), x_scale="jac", method="trf",
                               max_nfev=self.max_iterations * (len(x0) + 1) // 2 + 20)
        params, _ = unpack(result.x)
        n_res = len(result.fun)
        dof = max(n_res - len(x0), 1)
        sigma2 = float(result.fun @ result.fun / dof)
        half = n_res // 2
        eff = min(effective_sample_fraction(result.fun[:half]), effective_sample_fraction(result.fun[half:]))
        J = result.jac
        try:
            cov = np.linalg.pinv(J.T @ J) * sigma2 / eff
            std = np.sqrt(np.clip(np.diag(cov)[:len(names)], 0, None))
        except np.linalg.LinAlgError:
            std = np.full(len(names), np.inf)
        std_errors = {n: float(s) for n, s in zip(names, std)}
        std_errors.update({n: 0.0 for n in structure.fixed_names})
        flags = [f for f in first.flags if f.endswith("_out_of_bounds") is False and f != "complex_time_constants"]
        at_bound = [n for n, v, lo, hi in zip(names, result.x, lower, upper)
                    if np.isclose(v, lo, atol=1e-6 * max(1, abs(lo)) if np.isfinite(lo) else 0)
                    or np.isclose(v, hi, atol=1e-6 * max(1, abs(hi)) if np.isfinite(hi) else 0)]
        flags += [f"at_bound:{n}" for n in at_bound]
        if not result.success:
            flags.append("oe_not_converged")
        info = {"start": first.method, "start_parameters": first.parameters,
                "noise_heading": s_psi, "noise_yaw_rate": s_r, "iterations": int(result.nfev),
                "cost_ratio": float(np.sqrt(sigma2)), "effective_sample_fraction": float(eff),
                "start_info": {k: v for k, v in first.info.items() if k != "excitation"}}
        return finish_estimate(structure, dataset, self.name, params, std_errors, flags, info)
