"""The published uncertainty of an online estimate: three widenings of the estimator's errors.

The estimator's standard errors know the sensor noise of its window and the curvature of its cost
there. Three effects the window alone does not show widen them before an estimate is judged
(``trust``) and published:

* the scatter of successive estimates (``EstimateScatter``): a model that misses the vessel drifts
  with the data, a fit in a flat valley of its cost lands somewhere else each time;
* the slide of T1 along the T2 = T3 valley (``first_order_valley``), when the window cannot tell the
  second pole T2 from zero and the response it sees is nearly first order;
* the slides of K and T1 along the cubic yaw damping alpha (``along_the_damping``), which a few turn
  rates cannot tell from the gain.

The slides are read off profiles of the cost (``profile_slides``): the window refitted with one
parameter held at points up its valley, as profile-likelihood intervals are (Venzon and Moolgavkar
1988), the cost's rise deflated by the Gauss-Newton over the Newey-West variance (Newey and West 1987)
where the residuals are not white.
"""

from __future__ import annotations

import math
from collections import deque
from itertools import chain

import numpy as np

from ..estimators.base import TRUSTED_RELATIVE_ERRORS, Z_95, loose_parameters
from ..model.dataset import DataError
from ..model.structure import UNRESOLVED_POLE_SHARE, StructureError

SCATTER_PAIRS = 20  # successive estimates whose scatter sets the published uncertainty
SCATTER_REWEIGHTINGS = 4  # least-squares passes of the scatter fit (EstimateScatter)
MIN_FRESH_SHARE = 1e-3  # two estimates' difference has at least this share of their joint variance
# Shares of T1 above the estimate at which T2 is held to profile the cost along the T2 = T3 valley
# (``first_order_valley``): a second pole the window cannot tell from zero may lie far beyond its 95 % end.
VALLEY_RUNGS = (0.1, 0.2, 0.35, 0.5)
PROFILE_CLIMB_CHI2 = 16.0  # a point this far up a profile (4 standard errors) ends its climb
# Share of the trusted limit on K's or T1's error past which an estimate is first checked along the
# profile over the cubic damping alpha (``cubic_damping_slides``): gain and damping trade within alpha's error.
ALPHA_CHECK_SHARE = 0.75
# The same before a full window has been fitted: a short window holds fewer turn rates, so the trade
# bends further, and no run of successive estimates shows it yet.
START_UP_ALPHA_CHECK_SHARE = 0.5
ALPHA_RUNGS = (2.0, 4.0)  # the profile's points, in alpha's standard errors either side of the estimate
# Regressions cannot hold a parameter: below this share of T1, an undetermined T2 gives T1 the joint
# error of T1, T2 and T3 instead
FIRST_ORDER_SHARE = 0.1
# A slide along the T2 = T3 valley is reused (``ValleyProfile``) by a window sharing at least this
# share of its samples with the one profiled (two refit periods of a 180 s window): the cost is a sum
# over the samples, so the two costs' valleys differ by the few new samples' terms
REUSE_SHARED_SAMPLES = 0.85
REUSE_STANDARD_ERRORS = 0.5  # ... whose T1, T2 and T3 lie within this many of their errors of the profiled ones
# ... unless T1's error with that slide lies within this factor of its trusted limit (either way):
# there the slide decides whether T1 is trusted, and it is profiled afresh
REUSE_CLEAR_FACTOR = 1.5


