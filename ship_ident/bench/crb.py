"""Cramer-Rao lower bound of the Nomoto parameters for a simulated record.

Model: measured heading psi_k = psi(t_k; theta) + e_psi, yaw rate
r_k = r(t_k; theta) + e_r, white Gaussian noise of known std s_psi (rad),
s_r (rad/s). With a known rudder the Fisher information is

    F = S_psi' S_psi / s_psi^2 + S_r' S_r / s_r^2,

with S the output sensitivities d psi / d theta, d r / d theta at the true
parameters (central differences of the free-run simulation). theta holds
the free physical parameters and, as nuisance, the initial heading, yaw
rate and yaw acceleration of the record; the bound is the parameter block
of F^-1. A derived quantity g(theta) (e.g. T1 + T2 - T3) has the bound
grad(g)' F^-1 grad(g).

With rudder-sensor noise of std s_delta the simulation runs on the measured
rudder and the output error is no longer white: it adds the hull's response
to the rudder noise (``innovations.py``; the measured rudder is treated as
the input and its noise as independent of it, the Berkson view, exact to
O(s_delta^2 / var(delta)), here 1e-4). The error is Gaussian with a
theta-dependent covariance Sigma, and

    F = S' Sigma^-1 S + 1/2 tr(Sigma^-1 dSigma Sigma^-1 dSigma):

the first term by whitening every sensitivity column with the Kalman
innovation filter of the true model, the second, the information in the
noise's own spectrum (a few percent of the total here), by Whittle's
frequency-domain formula. This is the bound for the records the estimators
actually get; the known-rudder bound is lower and unattainable with them.
"""

from __future__ import annotations

import numpy as np

from ..estimators.base import fit_substeps
from ..estimators.innovations import innovation_filter, noise_model, spectral_fisher_information
from ..model.dataset import Dataset
from ..model.structure import Structure

# the parameters the linearised noise model depends on (either form)
NOISE_SHAPING = ("K", "T", "T1", "T2", "T3", "b", "b0", "b1", "m2", "a1")


def output_sensitivities(
    structure: Structure, truth: dict, dataset: Dataset, initial: list, relative_step: float = 1e-5
) -> tuple[np.ndarray, list[str]]:
    """Stacked [d psi; d r] / d theta (2N x (p + 3 per segment)) and the names of theta's entries."""
    names = list(structure.free_names)
    columns = []
    for name in names:
        step = relative_step * max(abs(truth[name]), 1e-3)
        outs = []
        for sign in (1.0, -1.0):
            p = dict(truth)
            p[name] = truth[name] + sign * step
            outs.append(np.concatenate(structure.simulate(p, dataset, initial=initial)))
        columns.append((outs[0] - outs[1]) / (2 * step))
    for i in range(len(dataset.segments)):
        for c, label in enumerate(("psi0", "r0", "rdot0")):
            step = 1e-6
            outs = []
            for sign in (1.0, -1.0):
                init = [list(s) for s in initial]
                init[i][c] += sign * step
                outs.append(np.concatenate(structure.simulate(truth, dataset, initial=init)))
            columns.append((outs[0] - outs[1]) / (2 * step))
            names.append(f"{label}[{i}]")
    return np.column_stack(columns), names


def _noise_models(structure: Structure, truth: dict, dataset: Dataset, noise: tuple) -> tuple:
    h = dataset.sample_time
    substeps = fit_substeps(h, truth)

    def model(params):
        return noise_model(structure, params, h, substeps, *noise)

    slopes = []
    for name in structure.free_names:
        if name in NOISE_SHAPING:
            step = 1e-5 * abs(truth[name])
            slopes.append(
                (
                    model(dict(truth, **{name: truth[name] + step})),
                    model(dict(truth, **{name: truth[name] - step})),
                    2 * step,
                )
            )
    return model(truth), slopes


