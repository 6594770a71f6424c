"""Online identification core shared by the ROS node and ``ship-ident replay``.

Samples (time in s, SI values, NED) arrive one by one, per role (rudder,
heading, yaw rate, speed). ``OnlineIdentifier`` keeps a sliding window of the
last ``window_length`` seconds of each role, rejects samples that cannot be
used, and on a fixed period (``refit_period``, on whatever clock feeds it:
the node's clock, or the bag's time in replay) resamples the window to
``sample_time`` and refits the configured model. Nothing here knows ROS or
files, so the node and replay run the very same code.

Each refit returns a ``RefitRecord``: the estimate in force (a new one, or
the last good one when this window could not give one), the window it came
from, the model's predicted yaw rate at the window end, and the conditions
found (no data, stale input, gap, too little excitation, poor fit, implausible
units or signs, ...), each with a severity OK / WARN / ERROR and a sentence.
The configuration is ``online.config.OnlineConfig``, the checks of the inputs
``input_checks``; the node's estimate log (a file writer) ``estimate_log``.
"""

from __future__ import annotations

import math
import threading
import time as wallclock
from collections import deque
from dataclasses import dataclass, field, replace
from itertools import chain

import numpy as np

from ..estimators import make_estimator
from ..estimators.base import (
    MAX_RELATIVE_ERRORS,
    TRUSTED_RELATIVE_ERRORS,
    Z_95,
    Estimate,
    excitation_shortfall,
    loose_parameters,
)
from ..model.dataset import DataError, Dataset, cut_segments, resample_series
from ..model.effects import slow_time_constant
from ..model.metrics import free_run_fit, noise_limited_correlation
from ..model.structure import Structure, StructureError
from .change import (
    CHANGED_PARAMETERS,
    GAIN_FIT_SPAN,
    ChangeDetector,
    block_errors,
    fit_gain,
    with_held_errors,
)
from .config import OnlineConfig
from .input_checks import (
    REJECTIONS,
    heading_plausibility,
    input_conditions,
    order_rejection,
    rudder_saturation,
    value_rejection,
    window_truncation,
)
from .samples import ROLES, Sample
from .window import SampleWindow

OK, WARN, ERROR = 0, 1, 2
LEVEL_NAMES = {OK: "OK", WARN: "WARN", ERROR: "ERROR"}

# Severity of each condition a refit can report.
CONDITION_LEVELS = {
    "no_data": ERROR,
    "window_filling": WARN,
    "stale_input": WARN,
    "gap_in_window": WARN,
    "too_little_excitation": WARN,
    "poor_fit": WARN,
    "refit_failed": ERROR,
    "refit_overran": WARN,
    "rejected_samples": WARN,
    "clock_jump": WARN,
    "vessel_changed": WARN,
    "implausible_estimate": WARN,
    "uncertain_estimate": WARN,
    "window_truncated": WARN,
    "heading_in_degrees": WARN,
    "yaw_rate_sign": WARN,
    "rudder_saturated": WARN,
    "wrong_message_type": WARN,  # reported by the node (ROS graph)
    "estimate_log_failed": WARN,  # reported by the node
    "missing_effect": WARN,  # reported by the diagnosis on board (diagnosis.onboard)
}

# Trust in a new estimate against the last good one (see OnlineIdentifier._distrust).
JUMP_STANDARD_ERRORS = 5.0  # a jump beyond this many joint standard errors needs evidence
CLEAR_IMPROVEMENT = 2.0  # ... its free run over the newest data this many times better
# (mean squares) than the last good one's, or the next refit agreeing
FREE_RUN_TOLERANCE = 1.25  # a new estimate's free run may miss the window at most this much
# more (mean squares) than the last good one's
# Refitted on the new data after a change, the first set the data determine: the gain with the main
# time constant, or alone, once the new data span GAIN_FIT_SPAN main time constants of the last good
# estimate (each block's initial yaw rate and acceleration are fitted with them). The rudder offset is
# held: loading does not move it, and a held rudder cannot tell it from the gain.
GAIN_FITS = (CHANGED_PARAMETERS, ("K",))
MIN_GAIN_SAMPLES = 20  # new samples needed for the gain refit after a change
# The gain refit's free runs restart from the measured state every change_test_length s, or every
# GAIN_BLOCK_SPAN held main time constants when that is longer: a block shorter than the response
# leaves the gain to the fitted initial states (a ship with T1 35 s restarted every 30 s).
GAIN_BLOCK_SPAN = 2.0
# A full fit refused after a change (the new data do not yet determine every parameter) leaves the
# gain followed on all the new data: its sentence then says so instead of keeping the last good one.
KEEPING = "keeping the last good estimate"
FOLLOWED_INSTEAD = "K refitted on the new data instead (see vessel_changed)"
# Between refits the newest data are watched for a change (the change detector's quick test), and
# while the new data after one are shorter than min_window_length the gain follow refits, this many
# times per refit period: a gain refit costs a few ms, and K is published as soon as the new data
# determine it rather than at the next scheduled refit.
WATCHES_PER_REFIT = 10
SCATTER_PAIRS = 20  # successive estimates whose scatter sets the published uncertainty
SCATTER_REWEIGHTINGS = 4  # least-squares passes of the scatter fit (EstimateScatter)
MIN_FRESH_SHARE = 1e-3  # two estimates' difference has at least this share of their joint variance
# A window is full when its resampled data span window_length within this many sample times: the
# newest sample of each input may be a sample time old, the oldest a sample time inside the window,
# and the grid's floor loses one more (with 1.5 a ship's window, sample time 0.37 s, never was).
FULL_WINDOW_MARGIN = 3.0

