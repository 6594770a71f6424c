"""Has the vessel changed? A model's out-of-sample free-run error on the newest data.

A hull that is loaded, fouled or damaged mid-trip answers its rudder
differently; a sliding window of ``window_length`` s mixes the old and new
response until the old data have left it. Here a model is run free over
blocks of ``length`` s, each run started from the measured state one
``length`` before its block (a run started at the block itself carries the
transient of its unknown initial yaw acceleration into it, after a rudder
step many times the noise on a hull with a slow pole), and
its yaw-rate error e (rad/s) is summarised per block by the robust mean
square median(e^2) / 0.455 (the variance for Gaussian errors; spikes do not
move it). When a fit on a full window is accepted, the median of that
statistic over the blocks of its window is the model's usual error level
(never below the yaw-rate noise floor); a model from a shorter window (at
start-up or after a change) or a poorly determined one (a window of steady
turning) is still learning and new conditions may surprise it, so it is not
a reference. At each refit the newest block is run with the newest
model fitted before the block began (out of sample: a model fitted on the
block itself has already bent towards a new response) and compared with
that model's level: above ``ratio`` times it on ``CONFIRMATIONS`` refits in
a row, the vessel has changed. A large change shows sooner: the newest
``short`` s (one refit period), run with the model of the refit before them,
above SHORT_RATIO_FACTOR ``ratio`` times the level from any sample on (the
newest MIN_SHORT_SAMPLES at least) declare it at once; between refits this quick
test alone runs several times per refit period (``quick_test``), so that a change shows within a
fraction of one. Where it changed is found in the newest
2 ``length`` s of that free run: the split of greatest likelihood for a step
in the error's variance, then, up to ``length`` before it, the time of
greatest likelihood of two hulls, the reference with its gain and main time
constant refitted before it and after it (``locate_change``: the error
steps up when the rudder moves, the hull may have changed while it coasted);
the window then restarts there.

Right after a change the new data are too short to determine every time
constant, but a free run is almost linear in the gain: ``fit_gain`` refits
K (and the main time constant when they determine it) on them with
everything else held from the reference the change was declared against
(``base``: a full window's well-determined model of the hull before the
change; the estimates in force just before it may have come from windows
straddling the change, bent towards a mixture of the two hulls) (a steady
turn with the rudder held gives K = r / delta alone).
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from ..estimators.base import REFERENCE_RELATIVE_ERRORS, scaled_inverse
from ..estimators.shooting import ShootingProblem
from ..model.dataset import Dataset, cut_segments
from ..model.effects import slow_time_constant
from ..model.metrics import effective_sample_fraction
from ..model.noise import SENSOR_RESOLUTION, median
from ..model.structure import Structure

CONFIRMATIONS = 2  # refits in a row above the ratio before a change is declared
SHORT_RATIO_FACTOR = 4.0  # the newest refit period's error must exceed this many times the ratio
MIN_SHORT_SAMPLES = 20  # the short test's newest samples: at least this many (a median of 20)
QUICK_SPAN_MARGIN = 5.0  # s of data the quick test reads beyond its run (``quick_span``)
MEDIAN_OF_CHI2_1 = 0.4549  # median of e^2 / sigma^2 for Gaussian e
MIN_LEVEL = SENSOR_RESOLUTION**2  # (rad/s)^2: no yaw-rate sensor resolves finer errors
# The gain test: a newest block mispredicted by more than GAIN_TEST_RATIO (below ``ratio``) also votes
# for a change when K refitted on it moves by more than GAIN_TEST_SHIFT and GAIN_TEST_STANDARD_ERRORS
# (a loaded hull in a steady turn, its yaw rate 30 % low, shows only 4-6x its usual error in noisy
# data: a changed gain, not noise or a manoeuvre the model meets badly).
GAIN_TEST_RATIO = 3.0
GAIN_TEST_SHIFT = 0.15
GAIN_TEST_STANDARD_ERRORS = 5.0
# What a loaded, fouled or damaged hull changes first: its gain and main time constant (refitted after
# a candidate change time to locate the change, ``locate_change``, and after a change, ``fit_gain``).
CHANGED_PARAMETERS = ("K", "T", "T1")
# New data shorter than this many main time constants determine K alone, not the time constant with it
# (on one time constant of a random-step record K came out 13 % off, on half of one 27 %).
GAIN_FIT_SPAN = 1.5
LOCATION_STEP = 0.5  # s between candidate change times (a coarse pass at four times it first)
# The change is placed at the latest candidate whose summed squared errors exceed the smallest by at
# most this (the 95 % likelihood-ratio bound of one parameter): old data after the restart bend the
# new fit (a steady turn's restart 1.4 s early: the first full fit 16 % off), new data before it only
# go unused.
LOCATION_TOLERANCE = 3.84


def block_squared_errors(structure: Structure, params: dict, dataset: Dataset, blocks: tuple, lead: int = 0) -> list:
    """Squared free-run yaw-rate errors (rad^2/s^2) over each of ``blocks`` (half-open index ranges
    inside the segments), the model run free from the measured state ``lead`` samples before each
    block (or from its segment's start). A run started at a block from the measured yaw rate with no
    yaw acceleration carries, just after a rudder step, an initial transient of about K delta T3 / T1
    (1-2 deg/s on a quick USV, 10-20 times its yaw-rate noise, dying out over T1), which a run
    started one test length earlier has shed by the block; blocks restarted at their start put a
    right model at many times its usual error (a false change). Runs that do not overlap share one
    simulation."""
    runs = [(max(a - lead, max(s for s, e in dataset.segments if s <= a < e)), b) for a, b in blocks]
    families, ends = [], []  # runs of one simulation each, in time order, none overlapping
    for i in sorted(range(len(runs)), key=lambda i: runs[i]):
        family = next((f for f, end in enumerate(ends) if end <= runs[i][0]), len(families))
        if family == len(families):
            families.append([])
            ends.append(0)
        families[family].append(i)
        ends[family] = runs[i][1]
    squared = [np.zeros(0)] * len(blocks)
    for family in families:
        _, r = structure.simulate(params, replace(dataset, segments=tuple(runs[i] for i in family)))
        for i in family:
            a, b = blocks[i]
            squared[i] = (r[a:b] - dataset.yaw_rate[a:b]) ** 2
    return squared


def largest_newest_median(values: np.ndarray, shortest: int) -> float:
    """The largest median of the newest k ``values`` over k from ``shortest`` to all of them, the
    newest values sorted once and one more inserted per k (not a median of each afresh). A median
    over a NaN is NaN and never the largest: only the newest values up to the newest NaN count (NaN
    when they are fewer than ``shortest``)."""
    newest = values[::-1]
    lost = np.flatnonzero(np.isnan(newest))
    if len(lost):
        if lost[0] < shortest:
            return math.nan
        newest = newest[: lost[0]]
    newest = newest.tolist()
    ordered = sorted(newest[: shortest - 1])
    largest = -math.inf
    for k in range(shortest, len(newest) + 1):
        bisect.insort(ordered, newest[k - 1])
        middle = k // 2
        median = ordered[middle] if k % 2 else (ordered[middle - 1] + ordered[middle]) / 2
        largest = max(largest, median)
    return largest


def block_errors(structure: Structure, params: dict, dataset: Dataset, blocks: tuple, lead: int = 0) -> np.ndarray:
    """Robust mean square of the free-run yaw-rate error in each block, median(e^2) / 0.455.

    The model runs free from the measured state ``lead`` samples before each block
    (``block_squared_errors``); for Gaussian errors the statistic is their variance, and spikes do not
    move it.

    Parameters
    ----------
    structure : Structure
        The model.
    params : dict
        Its parameters (SI units).
    dataset : Dataset
        The data (rad, rad/s).
    blocks : tuple of (int, int)
        Half-open sample-index ranges inside the segments (``cut_segments``).
    lead : int
        Samples the free run starts before its block (0: at the block).

    Returns
    -------
    numpy.ndarray
        One mean square per block, (rad/s)^2; NaN or inf where the free run diverges.
    """
    squared = block_squared_errors(structure, params, dataset, blocks, lead)
    return np.array([median(e) / MEDIAN_OF_CHI2_1 for e in squared])


class Reference(NamedTuple):
    """A model accepted on a full window, against which the change test runs the newest data."""

    end: float  # s, the end of its window
    parameters: dict  # SI units
    level: float  # (rad/s)^2, its usual robust mean square free-run yaw-rate error
    std_errors: dict  # its published standard errors (SI units)


class ChangeDetector:
    """Has the vessel changed? The newest data's out-of-sample free-run error against the usual level.

    Declares a change when the newest ``length`` s of free-run error, of the newest model fitted
    before them, exceed ``ratio`` times that model's usual level on CONFIRMATIONS refits in a row, or
    the newest ``short`` s exceed SHORT_RATIO_FACTOR ``ratio`` times it once (see the module
    docstring).

    Parameters
    ----------
    ratio : float
        Mean-square ratio (dimensionless) over the usual level that shows a change; 0: never.
    length : float
        Length of the tested block of newest data (s), ``change_test_length``.
    short : float
        Newest data of the quick test (s), about one refit period.
    """

    def __init__(self, ratio: float, length: float, short: float):
        self.ratio = ratio  # mean-square ratio (dimensionless); 0: never
        self.length = length  # s
        self.short = short  # s, the newest data of the quick test (one refit period)
        self.references = deque()  # Reference, oldest first
        self.votes = 0
        self.short_votes = 0
        self.base = None  # parameters of the reference the last change was declared against, or None
        self.base_errors = {}  # its published standard errors

    def calibrate(self, structure: Structure, estimate, dataset: Dataset) -> None:
        """Learn the usual error level of a just-accepted estimate on its own full window.

        An estimate less well determined than REFERENCE_RELATIVE_ERRORS is not a reference (new
        conditions would surprise a model still learning them).

        Parameters
        ----------
        structure : Structure
            The model.
        estimate : Estimate
            The accepted estimate, with its published standard errors (SI units).
        dataset : Dataset
            The full window it was fitted on.
        """
        params, errors = estimate.parameters, estimate.std_errors
        if not all(
            errors.get(name, math.inf) <= limit * abs(params[name])
            for name, limit in REFERENCE_RELATIVE_ERRORS.items()
            if name in params
        ):
            return
        n = int(round(self.length / dataset.sample_time))
        blocks = cut_segments(dataset.segments, n, align="start", whole=True) + cut_segments(
            dataset.segments, n, align="start", offset=n // 2, whole=True
        )
        errors = block_errors(structure, params, dataset, blocks, lead=n)
        if len(errors):
            floor = max(dataset.noise_std("yaw_rate", 0.0) ** 2, MIN_LEVEL)
            level = max(float(np.median(errors)), floor)
            self.references.append(Reference(float(dataset.time[-1]), params, level, dict(estimate.std_errors)))

    def forget(self) -> None:
        """Drop every reference and vote (a new model, a clock jump back: the old levels no longer apply)."""
        self.references.clear()
        self.votes = self.short_votes = 0
        self.base, self.base_errors = None, {}

    def _reference(self, before: float, drop: bool = True):
        """The newest reference fitted on data ending at or before ``before`` (s), or None; older
        ones are dropped unless ``drop`` is False."""
        while len(self.references) > 1 and self.references[1].end <= before and drop:
            self.references.popleft()
        fitted = [ref for ref in self.references if ref.end <= before]
        return fitted[-1] if fitted else None

    def _short_ratio(self, structure: Structure, dataset: Dataset) -> float:
        """Error of the newest ``short`` s, run with the newest reference fitted before them, over
        that reference's usual level (NaN without one): the largest robust mean square (median of
        e^2 / 0.455) of the samples from any one of them on, the newest MIN_SHORT_SAMPLES at least.
        A changed hull's error grows from the rudder's first move: its newest 2 s show it while the
        whole ``short`` s do not yet (bench peers --quick, random: 85 times the level 2 s after
        the rudder left amidships, 1.8 times over 5 s, above the quartile 35 times a second later);
        half of those samples must be off, so spikes do not count. The run starts ``length`` s back,
        so that its unknown initial yaw acceleration has died out by then."""
        m = max(int(round(self.short / dataset.sample_time)), MIN_SHORT_SAMPLES)
        if not dataset.segments:  # every sample lost to gaps: nothing to test
            return math.nan
        start, stop = dataset.segments[-1]
        reference = self._reference(float(dataset.time[stop - m]), drop=False) if stop - start >= m else None
        if reference is None:
            return math.nan
        lead = int(round(self.length / dataset.sample_time))
        (squared,) = block_squared_errors(structure, reference.parameters, dataset, ((stop - m, stop),), lead)
        return largest_newest_median(squared, MIN_SHORT_SAMPLES) / MEDIAN_OF_CHI2_1 / reference.level

    def test(self, structure: Structure, dataset: Dataset) -> tuple[float, float | None]:
        """The change test of a refit: the newest block's error against the usual level, and where it changed.

        The newest block is out of sample: the model is the newest one fitted before it began.

        Parameters
        ----------
        structure : Structure
            The model.
        dataset : Dataset
            The window (rad, rad/s), its newest ``length`` s the tested block.

        Returns
        -------
        ratio : float
            The newest block's robust mean square over the reference's usual level (NaN without a
            reference or with the test off).
        changed_at : float or None
            Time (s) the vessel most likely changed, when a change is declared; None otherwise.
        """
        if not self.ratio or not dataset.segments:
            return math.nan, None
        short = self._short_ratio(structure, dataset)
        self.short_votes = CONFIRMATIONS if short > SHORT_RATIO_FACTOR * self.ratio else 0
        n = int(round(self.length / dataset.sample_time))
        start, stop = dataset.segments[-1]
        reference = self._reference(float(dataset.time[stop - n])) if stop - start >= n else None
        if reference is None and self.short_votes < CONFIRMATIONS:
            return short, None
        if reference is None:  # the short test alone: the location uses the newest model before it
            reference = self._reference(float(dataset.time[stop - 1]), drop=False)
            ratio = short
        else:
            run_error = block_errors(structure, reference.parameters, dataset, ((stop - n, stop),), lead=n)[0]
            ratio = float(run_error) / reference.level
            shifted = ratio > GAIN_TEST_RATIO and gain_shifted(
                structure, reference.parameters, dataset.slice(stop - n, stop)
            )
            self.votes = self.votes + 1 if ratio > self.ratio or shifted else 0
        if self.votes < CONFIRMATIONS and self.short_votes < CONFIRMATIONS:
            return ratio, None
        if self.short_votes >= CONFIRMATIONS:
            ratio = max(ratio, short)
        return ratio, self._declare(structure, dataset, reference)

    def quick_span(self, sample_time: float) -> float:
        """Newest data the quick test's error reads (s).

        Its newest ``short`` s (MIN_SHORT_SAMPLES samples at least) and the ``length`` s its run
        starts before them, with QUICK_SPAN_MARGIN for inputs whose newest samples lag the clock.

        Parameters
        ----------
        sample_time : float
            The grid step (s).

        Returns
        -------
        float
            The span (s).
        """
        return self.length + max(self.short, MIN_SHORT_SAMPLES * sample_time) + QUICK_SPAN_MARGIN

    def quick_test(self, structure: Structure, dataset: Dataset, wider=None) -> tuple[float, float | None]:
        """The quick test alone, between refits: the newest ``short`` s against SHORT_RATIO_FACTOR ``ratio``.

        The votes of the full test are left as they are: its blocks would barely move between calls.

        Parameters
        ----------
        structure : Structure
            The model.
        dataset : Dataset
            The newest data (rad, rad/s), ``quick_span`` s at least.
        wider : callable or None
            Returns the newest 2 ``length`` s, where a change that shows is located; asked for only
            then (None: ``dataset`` holds them).

        Returns
        -------
        ratio : float
            The newest ``short`` s' robust mean square over the usual level (NaN with the test off).
        changed_at : float or None
            Time (s) the vessel most likely changed, when the ratio shows a change; None otherwise.
        """
        if not self.ratio:
            return math.nan, None
        short = self._short_ratio(structure, dataset)
        if short > SHORT_RATIO_FACTOR * self.ratio and wider is not None:
            dataset = wider()
            short = self._short_ratio(structure, dataset)
        if not short > SHORT_RATIO_FACTOR * self.ratio:
            return short, None
        return short, self._declare(structure, dataset, self._reference(float(dataset.time[-1]), drop=False))

    def _declare(self, structure: Structure, dataset: Dataset, reference) -> float:
        """A change against ``reference``: the references are forgotten, its parameters kept as
        ``base``, and the time (s) the error stepped up in the newest 2 ``length`` s is returned."""
        params, level, errors = reference.parameters, reference.level, reference.std_errors
        self.forget()
        self.base, self.base_errors = params, errors
        start, stop = dataset.segments[-1]
        n = int(round(self.length / dataset.sample_time))
        a = max(start, stop - 2 * n)
        (squared,) = block_squared_errors(structure, params, dataset, ((a, stop),), lead=n)
        squared = np.minimum(squared, 100 * self.ratio * level)
        return float(dataset.time[locate_change(structure, params, dataset, a + variance_change_point(squared), n)])


def gain_shifted(structure: Structure, params: dict, dataset: Dataset) -> bool:
    """Whether K refitted on ``dataset`` (its start fitted, the rest held at ``params``) moved from
    ``params``' K by more than GAIN_TEST_SHIFT of it and GAIN_TEST_STANDARD_ERRORS of the refit."""
    fitted, errors = fit_gain(structure, params, dataset, dataset.segments)
    shift = abs(fitted["K"] - params["K"])
    return bool(shift > GAIN_TEST_SHIFT * abs(params["K"]) and shift > GAIN_TEST_STANDARD_ERRORS * errors["K"])


