"""Output-error refinement: minimise the free-run simulation error.

Equation-error regressions are biased when the yaw rate is noisy (the
noise sits in the regressors) and by the smoothing of derivatives. The
output-error stage starts from any regression estimate and solves

    min_theta  sum_k [(psi_sim_k - psi_k) / s_psi]^2 + [(r_sim_k - r_k) / s_r]^2

with a bounded Levenberg-Marquardt over the free physical parameters
within their physical bounds (K > 0, T1, T2 > 0, T3 >= 0, ...). s_psi and s_r are the measurement noise
levels estimated from the high-frequency part of each signal.

Multiple shooting: every segment is cut into intervals of about
``shooting_s`` seconds, and each interval is simulated from its own
estimated initial state (heading, yaw rate and, for nomoto2, yaw
acceleration). Noise on the measured rudder drives the simulated heading
on a random walk (0.1 deg of rudder noise adds about 0.45 deg of heading
error over 600 s on seed 001's vessel, four times the heading noise);
restarting every interval keeps that drift below the heading noise, so the
output residual stays close to white and the estimate close to efficient.
The default of 30 s is where that walk, of variance (K s_delta)^2 h t, reaches
the heading noise variance for 0.1 deg of rudder and heading noise; it was
confirmed over noise seeds (``ship-ident bench efficiency``: 10 s loses
information to the extra initial states, 60 s or one long interval is
biased by the walk and the long-horizon cost is harder to optimise).
The Jacobian is a forward difference with one simulation per physical
parameter plus one per state component (the intervals' states touch
disjoint residuals, so they are perturbed together), all run side by side in
one compiled call (``Structure.simulate_runs``). Standard errors are
Newey-West (sandwich) ones, honest under the residual autocorrelation that
remains (``parameter_std_errors``). Residuals beyond 5 robust standard
deviations of the start's residual get Huber weights, so that sensor spikes
do not drag the fit.

The bounds are the physical ones narrowed by the data (``Structure.bounds``:
cubic_yaw keeps the model stable over the turn rates the window reaches). A
search that has not converged in ``max_iterations`` with its residuals near the
noise is crawling along a curved valley (T1-T2-T3-alpha of a slow ship took 48
iterations; the gain, T1 and cubic damping of a USV on a small zigzag, which
barely reaches the turn rates where the damping acts, trade along one): it goes
on with a gentler damping rule for up to twice as many iterations, a nomoto2 one
with T2 still at the foot of the T2 = T3 valley after a look along that valley
(``_valley_starts``); a search whose residuals are far above the noise misses
the motion and ends as it did. A
parameter within 1 % of a physical bound is reported ``at_bound`` (T1 = 999 s of 1000 s
is a search that ran off along the K, T1, alpha -> infinity ridge of a window
no model fits, not a hull), and T1 within 1 % of T2 ``repeated_time_constants``,
their standard errors infinite (the model is symmetric in them: on that fold only
their sum and product are determined).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ..model.dataset import Dataset, cut_segments
from ..model.effects import BOUND_SHARE, slow_time_constant
from ..model.filters import convolve_columns
from ..model.noise import robust_std
from ..model.structure import ACCELERATION_NAMES, Structure
from .base import Estimate, Estimator, Influence, finish_estimate, fit_substeps, scaled_inverse
from .shooting import ShootingProblem, normal_equations

MAX_INTERVALS = 64  # shooting intervals per window at most (each adds 2-3 unknowns)
CHI_SQUARE_TOLERANCE = 1e-2  # cost gains (in noise-variance units) below this end the search
MIN_INTERVAL_SAMPLES = 50  # shorter intervals are not split further
VALLEY_SHARES = (0.03, 0.1, 0.2, 0.35, 0.5)  # T2 / T1 of the starts along the T2 = T3 valley (nomoto2)
VALLEY_HELD_ITERATIONS = 8  # search iterations at each of them with T2 held
RESCUE_ITERATIONS_FACTOR = 2  # a search not converged in max_iterations goes on this many times longer
RESCUE_MAX_COST = 4.0  # ... when its mean squared residual is within this many noise variances
SHOOTING_SPAN = 3.0  # slow time constants per shooting interval at least (``shooting_length``)
RESHOOT_RATIO = 1.5  # a fit whose hull wants intervals this much longer than it used is searched again on them
SPARSE_INTERVALS = 12  # beyond this many intervals the Jacobian is stored sparse (cheaper J'J)
TIME_CONSTANT_STARTS = (1.0, 3.0, 10.0, 30.0, 100.0)  # s, main time constants also started from
START_POLISH_STEPS = 2  # Gauss-Newton steps on a start's gain, (then) rudder offset and states before comparing
# A regression start flagged so has missed the hull's time scale (a slow ship's yaw rate buried in its
# noise put T1 at its 0.01 s floor): the search then explores
MISSED_TIME_SCALE_FLAGS = (
    "complex_time_constants",
    "diverged",
    "T_out_of_bounds",
    "T1_out_of_bounds",
    "T2_out_of_bounds",
)
LINEAR_NAMES = ("K", "delta_r")  # a start's free run is (nearly) linear in these: fitted before starts are compared


def shooting_intervals(segments, samples_per_interval: int) -> tuple[tuple[int, int], ...]:
    """Cut each segment [a, b) into near-equal intervals of about ``samples_per_interval``."""
    total = sum(b - a for a, b in segments)
    return cut_segments(segments, max(samples_per_interval, MIN_INTERVAL_SAMPLES, int(np.ceil(total / MAX_INTERVALS))))


@dataclass
class LeastSquaresResult:
    """A search's end: the unknowns ``x``, their residuals ``fun``, the iterations and whether it
    converged; ``jac``, the Jacobian at ``x``, is taken by ``jacobian(x, fun)`` on first use (a
    profile's point needs its cost alone, not the simulations of a last Jacobian)."""

    x: np.ndarray
    fun: np.ndarray
    iterations: int
    success: bool
    jacobian: Callable = field(repr=False)
    known_jac: np.ndarray | None = field(default=None, repr=False)  # the Jacobian at x, once taken

    @property
    def jac(self):
        if self.known_jac is None:
            self.known_jac = self.jacobian(self.x, self.fun)
        return self.known_jac


def bounded_levenberg_marquardt(
    residual, jacobian, x0, lower, upper, max_iterations: int, tolerance: float = 1e-6, gentle: bool = False
) -> LeastSquaresResult:
    """Levenberg-Marquardt with Marquardt's diagonal scaling on the normal equations, bounds by
    projection (a parameter at a bound whose gradient points outward is held there).

    The normal equations are (p x p) with p the unknowns, so an iteration costs the
    Jacobian's simulations and almost nothing else (``jacobian`` may return a scipy sparse
    matrix; the one at the end is taken only when the result's ``jac`` is read). It stops when a
    step gains less than ``tolerance`` of the cost (far below the chi-square scatter of the cost,
    1/sqrt(N)) or less
    than ``CHI_SQUARE_TOLERANCE``: the residuals are in noise units, so such a step moves the
    parameters by a tenth of a standard error or less. The damping lam grows tenfold on a
    rejected step and shrinks tenfold on an accepted one; ``gentle`` (for a search that crawls
    along a curved valley, where lam then swings between a rejected and a needlessly small
    step) doubles it on rejections (x2, x4, ...) and shrinks it threefold (Nielsen's rule).
    """
    grow_first, shrink = (2.0, 3.0) if gentle else (10.0, 10.0)
    x = np.clip(np.asarray(x0, dtype=float), lower, upper)
    f = residual(x)
    cost = float(f @ f)
    lam, converged = 1e-3, False
    J = None  # the Jacobian at x, taken when a step is sought from x
    for iteration in range(1, max_iterations + 1):  # noqa: B007 (the count is returned)
        J = jacobian(x, f) if J is None else J
        g, A = normal_equations(J, f)
        free = ~(((x <= lower) & (g > 0)) | ((x >= upper) & (g < 0)))
        d = np.maximum(np.diag(A)[free], 1e-12)
        improved = False
        grow = grow_first
        for _ in range(24 if gentle else 12):
            step = np.zeros_like(x)
            try:
                step[free] = np.linalg.solve(A[np.ix_(free, free)] + lam * np.diag(d), -g[free])
            except np.linalg.LinAlgError:
                lam *= grow
                continue
            x_new = np.clip(x + step, lower, upper)
            f_new = residual(x_new)
            cost_new = float(f_new @ f_new)
            if cost_new < cost:
                improved = True
                break
            lam *= grow
            grow = grow * 2.0 if gentle else grow
        if not improved:
            converged = True  # no descent left at this precision
            break
        small_step = np.all(np.abs(x_new - x) <= tolerance * (np.abs(x) + 1e-3))
        small_gain = cost - cost_new <= max(tolerance * cost, CHI_SQUARE_TOLERANCE)
        x, f, cost, J = x_new, f_new, cost_new, None
        lam = max(lam / shrink, 1e-9)
        if small_step or small_gain:
            converged = True
            break
    return LeastSquaresResult(x=x, fun=f, iterations=iteration, success=converged, jacobian=jacobian, known_jac=J)


def held_bounds(lower: np.ndarray, upper: np.ndarray, held: dict) -> tuple[np.ndarray, np.ndarray]:
    """Copies of the bounds with each unknown of ``held`` (index -> value) at its value on both: the
    search's projection (``bounded_levenberg_marquardt``) keeps it there."""
    lower, upper = lower.copy(), upper.copy()
    for index, value in held.items():
        lower[index] = upper[index] = value
    return lower, upper


def parameter_std_errors(J, f: np.ndarray, n_samples: int, p: int, bandwidth: int) -> tuple[np.ndarray, ...]:
    """Heteroscedasticity-and-autocorrelation-consistent standard errors (Newey and West, "A simple,
    positive semi-definite, heteroskedasticity and autocorrelation consistent covariance matrix",
    1987) of the first ``p`` unknowns: bread (J'J)^-1 (``scaled_inverse``), meat the
    Bartlett-weighted long-run covariance of the per-sample scores J_k' f_k (heading and yaw-rate
    rows of one sample summed), lags up to ``bandwidth`` samples (one shooting interval: residuals
    of different intervals are nearly independent). Only the parameter rows of the bread are needed, so the long-run
    covariance is taken of the p-dimensional projected scores: u' W u with W the Toeplitz
    matrix of the Bartlett weights, W u one convolution (FFT for long lag windows), so the
    cost is linear in the samples. ``J`` may be a scipy sparse matrix. Also returns the plain
    Gauss-Newton errors sqrt(diag (J'J)^-1) (white residuals of unit variance) and each sample's
    share of their variances (``Influence``: n_samples x p, columns summing to one)."""
    bread, free = fold_inverse(normal_equations(J, f)[1])
    bread = bread[:p]
    projected = np.asarray(J @ bread.T)
    squares = projected[:n_samples] ** 2 + projected[n_samples:] ** 2
    shares = squares / np.maximum(squares.sum(axis=0), 1e-300)
    u = projected[:n_samples] * f[:n_samples, None] + projected[n_samples:] * f[n_samples:, None]
    lags = np.arange(-min(bandwidth, n_samples - 1), min(bandwidth, n_samples - 1) + 1)
    bartlett = 1.0 - np.abs(lags) / (bandwidth + 1.0)
    meat = u.T @ convolve_columns(u, bartlett)
    unknown = np.where(free[:p], np.inf, 0.0)  # along a direction the data do not see at all
    hac, plain = (np.sqrt(np.clip(v, 0, None)) + unknown for v in (np.diag(meat), np.diag(bread[:, :p])))
    return hac, plain, shares, meat


NULL_EIGENVALUE = 1e-13  # of the unit-diagonal normal matrix: a direction the residuals do not depend on


def fold_inverse(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The inverse of a normal matrix J'J on the directions the residuals depend on, and which
    unknowns have a part along one they do not.

    Where the model is symmetric in two parameters (nomoto2's poles at T1 = T2: the response
    1 / ((1 + T1 s)(1 + T2 s)) does not change to first order when they split) J'J is singular, and
    its inverse would spread rounding over every error; the gain and the other parameters are still
    determined. Eigen-directions below ``NULL_EIGENVALUE`` (of the matrix scaled to a unit
    diagonal) are left out of the inverse, and the unknowns with a part along them are flagged:
    their errors are infinite.

    Parameters
    ----------
    normal : ndarray
        A symmetric positive semi-definite matrix J'J.

    Returns
    -------
    inverse : ndarray
        Its inverse on the determined directions (the pseudo-inverse there).
    free : ndarray of bool
        The unknowns with a part along an undetermined direction.
    """
    scale = np.sqrt(np.maximum(np.diag(normal), 1e-300))
    values, vectors = np.linalg.eigh(normal / np.outer(scale, scale))
    null = values < NULL_EIGENVALUE * max(values[-1], 1e-300)
    kept = vectors[:, ~null]
    inverse = (kept / values[~null]) @ kept.T / np.outer(scale, scale)
    free = np.sum(vectors[:, null] ** 2, axis=1) > 1e-6
    return inverse, free


HUBER_THRESHOLD = 5.0  # robust standard deviations beyond which a residual counts linearly


def huber_weights(start_residual: np.ndarray, n_samples: int) -> np.ndarray:
    """Square roots of Huber's IRLS weights min(1, c s / |e|) for the heading and the yaw-rate
    halves of the start's residual, s = their robust std (1.4826 MAD) per half: isolated sensor spikes (tens of
    noise levels) then pull on the fit linearly, not quadratically."""
    weights = np.ones_like(start_residual)
    for half in (slice(0, n_samples), slice(n_samples, 2 * n_samples)):
        e = start_residual[half]
        scale = robust_std(e) or 1.0
        weights[half] = np.minimum(1.0, HUBER_THRESHOLD * scale / np.maximum(np.abs(e), 1e-300))
    return np.sqrt(weights)


class _Search:
    """The weighted free-run residuals of a ``ShootingProblem`` and their Jacobian, as the output-error
    search sees them: each sample's heading and yaw-rate error through the search's weighting
    ``weigh`` (noise model) and the Huber weights ``robust``; the unknowns bounded by ``lo``, ``hi``.

    Parameters
    ----------
    problem : ShootingProblem
        The unknowns and the free runs.
    lower, upper : ndarray
        Bounds of the parameters (the blocks' states are free).
    yaw_rate_bias : float
        The yaw-rate sensor's reading at rest (rad/s), taken off the blocks' initial yaw rates.
    """

    def __init__(self, problem: ShootingProblem, lower: np.ndarray, upper: np.ndarray, yaw_rate_bias: float):
        self.problem = problem
        self.upper = upper
        self.states0 = problem.initial_states(yaw_rate_bias)
        self.lo = np.concatenate([lower, np.full(self.states0.size, -np.inf)])
        self.hi = np.concatenate([upper, np.full(self.states0.size, np.inf)])
        n = problem.dataset.n_samples
        self.columns = problem.columns(np.concatenate([problem.owner, problem.owner]))  # rows: heading, yaw rate
        self.robust = np.ones(2 * n)  # Huber weights (square roots), fixed at the start
        self.weigh = None  # (psi_err, r_err) -> residual vector: the chosen start's weighting
        self.simulations = 0
        self._last = None  # (x, substeps, weighting, its weighted residuals): the last single run

    def substeps(self, x: np.ndarray) -> int:
        """RK4 substeps per sample at the parameters of the unknowns ``x`` (``fit_substeps``)."""
        return fit_substeps(self.problem.dataset.sample_time, self.problem.unpack(x)[0])

    def residuals(self, points, substeps: int, weighs=None) -> np.ndarray:
        """Weighted residual vectors of several points (rows), simulated in one compiled call;
        ``weighs``: each point's own weighting (default: the search's); a run that diverged gets
        residuals of 1e6."""
        out = np.full((len(points), 2 * self.problem.dataset.n_samples), 1e6)
        for k, weighed in enumerate(self._weighed(points, substeps, weighs)):
            if weighed is not None:
                out[k] = self.robust * weighed
        return out

    def _weighed(self, points, substeps: int, weighs) -> list:
        """Each point's free-run errors through its weighting, before the Huber weights; None for
        a run that diverged."""
        dataset = self.problem.dataset
        self.simulations += len(points)
        psi, r = self.problem.simulate(points, substeps)
        psi_err, r_err = psi - dataset.heading, r - dataset.yaw_rate
        finite = np.all(np.isfinite(psi_err), axis=1) & np.all(np.isfinite(r_err), axis=1)
        if not weighs and len(points) > 1 and hasattr(self.weigh, "rows"):  # one compiled call for all
            weighed = iter(self.weigh.rows(psi_err[finite], r_err[finite]))
            return [next(weighed) if finite[k] else None for k in range(len(points))]
        return [
            (weighs[k] if weighs else self.weigh)(psi_err[k], r_err[k]) if finite[k] else None
            for k in range(len(points))
        ]

    def residual(self, x: np.ndarray) -> np.ndarray:
        """The weighted residual vector at the unknowns ``x``. The last such run is kept: a search
        asks again for the point it starts from once its Huber weights are set."""
        substeps = self.substeps(x)
        last = self._last
        if last is not None and last[1] == substeps and last[2] is self.weigh and np.array_equal(last[0], x):
            weighed = last[3]
        else:
            weighed = self._weighed([x], substeps, None)[0]
            self._last = (x.copy(), substeps, self.weigh, weighed)
        return np.full(2 * self.problem.dataset.n_samples, 1e6) if weighed is None else self.robust * weighed

    def jacobian(self, x: np.ndarray, f0: np.ndarray, chosen=None):
        """Forward differences (``ShootingProblem``), all simulated in one call at the substeps of
        ``x`` whose residuals are ``f0``; the columns of the parameters not ``chosen`` (default: all)
        are zero."""
        problem = self.problem
        chosen = tuple(range(problem.n_params)) if chosen is None else chosen
        points, steps = problem.difference_points(x, self.upper, chosen)
        diff = self.residuals(points, self.substeps(x)) - f0
        return problem.jacobian(x, points, steps, diff, chosen, self.columns, len(problem.blocks) > SPARSE_INTERVALS)

    def polished(self, x: np.ndarray, weighting, gain_first: list, linear: list) -> tuple[np.ndarray, float]:
        """``x`` after up to START_POLISH_STEPS Gauss-Newton steps on the unknowns its free run is
        (nearly) linear in (``gain_first`` at the first step, ``linear`` after), each kept while it
        lowers the cost under ``weighting`` and the start's own Huber weights (sensor spikes steer
        neither the steps nor the choice), and that cost."""
        p = self.problem.n_params
        self.weigh, self.robust = weighting, np.ones(2 * self.problem.dataset.n_samples)
        self.robust = huber_weights(self.residual(x), self.problem.dataset.n_samples)
        f = self.residual(x)
        for number in range(START_POLISH_STEPS):
            unknowns = linear if number else gain_first
            Jc = self.jacobian(x, f, tuple(i for i in unknowns if i < p))[:, unknowns]
            gradient, normal = normal_equations(Jc, f)
            try:
                step = -scaled_inverse(normal) @ gradient
            except np.linalg.LinAlgError:
                break
            moved = x.copy()
            moved[unknowns] += step
            moved = np.clip(moved, self.lo, self.hi)
            f_moved = self.residual(moved)
            if not f_moved @ f_moved < f @ f:
                break
            x, f = moved, f_moved
        return x, float(f @ f)


class OutputError(Estimator):
    """Refine a starting estimator's result by minimising the free-run error (output error).

    A bounded Levenberg-Marquardt search (Levenberg 1944, Marquardt 1963) on multiple shooting
    intervals (Bock 1983), standard errors by Newey and West (1987) under the residuals'
    autocorrelation (see the module docstring).
    """

    uses_starts = True
    walk_limited = True  # shooting intervals no longer than the rudder-noise walk (``shooting_length``)

    def __init__(self, start: Estimator, max_iterations: int = 30, shooting_s: float = 30.0, explore: bool = True):
        """``explore``: when the regression start missed the time scale, also search from a range of
        main time constants (``fit``), fit a given start's gain, rudder offset and interval
        states before the starts are compared, and search with T2 held at each start along the
        T2 = T3 valley (``_along_valley``)."""
        self.start = start
        self.max_iterations = max_iterations
        self.shooting_s = shooting_s
        self.explore = explore
        # the diagnosis's figures were measured on fixed intervals
        self.shooting_span = SHOOTING_SPAN if explore else 0.0
        self.name = f"{start.name}+oe"

    def fit(self, structure: Structure, dataset: Dataset, starts: tuple = (), warm: bool = False) -> Estimate:
        """Minimise the free-run error from the regression fit, its conservative variant and each of ``starts``.

        The search goes on from whichever start simulates closest to the data; ``starts`` are parameter
        dicts (the last window's estimate, the model without its last effect; parameters a start lacks
        are the regression fit's). Without ``starts``, a model with effects also starts from the
        regression fit of the bare model with the effects at their neutral values (an effect's
        regression column can make the regression start course-unstable: KVLCC2 with cubic_yaw, T < 0);
        given starts take its place (they come from such models already). Without ``starts``, when the
        regression missed the time scale (MISSED_TIME_SCALE_FLAGS), the search also explores
        (``_refine``); a given start is a converged estimate of a nearby window, and a sound regression
        start needs no exploring (the refit stays as quick as it was). A ``warm`` fit whose first start
        holds every parameter of the model searches from that start alone, polished: the equation-error
        regression (about a sixth of an online refit's time) is not solved, and neither it nor its
        conservative variant is judged. On the online refits measured (bag replays of a quick USV, an
        hour of a mixed manoeuvre) the polished warm start won every comparison with them; a warm
        search that gets stuck or does not converge is followed by a cold fit, which starts from the
        regression (``online.window_fit``).

        Parameters
        ----------
        structure : Structure
            The model to fit.
        dataset : Dataset
            The data: rudder, heading, yaw rate (rad, rad/s) on a uniform grid, split at gaps.
        starts : tuple of dict
            Parameter sets (SI units) the search also starts from.
        warm : bool
            ``starts[0]`` is this model's estimate on a nearby window (an online refit).

        Returns
        -------
        Estimate
            The parameters (SI units) with Newey-West standard errors, the free-run fit, flags (a
            parameter on a bound, an unconverged search, the fold T1 = T2) and the search's facts in
            ``info`` (cost, cost ratio, Gauss-Newton errors, influence).
        """
        needed = (*structure.free_names, *structure.fixed_names)
        warm = warm and bool(starts) and all(n in starts[0] for n in needed)
        if warm:
            first = Estimate(structure, "warm start", dict(starts[0]), {}, {}, dataset.n_samples)
        else:
            first = self.start.fit(structure, dataset)
        explore = self.explore and not starts and any(f in MISSED_TIME_SCALE_FLAGS for f in first.flags)
        if not starts and structure.effects:
            bare = self.start.fit(Structure(structure.model, ()), dataset).parameters
            starts = (structure.neutral_effect_start(bare),)
        estimate = self._refine(structure, dataset, first, tuple(starts), explore, warm=warm)
        used = estimate.info.get("shooting_s", math.inf)
        if self.shooting_length(dataset, estimate.parameters) > RESHOOT_RATIO * used:
            # the starts missed the hull's time scale, and its shooting intervals with it (a ship's
            # regression put T1 at 0.01 s): the search again on the intervals of the hull found
            again = self._refine(structure, dataset, estimate, (estimate.parameters,), explore=False)
            if again.ok or not estimate.ok:
                estimate = again
        return estimate

    def fit_polished(self, structure: Structure, dataset: Dataset, starts: tuple) -> Estimate:
        """Minimise the free-run error from ``starts`` alone, each polished before they are compared.

        Every start's gain, rudder offset and interval states are fitted first (they enter the free
        run linearly), and a range of main time constants is tried beside them, as a cold fit that
        missed the time scale explores (``fit``); no regression start. A second opinion for starts
        whose costs as given do not tell their basins apart: a start a rudder delay's lead hides
        in looks as close to the data as one that leads to the delay.

        Parameters
        ----------
        structure : Structure
            The model to fit.
        dataset : Dataset
            The data: rudder, heading, yaw rate (rad, rad/s) on a uniform grid, split at gaps.
        starts : tuple of dict
            Parameter sets (SI units) holding every parameter of ``structure``.

        Returns
        -------
        Estimate
            As ``fit``'s.
        """
        first = Estimate(structure, "polished start", dict(starts[0]), {}, {}, dataset.n_samples)
        return self._refine(structure, dataset, first, tuple(starts), explore=True)

    def fit_held(
        self,
        structure: Structure,
        dataset: Dataset,
        estimate: Estimate,
        start: dict,
        held: tuple,
        weighted_at: dict | None = None,
    ) -> Estimate:
        """Minimise the free-run error with the parameters ``held`` fixed: one point of the cost's profile.

        From ``start`` (``estimate``'s parameters moved), with the parameters named in ``held`` fixed at
        their values there: how far the others move when those are set elsewhere. ``weighted_at``: the
        parameters whose noise model and Huber weights weigh the residuals (default: each start's own),
        so that the costs (``info['cost']``) of points of one profile compare.

        Parameters
        ----------
        structure : Structure
            The model to fit.
        dataset : Dataset
            The data: rudder, heading, yaw rate (rad, rad/s) on a uniform grid, split at gaps.
        estimate : Estimate
            The estimate whose profile is traced.
        start : dict
            The parameters moved for this point (SI units), the held ones among them.
        held : tuple of str
            The parameters held fixed.
        weighted_at : dict or None
            The parameters the residual weighting is computed at (SI units).

        Returns
        -------
        Estimate
            The refit with ``held`` fixed; ``info['cost']`` its cost (-2 log-likelihood, up to a constant).
        """
        first = replace(estimate, parameters=dict(estimate.parameters, **start))
        return self._refine(structure, dataset, first, (), explore=False, held=held, weighted_at=weighted_at)

    def held_point(
        self, structure: Structure, dataset: Dataset, estimate: Estimate, start: dict, held: tuple, weighted_at: dict
    ) -> tuple[dict, float]:
        """The parameters and cost of one point of a profile: ``fit_held`` without its standard errors.

        For the points of a profile whose standard errors and free-run fit nobody reads: neither the
        search's last Jacobian nor the free run they need is simulated.

        Parameters
        ----------
        structure, dataset, estimate, start, held, weighted_at
            As ``fit_held``'s.

        Returns
        -------
        parameters : dict
            The refit's parameters (SI units), T1 >= T2 as ``fit_held`` reports them.
        cost : float
            Its cost (-2 log-likelihood, up to a constant), ``fit_held``'s ``info['cost']``.
        """
        first = replace(estimate, parameters=dict(estimate.parameters, **start))
        problem, _, result, info = self._search(structure, dataset, first, (), False, held, weighted_at)
        params = problem.unpack(result.x)[0]
        if _swapped_time_constants(problem.names, params):
            params["T1"], params["T2"] = params["T2"], params["T1"]
        return params, info["cost"]

    def shooting_length(self, dataset: Dataset, params: dict) -> float:
        """Seconds per shooting interval for a hull near ``params``.

        ``shooting_s``, or SHOOTING_SPAN slow time constants (``slow_time_constant``) when longer
        (``explore`` fits; the diagnosis's figures were measured on fixed intervals), but no longer than
        the rudder-noise walk time s_psi^2 / ((K s_delta)^2 h) (``walk_limited``), where the heading
        drift the free run accumulates from the rudder's noise reaches the heading noise (30 s on the
        WLSSVM paper's USV). Each interval's own initial state costs the information of its first time
        constants: a ship's K (T1 66 s, prediction error) scattered 1.3 % RMS over noise seeds on 120 s
        intervals, 8.8 % on 50 s ones, 0.4 % on 200 s ones, at its standard error.

        Parameters
        ----------
        dataset : Dataset
            The data (its sample time h, s, and noise levels).
        params : dict
            The hull's parameters (SI units).

        Returns
        -------
        float
            The interval length (s).
        """
        length = self.shooting_s
        if "K" not in params:  # the acceleration form: a course-unstable hull's free run grows as
            return length  # exp(|a1| t), and intervals of several of its times would diverge
        main = slow_time_constant(params)
        if self.shooting_span * main > length:
            length = self.shooting_span * main
            if self.walk_limited:
                rudder_walk = (params["K"] * dataset.noise_std("rudder")) ** 2 * dataset.sample_time
                length = min(length, dataset.noise_std("heading") ** 2 / rudder_walk)
        return max(length, self.shooting_s)

    @staticmethod
    def residual_weighting(structure, dataset, params0, s_psi, s_r, intervals):
        """Map free-run errors to the residual vector: each scaled by its white-noise level.

        The log-determinant of the residual covariance per sample in those units is 0 here (it does not
        depend on the parameters); with the squared residuals it makes -2 log-likelihood.

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
        return (lambda psi_err, r_err: np.concatenate([psi_err / s_psi, r_err / s_r])), 0.0

    @staticmethod
    def bandwidth(intervals) -> int:
        """Newey-West lag window: residuals of different intervals are nearly independent.

        Parameters
        ----------
        intervals : list of (int, int)
            The shooting intervals, half-open sample-index ranges.

        Returns
        -------
        int
            The lag window (samples): the longest interval.
        """
        return max(b - a for a, b in intervals)

    @staticmethod
    def _starts(structure: Structure, names: list, x0: np.ndarray, params0: dict, explore: bool) -> list:
        """The regression's start, a conservative one (effects at their neutral values, T2 and T3
        small), since a noisy regression can start the simulation unstable, and (``explore``) the
        conservative one with its main time constant at each of TIME_CONSTANT_STARTS (T2 a tenth of it): a
        regression on a yaw rate buried in its noise can miss the time scale altogether (a slow
        ship's T1 of 15 s came out at its 0.01 s floor, and every search from there stayed in
        that basin)."""
        conservative = x0.copy()
        for i, name in enumerate(names):
            if name in ("K", "T", "T1") or name in ACCELERATION_NAMES:
                continue
            if name == "T2":
                conservative[i] = min(params0["T2"], 0.1 * params0["T1"])
            elif name == "T3":
                conservative[i] = 0.0
            else:
                conservative[i] = structure.parameter(name).initial
        time_scales = []
        main = "T1" if "T1" in names else "T" if "T" in names else None
        for value in TIME_CONSTANT_STARTS if main and explore else ():
            scaled = conservative.copy()
            scaled[names.index(main)] = value
            if "T2" in names:
                scaled[names.index("T2")] = 0.1 * value
                scaled[names.index("T3")] = 0.0
            time_scales.append(scaled)
        return [x0, conservative, *time_scales]

    @staticmethod
    def _in_valley_foot(names: list, x: np.ndarray) -> bool:
        """T2 below the smallest valley share of T1: where a search up the T2 = T3 valley
        starts its crawl (nomoto2 only)."""
        return "T2" in names and x[names.index("T2")] < VALLEY_SHARES[0] * x[names.index("T1")]

    @staticmethod
    def _valley_starts(names: list, x: np.ndarray) -> list:
        """Variants of the start ``x`` along the T2 = T3 valley of nomoto2 (none for nomoto1).

        When T3 is close to T2 the zero cancels the fast pole and the response is nearly
        first order in T1: the cost is almost flat along T2 - T3 = const, and a search that
        starts with both near zero (as smoothed regressions often give) crawls up that curved
        valley, lam swinging between a rejected and a needlessly small step, for 50-100
        iterations (boats of issue 13's ranges: 30 iterations ended oe_not_converged with T2 at
        0.02-0.06 s of 0.9-1.3 s). Variants with T2 at 3-50 % of T1 (``VALLEY_SHARES``) and the
        start's T3 - T2 (so T1 + T2 - T3 is kept) are tried before the search goes on gently."""
        if "T2" not in names or "T3" not in names:
            return []
        t1, t2, t3 = names.index("T1"), names.index("T2"), names.index("T3")
        out = []
        for share in VALLEY_SHARES:
            valley = x.copy()
            valley[t2] = share * x[t1]
            valley[t3] = max(valley[t2] + x[t3] - x[t2], 0.0)
            out.append(valley)
        return out

    def _refine(
        self,
        structure: Structure,
        dataset: Dataset,
        first: Estimate,
        starts: tuple,
        explore: bool,
        held: tuple = (),
        weighted_at: dict | None = None,
        warm: bool = False,
    ) -> Estimate:
        """Minimise the free-run error from ``first`` (the regression fit, and its conservative
        variant) or from any of ``starts``, whichever simulates closest to the data; ``explore``:
        also from a range of time constants, every start's gain, rudder offset and states polished
        first (a cold fit; a warm one, from an estimate of a nearby window, needs neither); the
        parameters named in ``held`` stay at ``first``'s values; ``weighted_at`` (parameters): every
        start weighed with the noise model and Huber weights there (``fit_held``); ``warm``:
        ``starts[0]`` is the model's estimate on a nearby window, searched from alone (polished)."""
        return self._estimate(*self._search(structure, dataset, first, starts, explore, held, weighted_at, warm))

    def _search(
        self,
        structure: Structure,
        dataset: Dataset,
        first: Estimate,
        starts: tuple,
        explore: bool,
        held: tuple,
        weighted_at: dict | None,
        warm: bool = False,
    ) -> tuple[ShootingProblem, Estimate, LeastSquaresResult, dict]:
        """``_refine``'s search: its shooting problem, ``first``, the search's end and its facts."""
        names = structure.free_names
        params0 = structure.clip_to_bounds(first.parameters)
        lower, upper = held_bounds(*structure.bounds(names, dataset), {names.index(n): params0[n] for n in held})
        hull = dict(params0, **starts[0]) if starts else params0  # a given start knows the hull best
        shooting_s = self.shooting_length(dataset, hull)  # each interval restarts from its own fitted state
        intervals = shooting_intervals(dataset.segments, int(round(shooting_s / dataset.sample_time)))
        problem = ShootingProblem(structure, dataset, intervals, names, {n: params0[n] for n in structure.fixed_names})
        search = _Search(problem, lower, upper, structure.yaw_rate_bias(params0))
        x0 = self._best_start(search, first, params0, starts, explore, weighted_at, warm)
        if weighted_at is not None:  # the Huber weights of that point, its states from the data
            at = np.concatenate([[structure.clip_to_bounds(weighted_at)[n] for n in names], search.states0.ravel()])
            search.robust = huber_weights(search.residual(at), dataset.n_samples)
        else:
            search.robust = huber_weights(search.residual(x0), dataset.n_samples)
        result, iterations = self._minimise(search, x0)
        info = {
            "start": first.method,
            "start_parameters": first.parameters,
            "noise_heading": dataset.noise_std("heading"),
            "noise_yaw_rate": dataset.noise_std("yaw_rate"),
            "iterations": iterations,
            "simulations": search.simulations,
            "shooting_intervals": len(intervals),
            "shooting_s": shooting_s,
            "cost": float(result.fun @ result.fun),  # squared weighted residuals (-2 log-likelihood + const)
            "gauss_newton_std": None,  # with the standard errors (``_estimate``)
            "cost_ratio": float(np.sqrt(result.fun @ result.fun / max(len(result.fun) - len(x0), 1))),
            "start_info": {k: v for k, v in first.info.items() if k != "excitation"},
        }
        return problem, first, result, info

    def _best_start(
        self,
        search: _Search,
        first: Estimate,
        params0: dict,
        starts: tuple,
        explore: bool,
        weighted_at: dict | None,
        warm: bool = False,
    ) -> np.ndarray:
        """The unknowns of the start that simulates closest to the data (``_refine``), its
        weighting set as the search's; each start judged with the noise model at its own parameters
        (-2 log-likelihood: one fixed at a regression start that missed the time scale favours
        starts near it) and with the unknowns its free run is linear in (gain, rudder offset,
        interval states) fitted; a ``warm`` fit judges ``starts`` alone (``fit``)."""
        problem, structure, dataset = search.problem, search.problem.structure, search.problem.dataset
        names, p, h = problem.names, problem.n_params, dataset.sample_time
        s_psi, s_r = dataset.noise_std("heading"), dataset.noise_std("yaw_rate")
        x0 = np.array([params0[n] for n in names])
        guesses = ([] if warm else self._starts(structure, names, x0, params0, explore)) + [
            np.array([structure.clip_to_bounds(dict(params0, **s))[n] for n in names]) for s in starts
        ]
        points = [np.clip(np.concatenate([g, search.states0.ravel()]), search.lo, search.hi) for g in guesses]
        substeps = max(fit_substeps(h, problem.unpack(x)[0]) for x in points)
        at = [problem.unpack(x)[0] for x in points] if weighted_at is None else [weighted_at] * len(points)
        weighings = []  # one noise model per distinct parameter set (a Riccati equation each)
        for i, q in enumerate(at):
            same = next((weighings[j] for j in range(i) if at[j] == q), None)
            weighings.append(same or self.residual_weighting(structure, dataset, q, s_psi, s_r, problem.blocks))
        linear = [names.index(n) for n in LINEAR_NAMES if n in names] + list(range(p, problem.size))
        # the first step holds the rudder offset: at a gain far off its column (the gain times the
        # offset) is tiny and the step would send the offset to its bound, losing a slow ship's start
        gain_first = [i for i in linear if i >= p or names[i] != "delta_r"]
        # a given start (a nearby window's estimate) is polished too when exploring is on (the
        # diagnosis, which starts candidates from other models' fits, keeps its figures without):
        # the interval states taken from the data (yaw acceleration 0) suit a hull whose rudder
        # lead T3 is small; a ship with a rudder lead of many seconds puts even its own good
        # estimate far from the data until the interval states are polished with it
        if explore:
            first_polished = 0
        else:
            first_polished = len(guesses) - len(starts) if self.explore else len(points)
        # a plain start equal to a polished one (a warm fit's estimate, also given as a start) is not
        # judged apart: its polished twin costs at most as much (Huber weights <= 1, steps kept
        # only when they lower the cost)
        twins = points[first_polished:]
        plain = [i for i in range(first_polished) if not any(np.array_equal(points[i], q) for q in twins)]
        costs = [math.inf] * first_polished
        if plain:
            judged = search.residuals([points[i] for i in plain], substeps, [weighings[i][0] for i in plain])
            for i, cost in zip(plain, np.sum(judged**2, axis=1)):
                costs[i] = cost
        for i in range(first_polished, len(points)):
            points[i], cost = search.polished(points[i], weighings[i][0], gain_first, linear)
            costs.append(cost)
        search.robust = np.ones(2 * dataset.n_samples)
        best = int(np.argmin(costs + dataset.n_samples * np.array([d for _, d in weighings])))
        search.weigh = weighings[best][0]
        return points[best]

    def _minimise(self, search: _Search, x0: np.ndarray) -> tuple[LeastSquaresResult, int]:
        """The bounded search from ``x0``, and its iterations; a model that explains the data to near
        its noise but did not converge, crawling along a valley (up the T2 = T3 valley from its
        foot: jump along it first), searched on gently (a model that misses the motion, residuals
        far above the noise, is not helped by more search)."""
        p = search.problem.n_params
        result = bounded_levenberg_marquardt(
            search.residual, search.jacobian, x0, search.lo, search.hi, self.max_iterations
        )
        iterations = result.iterations
        in_valley_foot = self._in_valley_foot(search.problem.names, result.x[:p])
        if not result.success and result.fun @ result.fun <= RESCUE_MAX_COST * len(result.fun):
            start, valley_iterations = self._along_valley(search, result.x) if in_valley_foot else (result.x, 0)
            result = bounded_levenberg_marquardt(
                search.residual,
                search.jacobian,
                start,
                search.lo,
                search.hi,
                RESCUE_ITERATIONS_FACTOR * self.max_iterations,
                gentle=True,
            )
            iterations += valley_iterations + result.iterations
        return result, iterations

    def _along_valley(self, search: _Search, x: np.ndarray) -> tuple[np.ndarray, int]:
        """The best of ``x`` and its variants along the T2 = T3 valley, each with the yaw
        accelerations of the intervals' starts back at zero (the ones fitted with a small T2
        mean nothing with a larger one) and, with ``explore``, searched with T2 held
        (VALLEY_HELD_ITERATIONS: the gain, T1 and alpha follow T2 up the valley, which a variant
        alone does not, and a search from a small T2 crawls along the flat valley for many
        iterations; the diagnosis keeps the variants alone, its figures were measured so); and the
        search iterations spent."""
        problem = search.problem
        names, p, n_state = problem.names, problem.n_params, problem.n_state
        variants = self._valley_starts(names, x[:p])
        if not variants:
            return x, 0
        states = x[p:].copy()
        states[2::n_state] = search.states0[:, 2]
        points = [x] + [np.clip(np.concatenate([g, states]), search.lo, search.hi) for g in variants]
        if not self.explore:
            substeps = max(fit_substeps(problem.dataset.sample_time, problem.unpack(q)[0]) for q in points)
            return points[int(np.argmin(np.sum(search.residuals(points, substeps) ** 2, axis=1)))], 0
        t2 = names.index("T2")
        best, best_cost, iterations = x, float(np.sum(search.residual(x) ** 2)), 0
        for point in points[1:]:
            held_lo, held_hi = held_bounds(search.lo, search.hi, {t2: point[t2]})
            found = bounded_levenberg_marquardt(
                search.residual, search.jacobian, point, held_lo, held_hi, VALLEY_HELD_ITERATIONS
            )
            iterations += found.iterations
            if found.fun @ found.fun < best_cost:
                best, best_cost = found.x, float(found.fun @ found.fun)
        return best, iterations

    def _estimate(self, problem: ShootingProblem, first: Estimate, result: LeastSquaresResult, info: dict) -> Estimate:
        """The estimate at the search's end ``result``: standard errors with the residuals'
        correlation (Newey-West), flags of parameters on a physical bound, an unconverged search
        and repeated time constants, and ``info`` with the Gauss-Newton errors."""
        structure, dataset, names = problem.structure, problem.dataset, problem.names
        p = problem.n_params
        params, _ = problem.unpack(result.x)
        std, gauss_newton, shares, covariance = parameter_std_errors(
            result.jac, result.fun, dataset.n_samples, p, bandwidth=self.bandwidth(problem.blocks)
        )
        std_errors = {n: float(s) for n, s in zip(names, std)}
        cumulative = dict(zip(names, np.cumsum(shares, axis=0).T))
        std_errors.update({n: 0.0 for n in structure.fixed_names})
        flags = [
            f
            for f in first.flags
            if not f.endswith("_out_of_bounds")
            and not f.startswith("at_bound:")
            and f not in ("complex_time_constants", "diverged")
        ]  # the start's, not this fit's
        # the physical bounds: the data's stability limit of alpha is no physical bound
        at_bound = [n for n, v in zip(names, result.x) if structure.parameter(n).bound_reached(v) is not None]
        flags += [f"at_bound:{n}" for n in at_bound]
        if not result.success:
            flags.append("oe_not_converged")
        if _swapped_time_constants(names, params):
            params["T1"], params["T2"] = params["T2"], params["T1"]
            std_errors["T1"], std_errors["T2"] = std_errors["T2"], std_errors["T1"]
            cumulative["T1"], cumulative["T2"] = cumulative["T2"], cumulative["T1"]
        if "T2" in names and np.isclose(params["T1"], params["T2"], rtol=BOUND_SHARE):
            # the poles met: the search sits on the fold T1 = T2 of the symmetric pair, at the edge
            # of real time constants; their sum and product are determined there, neither alone
            # (a hull whose rudder lead exceeds its main time constant lands there)
            std_errors["T1"] = std_errors["T2"] = float("inf")
            flags.append("repeated_time_constants")
        info = dict(info, gauss_newton_std={n: float(s) for n, s in zip(names, gauss_newton)})
        estimate = finish_estimate(structure, dataset, self.name, params, std_errors, flags, info)
        return replace(estimate, influence=Influence(dataset.time, cumulative), covariance=covariance)


def _swapped_time_constants(names: list, params: dict) -> bool:
    """Whether a fit's T2 exceeds its T1: the model is symmetric in them, and T1 >= T2 is reported."""
    return "T2" in names and params["T2"] > params["T1"]