# A new estimate is trusted (OK) when its published relative errors are within TRUSTED_RELATIVE_ERRORS;
# a looser one within MAX_RELATIVE_ERRORS is published as uncertain_estimate (WARN), and after a change
# not at all if its K is known worse than the last good estimate's.
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


@dataclass
class RefitRecord:
    """The outcome of one refit: the estimate in force and what was found on the way."""

    time: float  # s, clock time the refit ran at
    conditions: dict  # condition name -> sentence
    estimate: dict | None = None  # Estimate.to_json() in force (new or last good)
    new_estimate: bool = False  # True when this refit produced the estimate
    window: tuple = (math.nan, math.nan)  # s, start and end of the data in the window
    predicted_yaw_rate: float = math.nan  # rad/s at the window end, free run from measured state
    measured_yaw_rate: float = math.nan  # rad/s at the window end
    compute_seconds: float = 0.0  # wall time of the refit
    counts: dict = field(default_factory=dict)  # cumulative input counts by outcome
    diagnosis: dict | None = None  # the diagnosis that finished at this refit (diagnosis.onboard), if any

    @property
    def level(self) -> int:
        return max((CONDITION_LEVELS[c] for c in self.conditions), default=OK)

    @property
    def status(self) -> str:
        return LEVEL_NAMES[self.level]

    def to_json(self) -> dict:
        """The ``~/estimate`` / ``replay --json`` record: the identify JSON plus online fields."""
        estimate = self.estimate or {}
        record = {
            "stamp": self.time,
            "status": self.status,
            "conditions": dict(self.conditions),
            "new_estimate": self.new_estimate,
            "structure": estimate.get("structure"),
            "method": estimate.get("method"),
            "parameters": estimate.get("parameters", {}),
            "std_errors": estimate.get("std_errors", {}),
            "fit": estimate.get("fit", {}),
            "samples": estimate.get("samples", 0),
            "flags": estimate.get("flags", []),
            "estimate_window": estimate.get("window"),
            "window": {"start": self.window[0], "end": self.window[1]},
            "predicted_yaw_rate": self.predicted_yaw_rate,
            "measured_yaw_rate": self.measured_yaw_rate,
            "compute_seconds": self.compute_seconds,
            "counts": dict(self.counts),
        }
        if self.diagnosis is not None:
            record["diagnosis"] = self.diagnosis
        return record