def fit_gain(
    structure: Structure, params: dict, dataset: Dataset, blocks: tuple, names=("K",), iterations: int = 8
) -> tuple[dict, dict]:
    """The gain (and any of ``names``) refitted on free runs from each block's start, the rest held.

    The parameters ``names`` (those the structure has; by default the gain K, 1/s) are fitted by
    Gauss-Newton to the yaw rate and heading of ``dataset``, each over its noise std, run free from
    the start of each of ``blocks``, with every other parameter held at ``params``. Each block starts
    from an initial heading (rad), yaw rate (rad/s) and, for nomoto2, yaw acceleration (rad/s^2)
    fitted with them (from the measured heading and yaw rate and zero): new data often begin
    mid-manoeuvre, the hull turning ever faster after a rudder step, and a free run started steady
    from a noisy yaw rate would bend the gain to that transient (K 16 % low on the first 12 s of a
    turn after a zigzag, 4 % with the start fitted). The heading, the integral of the yaw rate with a
    tenth of its noise per sample (0.1 deg against 0.2 deg/s), determines K sooner after a rudder
    step (``bench peers --quick``, random: K and T1 to 8 % 3.2 s after the step, to 11 % on the yaw
    rate alone).

    Parameters
    ----------
    structure : Structure
        The model.
    params : dict
        The held hull's parameters (SI units), the start of the fitted ones.
    dataset : Dataset
        The data since the change (rad, rad/s).
    blocks : tuple of (int, int)
        Half-open sample-index ranges, each a free run of its own.
    names : tuple of str
        The parameters to fit.
    iterations : int
        Gauss-Newton iterations.

    Returns
    -------
    parameters : dict
        ``params`` with the fitted ones replaced (SI units).
    std_errors : dict
        Standard errors of the fitted ones (residual variance, autocorrelation allowed for).
    """
    return fit_gain_and_cost(structure, params, dataset, blocks, names, iterations)[:2]