class EstimateScatter:
    """Standard errors that cover the scatter of recent estimates, model error included.

    The estimator's standard errors know the sensor noise only. Two estimates of a right model,
    a with variance Va learnt a share i_a of it from the data it shares with b (and b likewise),
    differ by a variance U = Va (1 - i_a) + Vb (1 - i_b) + (sqrt(Va i_a) - sqrt(Vb i_b))^2 (each
    learns the shared data with its own weight); the shares come from where each fit learnt its
    parameters (``Influence``; the time shares for an estimator without one): windows sliding off
    the steps that taught them T1 onto a straight leg differ far more than their time shares say.
    The recent estimates (SCATTER_PAIRS of them) scatter further
    when the model misses the vessel (an error that drifts with the data: differences grow as
    phi^2 U) or when each fit lands somewhere else in a flat valley of its cost (an error of its
    own, sigma, whatever the shares: 2 sigma^2). Over every pair of recent estimates, d^2 / U =
    phi^2 + sigma^2 2 / U is fitted by least squares with phi^2, sigma^2 >= 0, and a parameter's
    published standard error is sqrt(max(phi^2, 1) s^2 + sigma^2): a fit's own error is added
    once, not inflated as a drifting one is.
    """

    def __init__(self):
        self.recent = deque(maxlen=SCATTER_PAIRS)  # accepted estimates (estimator's errors), oldest first
        # for each recent estimate, its pair rows with each later one ({parameter: (d^2 / U, 2 / U)}):
        # a pair's rows never change, so a new estimate adds only its own pairs
        self._rows = deque(maxlen=SCATTER_PAIRS)
        self._newest = (None, [])  # the estimate components() last saw and its rows with the recent ones

    def add(self, estimate) -> None:
        """Enter an accepted estimate (with the estimator's own errors) into the recent ones.

        Parameters
        ----------
        estimate : Estimate
            The accepted estimate.
        """
        seen, rows = self._newest
        if seen is not estimate:
            rows = [_pair_rows(a, estimate) for a in self.recent]
        for earlier, row in zip(self._rows, rows):
            earlier.append(row)
        self.recent.append(estimate)
        self._rows.append([])
        self._newest = (None, [])

    def forget(self) -> None:
        """Drop the recent estimates (a change of the vessel or of the model: they scatter about other values)."""
        self.recent.clear()
        self._rows.clear()
        self._newest = (None, [])

    def components(self, estimate) -> dict:
        """The drift and own-error components of the scatter of the recent estimates and this one.

        Parameters
        ----------
        estimate : Estimate
            The new estimate (the estimator's own errors, its window and influence).

        Returns
        -------
        dict
            {parameter: (phi^2 >= 1, sigma^2 >= 0)}: the drift's variance factor (dimensionless) and
            each fit's own error variance (the parameter's unit squared).
        """
        newest = [_pair_rows(a, estimate) for a in self.recent]
        self._newest = (estimate, newest)
        pairs = {name: [] for name in estimate.parameters}  # (d^2 / U, 2 / U), pairs in the order of the chain
        for later, new in zip(self._rows, newest):
            for row in chain(later, (new,)):
                for name, rows in pairs.items():
                    if name in row:
                        rows.append(row[name])
        return {name: _drift_and_own_error(rows) for name, rows in pairs.items()}

    def honest(self, estimate) -> dict:
        """Standard errors that cover the scatter of the recent estimates: sqrt(phi^2 s^2 + sigma^2).

        Parameters
        ----------
        estimate : Estimate
            The new estimate, with the estimator's own standard errors s.

        Returns
        -------
        dict
            Published standard errors by parameter (SI units), at least the estimator's.
        """
        components = self.components(estimate)
        honest = {}
        for name, std in estimate.std_errors.items():
            phi_square, sigma_square = components.get(name, (1.0, 0.0))
            honest[name] = math.sqrt(phi_square * std**2 + sigma_square)
        return honest


def _pair_rows(a, b) -> dict:
    """{parameter: (d^2 / U, 2 / U)} of the estimates ``a`` (the older) and ``b``: their squared
    difference d^2 over the variance U their fresh shares give it (see ``EstimateScatter``), and
    2 / U; parameters with no finite, positive joint variance have none."""
    (a_shares, a_time), (b_shares, b_time) = _shared_shares(a, b), _shared_shares(b, a)
    rows = {}
    for name, value in a.parameters.items():
        va, vb = a.std_errors.get(name, 0.0) ** 2, b.std_errors.get(name, 0.0) ** 2
        if va + vb > 0 and math.isfinite(va + vb) and name in b.parameters:
            ia, ib = a_shares.get(name, a_time), b_shares.get(name, b_time)
            apart = va * (1 - ia) + vb * (1 - ib) + (math.sqrt(va * ia) - math.sqrt(vb * ib)) ** 2
            unit = max(apart, MIN_FRESH_SHARE * (va + vb))
            rows[name] = ((b.parameters[name] - value) ** 2 / unit, 2.0 / unit)
    return rows