class OnlineIdentifier:
    """Sliding-window identifier: ``add`` samples, ``due``/``refit`` on a period.

    Thread-safe: ``add`` (from message callbacks) and ``refit`` (from a worker)
    may run on different threads; the refit copies the window under a lock and
    fits outside it. Configuration changes take effect at the next refit.
    """

    def __init__(self, config: OnlineConfig):
        self._lock = threading.Lock()
        self._config = config.validate()
        cap = config.max_window_samples
        self._window = {role: SampleWindow(cap) for role in ROLES}
        self._newest = {role: -math.inf for role in ROLES}  # s, last accepted stamp per role
        self._latest_time = -math.inf  # s, newest stamp or clock reading seen
        self._next_due: float | None = None
        self._next_watch = -math.inf  # s: the next quick change test between refits
        self.counts = {"accepted": 0, **{r: 0 for r in REJECTIONS}, "clock_jumps": 0}
        self._reported = dict(self.counts)
        self._last_jump = 0.0
        self._last_good = None  # Estimate of the current structure
        self._last_good_window = (math.nan, math.nan)
        self._change = ChangeDetector(config.change_ratio, config.change_test_length, _short_test(config))
        self._window_floor = -math.inf  # s: where the vessel last changed; older data are dropped
        self._change_note = None  # sentence reported until the first estimate after a change
        self._candidate = None  # the last estimate held for jumping: the next may confirm it
        self._scatter = EstimateScatter()
        self._full_window_fitted = False  # an estimate of a full window published since the start

    # --- configuration ---------------------------------------------------
    @property
    def config(self) -> OnlineConfig:
        return self._config

    def reconfigure(self, config: OnlineConfig) -> None:
        """Use a new configuration from the next refit on (window and schedule are kept)."""
        config = config.validate()
        with self._lock:
            if (config.model, config.effects) != (self._config.model, self._config.effects):
                self._last_good = self._candidate = None
                self._change.forget()
                self._scatter.forget()
                self._full_window_fitted = False
            self._change.ratio, self._change.length = config.change_ratio, config.change_test_length
            self._change.short = _short_test(config)
            if config.refit_period != self._config.refit_period and self._next_due is not None:
                self._next_due = min(self._next_due, self._latest_time + config.refit_period)
            self._config = config

    # --- input -----------------------------------------------------------
    def add(self, sample: Sample) -> str:
        """Store a sample; return ``accepted`` or why it was rejected (also counted)."""
        with self._lock:
            outcome = self._check(sample)
            self.counts[outcome] += 1
            if outcome == "accepted":
                self._window[sample.role].append(sample.time, sample.value)
                self._newest[sample.role] = sample.time
                self._latest_time = max(self._latest_time, sample.time)
            return outcome

    def _check(self, sample: Sample) -> str:
        """``accepted`` or why not; a usable value moves the clock even when its stamp is out of order."""
        rejection = value_rejection(sample)
        if not rejection:
            self._observe_clock(sample.time)
            rejection = order_rejection(sample.time, self._newest[sample.role])
        return rejection or "accepted"

    def _observe_clock(self, now: float) -> None:
        """Clock jumps restart the schedule from ``now`` (at the pace of ``_period``).

        A reading far behind the newest time seen (bag loop, simulator restart)
        also empties the window. A step forward by more than one refit period
        (the node looks at its clock several times per period; replay at every
        sample) is a jump forward, or every input fell silent: the window keeps
        what is still inside ``window_length``.
        """
        config = self._config
        if now < self._latest_time - config.clock_jump_threshold:
            for role in ROLES:
                self._window[role].clear()
                self._newest[role] = -math.inf
            self._window_floor = -math.inf
            self._change.forget()  # its references belong to the old time line
            self._scatter.forget()
            self._full_window_fitted = False
        elif (
            not now > self._latest_time + max(config.clock_jump_threshold, config.refit_period)
            or self._latest_time == -math.inf
        ):
            self._latest_time = max(self._latest_time, now)
            return
        self._last_jump = now - self._latest_time
        self.counts["clock_jumps"] += 1
        self._latest_time = now
        self._next_due = now + self._period(now)  # a gain followed through the jump keeps its pace

    # --- schedule --------------------------------------------------------
    def due(self, now: float) -> bool:
        """Whether a refit is due at clock time ``now`` (s); the schedule starts at the first call."""
        with self._lock:
            self._observe_clock(now)
            if self._next_due is None:
                self._next_due = now + self._config.refit_period
            return now >= self._next_due

    def skip(self, now: float) -> None:
        """Move the schedule past ``now`` without refitting (a refit was still running)."""
        with self._lock:
            self._advance_schedule(now)

    def _advance_schedule(self, now: float) -> None:
        """The next refit one period on (a refit period; WATCHES_PER_REFIT times faster while the
        gain follows a change); a refit off the schedule (a change just found) brings it no later
        than one period from ``now``."""
        self._next_watch = now + self._config.refit_period / WATCHES_PER_REFIT
        period = self._period(now)
        if self._next_due is None or now - self._next_due >= period:
            self._next_due = now + period
        elif now < self._next_due:
            self._next_due = min(self._next_due, now + period)
        else:
            self._next_due += period

    def _period(self, now: float) -> float:
        """The time to the next refit (s): a refit period, WATCHES_PER_REFIT times shorter while
        the gain follows a change."""
        period = self._config.refit_period
        return period / WATCHES_PER_REFIT if self._following(now) else period

    def _following(self, now: float) -> bool:
        """Whether the gain follows a change at clock time ``now`` (s): one was found, and the data
        since it span less than ``min_window_length``."""
        return self._change_note is not None and now - self._window_floor < self._config.min_window_length

    def watch(self, now: float) -> bool:
        """Between refits, at most WATCHES_PER_REFIT times per refit period: whether the newest data
        show a change (the change detector's quick test on the newest 2 ``change_test_length`` s, with
        an accepted estimate in force and no change being followed). A change found restarts the
        window where it happened and makes a refit due at once (call ``refit(now)``)."""
        with self._lock:
            config = self._config
            if not (
                config.change_ratio
                and self._last_good is not None
                and self._change_note is None
                and now >= self._next_watch
            ):
                return False
            step = config.refit_period / WATCHES_PER_REFIT  # on a grid: a timer's jitter skips none
            self._next_watch = self._next_watch + step if now - self._next_watch < step else now + step
            oldest = max(now - min(2 * config.change_test_length, config.window_length), self._window_floor)
            series = {role: self._window[role].array(oldest) for role in ROLES}
        try:
            dataset = _resample(config, series)
            ratio, changed_at = self._change.quick_test(config.structure(), dataset)
        except (DataError, StructureError, ValueError):
            return False
        if changed_at is None:
            return False
        self._declare_change(config, now, ratio, changed_at)
        return True

    # --- refit -----------------------------------------------------------
    def refit(self, now: float) -> RefitRecord:
        """Fit the window as it is at clock time ``now`` (s) and advance the schedule."""
        started = wallclock.perf_counter()
        with self._lock:
            self._advance_schedule(now)
            self._observe_clock(now)  # after: a clock jump restarts the schedule from now
            config = self._config
            for role in ROLES:
                self._window[role].prune(max(now - config.window_length, self._window_floor))
            series = {role: self._window[role].array() for role in ROLES}
            full = [role for role in ROLES if len(self._window[role]) == config.max_window_samples]
            newest = dict(self._newest)
            counts = dict(self.counts)
            fresh = {k: counts[k] - self._reported[k] for k in counts}
            self._reported = counts
            last_good, last_window = self._last_good, self._last_good_window
            last_jump = self._last_jump
            change_note = self._change_note
        conditions = input_conditions(config, series, newest, now, fresh, last_jump)
        if change_note:
            conditions["vessel_changed"] = change_note
            if last_good is not None:  # the new data are being fitted (K first): not a first fit
                conditions.pop("window_filling", None)
        conditions.update(window_truncation(config, series, full, now))
        conditions.update(heading_plausibility(series))
        record = RefitRecord(time=now, conditions=conditions, counts=counts)
        if "no_data" not in conditions and "window_filling" not in conditions:
            self._fit(config, series, last_good, record)
        if record.estimate is None and last_good is not None:
            record.estimate = last_good.to_json()
            record.window = last_window
        record.compute_seconds = wallclock.perf_counter() - started
        return record

    def window_dataset(self, now: float) -> Dataset:
        """The window at clock time ``now`` (s) resampled as a refit resamples it (after the last
        change, if any); raises DataError when it cannot be resampled."""
        with self._lock:
            config = self._config
            oldest = max(now - config.window_length, self._window_floor)
            series = {role: self._window[role].array(oldest) for role in ROLES}
        return _resample(config, series)

    def _fit(self, config: OnlineConfig, series: dict, last_good, record: RefitRecord) -> None:
        try:
            dataset = _resample(config, series)
        except DataError as exc:
            record.conditions["refit_failed"] = f"window unusable: {exc}"
            return
        structure = config.structure()
        if last_good is not None and self._change_note is None:
            dataset = self._test_for_change(config, structure, dataset, record)
        if self._change_note is not None and last_good is not None:
            if dataset.duration >= config.min_window_length - 0.5 * config.sample_time:
                self._full_fit(config, structure, dataset, last_good, record)
                if record.new_estimate or self._change_note is None:
                    return
                refused = dict(record.conditions)  # the full fit's refusal, then K followed instead
            else:
                refused = {}
            self._follow_gain(config, structure, dataset, last_good, record)
            if record.new_estimate:
                for name, sentence in refused.items():
                    record.conditions[name] = sentence.replace(KEEPING, FOLLOWED_INSTEAD)
            return
        self._full_fit(config, structure, dataset, last_good, record)

    def _full_fit(self, config, structure, dataset, last_good, record: RefitRecord) -> None:
        """Every free parameter fitted on the window's ``dataset``; published when the checks of a new
        estimate pass."""
        record.window = (float(dataset.time[0]), float(dataset.time[-1]))
        if dataset.gaps:
            longest = max(b - a for a, b in dataset.gaps)
            record.conditions["gap_in_window"] = (
                f"{len(dataset.gaps)} gap(s) in the window, longest {longest:.1f} s; fitting the segments apart"
            )
        record.conditions.update(rudder_saturation(dataset.rudder, config.rudder_limit))
        shortfall = excitation_shortfall(dataset, min_rudder_std=config.min_rudder_std)
        if shortfall:
            record.conditions["too_little_excitation"] = f"{shortfall}; {KEEPING}"
            return
        estimator = make_estimator(config.method)
        try:
            estimate = None
            if last_good is not None and last_good.ok and last_good.method == config.method:
                estimate = estimator.fit(structure, dataset, starts=(last_good.parameters,))  # warm start
            if estimate is None or any(f in RETRY_COLD_FLAGS for f in estimate.flags):
                # none, or the vessel changed beyond the warm start's reach, or the search crawled
                # along a valley from it: fit afresh (exploring time scales), keep the better search
                cold = estimator.fit(structure, dataset)
                if estimate is None or _better_search(cold, estimate):
                    estimate = cold
        except (DataError, StructureError, ValueError, np.linalg.LinAlgError) as exc:
            record.conditions["refit_failed"] = f"{type(exc).__name__}: {exc}"
            return
        # the estimator judged the floors with the default rudder floor; the window passed the node's above
        estimate = replace(estimate, flags=[f for f in estimate.flags if f != "low_excitation"])
        if not estimate.ok:
            record.conditions["refit_failed"] = (
                f"estimate rejected ({', '.join(estimate.flags)}); keeping the last good estimate"
            )
            return
        # on the fold T1 = T2 the time constants' errors are infinite by the search's end, not the data's
        folded = "repeated_time_constants" in estimate.flags
        undetermined = (
            None
            if folded
            else excitation_shortfall(dataset, estimate.parameters, estimate.std_errors, config.min_rudder_std)
        )
        if undetermined:
            record.conditions["too_little_excitation"] = f"{undetermined}; {KEEPING}"
            return
        correlation = estimate.fit.get("r_yaw_rate", math.nan)
        best = noise_limited_correlation(dataset.yaw_rate, dataset.noise_std("yaw_rate"))
        needed = config.min_fit_correlation * best
        at_bounds = [f for f in estimate.flags if f in POOR_FIT_FLAGS]
        if not correlation >= needed or at_bounds:
            figures = (
                f"free-run yaw-rate correlation {correlation:.2f} (needs >= {needed:.2f}, "
                f"{config.min_fit_correlation:g} of the {best:.2f} its noise allows)"
            )
            record.conditions["poor_fit"] = (
                f"{figures}{', ' + ', '.join(at_bounds) if at_bounds else ''}: the model misses the motion"
                if not correlation >= needed
                else f"the search ended {', '.join(at_bounds)} ({figures}): no estimate to trust"
            ) + "; keeping the last good estimate"
            return
        full = dataset.duration >= config.window_length - FULL_WINDOW_MARGIN * config.sample_time
        start_up = not (full or self._full_window_fitted)  # a short window, no history of estimates
        # its own errors, T1's with its slide along the T2 = T3 valley: so it enters the scatter of the
        # next estimates (a fit at the valley's foot with a small error makes the right estimates after
        # it look scattered); whether T2 is told from zero is judged on the window's own T2 error
        estimate = replace(
            estimate, std_errors=first_order_valley(estimate, estimate.std_errors, estimator, structure, dataset)
        )
        published = replace(estimate, std_errors=self._scatter.honest(estimate))
        distrust = self._distrust(config, structure, published, dataset, last_good)
        if distrust:
            record.conditions["implausible_estimate"] = f"{distrust}; {KEEPING}"
            return
        limits = TRUSTED_RELATIVE_ERRORS
        loose, figures = loose_parameters(published.parameters, published.std_errors, limits)
        check_share = START_UP_ALPHA_CHECK_SHARE if start_up else ALPHA_CHECK_SHARE
        close = any(  # an error past check_share of its limit
            published.std_errors[q] > check_share * limit * abs(published.parameters[q])
            for q, limit in limits.items()
            if q in published.parameters
        )
        if close and not loose and hasattr(estimator, "fit_held"):
            published = replace(
                published,
                std_errors=cubic_damping_slides(published, published.std_errors, estimator, structure, dataset),
            )
            loose, figures = loose_parameters(published.parameters, published.std_errors, limits)
        if loose:
            followed = self._gain_followed()
            held = (  # after a change, a K refitted on the new data is not replaced by a looser fit
                self._change_note is not None
                and last_good is not None
                and (followed or ("K" in loose and last_good.std_errors.get("K", math.inf) < published.std_errors["K"]))
            )
            kept = "the gain followed on the new data" if followed else "K known better by the last good estimate"
            record.conditions["uncertain_estimate"] = (
                f"the window determines {', '.join(loose)} only loosely ({figures}): "
                + (
                    f"{kept} is kept until a full fit is trusted; {KEEPING}"
                    if held
                    else "published with its uncertainty, not to be trusted as OK"
                )
            )
            if held:
                return
        self._publish(config, structure, estimate, published, dataset, record)
        if full and structure.form == "nomoto":  # a full window's model, judged by its published errors
            # (a window straddling a change fits a mixture of two hulls whose scatter the estimator's own
            # errors do not show); the change detector follows the gain K, which the acceleration form lacks
            self._change.calibrate(structure, published, dataset)
            self._full_window_fitted = True
        with self._lock:
            self._change_note = None

    def _publish(self, config, structure, estimate, published, dataset, record, scatter=True) -> None:
        """Make ``published`` (``estimate`` with the published standard errors) the estimate in force;
        ``scatter``: a full fit, whose scatter about the next ones sets their published errors."""
        if scatter:
            self._scatter.add(estimate)
        record.estimate = published.to_json()
        record.estimate.pop("info", None)
        record.new_estimate = True
        record.predicted_yaw_rate, record.measured_yaw_rate = self._predict(
            config, structure, estimate.parameters, dataset
        )
        with self._lock:
            if (config.model, config.effects) == (self._config.model, self._config.effects):
                self._last_good, self._last_good_window = published, record.window
            self._candidate = None

    def _follow_gain(self, config, structure, dataset, last_good, record) -> None:
        """After a change, while the new data are shorter than ``min_window_length`` or the full fits
        on them are refused: the first set
        of GAIN_FITS they determine (K with the main time constant T1 or T, or K alone) refitted
        on them, run free in blocks of ``change_test_length`` (at least GAIN_BLOCK_SPAN held time
        constants), the other parameters held from the
        reference the change was declared against (ChangeDetector.base; the last good estimate
        without one), not from estimates of windows straddling the change (a USV's cubic damping
        bent from 0.4 to 147 by them held K 20 % high) (a free run is almost linear in K; a held
        rudder determines it);
        published when they determine K (standard error within MAX_RELATIVE_ERRORS, however little the
        rudder moves) and pass the checks of any new estimate, judged against the held hull (with the
        last good estimate's errors), with errors widened by the held hull's (``with_held_errors``:
        the data's own alone covered the new K in half the follow refits of a bench vessels draw)."""
        record.window = (float(dataset.time[0]), float(dataset.time[-1]))
        if dataset.n_samples < MIN_GAIN_SAMPLES:
            return
        if self._change.base:
            held, held_errors = self._change.base, self._change.base_errors
        else:
            held, held_errors = last_good.parameters, last_good.std_errors
        time_constant = slow_time_constant(held)
        if dataset.duration < GAIN_FIT_SPAN * time_constant:
            return
        block = max(config.change_test_length, GAIN_BLOCK_SPAN * time_constant)
        # blocks counted back from the end: the newest, where a changed hull shows first, is a whole one
        blocks = cut_segments(dataset.segments, int(round(block / dataset.sample_time)), min_samples=2, align="end")
        try:
            for names in GAIN_FITS:  # the most the new data determine (judged by the standard errors alone:
                # a rudder held in a turn determines K, r = K delta, however little it moves)
                params, errors = fit_gain(structure, held, dataset, blocks, names)
                loose = loose_parameters({n: params[n] for n in errors}, errors, MAX_RELATIVE_ERRORS)[1]
                if not loose:
                    break
            if not loose:  # what the new data determine is judged by their own errors; the held hull's
                # add to those of a refit that may be published (a refused one is not)
                errors = with_held_errors(structure, params, errors, held_errors, dataset, blocks)
            psi, r = structure.simulate(params, dataset)
        except (DataError, StructureError, ValueError, np.linalg.LinAlgError) as exc:
            record.conditions["refit_failed"] = f"gain refit after the change: {type(exc).__name__}: {exc}"
            return
        fit = free_run_fit(dataset.heading, dataset.yaw_rate, psi, r)
        estimate = Estimate(
            structure,
            last_good.method,
            params,
            dict(held_errors, **errors),
            fit,
            dataset.n_samples,
            flags=["diverged"] if fit["diverged"] else [],
            window=record.window,
        )
        undetermined = "it diverged" if fit["diverged"] else loose
        # judged against the hull it was refitted from: the last good estimate may come from a
        # window straddling the change, fitted partly on these very data; once K has been followed
        # on the new data, against that (each refit would otherwise jump from the old hull again and
        # be held for the next one to confirm: every other refit refused)
        followed = self._gain_followed()
        yardstick = last_good if followed else replace(last_good, parameters=dict(last_good.parameters, **held))
        reason = undetermined or self._distrust(config, structure, estimate, dataset, yardstick)
        if reason:
            name = "too_little_excitation" if undetermined else "implausible_estimate"
            sentence = f"gain refit on the {dataset.duration:.0f} s since the change: {reason}; {KEEPING}"
            full_fit = record.conditions.get(name)  # the full fit's refusal of the same kind, if any
            record.conditions[name] = f"{full_fit.removesuffix('; ' + KEEPING)}; {sentence}" if full_fit else sentence
            return
        self._publish(config, structure, estimate, estimate, dataset, record, scatter=False)

    def _gain_followed(self) -> bool:
        """Whether the estimate in force was fitted on data after the last change (a followed gain)."""
        with self._lock:
            return self._last_good_window[0] >= self._window_floor

    def _distrust(self, config, structure, estimate, dataset, last_good) -> str | None:
        """Why a new estimate (published standard errors) must not replace the last good one, or None.

        It sits on a physical bound; or its free run misses this window more than the last good
        estimate's (FREE_RUN_TOLERANCE, mean squares over blocks of ``change_test_length``, each run
        free from the measured state one block before it: a run started at the block carries the
        transient of its unknown yaw acceleration, which favours whichever time constants shed it
        fastest); or its gain or main time constant jumps beyond
        JUMP_STANDARD_ERRORS joint standard errors from the last good one, and neither does its free
        run over the newest ``change_test_length`` s beat the last good one's CLEAR_IMPROVEMENT times
        (a changed vessel shows there first), nor does the previous refit's held estimate agree with
        it. A last good estimate whose free run diverges on this window (a changed vessel can make it
        unstable) is no yardstick: it blocks nothing."""
        on_bound = _on_bound(structure, estimate.parameters)
        if on_bound:
            return f"{on_bound}: the search ran to a physical limit, not to the vessel"
        if last_good is None or last_good.structure.label() != structure.label():
            return None
        n = int(round(config.change_test_length / dataset.sample_time))
        blocks = cut_segments(dataset.segments, n, min_samples=2, align="end")
        new_blocks, old_blocks = (
            block_errors(structure, p, dataset, blocks, lead=n) for p in (estimate.parameters, last_good.parameters)
        )
        new_error, old_error = float(np.mean(new_blocks)), float(np.mean(old_blocks))
        if math.isfinite(old_error) and not new_error <= FREE_RUN_TOLERANCE * old_error:
            return (
                f"its free run misses the window more than the last good estimate's (yaw-rate rms "
                f"{math.degrees(math.sqrt(new_error)):.3f} vs {math.degrees(math.sqrt(old_error)):.3f} deg/s)"
            )
        jump, name = _jump(estimate, last_good)
        if jump <= JUMP_STANDARD_ERRORS:
            return None
        new_newest, old_newest = float(new_blocks[-1]), float(old_blocks[-1])
        if not old_newest < CLEAR_IMPROVEMENT * new_newest:  # NaN: the last good one diverges there
            return None
        candidate, self._candidate = self._candidate, estimate
        if (
            candidate is not None
            and candidate.structure.label() == structure.label()
            and _jump(estimate, candidate)[0] <= JUMP_STANDARD_ERRORS
        ):
            return None
        return (
            f"{name} {estimate.parameters[name]:.4g} +- {estimate.std_errors[name]:.2g} jumps "
            f"{jump:.0f} standard errors from the last good {last_good.parameters[name]:.4g} +- "
            f"{last_good.std_errors[name]:.2g}, and its free run over the newest "
            f"{config.change_test_length:g} s is not clearly better (yaw-rate rms "
            f"{math.degrees(math.sqrt(new_newest)):.3f} vs {math.degrees(math.sqrt(old_newest)):.3f} "
            "deg/s); held until a refit confirms it"
        )

    def _test_for_change(self, config, structure, dataset, record):
        """Run the change test; on a change, restart the window where it happened and return the
        data after it."""
        try:
            ratio, changed_at = self._change.test(structure, dataset)
        except (DataError, StructureError, ValueError):
            return dataset
        if changed_at is None:
            return dataset
        record.conditions["vessel_changed"] = self._declare_change(config, record.time, ratio, changed_at)
        return dataset.slice(int(np.searchsorted(dataset.time, changed_at)), dataset.n_samples)

    def _declare_change(self, config, now: float, ratio: float, changed_at: float) -> str:
        """Restart the window at ``changed_at`` (s), follow the gain from the next refit, due within
        a follow period of ``now`` (s); returns the vessel_changed sentence."""
        note = (
            f"the newest model fitted before the newest data (the last {_short_test(config):g} or "
            f"{config.change_test_length:g} s) mispredicts them "
            f"({ratio:.0f}x its usual free-run yaw-rate error, mean squares): the vessel changed (loading, fouling, "
            f"damage) or it meets conditions the model lacks an effect for (ship-ident diagnose); "
            f"the window restarts at {changed_at:.1f} s, where it most likely changed (K refitted on the "
            f"new data with the time constants held until they span {config.min_window_length:g} s, and while "
            f"full fits on them are refused)"
        )
        with self._lock:
            self._window_floor, self._change_note = changed_at, note
            self._scatter.forget()  # the new response's estimates scatter about other values
            if self._next_due is not None:
                self._next_due = min(self._next_due, now + config.refit_period / WATCHES_PER_REFIT)
        return note

    @staticmethod
    def _predict(config, structure, params, dataset) -> tuple[float, float]:
        """Yaw rate (rad/s) at the window end: the model run free over the last
        ``prediction_horizon`` s from the measured state, and the measurement."""
        stop = dataset.n_samples
        start = max(dataset.segments[-1][0], stop - int(round(config.prediction_horizon / config.sample_time)))
        tail = dataset.slice(start, stop)
        try:
            _, r = structure.simulate(params, tail)
        except (DataError, StructureError, ValueError):
            return math.nan, float(dataset.yaw_rate[-1])
        return float(r[-1]), float(dataset.yaw_rate[-1])


