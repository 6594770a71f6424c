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
``input_checks``; the node's estimate log (a file writer) ``estimate_log``. The
decisions on a window are modules of their own: the full fit (``window_fit``),
the published uncertainty (``uncertainty``), whether an estimate replaces the
one in force (``trust``), the gain followed after a change (``gain_follow``);
each returns a ``verdicts.Verdict`` (a code and its figures), worded for the
record's conditions in ``verdicts`` alone.
"""

from __future__ import annotations

import math
import threading
import time as wallclock
from dataclasses import dataclass, field, replace

import numpy as np

from ..model.dataset import DataError, Dataset, resample_series
from ..model.structure import StructureError
from .change import ChangeDetector
from .config import OnlineConfig
from .gain_follow import refit_gain
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
from .trust import TrustPolicy
from .uncertainty import EstimateScatter, ValleyProfile, along_the_damping, first_order_valley
from .verdicts import FOLLOWED, LAST_GOOD, Verdict
from .window import SampleWindow
from .window_fit import fit_window

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

# Between refits the newest data are watched for a change (the change detector's quick test), and
# while the new data after one are shorter than min_window_length the gain follow refits, this many
# times per refit period: a gain refit costs a few ms, and K is published as soon as the new data
# determine it rather than at the next scheduled refit.
WATCHES_PER_REFIT = 10
# A window is full when its resampled data span window_length within this many sample times: the
# newest sample of each input may be a sample time old, the oldest a sample time inside the window,
# and the grid's floor loses one more (with 1.5 a ship's window, sample time 0.37 s, never was).
FULL_WINDOW_MARGIN = 3.0


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
    verdicts: dict = field(default_factory=dict)  # condition -> Verdict: the code and figures of a decision

    def report(self, verdict: Verdict) -> None:
        """Record a decision: its sentence under its condition, the verdict itself in ``verdicts``.

        Parameters
        ----------
        verdict : Verdict
            The decision (condition, code, figures).
        """
        self.conditions[verdict.condition] = verdict.sentence
        self.verdicts[verdict.condition] = verdict

    @property
    def level(self) -> int:
        """The record's severity: the worst of its conditions' (OK 0, WARN 1, ERROR 2)."""
        return max((CONDITION_LEVELS[c] for c in self.conditions), default=OK)

    @property
    def status(self) -> str:
        """The record's severity by name: 'OK', 'WARN' or 'ERROR'."""
        return LEVEL_NAMES[self.level]

    def to_json(self) -> dict:
        """The ``~/estimate`` / ``replay --json`` record: the identify JSON plus online fields.

        Returns
        -------
        dict
            Stamp, status, conditions (name -> sentence), the estimate in force (SI units), the windows,
            the predicted and measured yaw rate at the window end (rad/s), compute time and input counts;
            the diagnosis that finished at this refit, if any (the ``~/estimate`` message of docs/node.md).
        """
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

    Parameters
    ----------
    config : OnlineConfig
        The configuration (validated here; ConfigError names a bad value).
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
        self._trust = TrustPolicy()  # remembers the last estimate held for jumping: the next may confirm it
        self._scatter = EstimateScatter()
        self._valley = ValleyProfile()  # the last profile along the T2 = T3 valley: reused where it cannot decide
        self._full_window_fitted = False  # an estimate of a full window published since the start

    # --- configuration ---------------------------------------------------
    @property
    def config(self) -> OnlineConfig:
        """The configuration in force."""
        return self._config

    def reconfigure(self, config: OnlineConfig) -> None:
        """Use a new configuration from the next refit on (window and schedule are kept).

        A new model or new effects forget the estimate in force and the change detector's references.

        Parameters
        ----------
        config : OnlineConfig
            The new configuration (validated here).
        """
        config = config.validate()
        with self._lock:
            if (config.model, config.effects) != (self._config.model, self._config.effects):
                self._last_good = self._trust.candidate = None
                self._change.forget()
                self._scatter.forget()
                self._valley.forget()
                self._full_window_fitted = False
            self._change.ratio, self._change.length = config.change_ratio, config.change_test_length
            self._change.short = _short_test(config)
            if config.refit_period != self._config.refit_period and self._next_due is not None:
                self._next_due = min(self._next_due, self._latest_time + config.refit_period)
            self._config = config

    # --- input -----------------------------------------------------------
    def add(self, sample: Sample) -> str:
        """Store a sample, or count why it was rejected.

        Parameters
        ----------
        sample : Sample
            The sample (time s on the clock that feeds the identifier, SI value, NED).

        Returns
        -------
        str
            'accepted', or the rejection ('non_finite', 'absurd', 'duplicate', 'out_of_order').
        """
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
            self._valley.forget()
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
        """Whether a refit is due at clock time ``now``; the schedule starts at the first call.

        Parameters
        ----------
        now : float
            Clock time (s).

        Returns
        -------
        bool
            True when a refit is due (call ``refit(now)``).
        """
        with self._lock:
            self._observe_clock(now)
            if self._next_due is None:
                self._next_due = now + self._config.refit_period
            return now >= self._next_due

    def skip(self, now: float) -> None:
        """Move the schedule past ``now`` without refitting (a refit was still running).

        Parameters
        ----------
        now : float
            Clock time (s).
        """
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
        """Between refits: whether the newest data show a change of the vessel.

        At most WATCHES_PER_REFIT times per refit period, the change detector's quick test on the newest
        data it reads (``quick_span``; the newest 2 ``change_test_length`` s where a change shows, to
        locate it), with an accepted estimate in force and no change being followed. A change found
        restarts the window where it happened and makes a refit due at once.

        Parameters
        ----------
        now : float
            Clock time (s).

        Returns
        -------
        bool
            True when a change was found (call ``refit(now)``).
        """
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
        # the test's own span resampled, the wider one only where a change shows and is located
        newest = max(now - self._change.quick_span(config.sample_time), oldest)
        try:
            dataset = _resample(
                config, {role: rows[np.searchsorted(rows[:, 0], newest) :] for role, rows in series.items()}
            )
            ratio, changed_at = self._change.quick_test(config.structure(), dataset, lambda: _resample(config, series))
        except (DataError, StructureError, ValueError):
            return False
        if changed_at is None:
            return False
        self._declare_change(config, now, ratio, changed_at)
        return True

    # --- refit -----------------------------------------------------------
    def refit(self, now: float) -> RefitRecord:
        """Fit the window as it is at clock time ``now`` and advance the schedule.

        Parameters
        ----------
        now : float
            Clock time (s).

        Returns
        -------
        RefitRecord
            The estimate in force (new, or the last good one), the window, the conditions found and
            the verdicts behind them.
        """
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
        """The window at clock time ``now`` resampled as a refit resamples it (after the last change, if any).

        Parameters
        ----------
        now : float
            Clock time (s).

        Returns
        -------
        Dataset
            The window on the ``sample_time`` grid, split at gaps.

        Raises
        ------
        DataError
            When it cannot be resampled.
        """
        with self._lock:
            config = self._config
            oldest = max(now - config.window_length, self._window_floor)
            series = {role: self._window[role].array(oldest) for role in ROLES}
        return _resample(config, series)

    def _fit(self, config: OnlineConfig, series: dict, last_good, record: RefitRecord) -> None:
        """Fit the window's ``series``: the full fit, or after a change the gain follow (``gain_follow``)
        while the new data are short or their full fits are refused."""
        try:
            dataset = _resample(config, series)
        except DataError as exc:
            record.report(Verdict("refit_failed", "window_unusable", {"error": str(exc)}))
            return
        structure = config.structure()
        if last_good is not None and self._change_note is None:
            dataset = self._test_for_change(config, structure, dataset, record)
        if not dataset.n_samples:  # the inputs' samples never meet on one grid (gaps), or a change restarted it
            record.report(Verdict("refit_failed", "window_unusable", {"error": "no sample time has all inputs"}))
            return
        if self._change_note is not None and last_good is not None:
            if dataset.duration >= config.min_window_length - 0.5 * config.sample_time:
                self._full_fit(config, structure, dataset, last_good, record)
                if record.new_estimate or self._change_note is None:
                    return
                refused = dict(record.verdicts)  # the full fit's refusal, then K followed instead
            else:
                refused = {}
            self._follow_gain(config, structure, dataset, last_good, record)
            if record.new_estimate:
                for verdict in refused.values():
                    record.report(replace(verdict, keeping=FOLLOWED) if verdict.keeping else verdict)
            return
        self._full_fit(config, structure, dataset, last_good, record)

    def _full_fit(self, config, structure, dataset, last_good, record: RefitRecord) -> None:
        """Every free parameter fitted on the window's ``dataset`` (``window_fit``), its errors widened
        (``uncertainty``), judged (``trust``) and published when it passes; a full window's estimate
        then calibrates the change detector."""
        record.window = (float(dataset.time[0]), float(dataset.time[-1]))
        if dataset.gaps:
            gaps = {"gaps": len(dataset.gaps), "longest": max(b - a for a, b in dataset.gaps)}
            record.report(Verdict("gap_in_window", "segments_apart", gaps))
        record.conditions.update(rudder_saturation(dataset.rudder, config.rudder_limit))
        fitted = fit_window(config, structure, dataset, last_good)
        if isinstance(fitted, Verdict):
            record.report(fitted)
            return
        estimate, estimator = fitted
        full = dataset.duration >= config.window_length - FULL_WINDOW_MARGIN * config.sample_time
        # its own errors, T1's with its slide along the T2 = T3 valley: so it enters the scatter of the
        # next estimates (a fit at the valley's foot with a small error makes the right estimates after
        # it look scattered); whether T2 is told from zero is judged on the window's own T2 error
        estimate = replace(
            estimate,
            std_errors=first_order_valley(estimate, estimate.std_errors, estimator, structure, dataset, self._valley),
        )
        published = replace(estimate, std_errors=self._scatter.honest(estimate))
        implausible = self._trust.plausibility(config, structure, published, dataset, last_good)
        if implausible:
            record.report(implausible)
            return
        start_up = not (full or self._full_window_fitted)  # a short window, no history of estimates
        published = replace(published, std_errors=along_the_damping(published, estimator, structure, dataset, start_up))
        uncertain = self._trust.precision(
            published, last_good, after_change=self._change_note is not None, followed=self._gain_followed()
        )
        if uncertain:
            record.report(uncertain)
            if uncertain.keeping:
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
            self._trust.candidate = None

    def _follow_gain(self, config, structure, dataset, last_good, record) -> None:
        """After a change, while the new data are shorter than ``min_window_length`` or the full fits
        on them are refused: the gain refitted on them (``gain_follow.refit_gain``), the other
        parameters held from the reference the change was declared against (ChangeDetector.base; the
        last good estimate without one); published when the new data determine it and it passes the
        checks of any new estimate (``trust``), judged against the held hull with the last good
        estimate's errors."""
        record.window = (float(dataset.time[0]), float(dataset.time[-1]))
        if self._change.base:
            held, held_errors = self._change.base, self._change.base_errors
        else:
            held, held_errors = last_good.parameters, last_good.std_errors
        estimate, undetermined = refit_gain(
            config, structure, dataset, held, held_errors, last_good.method, record.window
        )
        if estimate is None:
            if undetermined:
                record.report(undetermined)
            return
        # judged against the hull it was refitted from: the last good estimate may come from a
        # window straddling the change, fitted partly on these very data; once K has been followed
        # on the new data, against that (each refit would otherwise jump from the old hull again and
        # be held for the next one to confirm: every other refit refused)
        followed = self._gain_followed()
        yardstick = last_good if followed else replace(last_good, parameters=dict(last_good.parameters, **held))
        reason = undetermined or self._trust.plausibility(config, structure, estimate, dataset, yardstick)
        if reason:
            figures = {
                "duration": dataset.duration,
                "reason": reason,
                "full_fit": record.verdicts.get(reason.condition),
            }
            record.report(Verdict(reason.condition, "gain_refit_refused", figures, LAST_GOOD))
            return
        self._publish(config, structure, estimate, estimate, dataset, record, scatter=False)

    def _gain_followed(self) -> bool:
        """Whether the estimate in force was fitted on data after the last change (a followed gain)."""
        with self._lock:
            return self._last_good_window[0] >= self._window_floor

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
            self._valley.forget()  # and lie in another valley
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


