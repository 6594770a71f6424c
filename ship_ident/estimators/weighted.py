"""Reconstructed weighted LS-SVM with weights tuned by an adaptive PSO with mutation.

Weights (Suykens, De Brabanter, Lukas and Vandewalle, "Weighted least squares support vector
machines: robustness and sparse approximation", 2002) from the residual e of the unweighted
reconstructed fit, standardised by s = 1.4826 MAD(e):

    v_i = 1                          if |e_i/s| <= c1
        = (c2 - |e_i/s|) / (c2 - c1)  if c1 < |e_i/s| <= c2
        = 1e-4                       otherwise

The swarm searches (c1, c2 - c1, log10 gamma) to minimise the trimmed mean
squared one-step error on held-out blocks of the window (every fifth block
of 5 s). All particles of one iteration are solved in one batch: with the
per-row outer products Z[n] = x_n x_n' precomputed, the normal matrices of
the whole swarm are one matrix product V Z.

Adaptive PSO: each particle's inertia is set from its fitness rank
(good particles exploit with low inertia, poor ones explore with high);
mutation re-draws one coordinate of a random particle when the swarm's
spread collapses, against premature convergence. Deterministic for a seed.
"""

from __future__ import annotations

import numpy as np

from ..model.noise import robust_std
from .base import RegressionEstimator, Solution, column_scales
from .lssvm import ridge_primal

CHUNK_ROWS = 4096  # rows of the regression per batched product (the swarm's weights stay in cache)
BOUNDS = np.array(
    [
        [0.5, 4.0],  # c1: residuals below c1*s keep full weight
        [0.5, 8.0],  # c2 - c1: width of the down-weighting ramp
        [2.0, 9.0],
    ]
)  # log10 gamma


def robust_weights(standardised: np.ndarray, c1: np.ndarray, c2: np.ndarray) -> np.ndarray:
    """Suykens' weights for each (c1, c2) row: shape (particles, samples)."""
    a = np.abs(standardised)[None, :]
    c1, c2 = c1[:, None], c2[:, None]
    ramp = (c2 - a) / np.maximum(c2 - c1, 1e-9)
    return np.where(a <= c1, 1.0, np.where(a <= c2, ramp, 1e-4))


def robust_scale(e: np.ndarray) -> float:
    return robust_std(e) or float(np.std(e)) or 1.0


class SwarmObjective:
    """Held-out error of the weighted LS-SVM for a batch of (c1, c2-c1, log10 gamma)."""

    def __init__(self, X: np.ndarray, y: np.ndarray, held_out: np.ndarray):
        self.scale = column_scales(X)
        Xs = X / self.scale
        self.train = ~held_out
        Xt, yt = Xs[self.train], y[self.train]
        self.Xv, self.yv = Xs[held_out], y[held_out]
        w0 = np.linalg.lstsq(Xt, yt, rcond=None)[0]
        e = yt - Xt @ w0
        self.standardised = e / robust_scale(e)
        p = X.shape[1]
        self.Z = (Xt[:, :, None] * Xt[:, None, :]).reshape(len(yt), p * p)
        self.Zy = Xt * yt[:, None]
        self.p = p

    def solve(self, particles: np.ndarray) -> np.ndarray:
        c1 = particles[:, 0]
        c2 = c1 + particles[:, 1]
        gamma = 10.0 ** particles[:, 2]
        G = np.zeros((len(particles), self.p * self.p))
        rhs = np.zeros((len(particles), self.p))
        for start in range(0, len(self.standardised), CHUNK_ROWS):  # weights in cache, not in memory
            rows = slice(start, start + CHUNK_ROWS)
            V = robust_weights(self.standardised[rows], c1, c2)
            G += V @ self.Z[rows]
            rhs += V @ self.Zy[rows]
        G = G.reshape(-1, self.p, self.p) + np.eye(self.p)[None] / gamma[:, None, None]
        return np.linalg.solve(G, rhs[:, :, None])[:, :, 0]

    def __call__(self, particles: np.ndarray) -> np.ndarray:
        W = self.solve(particles)
        err2 = (self.yv[None, :] - W @ self.Xv.T) ** 2
        keep = max(1, int(0.98 * err2.shape[1]))
        return np.mean(np.partition(err2, keep - 1, axis=1)[:, :keep], axis=1)