def _resample(config: OnlineConfig, series: dict) -> Dataset:
    """The inputs' (time, value) arrays resampled to ``sample_time``, split at gaps; the speed only
    when ``speed_topic`` is set."""
    roles = [r for r in ROLES if r != "speed" or config.speed_topic]
    return resample_series({r: (series[r][:, 0], series[r][:, 1]) for r in roles}, config.sample_time, config.gap)


def _short_test(config: OnlineConfig) -> float:
    """s of newest data of the change detector's quick test: one refit period, 3 s to a third of
    ``change_test_length``."""
    return min(max(config.refit_period, 3.0), config.change_test_length / 3)


def _better_search(cold: Estimate, warm: Estimate) -> bool:
    """Whether the cold fit replaces a warm one that got stuck or did not converge: it did not get
    stuck itself and converged where the warm one did not, or ran closer to the data (cost)."""
    if any(f in STUCK_FLAGS for f in cold.flags):
        return any(f in STUCK_FLAGS for f in warm.flags)
    if any(f in STUCK_FLAGS for f in warm.flags):
        return True
    cold_converged, warm_converged = ("oe_not_converged" not in e.flags for e in (cold, warm))
    if cold_converged != warm_converged:
        return cold_converged
    return cold.info.get("cost_ratio", math.inf) < warm.info.get("cost_ratio", math.inf)