def with_held_errors(
    structure: Structure, params: dict, errors: dict, held_errors: dict, dataset: Dataset, blocks: tuple
) -> dict:
    """Standard errors of a gain refit widened by the errors of the parameters it held.

    Each held parameter is moved by its standard error (towards the inside of its bounds) and the
    fitted ones refitted from ``params``; their shifts add in quadrature to ``errors`` (the held
    errors taken as independent): K refitted with T1 held inherits T1's uncertainty through the
    free run's shape.

    Parameters
    ----------
    structure : Structure
        The model.
    params : dict
        The refit's parameters (SI units).
    errors : dict
        Standard errors of the parameters ``fit_gain`` fitted (its keys are those parameters).
    held_errors : dict
        Standard errors of the held parameters (the hull before the change).
    dataset : Dataset
        The data of the refit.
    blocks : tuple of (int, int)
        The refit's blocks.

    Returns
    -------
    dict
        Widened standard errors of the fitted parameters (SI units).
    """
    names = tuple(errors)
    variances = {n: errors[n] ** 2 for n in names}
    for held in [h for h in structure.free_names if h not in errors and h in params]:
        sigma = held_errors.get(held, 0.0)
        if not (math.isfinite(sigma) and sigma > 0):
            continue
        (lower,), (upper,) = structure.bounds([held])
        value = params[held] + sigma if params[held] + sigma <= upper else max(params[held] - sigma, lower)
        moved, _ = fit_gain(structure, dict(params, **{held: value}), dataset, blocks, names, iterations=3)
        for n in names:
            variances[n] += (moved[n] - params[n]) ** 2
    return {n: math.sqrt(v) for n, v in variances.items()}


