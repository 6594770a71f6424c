"""The estimator interface and the Estimate it returns.

Every estimator is an object with plain constructor parameters and one
method, ``fit(structure, dataset, starts=()) -> Estimate``; ``starts`` are
parameter sets (dicts) an iterative refinement also searches from (the last
window's estimate, the model without an effect with that effect at its
neutral values: ``Structure.neutral_effect_start``), and ``uses_starts`` says
whether an estimator reads them. Regression estimators only implement
``solve(X, y, sample_time)``; the shared ``RegressionEstimator.fit`` builds the
regression, maps coefficients to physical parameters, propagates the
coefficient covariance to standard errors (delta method, inflated for
residual autocorrelation), judges excitation and runs the model free on the
data for the fit figures.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from ..model.dataset import DataError, Dataset
from ..model.integrate import substeps_for
from ..model.metrics import effective_sample_fraction, free_run_fit
from ..model.signals import Signals, compute_signals
from ..model.structure import Regression, Structure, fastest_time_constant, nomoto_view

Z_95 = 1.96  # two-sided 95 % point of the normal distribution
MIN_RUDDER_STD = np.radians(1.0)  # rad: below this the rudder does not excite the hull
MIN_YAW_RATE_STD = np.radians(0.02)  # rad/s: an absolute floor under the noise-relative need
HARDLY_MOVES_SNR = 2.0  # yaw-rate std below this many noise levels: it hardly moves
# Relative standard errors (std / |value|) of the gain and the main time constant that three
# decisions accept, side by side. The parameters that play each role, in every model form: the
# gain K, the time constant T (T1), and in the acceleration form (a hull whose linear yaw damping is
# weak or negative) the rudder's yaw acceleration b (b0) for K and the damping a1 for the time
# constant. A limit of None leaves the role out of the decision.
RELATIVE_ERROR_ROLES = (("K",), ("T", "T1"), ("b", "b0"), ("a1",))
RELATIVE_ERROR_POLICIES = {
    #                 K     T, T1  b, b0  a1
    # a window that misses these does not determine the hull (its estimate is refused); a1 may be
    # near zero (a marginally stable hull), where no relative error is small: judged by the others
    "determined": (0.1, 0.3, 0.1, None),
    # a new online estimate is trusted (OK) within these: a 10 % error is then 3 (K) or 2.5 (T1)
    # standard errors away; a looser one that is determined is published as uncertain (WARN)
    "trusted": (0.03, 0.04, 0.03, 0.1),
    # the change detector's reference: a loosely known K travels with a cubic damping far off,
    # which mispredicts the next turns of the same hull (a false change); T1 may be looser: steady
    # turns determine K to 0.2 % but T1 only to 8-20 %, and such a reference still finds a change
    "reference": (0.03, 0.2, None, None),
}


def relative_error_limits(policy: str) -> dict:
    """The relative standard error limits of a decision, per parameter name.

    Parameters
    ----------
    policy : str
        A key of ``RELATIVE_ERROR_POLICIES``: "determined", "trusted" or "reference".

    Returns
    -------
    dict
        Parameter name -> largest accepted std / |value| (dimensionless).
    """
    return {
        name: limit
        for names, limit in zip(RELATIVE_ERROR_ROLES, RELATIVE_ERROR_POLICIES[policy])
        if limit is not None
        for name in names
    }


MAX_RELATIVE_ERRORS = relative_error_limits("determined")
TRUSTED_RELATIVE_ERRORS = relative_error_limits("trusted")
REFERENCE_RELATIVE_ERRORS = relative_error_limits("reference")


@dataclass
class Solution:
    """Regression coefficients, their covariance (up to the noise variance) and solver facts."""

    w: np.ndarray
    cov: np.ndarray
    info: dict = field(default_factory=dict)
    residual: np.ndarray | None = None


@dataclass(frozen=True)
class Influence:
    """Where in time a fit learnt its parameters.

    Each free parameter's share of its variance from each sample (squared rows of J (J'J)^-1,
    heading and yaw rate together; they sum to one),
    kept as cumulative sums at the fit's sample times (s). Information is seldom spread evenly:
    a window of steps followed by a straight leg learnt T1 from the steps alone."""

    time: np.ndarray  # s
    cumulative: dict  # parameter -> cumulative share at each sample time (ends at 1)

    def shares_within(self, start: float, end: float) -> dict:
        """The share of each parameter's variance learnt from the samples within [start, end].

        Parameters
        ----------
        start, end : float
            The time span (s).

        Returns
        -------
        dict
            {parameter: share in [0, 1]}.
        """
        a, b = np.searchsorted(self.time, start, "left"), np.searchsorted(self.time, end, "right")
        return {
            name: float((c[b - 1] if b > 0 else 0.0) - (c[a - 1] if a > 0 else 0.0))
            for name, c in self.cumulative.items()
        }


@dataclass
class Estimate:
    """Identified parameters with their standard errors, fit figures and flags."""

    structure: Structure
    method: str
    parameters: dict
    std_errors: dict
    fit: dict
    samples: int
    flags: list = field(default_factory=list)
    info: dict = field(default_factory=dict)
    window: tuple = (0.0, 0.0)
    influence: Influence | None = field(default=None, repr=False, compare=False)  # a search's, not a regression's
    covariance: np.ndarray | None = field(default=None, repr=False, compare=False)  # of the free parameters

    @property
    def ok(self) -> bool:
        """Whether the estimate may be used: no low_excitation, diverged or failed flag."""
        return not any(f in self.flags for f in ("low_excitation", "diverged", "failed"))

    def published(self) -> tuple[dict, dict]:
        """The parameters and standard errors a user reads.

        The fitted ones and, for a fit in the acceleration form, K and the time constants where the hull
        has them (positive linear damping), by the delta method through the fit's covariance.

        Returns
        -------
        parameters : dict
            Values by name (SI units).
        std_errors : dict
            Their standard errors (SI units).
        """
        values, errors = dict(self.parameters), dict(self.std_errors)
        if self.structure.form == "acceleration":
            nomoto, nomoto_errors = nomoto_view(
                self.parameters, self.covariance, self.structure.free_names, self.std_errors
            )
            values.update(nomoto)
            errors.update(nomoto_errors)
        return values, errors

    def course_stability(self) -> dict | None:
        """Whether the hull holds a straight course by itself, for a fit in the acceleration form.

        Its linear yaw damping a1 (negative: course-unstable; Norrbin, "Theory and observations on the use
        of a mathematical model for ship manoeuvring in deep and confined waters", 1970), how many standard
        errors it lies from zero, and a sentence. Within ``Z_95`` standard errors of zero the data do not
        decide.

        Returns
        -------
        dict or None
            {'verdict': 'stable', 'unstable' or 'undetermined', 'linear_damping': a1 (the structure's
            unit), 'std_error', 'z': a1 in standard errors, 'sentence'}; None for the Nomoto form, whose
            K, T > 0 is course-stable by construction.
        """
        if self.structure.form != "acceleration" or "a1" not in self.structure.free_names:
            return None
        a1, error = self.parameters["a1"], self.std_errors.get("a1", math.inf)
        z = a1 / error if error > 0 else math.copysign(math.inf, a1)
        unit = self.structure.parameter("a1").unit
        figures = f"linear yaw damping a1 = {a1:.3g} +- {error:.2g} {unit}, {abs(z):.1f} standard errors from zero"
        if abs(z) >= Z_95:
            verdict = "unstable" if a1 < 0 else "stable"
            sentence = f"course-{verdict}: {figures}"
        else:
            verdict = "undetermined"
            lean = "unstable" if a1 < 0 else "stable"
            sentence = f"course stability not determined by these data ({figures}; it leans {lean})"
        return {"verdict": verdict, "linear_damping": a1, "std_error": error, "z": z, "sentence": sentence}

    def to_json(self) -> dict:
        """The estimate as ``ship-ident identify --json`` writes it.

        Returns
        -------
        dict
            Structure, method, published parameters and standard errors (SI units), fit figures, sample
            count, flags, window (s) and the course stability of an acceleration-form fit.
        """
        values, errors = self.published()
        stability = self.course_stability()
        return {
            "structure": self.structure.to_json(),
            "method": self.method,
            "parameters": {k: float(v) for k, v in values.items()},
            "std_errors": {k: float(v) for k, v in errors.items()},
            **({"course_stability": stability} if stability else {}),
            "fit": self.fit,
            "samples": int(self.samples),
            "window": {"start": float(self.window[0]), "end": float(self.window[1])},
            "flags": list(self.flags),
            "info": self.info,
        }

    def dumps(self) -> str:
        """The estimate as a JSON string (``to_json``; NaN and inf written as JavaScript does).

        Returns
        -------
        str
            One JSON object.
        """
        return json.dumps(self.to_json(), allow_nan=True)


def excitation(dataset: Dataset) -> dict:
    """Rudder, yaw-rate and heading activity of a dataset (rad, rad/s, rad), and the activity below
    which each hardly moves: twice its sensor noise (the spread is then mostly noise)."""
    return {
        "rudder_std": float(np.std(dataset.rudder)),
        "yaw_rate_std": float(np.std(dataset.yaw_rate)),
        "yaw_rate_std_needed": max(HARDLY_MOVES_SNR * dataset.noise_std("yaw_rate", 0.0), MIN_YAW_RATE_STD),
        "heading_std": float(np.std(dataset.heading)),
        "heading_std_needed": HARDLY_MOVES_SNR * dataset.noise_std("heading"),
    }


def excitation_shortfall(
    dataset: Dataset,
    parameters: dict | None = None,
    std_errors: dict | None = None,
    min_rudder_std: float = MIN_RUDDER_STD,
) -> str | None:
    """Why the data cannot support an estimate (a sentence with the figures), or None.

    Without an estimate only the floors apply: a rudder that hardly moves (its std below
    ``min_rudder_std``, rad: the node's ``min_rudder_std``, by default ``MIN_RUDDER_STD``), a boat
    that hardly turns (yaw-rate and heading spreads both mostly noise; a slow ship's yaw rate may be
    buried in its noise while its heading, the integral, still determines the model). With an
    estimate's parameters and standard errors, the data are judged by what they determine: the gain
    and the main time constant within MAX_RELATIVE_ERRORS of their values, whatever the yaw-rate
    spread.

    Parameters
    ----------
    dataset : Dataset
        The data.
    parameters, std_errors : dict or None
        An estimate's parameters and standard errors (SI units), if there is one.
    min_rudder_std : float
        The rudder's smallest standard deviation that excites the hull (rad).

    Returns
    -------
    str or None
        Why the data fall short, or None when they suffice.
    """
    ex = excitation(dataset)
    still = ex["yaw_rate_std"] < ex["yaw_rate_std_needed"] and ex["heading_std"] < ex["heading_std_needed"]
    if ex["rudder_std"] < min_rudder_std or still:
        moves = "the rudder hardly moves" if ex["rudder_std"] < min_rudder_std else "the boat hardly turns"
        return (
            f"too little excitation ({moves}): rudder std {np.degrees(ex['rudder_std']):.2f} deg "
            f"(need {np.degrees(min_rudder_std):.2f}), yaw-rate std {np.degrees(ex['yaw_rate_std']):.3f} "
            f"deg/s and heading std {np.degrees(ex['heading_std']):.2f} deg (need "
            f"{np.degrees(ex['yaw_rate_std_needed']):.3f} or {np.degrees(ex['heading_std_needed']):.2f}, "
            "twice their noise)"
        )
    if parameters is None or std_errors is None:
        return None
    loose, figures = loose_parameters(parameters, std_errors, MAX_RELATIVE_ERRORS)
    if not loose:
        return None
    return (
        f"the window does not determine {', '.join(loose)}: {figures}; rudder std "
        f"{np.degrees(ex['rudder_std']):.2f} deg, yaw-rate std {np.degrees(ex['yaw_rate_std']):.3f} deg/s"
    )


def loose_parameters(parameters: dict, std_errors: dict, limits: dict) -> tuple[list, str]:
    """The parameters whose relative standard error exceeds its limit.

    Parameters
    ----------
    parameters, std_errors : dict
        Values and standard errors (SI units).
    limits : dict
        Largest std / |value| per parameter (``relative_error_limits``); the others are not judged.

    Returns
    -------
    names : list of str
        The parameters beyond their limits.
    figures : str
        Their figures, 'K 0.21 +- 0.03 (14 %, need <= 10 %), ...'.
    """
    relative = {
        name: std_errors.get(name, np.inf) / max(abs(parameters[name]), 1e-12) for name in limits if name in parameters
    }
    loose = {name: r for name, r in relative.items() if not r <= limits[name]}
    figures = ", ".join(
        f"{name} {parameters[name]:.4g} +- {std_errors.get(name, np.inf):.2g} "
        f"({100 * r:.0f} %, need <= {100 * limits[name]:g} %)"
        for name, r in loose.items()
    )
    return list(loose), figures


def excitation_flags(dataset: Dataset, parameters: dict | None = None, std_errors: dict | None = None) -> list[str]:
    return ["low_excitation"] if excitation_shortfall(dataset, parameters, std_errors) else []


def fit_substeps(h: float, params: dict) -> int:
    """RK4 substeps per sample for fitting and fit figures.

    Each step is at most 2/3 of the fastest time constant (free-run error ~1e-5 deg on seed 001's
    vessel, far below sensor noise).

    Parameters
    ----------
    h : float
        Sample time (s).
    params : dict
        The parameters (``fastest_time_constant``).

    Returns
    -------
    int
        Substeps per sample.
    """
    return substeps_for(h, fastest_time_constant(params), 1.5)


def finish_estimate(
    structure: Structure, dataset: Dataset, method: str, params: dict, std_errors: dict, flags: list, info: dict
) -> Estimate:
    """An estimate with its in-sample free-run fit, excitation facts and flags.

    Parameters
    ----------
    structure : Structure
        The model.
    dataset : Dataset
        The data fitted.
    method : str
        The estimator's name.
    params, std_errors : dict
        The fitted parameters and their standard errors (SI units).
    flags : list of str
        The estimator's flags; low excitation and a diverged free run are added.
    info : dict
        The estimator's facts.

    Returns
    -------
    Estimate
        The estimate over the dataset's time span.
    """
    psi_sim, r_sim = structure.simulate(params, dataset, substeps=fit_substeps(dataset.sample_time, params))
    fit = free_run_fit(dataset.heading, dataset.yaw_rate, psi_sim, r_sim)
    flags = list(dict.fromkeys(flags + excitation_flags(dataset) + (["diverged"] if fit["diverged"] else [])))
    info = dict(info, excitation=excitation(dataset))
    return Estimate(
        structure=structure,
        method=method,
        parameters=params,
        std_errors=std_errors,
        fit=fit,
        samples=dataset.n_samples,
        flags=flags,
        info=info,
        window=(float(dataset.time[0]), float(dataset.time[-1])),
    )


class Estimator:
    """Base class: fit a Structure to a Dataset, optionally also searching from given starts."""

    name = ""
    uses_starts = False  # True for iterative estimators, which search from the given starts

    def fit(self, structure: Structure, dataset: Dataset, starts: tuple = (), warm: bool = False) -> Estimate:
        """Fit ``structure`` to ``dataset``, searching also from ``starts``.

        Parameters
        ----------
        structure : Structure
            The model to fit (base model and effects).
        dataset : Dataset
            The data: rudder, heading, yaw rate (rad, rad/s) on a uniform grid, split at gaps.
        starts : tuple of dict
            Parameter sets (SI units) a search also starts from (the last window's estimate, ...).
        warm : bool
            ``starts[0]`` is the estimate of this model on a nearby window (an online refit): a search
            may start from the starts alone.

        Returns
        -------
        Estimate
            The parameters with their standard errors, fit figures and flags.
        """
        raise NotImplementedError


class RegressionEstimator(Estimator):
    """An estimator that solves the equation-error regression ``y = X w``."""

    def __init__(self, differentiation: str = "savgol"):
        self.differentiation = differentiation

    def solve(self, X: np.ndarray, y: np.ndarray, sample_time: float | None = None) -> Solution:
        """The coefficients w of the equation-error regression ``y = X w``.

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
        raise NotImplementedError

    def regression(self, structure: Structure, dataset: Dataset) -> Regression:
        """The equation-error regression of ``structure`` on ``dataset``: derivatives smoothed, columns built.

        Parameters
        ----------
        structure : Structure
            The model (its regression columns).
        dataset : Dataset
            The data (rad, rad/s).

        Returns
        -------
        Regression
            X, y and the column names.

        Raises
        ------
        DataError
            When the usable samples do not outnumber the coefficients.
        """
        structure.check_data(dataset)
        signals: Signals = compute_signals(dataset, self.differentiation)
        regression = structure.regression(signals)
        if regression.X.shape[0] <= regression.X.shape[1]:
            raise DataError(
                f"{regression.X.shape[0]} usable samples for {regression.X.shape[1]} "
                "coefficients; record a longer window"
            )
        return regression

    def fit(self, structure: Structure, dataset: Dataset, starts: tuple = (), warm: bool = False) -> Estimate:
        """The regression's closed-form fit: it has no search, so it ignores ``starts`` and ``warm``.

        The coefficients map back to physical parameters (``parameters_from_coefficients``); their
        standard errors come from the solution's covariance by the delta method, the residual variance
        inflated for its autocorrelation.

        Parameters
        ----------
        structure : Structure
            The model to fit (base model and effects).
        dataset : Dataset
            The data: rudder, heading, yaw rate (rad, rad/s) on a uniform grid, split at gaps.
        starts : tuple of dict
            Parameter sets (SI units) a search also starts from (the last window's estimate, ...).
        warm : bool
            Whether ``starts[0]`` is a nearby window's estimate (no search here: unused).

        Returns
        -------
        Estimate
            The parameters with their standard errors, fit figures and flags.
        """
        regression = self.regression(structure, dataset)
        solution = self.solve(regression.X, regression.y, dataset.sample_time)
        params, flags = structure.parameters_from_coefficients(solution.w, regression)
        residual = solution.residual if solution.residual is not None else regression.y - regression.X @ solution.w
        dof = max(len(residual) - len(solution.w), 1)
        sigma2 = float(residual @ residual / dof) / effective_sample_fraction(residual)
        std = coefficient_std_errors(structure, regression, solution.w, sigma2 * solution.cov)
        info = dict(
            solution.info,
            condition_number=float(np.linalg.cond(regression.X / column_scales(regression.X))),
            residual_std=float(np.sqrt(sigma2)),
            columns=regression.columns,
        )
        return finish_estimate(structure, dataset, self.name, structure.clip_to_bounds(params), std, flags, info)


def scaled_inverse(normal: np.ndarray) -> np.ndarray:
    """The inverse of a normal matrix J'J, its diagonal scaled to one.

    Unscaled, columns of very different sizes (a yaw-rate state's and alpha's 1e-7 of it) would lose
    the weak direction to rounding, and a pseudo-inverse would give it no error at all.

    Parameters
    ----------
    normal : ndarray
        A symmetric positive (semi-)definite matrix J'J.

    Returns
    -------
    ndarray
        Its inverse.

    Raises
    ------
    numpy.linalg.LinAlgError
        When it is singular.
    """
    scale = np.sqrt(np.maximum(np.diag(normal), 1e-300))
    return np.linalg.inv(normal / np.outer(scale, scale)) / np.outer(scale, scale)


def column_scales(X: np.ndarray) -> np.ndarray:
    """The RMS of each column: X / column_scales(X) has unit-RMS columns.

    Parameters
    ----------
    X : ndarray
        A regression matrix, samples by columns.

    Returns
    -------
    ndarray
        Each column's RMS (1 for an all-zero column).
    """
    scale = np.sqrt(np.mean(X**2, axis=0))
    return np.where(scale > 0, scale, 1.0)


def coefficient_std_errors(structure: Structure, regression: Regression, w: np.ndarray, cov_w: np.ndarray) -> dict:
    """Delta method: standard errors of the physical parameters from the coefficient covariance."""
    names = structure.parameter_names
    base, _ = structure.parameters_from_coefficients(w, regression)
    J = np.zeros((len(names), len(w)))
    for j in range(len(w)):
        step = 1e-6 * max(abs(w[j]), 1e-6)
        wp = w.copy()
        wp[j] += step
        shifted, _ = structure.parameters_from_coefficients(wp, regression)
        J[:, j] = [(shifted[n] - base[n]) / step for n in names]
    var = np.einsum("ij,jk,ik->i", J, cov_w, J)
    return {n: float(np.sqrt(max(v, 0.0))) if np.isfinite(v) else float("inf") for n, v in zip(names, var)}
