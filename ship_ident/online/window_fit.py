"""The full fit of an online window: excitation, warm or cold start, and the fit's quality.

A window is fitted when it excites the hull (``excitation_shortfall``'s floors on the rudder and the
turning), warm from the last good estimate when there is one of the same method, and afresh when
the warm search got stuck on a bound, did not converge or ended on the fold T1 = T2. The estimate
then has to determine the gain and the main time constant (MAX_RELATIVE_ERRORS), and its free run
has to follow the measured yaw rate as closely as the window's noise allows. Every refusal is a
``Verdict``.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from ..estimators import make_estimator
from ..estimators.base import Estimate, excitation_shortfall
from ..model.dataset import DataError
from ..model.metrics import noise_limited_correlation
from ..model.structure import StructureError
from .verdicts import LAST_GOOD, Verdict

# Estimator flags that make an estimate unusable even with a good-looking fit: the closed-form
# map gave a gain or time constant outside its physical range, the output-error search ended
# with the gain or the main time constant on a bound (no hull has K = 100 1/s) or on the fold
# T1 = T2, or it stopped before it converged.
STUCK_FLAGS = ("at_bound:K", "at_bound:T", "at_bound:T1")  # a warm start that ends here is refitted cold
# ... and one whose search did not converge or ended on the fold T1 = T2 (each time constant undetermined)
RETRY_COLD_FLAGS = STUCK_FLAGS + ("oe_not_converged", "repeated_time_constants")
POOR_FIT_FLAGS = (
    "complex_time_constants",
    "K_out_of_bounds",
    "T_out_of_bounds",
    "T1_out_of_bounds",
    "T2_out_of_bounds",
    "oe_not_converged",
    "repeated_time_constants",
) + STUCK_FLAGS


class WindowFit(NamedTuple):
    """A window's estimate that passed the fit's checks, and the estimator that made it."""

    estimate: Estimate
    estimator: object


def fit_window(config, structure, dataset, last_good) -> WindowFit | Verdict:
    """Every free parameter of ``structure`` fitted on a window, or why not.

    Parameters
    ----------
    config : OnlineConfig
        The identifier's configuration (``method``, ``min_rudder_std`` in rad, ``min_fit_correlation``).
    structure : Structure
        The model to fit.
    dataset : Dataset
        The window, resampled (SI units).
    last_good : Estimate or None
        The estimate in force: the warm start when it is good and of the same method.

    Returns
    -------
    WindowFit or Verdict
        The estimate (with the estimator's own standard errors) and its estimator; or the verdict
        that refuses the window: too_little_excitation (codes ``below_floors``,
        ``parameters_undetermined``), refit_failed (``fit_error``, ``estimate_rejected``) or poor_fit
        (``misses_motion``, ``search_on_bound``).
    """
    shortfall = excitation_shortfall(dataset, min_rudder_std=config.min_rudder_std)
    if shortfall:
        return Verdict("too_little_excitation", "below_floors", {"shortfall": shortfall}, LAST_GOOD)
    estimator = make_estimator(config.method)
    try:
        estimate = None
        if last_good is not None and last_good.ok and last_good.method == config.method:
            estimate = estimator.fit(structure, dataset, starts=(last_good.parameters,), warm=True)
        if estimate is None or any(f in RETRY_COLD_FLAGS for f in estimate.flags):
            # none, or the vessel changed beyond the warm start's reach, or the search crawled
            # along a valley from it: fit afresh (exploring time scales), keep the better search
            cold = estimator.fit(structure, dataset)
            if estimate is None or better_search(cold, estimate):
                estimate = cold
    except (DataError, StructureError, ValueError, np.linalg.LinAlgError) as exc:
        return Verdict("refit_failed", "fit_error", {"error_type": type(exc).__name__, "error": str(exc)})
    # the estimator judged the floors with the default rudder floor; the window passed the node's above
    estimate = replace(estimate, flags=[f for f in estimate.flags if f != "low_excitation"])
    if not estimate.ok:
        return Verdict("refit_failed", "estimate_rejected", {"flags": list(estimate.flags)}, LAST_GOOD)
    # on the fold T1 = T2 the time constants' errors are infinite by the search's end, not the data's
    if "repeated_time_constants" not in estimate.flags:
        undetermined = excitation_shortfall(dataset, estimate.parameters, estimate.std_errors, config.min_rudder_std)
        if undetermined:
            figures = {"shortfall": undetermined}
            return Verdict("too_little_excitation", "parameters_undetermined", figures, LAST_GOOD)
    poor = poor_fit(config, estimate, dataset)
    return poor or WindowFit(estimate, estimator)


def poor_fit(config, estimate, dataset) -> Verdict | None:
    """Whether an estimate misses the motion (a poor_fit verdict) or may be judged further (None).

    Its free run must correlate with the measured yaw rate at least ``min_fit_correlation`` of the
    correlation the window's noise allows (``noise_limited_correlation``: a perfect model of noisy
    data correlates below 1), and its search must not have ended on a bound, on the fold T1 = T2 or
    unconverged (POOR_FIT_FLAGS).

    Parameters
    ----------
    config : OnlineConfig
        The identifier's configuration (``min_fit_correlation``, a share of the best correlation).
    estimate : Estimate
        The window's estimate, with its free-run fit (``r_yaw_rate``) and flags.
    dataset : Dataset
        The window (its yaw-rate noise, rad/s, sets the best correlation).

    Returns
    -------
    Verdict or None
        ``misses_motion`` (the correlation falls short), ``search_on_bound`` (the search ended on a
        flag of POOR_FIT_FLAGS), or None.
    """
    correlation = estimate.fit.get("r_yaw_rate", math.nan)
    best = noise_limited_correlation(dataset.yaw_rate, dataset.noise_std("yaw_rate"))
    needed = config.min_fit_correlation * best
    at_bounds = [f for f in estimate.flags if f in POOR_FIT_FLAGS]
    if correlation >= needed and not at_bounds:
        return None
    figures = {
        "correlation": correlation,
        "needed": needed,
        "share": config.min_fit_correlation,
        "best": best,
        "at_bounds": at_bounds,
    }
    code = "misses_motion" if not correlation >= needed else "search_on_bound"
    return Verdict("poor_fit", code, figures, LAST_GOOD)


def better_search(cold: Estimate, warm: Estimate) -> bool:
    """Whether a cold fit replaces a warm one that got stuck or did not converge.

    Parameters
    ----------
    cold, warm : Estimate
        The fit from the estimator's own starts and the one started from the last good estimate.

    Returns
    -------
    bool
        True when the cold fit did not get stuck itself and converged where the warm one did not, or
        ran closer to the data (a smaller ``cost_ratio``).
    """
    if any(f in STUCK_FLAGS for f in cold.flags):
        return any(f in STUCK_FLAGS for f in warm.flags)
    if any(f in STUCK_FLAGS for f in warm.flags):
        return True
    cold_converged, warm_converged = ("oe_not_converged" not in e.flags for e in (cold, warm))
    if cold_converged != warm_converged:
        return cold_converged
    return cold.info.get("cost_ratio", math.inf) < warm.info.get("cost_ratio", math.inf)
