"""Cramer-Rao lower bound of the Nomoto parameters for a simulated record.

Model: measured heading psi_k = psi(t_k; theta) + e_psi, yaw rate
r_k = r(t_k; theta) + e_r, white Gaussian noise of known std s_psi (rad),
s_r (rad/s); the rudder is taken as known (its noise is not in the bound).
The Fisher information is

    F = S_psi' S_psi / s_psi^2 + S_r' S_r / s_r^2,

with S the output sensitivities d psi / d theta, d r / d theta at the true
parameters (central differences of the free-run simulation). theta holds
the free physical parameters and, as nuisance, the initial heading, yaw
rate and yaw acceleration of the record; the bound is the parameter block
of F^-1. A derived quantity g(theta) (e.g. T1 + T2 - T3) has the bound
grad(g)' F^-1 grad(g).
"""
from __future__ import annotations

import numpy as np

from ..dataset import Dataset
from ..structure import Structure


def output_sensitivities(structure: Structure, truth: dict, dataset: Dataset, initial: list,
                         relative_step: float = 1e-5) -> tuple[np.ndarray, list[str]]:
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


def cramer_rao_bound(structure: Structure, truth: dict, dataset: Dataset, initial: list,
                     heading_noise: float, yaw_rate_noise: float) -> dict:
    """Lower bounds on the std (SI units) of every free parameter and of ``T1+T2-T3`` (nomoto2)."""
    S, names = output_sensitivities(structure, truth, dataset, initial)
    n = dataset.n_samples
    weights = np.concatenate([np.full(n, 1 / heading_noise ** 2), np.full(n, 1 / yaw_rate_noise ** 2)])
    fisher = S.T @ (S * weights[:, None])
    cov = np.linalg.inv(fisher)
    p = len(structure.free_names)
    bound = {name: float(np.sqrt(cov[i, i])) for i, name in enumerate(structure.free_names)}
    if structure.order == 2:
        g = np.zeros(len(names))
        for name, sign in (("T1", 1.0), ("T2", 1.0), ("T3", -1.0)):
            g[structure.free_names.index(name)] = sign
        bound["T1+T2-T3"] = float(np.sqrt(g[:p] @ cov[:p, :p] @ g[:p]))
    return bound
