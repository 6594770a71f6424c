"""What the node publishes and ``replay --out`` writes, without ROS: one definition for both.

From each refit's ``RefitRecord``: the trusted parameters (``~/parameters``: status OK only),
K with its 95 % band (``~/gain_band``), the ``/diagnostics`` status, and from the diagnosis
the noise floor beside the held-out error. ``YawRatePrediction`` turns the input samples into
the ``~/predicted_yaw_rate`` stream: the newest estimate run free from the measured state,
restarted every ``prediction_horizon`` s, one value per yaw-rate sample. The node wraps these in
rclpy messages, replay in rosbags messages; nothing here knows either.
"""

from __future__ import annotations

import math
import threading

import numpy as np

from ..estimators.base import Z_95
from ..model.dataset import DataError, resample_series
from ..model.structure import Structure, StructureError
from .config import OnlineConfig
from .identifier import CONDITION_LEVELS, RefitRecord
from .samples import ROLES, Sample

GAIN_BAND_LABELS = ("K_low95", "K", "K_high95")
DIAGNOSTIC_NAME = "ship_ident: identification"
# ~/predicted_yaw_rate is a geometry_msgs/Vector3Stamped in the body frame forward-right-down (the
# yaw rate's NED sign: positive clockwise seen from above) with the yaw rate in z; x and y (roll and
# pitch rates) are not modelled and carry NaN.
PREDICTION_FRAME = "base_link_frd"


def trusted_parameters(record: RefitRecord) -> tuple[list[str], list[float]] | None:
    """The estimate an autopilot may steer by: the record's status is OK and every value finite.

    The names are the estimate's own, in its order (they follow the model and its effects: read them,
    never positions).

    Parameters
    ----------
    record : RefitRecord
        The refit's record.

    Returns
    -------
    tuple of (list of str, list of float) or None
        (names, values, SI units) of the estimate in force; None when it is not trusted.
    """
    parameters = (record.estimate or {}).get("parameters") or {}
    if record.status != "OK" or not parameters or not all(math.isfinite(v) for v in parameters.values()):
        return None
    return list(parameters), [float(v) for v in parameters.values()]


def gain_band(record: RefitRecord) -> list[float] | None:
    """The gain's 95 % band [K - 1.96 s, K, K + 1.96 s] (1/s) of the estimate in force, whatever its status.

    Its standard error s as published: a loose estimate shows a wide band.

    Parameters
    ----------
    record : RefitRecord
        The refit's record.

    Returns
    -------
    list of float or None
        The band's lower end, K and upper end (1/s); None without a finite K and error.
    """
    estimate = record.estimate or {}
    gain = estimate.get("parameters", {}).get("K", math.nan)
    error = estimate.get("std_errors", {}).get("K", math.nan)
    if not (math.isfinite(gain) and math.isfinite(error)):
        return None
    return [gain - Z_95 * error, gain, gain + Z_95 * error]


def diagnostic_status(record: RefitRecord, extra: dict | None = None) -> tuple[int, str, list[tuple[str, str]]]:
    """The ``/diagnostics`` status of a refit: level, message and key-values.

    The conditions (most severe first, ``condition/NAME``), the input counts, ``extra`` values, the
    parameters and the free-run fit of the estimate in force, the refit's compute time.

    Parameters
    ----------
    record : RefitRecord
        The refit's record.
    extra : dict or None
        More key-values to show (the node's own: its callback error count).

    Returns
    -------
    level : int
        0 OK, 1 WARN, 2 ERROR.
    message : str
        The conditions' sentences, or 'estimating'.
    values : list of (str, str)
        Key-values.
    """
    conditions = record.conditions
    ordered = sorted(conditions, key=lambda c: -CONDITION_LEVELS.get(c, 2))
    message = "; ".join(f"{c.replace('_', ' ')}: {conditions[c]}" for c in ordered) or "estimating"
    values = [(f"condition/{c}", conditions[c]) for c in ordered]
    values += [(k, str(v)) for k, v in record.counts.items()]
    values += [(k, str(v)) for k, v in (extra or {}).items()]
    estimate = record.estimate or {}
    if estimate.get("parameters"):
        values += [(k, f"{v:.6g}") for k, v in estimate["parameters"].items()]
        values.append(("rmse_yaw_rate", f"{estimate.get('fit', {}).get('rmse_yaw_rate', math.nan):.6g}"))
    values.append(("refit_seconds", f"{record.compute_seconds:.4f}"))
    return record.level, message, values