def fit_gain_and_cost(
    structure: Structure, params: dict, dataset: Dataset, blocks: tuple, names=("K",), iterations: int = 8
) -> tuple[dict, dict, float]:
    """``fit_gain``, with the sum of squared errors of the fitted free runs (yaw rate and heading, each
    over its noise std; dimensionless) last."""
    names = [n for n in names if n in params]
    problem = ShootingProblem(structure, dataset, blocks, names, params)
    lower, upper = structure.bounds(names)
    q, chosen = len(names), range(len(names))
    x = np.concatenate([[params[n] for n in names], problem.initial_states(structure.yaw_rate_bias(params)).ravel()])
    inside = problem.owner >= 0
    noise = np.array([dataset.noise_std("yaw_rate"), dataset.noise_std("heading")])
    measured = np.concatenate([dataset.yaw_rate[inside], dataset.heading[inside]])
    scale = np.repeat(1.0 / noise, int(inside.sum()))
    columns = problem.columns(np.tile(problem.owner[inside], 2))  # rows: yaw rate, heading

    def runs(points):
        """Yaw rate (rad/s) and heading (rad) of the free runs of several unknown vectors, one row
        each, in the blocks."""
        psi, r = problem.simulate(points)
        return np.hstack([r[:, inside], psi[:, inside]])

    for _ in range(iterations):
        points, steps = problem.difference_points(x, upper, chosen)
        r = runs([x] + points)
        error = (r[0] - measured) * scale
        jacobian = problem.jacobian(x, points, steps, (r[1:] - r[0]) * scale, chosen, columns)
        if not (np.all(np.isfinite(error)) and np.all(np.isfinite(jacobian))):
            break
        step = np.linalg.lstsq(jacobian, -error, rcond=None)[0]
        x[:q] = np.clip(x[:q] + step[:q], lower, upper)
        x[q:] += step[q:]
        if np.all(np.abs(step[:q]) <= 1e-6 * np.maximum(np.abs(x[:q]), 1e-3)):
            break
    fitted = dict(params, **dict(zip(names, x[:q])))
    error = (runs([x])[0] - measured) * scale
    yaw_rate_error, heading_error = np.split(error, 2)
    fraction = min(effective_sample_fraction(yaw_rate_error), effective_sample_fraction(heading_error))
    variance = float(error @ error) / max(len(error) - len(x), 1) / fraction
    try:
        std = np.sqrt(np.clip(variance * np.diag(scaled_inverse(jacobian.T @ jacobian))[:q], 0, None))
    except np.linalg.LinAlgError:
        std = np.full(q, np.inf)
    return fitted, {n: float(s) for n, s in zip(names, std)}, float(error @ error)


