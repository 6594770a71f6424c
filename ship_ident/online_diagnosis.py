"""Diagnosis on board: which catalogued effect the model in force misses, while the boat sails.

Every ``diagnosis_period`` seconds (node clock, or the bag's time in replay) the identifier's
window is diagnosed as ``ship-ident diagnose`` diagnoses a record (``diagnose.diagnose``, the same
ranking): the model in force is fitted on the older ``TRAINING_FRACTION`` (65 %) of the window
and run free on the newest 35 % (held out, cut into free-run windows, each started from the
measured heading and yaw rate); every effect not in the model is added in turn, refitted and
judged on the same held-out runs. The **held-out error** is the yaw-rate RMSE of those free runs
(rad/s); with the right model it sits at the yaw-rate **noise floor** (the sensor's noise,
rad/s), and an effect the model lacks lifts it above. Adding the effect makes it fall.

A single window holds about a minute of held-out data, where a weak effect's t statistic
(``diagnose.loss_t_statistic``) scatters about 3. A candidate is therefore also significant when
its t, pooled over the last ``POOLED_DIAGNOSES`` diagnoses of the same model (Stouffer:
sum t / sqrt(n), each t clipped to [-3, 6] so that no single window carries the pool), reaches
``SIGNIFICANCE_T`` while it removes on average at least ``MIN_IMPROVEMENT`` of the held-out
yaw-rate error and the newest window's training free runs gain too (``MIN_TRAINING_GAIN``).
The verdict ``missing_effect`` raises a ``missing_effect`` WARN in the refit records (and so in
``/diagnostics``) until a later diagnosis or a new model clears it.

With ``auto_add_effects``, an effect named in ``auto_add_after`` consecutive diagnoses is added
to the model, and removed again when none of the next ``CHECK_DIAGNOSES`` diagnoses of the new
model shows its held-out error below (1 - ``MIN_IMPROVEMENT``) times the error before; a removed
effect is not added again until the model is changed from outside.

A diagnosis is skipped, with a reason, when the window cannot support it: too short to hold
out ``MIN_HELD_OUT_S``, too little excitation, the fit failed; on the node also while the
previous one still runs or the CPU budget is spent. The node runs diagnoses in a child process at
low priority (``DiagnosisWorker``), so a refit never waits for one; replay runs them inline at
the refit where they are due (``InlineRunner``), so a replay is reproducible.
"""

from __future__ import annotations

import math
import os
import signal
import time
from collections import deque
from dataclasses import dataclass
from multiprocessing import get_context

import numpy as np

from .dataset import DataError, Dataset
from .diagnose import DEFAULT_METHOD as DIAGNOSIS_METHOD
from .diagnose import MIN_HELD_OUT_S, MIN_IMPROVEMENT, MIN_TRAINING_GAIN, SIGNIFICANCE_T, TRAINING_FRACTION, diagnose
from .estimators.base import excitation_shortfall
from .structure import StructureError

POOLED_DIAGNOSES = 3  # t statistics pooled over this many diagnoses of the same model
POOLED_T_LIMITS = (-SIGNIFICANCE_T, 2 * SIGNIFICANCE_T)  # each window's t clipped to this before pooling
CHECK_DIAGNOSES = 2  # an added effect must cut the held-out error within this many diagnoses
WORST_SHOWN = 3  # worst free-run segments (with their conditions) in the record
CPU_BUDGET = 0.1  # node: a diagnosis may start once the last one's CPU time is this share of the time since
NICENESS = 10  # the diagnosis process yields the CPU to the refits
MIN_WINDOW_S = MIN_HELD_OUT_S / (1.0 - TRAINING_FRACTION)  # s of window that hold out MIN_HELD_OUT_S


def add_command(node: str, effects) -> str:
    """The shell command that sets the node's effects: ``ros2 param set NODE effects "[a, b]"``."""
    return f'ros2 param set {node} effects "[{", ".join(effects)}]"'


# --- one diagnosis (runs in the child process on the node) ----------------------------------
def skipped(stamp: float, model: str, effects, reason: str) -> dict:
    """The record of a diagnosis not made at clock time ``stamp`` (s), and why."""
    return {
        "stamp": stamp,
        "status": "skipped",
        "structure": {"model": model, "effects": list(effects)},
        "method": DIAGNOSIS_METHOD,
        "reason": reason,
        "compute_seconds": 0.0,
    }


def too_short(dataset: Dataset) -> str | None:
    """Why the window is too short for a diagnosis (it must hold out ``MIN_HELD_OUT_S``), or None."""
    if dataset.duration >= MIN_WINDOW_S:
        return None
    return (
        f"the window holds {dataset.duration:.0f} s; a diagnosis needs {MIN_WINDOW_S:.0f} s "
        f"({MIN_HELD_OUT_S:.0f} s held out)"
    )