def adaptive_pso(
    objective, bounds: np.ndarray, particles: int = 16, iterations: int = 12, seed: int = 0, mutation_rate: float = 0.2
) -> tuple[np.ndarray, float, dict]:
    """Minimise a batched objective over a box; returns best point, value and a trace."""
    rng = np.random.default_rng(seed)
    lo, hi = bounds[:, 0], bounds[:, 1]
    x = lo + rng.random((particles, len(lo))) * (hi - lo)
    x[0] = (lo + hi) / 2  # a sensible member from the start
    v = np.zeros_like(x)
    f = objective(x)
    pbest, pbest_f = x.copy(), f.copy()
    g = int(np.argmin(f))
    gbest, gbest_f = x[g].copy(), float(f[g])
    mutations = 0
    history = [gbest_f]
    for _ in range(iterations):
        rank = np.argsort(np.argsort(f)) / max(particles - 1, 1)
        inertia = 0.4 + 0.5 * rank  # adaptive: 0.4 (best) .. 0.9 (worst)
        r1, r2 = rng.random(x.shape), rng.random(x.shape)
        v = inertia[:, None] * v + 1.5 * r1 * (pbest - x) + 1.5 * r2 * (gbest - x)
        v = np.clip(v, -(hi - lo) / 2, (hi - lo) / 2)
        x = np.clip(x + v, lo, hi)
        spread = np.mean(np.std(x, axis=0) / (hi - lo))
        if spread < 0.05 or rng.random() < mutation_rate:
            i, d = rng.integers(particles), rng.integers(len(lo))
            x[i, d] = lo[d] + rng.random() * (hi[d] - lo[d])
            mutations += 1
        f = objective(x)
        better = f < pbest_f
        pbest[better], pbest_f[better] = x[better], f[better]
        g = int(np.argmin(pbest_f))
        if pbest_f[g] < gbest_f:
            gbest, gbest_f = pbest[g].copy(), float(pbest_f[g])
        history.append(gbest_f)
    return gbest, gbest_f, {"mutations": mutations, "history": history}


def held_out_blocks(n: int, block: int) -> np.ndarray:
    """Every fifth block of ``block`` rows is held out; blocks shrink so that a short window
    still holds out about a fifth of its rows."""
    block = max(1, min(block, n // 10))
    return (np.arange(n) // block) % 5 == 4


class RWLSSVM(RegressionEstimator):
    """Reconstructed weighted LS-SVM, weights and gamma tuned by adaptive PSO with mutation."""

    name = "rwlssvm"

    def __init__(
        self,
        particles: int = 16,
        iterations: int = 12,
        seed: int = 0,
        block_s: float = 5.0,
        differentiation: str = "savgol",
    ):
        super().__init__(differentiation)
        self.particles, self.iterations, self.seed, self.block_s = particles, iterations, seed, block_s

    def solve(self, X, y, sample_time=None):
        """The weighted LS-SVM whose weights and gamma the adaptive PSO tunes on held-out blocks of time.

        ``sample_time`` between rows sets the held-out blocks of ``block_s``; it is required.

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
        if sample_time is None:
            raise ValueError("rwlssvm holds out blocks of time: solve needs the sample time of the rows")
        held_out = held_out_blocks(len(y), int(round(self.block_s / sample_time)))
        objective = SwarmObjective(X, y, held_out)
        best, best_f, trace = adaptive_pso(objective, BOUNDS, self.particles, self.iterations, self.seed)
        c1, c2, gamma = best[0], best[0] + best[1], 10.0 ** best[2]
        w0 = np.linalg.lstsq(X, y, rcond=None)[0]
        e = y - X @ w0
        weights = robust_weights(e / robust_scale(e), np.array([c1]), np.array([c2]))[0]
        w, cov = ridge_primal(X, y, gamma, weights)
        residual = np.sqrt(weights) * (y - X @ w)
        return Solution(
            w=w,
            cov=cov,
            residual=residual,
            info={
                "gamma": gamma,
                "c1": c1,
                "c2": c2,
                "held_out_mse": best_f,
                "downweighted": int(np.sum(weights < 1.0)),
                "pso": trace,
            },
        )