def _shared_shares(a, b) -> tuple[dict, float]:
    """The shares of estimate ``a``'s variances learnt within ``b``'s window: {parameter: share}
    from its ``Influence`` (none without one), and the share of its window's time, for the
    parameters it has no influence of."""
    start, end = b.window
    overlap = max(0.0, min(a.window[1], end) - max(a.window[0], start))
    time_share = overlap / max(a.window[1] - a.window[0], 1e-9)
    if a.influence is None:
        return {}, time_share
    return {
        name: min(max(share, 0.0), 1.0) for name, share in a.influence.shares_within(start, end).items()
    }, time_share


class ValleyProfile:
    """T1's slide along the T2 = T3 valley (``valley_slide``), profiled only where it can decide.

    Rule: a refit reuses the last profiled slide when its window shares REUSE_SHARED_SAMPLES of its
    samples with the profiled one, its T1, T2 and T3 lie within REUSE_STANDARD_ERRORS of their own
    errors of the profiled estimate's, and T1's error with that slide is not within
    REUSE_CLEAR_FACTOR of its trusted limit. Physical reason: the cost is a sum over the window's
    samples, so windows sharing nearly all of them have the same valley, and an estimate that sits
    at the same point of it slides as far; only a slide near the limit decides whether T1 is trusted
    (a slide far from it enters the published error and the scatter of the next estimates as the
    profile of the shared samples measured it).
    """

    def __init__(self):
        self._last = None  # (estimate profiled, T1's slide in s), or None

    def forget(self) -> None:
        """Drop the last profile (the window restarts: other samples, another valley)."""
        self._last = None

    def slide(self, estimate, std_errors: dict, estimator, structure, dataset) -> float:
        """T1's slide along the valley (s): the last profiled one where the rule reuses it.

        Else ``valley_slide``'s, kept for the next windows.

        Parameters
        ----------
        estimate, std_errors, estimator, structure, dataset
            As ``first_order_valley``'s: the window's estimate (T1, T2, T3 in s), its errors so far.

        Returns
        -------
        float
            T1's standard error along the valley (s).
        """
        if self._last is not None and self._reusable(estimate, std_errors, *self._last):
            return self._last[1]
        slide = valley_slide(estimate, estimator, structure, dataset)
        self._last = (estimate, slide)
        return slide

    @staticmethod
    def _reusable(estimate, std_errors: dict, profiled, slide: float) -> bool:
        """Whether ``estimate`` (own errors ``std_errors``) may take ``slide``, profiled at ``profiled``."""
        if (estimate.structure.label(), estimate.method) != (profiled.structure.label(), profiled.method):
            return False
        (a0, a1), (b0, b1) = profiled.window, estimate.window
        shared = max(0.0, min(a1, b1) - max(a0, b0)) / max(max(a1, b1) - min(a0, b0), 1e-9)
        moved = any(
            not abs(estimate.parameters[n] - profiled.parameters[n]) <= REUSE_STANDARD_ERRORS * std_errors[n]
            for n in ("T1", "T2", "T3")
        )
        limit = TRUSTED_RELATIVE_ERRORS["T1"] * abs(estimate.parameters["T1"])
        error = max(std_errors["T1"], slide)
        close = limit / REUSE_CLEAR_FACTOR < error < REUSE_CLEAR_FACTOR * limit
        return shared >= REUSE_SHARED_SAMPLES and not moved and not close