def _on_bound(structure: Structure, params: dict) -> str:
    """'T1 = 999.5 s on its bound 1000 s' for parameters at a physical bound ('' when none); a zero
    lower bound (no lead, no dead time) is physical, not a limit."""
    found = []
    for name in structure.free_names:
        parameter, value = structure.parameter(name), params[name]
        bound = parameter.bound_reached(value)
        if bound is not None and bound != 0:
            found.append(f"{name} = {value:.4g} {parameter.unit} on its bound {bound:g}")
    return ", ".join(found)


def _jump(estimate, reference) -> tuple[float, str]:
    """The largest jump of the gain or main time constant between two estimates, in joint standard
    errors, and the parameter's name."""
    jumps = []
    for name in TRUSTED_RELATIVE_ERRORS:
        if name in estimate.parameters and name in reference.parameters:
            joint = math.hypot(estimate.std_errors.get(name, 0.0), reference.std_errors.get(name, 0.0))
            step = abs(estimate.parameters[name] - reference.parameters[name])
            jumps.append((step / joint if joint > 0 else (math.inf if step else 0.0), name))
    return max(jumps)


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
        seen, rows = self._newest
        if seen is not estimate:
            rows = [_pair_rows(a, estimate) for a in self.recent]
        for earlier, row in zip(self._rows, rows):
            earlier.append(row)
        self.recent.append(estimate)
        self._rows.append([])
        self._newest = (None, [])

    def forget(self) -> None:
        self.recent.clear()
        self._rows.clear()
        self._newest = (None, [])

    def components(self, estimate) -> dict:
        """{parameter: (phi^2 >= 1, sigma^2 >= 0)} from the recent estimates and this one."""
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