def error_and_floor(diagnosis: dict | None) -> tuple[float, float] | None:
    """The held-out free-run yaw-rate error of a finished diagnosis and its noise floor.

    The figures its verdict is read from: those pooled since the model or vessel last changed
    (``diagnosis["pooled"]``), or the window's own while nothing is pooled yet. One window's error
    scatters about the floor by its fit's own scatter; the pooled one settles as the evidence grows.

    Parameters
    ----------
    diagnosis : dict or None
        The diagnosis on board's record (``diagnosis.onboard``).

    Returns
    -------
    tuple of float or None
        (error, floor) in rad/s; None unless the diagnosis is done.
    """
    if diagnosis is None or diagnosis.get("status") != "done":
        return None
    figures = diagnosis.get("pooled", diagnosis)
    return float(figures["held_out_error"]), float(figures["noise_floor"])


class YawRatePrediction:
    """``~/predicted_yaw_rate``: the model against the measurements, as a stream at the input rate.

    From the first yaw-rate sample after the first estimate on, the inputs are cut into runs of
    ``prediction_horizon`` s, each beginning at a yaw-rate sample. A run is simulated once, when a
    sample of any input reaches its horizon (the rudder it is driven by is only known then; the
    inputs arrive in time order, as the node stamps them and as a bag holds them): the estimate
    in force when the run began
    (``update``; any status) run free with the core's ``Structure.simulate`` from the measured
    heading and yaw rate at the run's start (yaw acceleration 0) over the measured rudder
    resampled to ``sample_time``, read at the run's yaw-rate sample times. ``add`` returns the
    finished run's (time s, predicted yaw rate rad/s) pairs; ``flush`` the run in progress (the
    end of a bag). The error grows along each run where the model misses the vessel, and every run
    starts again from the measurement, so the plot shows where the model fails, not a one-step
    echo. Thread-safe (samples from message callbacks, estimates from the refit worker).

    Parameters
    ----------
    config : OnlineConfig
        The configuration in force (``prediction_horizon`` and ``sample_time`` in s, gap, speed topic).
    """

    def __init__(self, config: OnlineConfig):
        self._lock = threading.Lock()
        self._config = config
        self._estimate = None  # (Structure, parameters) in force, from the newest refit with one
        self._run_estimate = None  # ... when the run in progress began
        self._run_start = math.nan  # s; NaN: no run in progress
        self._run = {role: [] for role in ROLES}  # (time, value) of the run in progress, per role
        self._last = dict.fromkeys(ROLES)  # the newest (time, value) of each role before the run

    def update(self, record: RefitRecord, config: OnlineConfig) -> None:
        """Take the refit's estimate in force and the configuration in force, both from the next run on.

        Parameters
        ----------
        record : RefitRecord
            The refit's record.
            Its estimate is kept when it has none.
        config : OnlineConfig
            The configuration in force (``prediction_horizon``, ``sample_time``, gap and speed topic).
        """
        estimate = record.estimate
        with self._lock:
            self._config = config
            if estimate and estimate.get("parameters") and estimate.get("structure"):
                try:
                    structure = Structure(estimate["structure"]["model"], estimate["structure"]["effects"])
                except StructureError:
                    return
                self._estimate = (structure, dict(estimate["parameters"]))

    def add(self, sample: Sample) -> list[tuple[float, float]]:
        """Take one input sample; return the predictions of the run it ends, if it ends one.

        A value that is not finite, or not newer than its role's last, is left out.

        Parameters
        ----------
        sample : Sample
            The input sample (time s, SI value).

        Returns
        -------
        list of (float, float)
            (time s, predicted yaw rate rad/s) of the finished run, else [].
        """
        with self._lock:
            finished = self._take(sample)
        return self._predict(*finished) if finished else []

    def _take(self, sample: Sample) -> tuple | None:
        """Store ``sample`` in the run in progress (or before it); the run it ends, if any. A sample
        of any input at or past the run's horizon ends it (an input falling silent cannot make a run
        grow); the next run begins at the next yaw-rate sample."""
        if sample.time < self._run_start - self._config.clock_jump_threshold:  # the clock went back
            self._forget()
        role, point = sample.role, (sample.time, sample.value)
        newest = self._run[role][-1] if self._run[role] else self._last[role]
        if not math.isfinite(sample.value) or (newest is not None and sample.time <= newest[0]):
            return None
        finished = None
        if math.isnan(self._run_start):
            self._last[role] = point
        else:
            self._run[role].append(point)
            if sample.time >= self._run_start + self._config.prediction_horizon:
                finished = self._take_run()  # its inputs reach its end; their newest open the next run
        if math.isnan(self._run_start) and role == "yaw_rate" and self._estimate is not None:
            self._run_start, self._run_estimate = sample.time, self._estimate  # from this measured state
        return finished

    def flush(self) -> list[tuple[float, float]]:
        """The run in progress, predicted on what arrived of it (the end of a bag).

        Returns
        -------
        list of (float, float)
            (time s, predicted yaw rate rad/s); [] without a run in progress.
        """
        with self._lock:
            if math.isnan(self._run_start):
                return []
            finished = self._take_run()
            self._forget()
        return self._predict(*finished)

    def _take_run(self) -> tuple:
        """(estimate, config, start s, samples per role with the newest before the run first) of the
        run in progress, which ends; the newest sample of each role is kept to open the next run."""
        series = {role: ([self._last[role]] if self._last[role] else []) + self._run[role] for role in ROLES}
        for role in ROLES:
            if series[role]:
                self._last[role] = series[role][-1]
            self._run[role] = []
        finished = self._run_estimate, self._config, self._run_start, series
        self._run_start, self._run_estimate = math.nan, None
        return finished

    def _forget(self) -> None:
        self._run_start, self._run_estimate = math.nan, None
        self._run = {role: [] for role in ROLES}
        self._last = dict.fromkeys(ROLES)

    @staticmethod
    def _predict(estimate, config: OnlineConfig, start: float, series: dict) -> list[tuple[float, float]]:
        """The run that began at ``start`` (s) simulated once, read at its yaw-rate samples before
        its horizon; [] when it cannot be (too few samples, a model needing an input the run lacks)."""
        structure, parameters = estimate
        roles = [r for r in ROLES if r != "speed" or structure.needs_speed]
        if any(len(series[r]) < 2 for r in roles):
            return []
        arrays = {r: np.array(series[r], dtype=float) for r in roles}
        try:
            series = {r: (a[:, 0], a[:, 1]) for r, a in arrays.items()}
            dataset = resample_series(series, config.sample_time, config.gap)
            _, predicted = structure.simulate(parameters, dataset)
        except (DataError, StructureError, ValueError):
            return []
        stamps = arrays["yaw_rate"][:, 0]
        simulated = (stamps >= dataset.time[0]) & (stamps <= dataset.time[-1] + 0.5 * config.sample_time)
        inside = stamps[simulated & (stamps >= start) & (stamps < start + config.prediction_horizon)]
        values = np.interp(inside, dataset.time, predicted)
        return [(float(t), float(v)) for t, v in zip(inside, values) if math.isfinite(v)]