def diagnose_window(dataset: Dataset, model: str, effects: tuple, stamp: float) -> dict:
    """The diagnosis of one window at clock time ``stamp`` (s), as a JSON-ready dict: ``status``
    ``done`` with the window's own verdict, candidates, held-out error and noise floor (rad/s),
    or ``skipped`` with the ``reason``. Never raises on bad data."""
    started = time.process_time()
    reason = too_short(dataset) or excitation_shortfall(dataset)
    record = skipped(stamp, model, effects, reason)
    if reason is None:
        try:
            result = diagnose(dataset, model, effects, workers=1)
        except (DataError, StructureError, ValueError, np.linalg.LinAlgError) as exc:
            record["reason"] = f"fit failed: {exc}"
        else:
            if "low_excitation" in result.estimate.flags:
                record["reason"] = "too little excitation: the training part hardly excites the yaw (low_excitation)"
            else:
                del record["reason"]
                record.update(_done(result))
    record["window"] = {"start": float(dataset.time[0]), "end": float(dataset.time[-1])}
    record["compute_seconds"] = time.process_time() - started
    return record


def _done(result) -> dict:
    """The parts of a ``diagnose.Diagnosis`` the crew reads."""
    held_out = result.held_out
    return {
        "status": "done",
        "verdict": result.verdict,
        "verdict_sentence": result.verdict_sentence,
        "candidates": [c.to_json() for c in result.candidates],
        "held_out_error": float(result.run.fit["rmse_yaw_rate"]),
        "held_out_error_heading": float(result.run.fit["rmse_heading"]),
        "noise_floor": float(result.noise["yaw_rate"]),
        "training": {"start": float(result.training.time[0]), "end": float(result.training.time[-1])},
        "held_out": {
            "start": float(held_out.time[0]),
            "end": float(held_out.time[-1]),
            "windows": len(held_out.segments),
        },
        "worst_conditions": result.worst_segments[:WORST_SHOWN],
        "parameters": {k: float(v) for k, v in result.estimate.parameters.items()},
    }


def _run(job: tuple) -> dict:
    return diagnose_window(*job)


# --- where diagnoses run ------------------------------------------------------------------
class InlineRunner:
    """Runs a diagnosis at once, in the caller's thread (replay: reproducible, no CPU budget)."""

    def __init__(self):
        self._result = None

    def refusal(self, now: float) -> str | None:
        return None

    def submit(self, job: tuple) -> None:
        self._result = _run(job)

    def poll(self) -> dict | None:
        result, self._result = self._result, None
        return result

    def close(self) -> None:
        pass