def first_order_valley(estimate, std_errors: dict, estimator, structure, dataset) -> dict:
    """Standard errors with T1's at least its slide along the T2 = T3 valley when the window cannot
    tell the second pole T2 from zero (its 95 % interval reaches it): the response it sees is nearly
    first order, and T1 may move with T2 and T3 further than the error at the search's end says.
    The slide is read off the cost's profile over T2 (``valley_slide``). With T2 undetermined the
    local errors describe no distribution: a single held point at T2's 95 % end misses truths far
    beyond it, so the profile climbs through several. An estimator that cannot hold a parameter (a
    regression without output error) gives T1 the joint error sqrt(s_T1^2 + s_T2^2 + s_T3^2) when T2
    is below FIRST_ORDER_SHARE of T1. A rudder lead T3 that cannot be told from zero alone is a hull
    without one (seed 001's: T1 stays determined)."""
    names = ("T1", "T2", "T3")
    parameters = estimate.parameters
    if not all(n in parameters and n in std_errors for n in names):
        return std_errors
    t1, t2 = abs(parameters["T1"]), abs(parameters["T2"])
    if not Z_95 * std_errors["T2"] > t2:
        return std_errors
    if hasattr(estimator, "fit_held"):
        return dict(std_errors, T1=max(std_errors["T1"], valley_slide(estimate, estimator, structure, dataset)))
    if t2 < FIRST_ORDER_SHARE * t1:
        return dict(std_errors, T1=max(std_errors["T1"], math.sqrt(sum(std_errors[n] ** 2 for n in names))))
    return std_errors