def first_order_valley(estimate, std_errors: dict, estimator, structure, dataset, profile=None) -> dict:
    """Standard errors with T1's at least its slide along the T2 = T3 valley when T2 is told from zero.

    When the window cannot tell the second pole T2 from zero (its 95 % interval reaches it), the
    response it sees is nearly first order, and T1 may move with T2 and T3 further than the error at
    the search's end says. The slide is read off the cost's profile over T2 (``valley_slide``). With
    T2 undetermined the local errors describe no distribution: a single held point at T2's 95 % end
    misses truths far beyond it, so the profile climbs through several. An estimator that cannot hold
    a parameter (a regression without output error) gives T1 the joint error
    sqrt(s_T1^2 + s_T2^2 + s_T3^2) when T2 is below FIRST_ORDER_SHARE of T1. A rudder lead T3 that
    cannot be told from zero alone is a hull without one (the WLSSVM paper's USV, "seed 001": T1 stays
    determined).

    Parameters
    ----------
    estimate : Estimate
        The window's estimate (second-order Nomoto: T1, T2, T3 in s).
    std_errors : dict
        Its standard errors so far (SI units).
    estimator : Estimator
        The estimator that fitted it (``fit_held`` profiles the cost).
    structure : Structure
        The model.
    dataset : Dataset
        The window.
    profile : ValleyProfile or None
        The online refits' last profile, reused where its rule allows (None: profiled afresh).

    Returns
    -------
    dict
        Standard errors by parameter (SI units), T1's widened where the valley lets it slide.
    """
    names = ("T1", "T2", "T3")
    parameters = estimate.parameters
    if not all(n in parameters and n in std_errors for n in names):
        return std_errors
    t1, t2 = abs(parameters["T1"]), abs(parameters["T2"])
    if not Z_95 * std_errors["T2"] > t2:
        return std_errors
    if hasattr(estimator, "fit_held"):
        if profile is None:
            slide = valley_slide(estimate, estimator, structure, dataset)
        else:
            slide = profile.slide(estimate, std_errors, estimator, structure, dataset)
        return dict(std_errors, T1=max(std_errors["T1"], slide))
    if t2 < FIRST_ORDER_SHARE * t1:
        return dict(std_errors, T1=max(std_errors["T1"], math.sqrt(sum(std_errors[n] ** 2 for n in names))))
    return std_errors


def valley_slide(estimate, estimator, structure, dataset) -> float:
    """T1's standard error (s) along the T2 = T3 valley, from the profile of the cost over T2
    (``profile_slides``) with T2 held at the fastest pole the samples resolve (UNRESOLVED_POLE_SHARE)
    and at VALLEY_RUNGS of T1 above the estimate, T3 moved with it (T1 + T2 - T3 kept as a start). On
    a quick USV whose T2 its window cannot resolve the slide can be three times the error at the
    search's end."""
    parameters = estimate.parameters
    t1, t2, t3 = abs(parameters["T1"]), abs(parameters["T2"]), parameters["T3"]
    floor = max(structure.parameter("T2").lower, UNRESOLVED_POLE_SHARE * dataset.sample_time)
    rungs = ([[floor]] if t2 > floor else []) + [[share * t1 for share in VALLEY_RUNGS if share * t1 > t2]]
    slides = profile_slides(
        estimate, estimator, structure, dataset, "T2", rungs, ("T1",), lambda v: {"T3": max(t3 + v - t2, 0.0)}
    )
    return slides["T1"]


def profile_slides(estimate, estimator, structure, dataset, name, ladders, of, moved=lambda value: {}) -> dict:
    """Standard errors of the parameters ``of`` from the profile of the cost over parameter ``name``:
    the window refitted with ``name`` held at each value of each ladder in turn (``moved(value)``:
    other parameters' starts there), every point weighed alike (``fit_held``'s ``weighted_at``). A
    point where the cost rose by chi2 (its rise over that of the estimate held where it is,
    deflated by the Gauss-Newton over the Newey-West variance of each parameter: residuals that are
    not white count less) moved a parameter by d: its error is at least |d| / max(sqrt(chi2), Z_95)
    (a point inside the 95 % region moved it within its interval; for a quadratic profile this is
    its error exactly). A ladder's climb stops past PROFILE_CLIMB_CHI2. A fit that fails leaves the
    parameters undetermined (infinite errors)."""
    parameters = estimate.parameters

    def start_at(value):
        return dict(moved(value), **{name: value})

    try:
        base = estimator.fit_held(structure, dataset, estimate, start_at(parameters[name]), (name,), parameters)
        deflate = {
            q: min(1.0, (base.info["gauss_newton_std"][q] / base.std_errors[q]) ** 2) if base.std_errors[q] > 0 else 1.0
            for q in of
        }
        slides = dict.fromkeys(of, 0.0)
        for ladder in ladders:
            for value in ladder:
                held, cost = estimator.held_point(structure, dataset, estimate, start_at(value), (name,), parameters)
                rise = cost - base.info["cost"]
                for q in of:
                    shift = abs(held[q] - base.parameters[q])
                    slides[q] = max(slides[q], shift / max(math.sqrt(max(deflate[q] * rise, 0.0)), Z_95))
                if rise > PROFILE_CLIMB_CHI2:
                    break
        return slides
    except (DataError, StructureError, ValueError, np.linalg.LinAlgError):
        return dict.fromkeys(of, math.inf)