def _serve(connection) -> None:
    """Child process: diagnose each job received, send back the result. A terminal's Ctrl-C reaches
    the whole process group: the child leaves it to the node, which ends it (``close``)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    while True:
        try:
            job = connection.recv()
        except EOFError:
            return
        try:
            result = _run(job)
        except Exception as exc:  # a bug in a diagnosis must not end the process serving them
            _, model, effects, stamp = job
            result = skipped(stamp, model, effects, f"diagnosis failed: {type(exc).__name__}: {exc}")
        connection.send(result)


class DiagnosisWorker:
    """Runs diagnoses in one child process at low priority (``NICENESS``), one at a time, so a
    refit never waits for one; a new diagnosis starts only when the last one's CPU time is at most
    ``CPU_BUDGET`` of the time since it started. The child starts with ``start`` (the node: at its
    start, so that its imports run while the window fills) or at the first diagnosis (``spawn``: a
    fresh interpreter, never a fork of the ROS process and its threads)."""

    def __init__(self):
        self._process = self._connection = None
        self._job = None  # (stamp, model, effects) of the diagnosis in progress
        self._budget_until = -math.inf  # clock time (s) before which no diagnosis starts

    def refusal(self, now: float) -> str | None:
        """Why no diagnosis can start at clock time ``now`` (s), or None."""
        if self._job is not None:
            return f"the previous diagnosis (started at {self._job[0]:.1f} s) still runs"
        if now < self._budget_until:
            return (
                f"CPU budget ({100 * CPU_BUDGET:g} % of one core): the last diagnosis used its share "
                f"until {self._budget_until:.1f} s"
            )
        return None

    def start(self) -> None:
        """Start the child process now (its imports take seconds) unless it runs already."""
        if self._process is None or not self._process.is_alive():
            context = get_context("spawn")
            self._connection, child = context.Pipe()
            self._process = context.Process(target=_serve, args=(child,), name="ship_ident diagnosis", daemon=True)
            self._process.start()
            os.setpriority(os.PRIO_PROCESS, self._process.pid, NICENESS)  # before its imports, not after
            child.close()

    def submit(self, job: tuple) -> None:
        self.start()
        self._job = (job[3], job[1], job[2])
        self._connection.send(job)

    def poll(self) -> dict | None:
        """The finished diagnosis, or None while it runs (a dead child: a skipped record)."""
        if self._job is None:
            return None
        stamp, model, effects = self._job
        try:
            if not self._connection.poll():
                if self._process.is_alive():
                    return None
                raise EOFError
            result = self._connection.recv()
        except (EOFError, OSError):
            result = skipped(stamp, model, effects, f"the diagnosis process ended (exit code {self._process.exitcode})")
            self._process = None
        self._job = None
        self._budget_until = stamp + result["compute_seconds"] / CPU_BUDGET
        return result

    def close(self) -> None:
        """Stop the child (a diagnosis in progress is abandoned)."""
        if self._process is not None:
            self._process.terminate()
            self._process.join(timeout=5.0)
            self._connection.close()
            self._process = None


# --- the schedule, the pooled verdict and auto-add ------------------------------------------
@dataclass
class Trial:
    """An effect added by the node itself, on probation: its held-out error before (rad/s)."""

    effect: str
    error_before: float
    diagnoses: int = 0


class OnlineDiagnosis:
    """Diagnoses the identifier's window every ``diagnosis_period`` (its configuration, read at
    each refit; 0: off) through ``runner`` (``InlineRunner`` by default, ``DiagnosisWorker`` on the
    node); pools the verdict over the last diagnoses and runs ``auto_add_effects``.

    ``after_refit(record, identifier)`` is called after every refit: it starts a due diagnosis,
    puts a finished one into ``record.diagnosis`` and the ``missing_effect`` WARN into
    ``record.conditions``, and returns the effects to set when auto-add adds or removes one
    (None otherwise). ``node`` names the node in the ``ros2 param set`` command of the record.
    """

    def __init__(self, runner=None, node: str = "/ship_ident"):
        self.runner = runner or InlineRunner()
        self.node = node
        self._next_due: float | None = None
        self._history: deque = deque(maxlen=POOLED_DIAGNOSES)  # done diagnoses of one model, oldest first
        self._warning: tuple | None = None  # ((model, effects), sentence) of the last missing_effect
        self._streak: tuple[str, int] = ("", 0)  # effect named in consecutive diagnoses, how many
        self._trial: Trial | None = None
        self._rejected: set[str] = set()  # effects auto-add removed (not added again)
        self._in_force: tuple | None = None  # (model, effects) at the last refit
        self._asked: tuple | None = None  # effects auto-add asked for (its own change, not an outside one)

    def after_refit(self, record, identifier) -> tuple | None:
        config = identifier.config
        structure = (config.model, tuple(config.effects))
        if self._in_force is not None and structure != self._in_force:
            self._model_changed(structure)
        self._in_force = structure
        now = record.time
        finished = self.runner.poll()  # first: a diagnosis that just ended frees the runner for a due one
        if config.diagnosis_period > 0 and self._is_due(now, config.diagnosis_period):
            refusal = self.runner.refusal(now)
            if refusal is None:
                try:
                    dataset = identifier.window_dataset(now)
                except DataError as exc:
                    refusal = f"window unusable: {exc}"
                else:
                    refusal = too_short(dataset)  # said here: no process started for it
                    if refusal is None:
                        self.runner.submit((dataset, config.model, tuple(config.effects), now))
                        finished = finished or self.runner.poll()  # inline: done at once
            if refusal is not None and finished is None:  # (a finished one is the news of this refit)
                record.diagnosis = skipped(now, config.model, config.effects, refusal)
        change = None
        if finished is not None:
            change = self.finish(finished, config)
            record.diagnosis = finished
        if self._warning is not None and self._warning[0] == structure:
            record.conditions["missing_effect"] = self._warning[1]
        return change

    def close(self) -> None:
        self.runner.close()

    def _is_due(self, now: float, period: float) -> bool:
        if self._next_due is None or now < self._next_due - period:  # first call, or the clock went back
            self._next_due = now + period
            return False
        if now < self._next_due:
            return False
        self._next_due = self._next_due + period if now - self._next_due < period else now + period
        return True

    def _model_changed(self, structure: tuple) -> None:
        """The model in force changed: its history, streak and warning no longer apply; a change
        from outside (not auto-add's own) ends a trial and forgives the removed effects."""
        self._history.clear()
        self._streak = ("", 0)
        self._warning = None
        if structure[1] != self._asked:
            self._trial = None
            self._rejected.clear()
        self._asked = None

    def finish(self, result: dict, config) -> tuple | None:
        """Take a finished diagnosis ``result`` of the model configured in ``config``: complete it in
        place (each candidate's pooled ``significant`` and ``pooled_t``, the verdict, the ``ros2
        param set`` command), keep the ``missing_effect`` warning, run auto-add; return the effects
        auto-add sets (None: unchanged). A skipped diagnosis, or one of another model than
        ``config``'s (it started before a change), changes nothing."""
        structure = (result["structure"]["model"], tuple(result["structure"]["effects"]))
        current = structure == (config.model, tuple(config.effects))
        if result["status"] != "done" or not current:
            return None
        if self._history and self._history[-1]["structure"] != result["structure"]:
            self._history.clear()  # pooled over diagnoses of one model only
        self._history.append(result)
        found = self._pool(result)
        effects = structure[1]
        if found is not None:
            top = next(c for c in result["candidates"] if c["effect"] == found)
            result["verdict"] = "missing_effect"
            result["add_command"] = add_command(self.node, effects + (found,))
            if top["significant_in_window"]:
                t = f"t {top['t_statistic']:.1f}"
            else:
                t = f"t {top['pooled_t']:.1f} pooled over the last {len(self._history)} diagnoses"
            result["verdict_sentence"] = (
                f"{found} is missing: adding it removes {100 * top['improvement_yaw_rate']:.0f} % of the held-out "
                f"yaw-rate error ({t}); {top['evidence']}"
            )
            self._warning = (structure, f"{result['verdict_sentence']}; add it: {result['add_command']}")
        else:
            result["add_command"] = None
            self._warning = None
        return self._auto_add(result, found, effects, config)

    def _pool(self, result: dict) -> str | None:
        """Mark each candidate's pooled significance; return the effect found missing (or None)."""
        low, high = POOLED_T_LIMITS
        for candidate in result["candidates"]:
            name = candidate["effect"]
            same = [next((c for c in h["candidates"] if c["effect"] == name), None) for h in self._history]
            ts = [float(np.clip(c["t_statistic"] if c else 0.0, low, high)) for c in same]
            gains = [c["improvement_yaw_rate"] if c else 0.0 for c in same]
            pooled_t = sum(ts) / math.sqrt(len(ts))
            candidate["significant_in_window"] = candidate["significant"]
            candidate["pooled_t"] = pooled_t
            candidate["significant"] = bool(
                candidate["significant"]
                or (
                    pooled_t >= SIGNIFICANCE_T
                    and float(np.mean(gains)) >= MIN_IMPROVEMENT
                    and candidate["improvement_yaw_rate"] > 0
                    and candidate["training_gain"] >= MIN_TRAINING_GAIN
                )
            )
        result["candidates"].sort(key=lambda c: not c["significant"])  # stable: diagnose's order otherwise
        top = result["candidates"][0] if result["candidates"] else None
        return top["effect"] if top is not None and top["significant"] else None

    def _auto_add(self, result: dict, found: str | None, effects: tuple, config) -> tuple | None:
        """Add the effect named in ``auto_add_after`` consecutive diagnoses; judge one added before."""
        trial = self._trial
        if trial is not None and trial.effect in effects:
            trial.diagnoses += 1
            error = result["held_out_error"]
            if error <= (1.0 - MIN_IMPROVEMENT) * trial.error_before:
                self._trial = None
                return self._announce(
                    result,
                    "kept",
                    trial.effect,
                    effects,
                    f"{trial.effect} kept: the held-out yaw-rate error fell from "
                    f"{math.degrees(trial.error_before):.3f} to {math.degrees(error):.3f} deg/s",
                )
            if trial.diagnoses >= CHECK_DIAGNOSES:
                self._trial = None
                self._rejected.add(trial.effect)
                kept = tuple(e for e in effects if e != trial.effect)
                return self._announce(
                    result,
                    "removed",
                    trial.effect,
                    kept,
                    f"{trial.effect} removed again: the held-out yaw-rate error did not fall in "
                    f"{trial.diagnoses} diagnoses ({math.degrees(trial.error_before):.3f} before, "
                    f"{math.degrees(error):.3f} deg/s now)",
                )
            return None
        if not config.auto_add_effects or found is None or found in self._rejected:
            self._streak = ("", 0)
            return None
        count = self._streak[1] + 1 if self._streak[0] == found else 1
        self._streak = (found, count)
        if count < config.auto_add_after:
            return None
        self._trial = Trial(found, result["held_out_error"])
        return self._announce(
            result,
            "added",
            found,
            effects + (found,),
            f"{found} added by auto_add_effects: named in {count} consecutive diagnoses; removed again "
            f"unless the held-out yaw-rate error ({math.degrees(result['held_out_error']):.3f} deg/s) "
            f"falls by {100 * MIN_IMPROVEMENT:.0f} % within {CHECK_DIAGNOSES} diagnoses",
        )

    def _announce(self, result: dict, action: str, effect: str, effects: tuple, sentence: str) -> tuple | None:
        """Record what auto-add did in the diagnosis; the effects to set (None: unchanged)."""
        result["auto_add"] = {"action": action, "effect": effect, "effects": list(effects), "sentence": sentence}
        if action == "kept":
            return None
        self._asked = effects
        return effects