def valley_slide(estimate, estimator, structure, dataset) -> float:
    """T1's standard error (s) along the T2 = T3 valley, from the profile of the cost over T2
    (``profile_slides``) with T2 held at its floor and at VALLEY_RUNGS of T1 above the estimate, T3
    moved with it (T1 + T2 - T3 kept as a start). On a quick USV whose T2 its window cannot resolve
    the slide can be three times the error at the search's end."""
    parameters = estimate.parameters
    t1, t2, t3 = abs(parameters["T1"]), abs(parameters["T2"]), parameters["T3"]
    floor = structure.parameter("T2").lower
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

    def held_at(value):
        start = dict(moved(value), **{name: value})
        return estimator.fit_held(structure, dataset, estimate, start, (name,), weighted_at=parameters)

    try:
        base = held_at(parameters[name])
        deflate = {
            q: min(1.0, (base.info["gauss_newton_std"][q] / base.std_errors[q]) ** 2) if base.std_errors[q] > 0 else 1.0
            for q in of
        }
        slides = dict.fromkeys(of, 0.0)
        for ladder in ladders:
            for value in ladder:
                held = held_at(value)
                rise = held.info["cost"] - base.info["cost"]
                for q in of:
                    shift = abs(held.parameters[q] - base.parameters[q])
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