def run_schedule(identifier: OnlineIdentifier, samples, diagnosis=None):
    """Feed time-ordered samples with their own stamps as the clock; yield each refit's record.

    This is the node's loop with the bag's time for the node's clock: a refit
    due at a sample's time, or one a change found between refits calls for
    (``watch``), runs on everything that arrived before it.
    An effect the diagnosis adds or removes by itself takes effect from the next refit.

    Parameters
    ----------
    identifier : OnlineIdentifier
        The identifier to feed.
    samples : iterable of Sample
        Samples in time order (time s, SI values).
    diagnosis : diagnosis.onboard.OnlineDiagnosis or None
        The diagnosis on board, run on the window after each refit when due.

    Yields
    ------
    RefitRecord
        Each refit's record, in time order.
    """
    checked = None  # the stamp the schedule was last checked at
    for sample in samples:
        # inputs sampled together share a stamp: a refit or watch there moved the schedule past it,
        # and neither is due again at that stamp
        if sample.time != checked and (identifier.due(sample.time) or identifier.watch(sample.time)):
            record = identifier.refit(sample.time)
            if diagnosis is not None:
                effects = diagnosis.after_refit(record, identifier)
                if effects is not None:
                    identifier.reconfigure(replace(identifier.config, effects=effects))
            yield record
        checked = sample.time
        identifier.add(sample)