def locate_change(structure: Structure, params: dict, dataset: Dataset, split: int, n: int) -> int:
    """Index in the last segment where the hull changed, by the likelihood of two hulls: before it
    and after it ``params`` (the reference) with CHANGED_PARAMETERS refitted on each side (after it K
    alone on less than GAIN_FIT_SPAN main time constants: Gauss-Newton runs to the bounds), run free
    in blocks of n samples from a fitted initial state (``fit_gain``); the candidate, on a grid of
    LOCATION_STEP s from n samples before ``split`` (where the reference's error variance stepped up)
    to it, the latest whose summed squared errors (yaw rate and heading over their noise; the same
    data for every candidate) are within LOCATION_TOLERANCE of the smallest. The side before is
    refitted too: over a 30 s block of a steady turn a K 0.3 % off drifts the heading by several
    times its noise, and with the reference held there its own small bias would pull the change
    early, where a K refitted after it absorbs that bias. The error steps up only when the rudder
    moves, but a changed hull coasting with the rudder amidships already shows its new time constant
    in the decay of its yaw rate and in its heading, so the location reaches back before the step."""
    start, stop = dataset.segments[-1]
    first = max(start, split - n)
    origin = max(start, first - n)  # the side before the candidate starts here

    def pieces(a: int, b: int) -> tuple:  # blocks of n samples from a to b, the last one shorter
        return cut_segments(((a, b),), n, min_samples=2, align="start")

    span = GAIN_FIT_SPAN * slow_time_constant(params) / dataset.sample_time

    def fitted_cost(blocks: tuple, names: tuple) -> float:
        # K alone is a point of the model with K and T1 (T1 held at the reference's): where the
        # search over both diverges (a steady turn: T1 to its bound, runs that blow up), it is the
        # better fit of that model, and without it the change is placed early
        costs = [fit_gain_and_cost(structure, params, dataset, blocks, n)[2] for n in dict.fromkeys((names, ("K",)))]
        return min((c for c in costs if math.isfinite(c)), default=math.inf)  # a run that diverged explains nothing

    def cost(k: int) -> float:
        before, after = pieces(origin, k), pieces(k, stop)
        if not after:
            return math.inf
        names = CHANGED_PARAMETERS if stop - k >= span else ("K",)
        return (fitted_cost(before, CHANGED_PARAMETERS) if before else 0.0) + fitted_cost(after, names)

    step = max(1, int(round(LOCATION_STEP / dataset.sample_time)))
    costs = {k: cost(k) for k in range(split, first - 1, -4 * step)}
    best = min(costs, key=costs.get)
    costs.update({k: cost(k) for k in range(min(split, best + 3 * step), max(first, best - 3 * step) - 1, -step)})
    lowest = min(costs.values())
    return max(k for k, c in costs.items() if c <= lowest + LOCATION_TOLERANCE)


def variance_change_point(squared: np.ndarray, margin: int = 10) -> int:
    """Index where the mean of a series of squared errors steps: the split of greatest Gaussian
    likelihood, min_k k log(mean before) + (n - k) log(mean after), at least ``margin`` samples
    from either end."""
    n = len(squared)
    total = np.concatenate([[0.0], np.cumsum(squared)])
    k = np.arange(margin, n - margin + 1)
    before = np.maximum(total[k] / k, 1e-300)
    after = np.maximum((total[n] - total[k]) / (n - k), 1e-300)
    return int(k[np.argmin(k * np.log(before) + (n - k) * np.log(after))])
