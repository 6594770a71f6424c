"""Estimators by name: ``ols``, ``lssvm``, ``rlssvm``, ``rwlssvm``, ``tlssvm``, each optionally
refined by ``+oe`` (output error, multiple shooting) or ``+pem`` (prediction error: the
free-run error whitened by a Kalman innovation filter that knows the rudder noise)."""

from __future__ import annotations

from .base import Estimate, Estimator, RegressionEstimator, Solution
from .lssvm import LSSVM, OLS, RLSSVM
from .output_error import OutputError
from .prediction_error import PredictionError
from .tlssvm import TLSSVM
from .weighted import RWLSSVM

ESTIMATORS = {cls.name: cls for cls in (OLS, LSSVM, RLSSVM, RWLSSVM, TLSSVM)}
REFINEMENTS = {"oe": OutputError, "pem": PredictionError}
DEFAULT_METHOD = "rwlssvm+pem"


class MethodError(ValueError):
    """An unknown estimator or refinement name."""


def method_names() -> list[str]:
    """Every method ``make_estimator`` builds.

    Returns
    -------
    list of str
        Each regression's name, then with each refinement ("rlssvm", "rlssvm+oe", ...).
    """
    return [n for base in ESTIMATORS for n in (base, *(f"{base}+{r}" for r in REFINEMENTS))]


def regression_method(method: str) -> str:
    """The regression that starts a method.

    Parameters
    ----------
    method : str
        A method name, e.g. "rlssvm+oe".

    Returns
    -------
    str
        Its regression, "rlssvm" of "rlssvm+oe" (a regression: itself).
    """
    return method.partition("+")[0]


def make_estimator(method: str = DEFAULT_METHOD, explore: bool = True, **options) -> Estimator:
    """Build an estimator from its name.

    Parameters
    ----------
    method : str
        ``NAME``, ``NAME+oe`` or ``NAME+pem`` (``method_names``).
    explore : bool
        For the refinement (``OutputError``): a cold fit explores a range of starts.
    **options
        For the regression estimator.

    Returns
    -------
    Estimator
        The regression, or the output-error or prediction-error refinement started from it.

    Raises
    ------
    MethodError
        For an unknown name.
    """
    base, _, refine = method.partition("+")
    if base not in ESTIMATORS:
        raise MethodError(f"unknown method {method!r}; choose from {', '.join(method_names())}")
    if refine and refine not in REFINEMENTS:
        raise MethodError(f"unknown refinement {refine!r} in {method!r}; use NAME+oe or NAME+pem")
    estimator = ESTIMATORS[base](**options)
    return REFINEMENTS[refine](estimator, explore=explore) if refine else estimator


__all__ = [
    "Estimate",
    "Estimator",
    "RegressionEstimator",
    "Solution",
    "ESTIMATORS",
    "DEFAULT_METHOD",
    "MethodError",
    "make_estimator",
    "method_names",
    "regression_method",
    "OutputError",
    "PredictionError",
]