def cubic_damping_slides(estimate, std_errors: dict, estimator, structure, dataset) -> dict:
    """Standard errors with K's and T1's (T's) at least their slides along the cubic yaw damping
    alpha (``profile_slides`` with alpha held 2 and 4 of its standard errors either side, within
    its bounds): a larger damping that the turns seen hardly feel is traded for a larger gain and a
    slower hull, and the cost can be flat that way far beyond alpha's own error (a slow ship on a
    zigzag turns at few rates, so its data hardly tell the cubic term from the gain)."""
    if structure.form != "nomoto" or "alpha" not in estimate.parameters or not std_errors.get("alpha", 0.0) > 0:
        return std_errors
    main = "T1" if "T1" in estimate.parameters else "T"
    alpha, s_alpha = estimate.parameters["alpha"], std_errors["alpha"]
    lower, upper = structure.bounds(["alpha"], dataset)
    ladders = [
        [v for v in (alpha + k * s_alpha for k in ALPHA_RUNGS) if v < upper[0]],
        [v for v in (alpha - k * s_alpha for k in ALPHA_RUNGS) if v > lower[0]],
    ]
    slides = profile_slides(estimate, estimator, structure, dataset, "alpha", ladders, ("K", main))
    return dict(std_errors, **{q: max(std_errors[q], slides[q]) for q in slides})


def along_the_damping(published, estimator, structure, dataset, start_up: bool) -> dict:
    """Published standard errors checked along the cubic yaw damping when K's or T1's nears its limit.

    An estimate whose gain or main time constant is determined within TRUSTED_RELATIVE_ERRORS, but
    past ALPHA_CHECK_SHARE of that limit (START_UP_ALPHA_CHECK_SHARE before a full window has been
    fitted), may trade gain for damping further than its errors say: its errors are widened by the
    slides along alpha (``cubic_damping_slides``). One already loose, or from an estimator that
    cannot hold a parameter, is left as it is.

    Parameters
    ----------
    published : Estimate
        The new estimate with its published standard errors (SI units).
    estimator : Estimator
        The estimator that fitted it (``fit_held`` profiles the cost).
    structure : Structure
        The model fitted.
    dataset : Dataset
        The window it was fitted on.
    start_up : bool
        Whether no full window has been fitted yet (a short window, no run of estimates behind it).

    Returns
    -------
    dict
        Standard errors by parameter (SI units), at least the published ones.
    """
    limits = TRUSTED_RELATIVE_ERRORS
    parameters, errors = published.parameters, published.std_errors
    check_share = START_UP_ALPHA_CHECK_SHARE if start_up else ALPHA_CHECK_SHARE
    close = any(errors[q] > check_share * limit * abs(parameters[q]) for q, limit in limits.items() if q in parameters)
    if close and not loose_parameters(parameters, errors, limits)[0] and hasattr(estimator, "fit_held"):
        return cubic_damping_slides(published, errors, estimator, structure, dataset)
    return errors


def _drift_and_own_error(rows: list) -> tuple[float, float]:
    """(phi^2 >= 1, sigma^2 >= 0): y = phi^2 + sigma^2 x fitted over rows (y, x) by least squares
    weighted by the inverse square of the fitted y (a squared difference scatters in proportion
    to its expectation; a few reweightings), both non-negative (one alone when the pair fits a
    negative value); (1, 0) without rows."""
    if not rows:
        return 1.0, 0.0
    y, x = np.fromiter(chain.from_iterable(rows), float, count=2 * len(rows)).reshape(-1, 2).T
    phi_square, sigma_square = float(np.mean(y)), 0.0
    for _ in range(SCATTER_REWEIGHTINGS):
        weight = 1.0 / np.maximum(phi_square + sigma_square * x, 1e-12)
        design = np.column_stack([np.ones_like(x), x]) * weight[:, None]
        phi_square, sigma_square = np.linalg.lstsq(design, y * weight, rcond=None)[0]
        if sigma_square < 0:  # the scatter does not grow as the windows share more: a drift only
            phi_square, sigma_square = float(np.mean(y)), 0.0
        elif phi_square < 0:  # the scatter does not grow with the fresh share: each fit's own error only
            phi_square, sigma_square = 0.0, float(np.sum(y * x * weight**2) / np.sum((x * weight) ** 2))
    return max(float(phi_square), 1.0), float(sigma_square)