def _drift_and_own_error(rows: list) -> tuple[float, float]:
    """(phi^2 >= 1, sigma^2 >= 0): y = phi^2 + sigma^2 x fitted over rows (y, x) by least squares
    weighted by the inverse square of the fitted y (a squared difference scatters in proportion
    to its expectation; a few reweightings), both non-negative (one alone when the pair fits a
    negative value); (1, 0) without rows."""
    if not rows:
        return 1.0, 0.0
    y, x = np.array(rows).T
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


def run_schedule(identifier: OnlineIdentifier, samples, diagnosis=None):
    """Feed time-ordered samples with their own stamps as the clock; yield each refit's record.

    This is the node's loop with the bag's time for the node's clock: a refit
    due at a sample's time, or one a change found between refits calls for
    (``watch``), runs on everything that arrived before it.
    ``diagnosis`` (an ``diagnosis.onboard.OnlineDiagnosis``) runs on the window after each refit
    when due; an effect it adds or removes by itself takes effect from the next refit.
    """
    for sample in samples:
        if identifier.due(sample.time) or identifier.watch(sample.time):
            record = identifier.refit(sample.time)
            if diagnosis is not None:
                effects = diagnosis.after_refit(record, identifier)
                if effects is not None:
                    identifier.reconfigure(replace(identifier.config, effects=effects))
            yield record
        identifier.add(sample)