def fisher_information(
    structure: Structure,
    truth: dict,
    dataset: Dataset,
    initial: list,
    heading_noise: float,
    yaw_rate_noise: float,
    rudder_noise: float = 0.0,
) -> tuple:
    """Fisher information of theta (free parameters, then the initial states) and theta's names."""
    S, names = output_sensitivities(structure, truth, dataset, initial)
    n = dataset.n_samples
    if rudder_noise == 0.0:
        weights = np.concatenate([np.full(n, 1 / heading_noise**2), np.full(n, 1 / yaw_rate_noise**2)])
        return S.T @ (S * weights[:, None]), names
    model, slopes = _noise_models(structure, truth, dataset, (rudder_noise, heading_noise, yaw_rate_noise))
    kalman = innovation_filter(model)
    whitened = np.empty((n, 2, S.shape[1]))
    for j in range(S.shape[1]):
        series = np.column_stack([S[:n, j], S[n:, j]])
        for a, b in dataset.segments:
            whitened[a:b, :, j] = kalman.whiten(series[a:b])
    whitened = whitened.reshape(2 * n, -1)
    fisher = whitened.T @ whitened
    shaping = [i for i, name in enumerate(structure.free_names) if name in NOISE_SHAPING]
    fisher[np.ix_(shaping, shaping)] += spectral_fisher_information(model, slopes, n)
    return fisher, names


def cramer_rao_bound(
    structure: Structure,
    truth: dict,
    dataset: Dataset,
    initial: list,
    heading_noise: float,
    yaw_rate_noise: float,
    rudder_noise: float = 0.0,
) -> dict:
    """Lower bounds on the std (SI units) of every free parameter and of ``T1+T2-T3`` (nomoto2 form);
    ``dataset`` carries the true rudder (the sensitivities), ``rudder_noise`` its sensor noise."""
    fisher, names = fisher_information(structure, truth, dataset, initial, heading_noise, yaw_rate_noise, rudder_noise)
    cov = np.linalg.inv(fisher)
    p = len(structure.free_names)
    bound = {name: float(np.sqrt(cov[i, i])) for i, name in enumerate(structure.free_names)}
    if "T1" in structure.free_names:
        g = np.zeros(len(names))
        for name, sign in (("T1", 1.0), ("T2", 1.0), ("T3", -1.0)):
            g[structure.free_names.index(name)] = sign
        bound["T1+T2-T3"] = float(np.sqrt(g[:p] @ cov[:p, :p] @ g[:p]))
    return bound


def identifiability(
    structure: Structure, truth: dict, dataset: Dataset, heading_noise: float, yaw_rate_noise: float
) -> tuple[float, dict]:
    """Whether the output-error problem determines every free parameter of ``structure`` at
    ``truth`` on the rudder of ``dataset`` (white sensor noise of std ``heading_noise`` rad and
    ``yaw_rate_noise`` rad/s): the condition number of the parameters' Fisher information, the
    initial states marginalised (Schur complement) and each parameter scaled by its value, and
    each parameter's Cramer-Rao bound relative to its value. A free direction (parameters that
    can move together without changing the motion) shows as a huge condition number."""
    initial = [(dataset.heading[a], dataset.yaw_rate[a], 0.0) for a, _ in dataset.segments]
    fisher, _ = fisher_information(structure, truth, dataset, initial, heading_noise, yaw_rate_noise)
    p = len(structure.free_names)
    states = fisher[p:, p:]
    marginal = fisher[:p, :p] - fisher[:p, p:] @ np.linalg.pinv(states) @ fisher[p:, :p]  # nomoto1 has no r' state
    scale = np.array([abs(truth[n]) for n in structure.free_names])
    scaled = marginal * np.outer(scale, scale)
    relative = np.sqrt(np.clip(np.diag(np.linalg.pinv(scaled)), 0.0, None))
    return float(np.linalg.cond(scaled)), {n: float(r) for n, r in zip(structure.free_names, relative)}
