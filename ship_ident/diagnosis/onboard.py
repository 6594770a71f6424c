"""Diagnosis on board: which catalogued effect the model in force misses, while the boat sails.

Every ``diagnosis_period`` seconds (node clock, or the bag's time in replay) the identifier's
window is diagnosed as ``ship-ident diagnose`` diagnoses a record (``diagnose.diagnose``, the same
ranking): the model in force is fitted on the older ``TRAINING_FRACTION`` (65 %) of the window and
run free on the newest 35 % (held out, cut into free-run windows, each started from the measured
heading and yaw rate); every effect not in the model is added in turn, refitted and judged on the
same held-out runs. The **held-out error** is the yaw-rate RMSE of those free runs (rad/s); with
the right model it sits at the yaw-rate **noise floor** (the sensor's noise, rad/s), and an effect
the model lacks lifts it above. Adding the effect makes it fall.

**Pooled evidence.** The hull does not change between diagnoses unless the identifier's change
test says so (``vessel_changed``), so the verdict rests on every held-out slice since the model
(its effects) or the vessel last changed, not on the newest window alone: each diagnosis adds the
part of its held-out data no earlier diagnosis held out (a *slice*, about ``diagnosis_period`` s),
with the errors of the model in force then and of each candidate refitted then
(``held_out_slice``). ``PooledEvidence`` keeps the sums over the slices, each slice counting by
its samples and the share of the configured window its diagnosis held (``window_share``; not by
how far the early, short-window fits missed), from which a candidate's pooled
share of the yaw-rate error removed (``1 - sqrt(e_after^2 / e_before^2)``, the ratio's geometric
mean over the slices) and its t follow: each slice's Diebold-Mariano t (the mean squared-error drop
over its standard error, from the differential's own autocorrelation), combined over the slices
as Stouffer's sum. A candidate is **significant** when it removes
at least ``MIN_IMPROVEMENT`` (15 %) of the pooled error, or ``MOST_OF_THE_ERROR`` (half) of the
pooled error above the noise floor with ``CLEAR_TRAINING_GAIN`` (10 %) off the training free runs,
or ``SMALL_SHARE`` (5 %) of the pooled error at t >= ``CERTAIN_T`` (6)
(``PooledEvidence.removes_enough``: the gyro's noise, which no model removes, must not hide a
missing effect the free runs show with certainty), with t >= ``SIGNIFICANCE_T`` (3)
(``PooledEvidence.clear_t``), and its training free runs gaining on average
(``MIN_TRAINING_GAIN``): the rule of ``diagnose`` on more data, once the pool holds
``MIN_HELD_OUT_S`` of held-out data counted as from full windows (``PooledEvidence.determines``).

**The heading.** Where no candidate is significant on the yaw rate, one is named on the heading of
the free runs (``PooledEvidence.heading_significant``): removing at least ``MIN_IMPROVEMENT`` of
their heading error at a t >= ``SIGNIFICANCE_T`` taken over the free runs, one value per run (the
log of its squared heading error over the model's), with some of the yaw-rate error removed too.
A slow ship's missing effect moves the yaw rate by less than the gyro's noise, and the heading,
which integrates it over a run while the compass's noise does not grow, shows what the yaw rate
cannot; within a run the heading error is one drift, so the run, not the sample, is the unit.

**One name.** Once an effect is named ``missing_effect`` (at t >= ``SIGNIFICANCE_T``), the verdict
names it as long as the pool holds it (its t stays at ``HOLD_T`` or above: slices where the effect
does not show dilute its share of the pooled error, and its t, but are no evidence against it, and
a t wavering about the threshold is the threshold's noise); another is named only when its pooled error is
significantly below the named one's (t >= ``SIGNIFICANCE_T`` on their loss differential) or the
named one's evidence is gone while another's holds: the pooled evidence reversed, and the sentence
says so. Candidates the pool cannot tell from the named one (removing at least
``MIN_IMPROVEMENT``, within ``EQUIVALENT_MARGIN`` of its share, not significantly worse) are
named with it as a group, with what would separate them
(``SIGNATURES``). Among yaw damping laws, whose separate refits differ by their searches, the law
the windows' fits holding both laws show most often (``damping_laws``) leads, and a rival law it
does not admit reverses nothing, nor, when it admits neither, one within ``EQUIVALENT_MARGIN`` of
the named law's share (``_law_lead``, ``_law_prefers``). The group is led by the member removing
most of the pooled error at the held-out data's tight turns (``_tight_turn_lead``): effects that fit
a trip's turns alike part where the turn is tightest. Adding or removing an effect starts the new
model's pool, or resumes the one it left when it was last in force (the evidence is the model's on
this vessel: an effect tried and removed again leaves the model's minutes of evidence as they
were); a changed vessel starts a new pool and drops the pools left.

With ``auto_add_effects``, an effect named in ``auto_add_after`` consecutive diagnoses is added
to the model; it is kept when, within ``CHECK_DIAGNOSES`` diagnoses of the new model, the pooled
held-out error falls by ``MIN_IMPROVEMENT`` from the pooled error before or lies within
``NOISE_MARGIN`` of the noise floor, and removed again otherwise; a removed effect is not added
again until the model is changed from outside.

A diagnosis is skipped, with a reason, only when the window cannot support it: too short to hold
out ``MIN_HELD_OUT_S``, too little excitation, the fit failed. The node runs diagnoses in a child
process at low priority (``DiagnosisWorker``), so a refit never waits for one; a diagnosis due
while the previous one runs waits for it with the window as it was when due (``MAX_QUEUED``).
Replay runs them inline at the refit where they are due (``InlineRunner``), so a replay is
reproducible.
"""

from __future__ import annotations

import math
import os
import signal
import threading
import time
from collections import Counter, deque
from dataclasses import dataclass
from multiprocessing import get_context

import numpy as np

from ..estimators.base import excitation_shortfall
from ..model.dataset import DataError, Dataset
from ..model.effects import EFFECTS, Evidence
from ..model.metrics import effective_sample_fraction
from ..model.structure import StructureError
from .damping_law import DAMPING_LAWS
from .diagnose import (
    CLEAR_TRAINING_GAIN,
    EQUIVALENT_MARGIN,
    MIN_HELD_OUT_S,
    MIN_IMPROVEMENT,
    MIN_TRAINING_GAIN,
    MOST_OF_THE_ERROR,
    NOISE_MARGIN,
    PARSIMONY,
    SIGNIFICANCE_T,
    TRAINING_FRACTION,
    Candidate,
    diagnose,
    free_run,
)
from .diagnose import DEFAULT_METHOD as DIAGNOSIS_METHOD

CHECK_DIAGNOSES = 2  # an added effect must cut the held-out error within this many diagnoses
WORST_SHOWN = 3  # worst free-run segments (with their conditions) in the record
NICENESS = 10  # the diagnosis process yields the CPU to the refits
MAX_QUEUED = 3  # node: diagnoses due while one runs wait, up to this many; beyond, the oldest is skipped
MIN_SLICE_SAMPLES = 10  # a slice with fewer fresh held-out samples adds nothing to the pool
# A t beyond doubt (twice SIGNIFICANCE_T) credits a candidate with a small share of the pooled error
# (SMALL_SHARE): the gyro's white noise, which no model removes, holds the total near the floor
CERTAIN_T = 2.0 * SIGNIFICANCE_T
SMALL_SHARE = 0.05
HOLD_T = 2.0  # t a named effect keeps its name down to (named at SIGNIFICANCE_T)
MIN_HEADING_RUNS = 5  # free runs a heading t takes
MIN_WINDOW_S = MIN_HELD_OUT_S / (1.0 - TRAINING_FRACTION)  # s of window that hold out MIN_HELD_OUT_S
MODEL = "model"  # the model in force, first row of a slice's sums
VESSEL_CHANGED = "the vessel changed"  # the origin of a pool restarted by a change of the vessel

# What the error each effect removes follows, and the manoeuvre that brings it out: the sentence that says
# what would separate near-equivalent candidates.
SIGNATURES = {
    "rudder_offset": ("a constant moment (a turn at zero rudder)", "straight legs with the rudder near zero"),
    "cubic_yaw": ("the turn rate cubed", "turns held at several rates, gentle to the tightest"),
    "quadratic_yaw": ("the turn rate squared", "turns held at several rates, gentle to the tightest"),
    "rudder_delay": ("the rudder rate (a lag)", "quick rudder reversals, as in a zigzag"),
    "wind_yaw": ("the heading", "legs on several headings"),
    "gyro_bias": (
        "nothing the boat does (a gyro offset: the compass heading does not turn with it)",
        "a straight leg, where the heading holds while a biased gyro reads a turn",
    ),
    "speed_dependence": ("the speed", "legs at different speeds"),
    "course_instability": (
        "the turn rate near zero (the linear damping)",
        "small rudder steps about zero held for a while (a spiral or pull-out test)",
    ),
    "rudder_stall": ("the rudder angle beyond its linear range", "steps to large as well as small rudder angles"),
}


def add_command(node: str, effects) -> str:
    """The shell command that sets the node's effects: ``ros2 param set NODE effects "[a, b]"``."""
    return f'ros2 param set {node} effects "[{", ".join(effects)}]"'


def duration_text(seconds: float) -> str:
    """``12 s`` below a minute, else ``3.5 min``."""
    return f"{seconds:.0f} s" if seconds < 60.0 else f"{seconds / 60.0:.1f} min"


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


def diagnose_window(dataset: Dataset, model: str, effects: tuple, stamp: float, since: float = -math.inf) -> dict:
    """The diagnosis of one window at clock time ``stamp`` (s), as a JSON-ready dict: ``status``
    ``done`` with the window's own verdict, candidates, held-out error and noise floor (rad/s) and
    ``held_out_slice``, the sums of its held-out samples later than ``since`` (s) for the pool
    (``held_out_slice``); or ``skipped`` with the ``reason``. Never raises on bad data."""
    started = time.process_time()
    reason = too_short(dataset) or excitation_shortfall(dataset)
    record = skipped(stamp, model, effects, reason)
    if reason is None:
        try:
            # one effect per round: the pool weighs single effects, and once the first of two is added
            # the next diagnoses see the second alone
            result = diagnose(dataset, model, effects, workers=1, pairs=False)
        except (DataError, StructureError, ValueError, np.linalg.LinAlgError) as exc:
            record["reason"] = f"fit failed: {exc}"
        else:
            if "low_excitation" in result.estimate.flags:
                record["reason"] = "too little excitation: the training part hardly excites the yaw (low_excitation)"
            else:
                del record["reason"]
                record.update(_done(result))
                record["held_out_slice"] = held_out_slice(result, since)
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
        "pinned": [w["message"] for w in result.pinned],
        "worst_conditions": result.worst_segments[:WORST_SHOWN],
        "parameters": {k: float(v) for k, v in result.estimate.parameters.items()},
        "damping_laws": list(result.damping_law.laws) if result.damping_law is not None else [],
    }


def held_out_slice(result, since: float) -> dict | None:
    """The sums the pool needs from the held-out samples of ``result`` (a ``diagnose.Diagnosis``)
    later than ``since`` (s), or None when fewer than ``MIN_SLICE_SAMPLES`` are.

    Rows are the model in force (``MODEL``) and every catalogued effect not in it (a candidate not
    fitted on these data counts with the model's errors: it adds nothing). With ``e_i`` the
    yaw-rate error (rad/s) of row i's free runs: ``squares[i] = sum e_i^2``; for each pair,
    ``pair_variance[i][j]``, the variance of the slice's sum of the differential ``d = e_i^2 -
    e_j^2``: ``sum (d - mean d)^2`` times ``n / n_eff``, with ``n_eff`` the effective sample size of
    the autocorrelated ``d`` (the free runs' errors are smooth); ``training_gain[i]``, the share of
    the training free runs' yaw-rate error the candidate removes, times the samples;
    ``noise_squares``, the noise floor squared times the samples; ``tight_squares[i]``, ``sum e_i^2``
    over the slice's tight turns (``tight_turns``); ``run_heading_squares``, per free run, each
    row's sum of squared heading errors (``run_heading_squares``). A free run that diverges counts
    as missing the yaw rate by the slice's largest turn rate plus the model's largest error there,
    and the heading by the slice's heading span plus the model's largest heading error.
    """
    held = result.held_out
    measured = held.yaw_rate
    model_error = result.run.yaw_rate - measured
    model_heading_error = result.run.heading - held.heading
    fresh = (held.time > since) & np.isfinite(model_error) & np.isfinite(model_heading_error)
    n = int(fresh.sum())
    if n < MIN_SLICE_SAMPLES:
        return None
    names = [name for name in EFFECTS if name not in result.structure.effect_names]
    by_name = {c.effect: c for c in result.candidates}
    worst = float(np.max(np.abs(measured[fresh])) + np.max(np.abs(model_error[fresh])))
    worst_heading = float(np.ptp(held.heading[fresh]) + np.max(np.abs(model_heading_error[fresh])))
    errors, heading_errors, gains = [model_error[fresh]], [model_heading_error[fresh]], [0.0]
    for name in names:
        candidate = by_name.get(name)
        if candidate is None or candidate.estimate is None:
            errors.append(model_error[fresh])
            heading_errors.append(model_heading_error[fresh])
            gains.append(0.0)
            continue
        run = free_run(candidate.estimate.structure, candidate.estimate.parameters, held)
        error = (run.yaw_rate - measured)[fresh]
        errors.append(np.where(np.isfinite(error), error, worst))
        heading_error = (run.heading - held.heading)[fresh]
        heading_errors.append(np.where(np.isfinite(heading_error), heading_error, worst_heading))
        gains.append(float(candidate.training_gain) if np.isfinite(candidate.training_gain) else -1.0)
    runs = np.full(held.n_samples, -1)  # samples outside every free run (gaps): none
    for k, (start, stop) in enumerate(held.segments):
        runs[start:stop] = k
    sums = slice_sums(
        held.time[fresh],
        held.sample_time,
        [MODEL, *names],
        errors,
        gains,
        float(result.noise["yaw_rate"]),
        measured[fresh],
    )
    sums["run_heading_squares"] = run_heading_squares(heading_errors, runs[fresh])
    return sums


def run_heading_squares(heading_errors: list, runs) -> list[list[float]]:
    """Per free run of a slice with at least ``MIN_SLICE_SAMPLES`` of its samples, each row's sum of
    squared heading errors (rad^2) over them; ``heading_errors``: per row, the heading error (rad) of
    its free runs at the slice's samples, ``runs``: the free run each sample belongs to."""
    squared = np.array(heading_errors) ** 2
    runs = np.asarray(runs)
    return [
        squared[:, runs == run].sum(axis=1).tolist()
        for run in np.unique(runs[runs >= 0])
        if np.count_nonzero(runs == run) >= MIN_SLICE_SAMPLES
    ]


def unjudged(effect: str, result: dict) -> dict:
    """The record of a candidate the pool names that the newest window ``result`` did not judge under
    its own name (its held-out slice counts it with the model's errors): the model's held-out
    errors, no refit. The name rests on the earlier slices, and the record still lists it."""
    evidence = Evidence(0.0, "not judged on the newest window: named on the pooled evidence of the earlier ones")
    error_heading, error_yaw_rate = result.get("held_out_error_heading"), result.get("held_out_error")
    unfitted = Candidate(effect, 0.0, False, error_heading, error_yaw_rate, evidence, note="not refitted here")
    return unfitted.to_json()


def window_share(result: dict, piece: dict, window_length: float) -> float:
    """The weight of a diagnosis's held-out slice in the pool: the share of the configured
    ``window_length`` (s) its window held (1 once full). The window's length is what the crew gives
    the vessel's dynamics to be determined (a slow ship's ten minutes); a fit on a part of it
    determines less, and its candidates' refits, extrapolated into the held-out part, miss by their
    own spread more than by what the effect adds (eight MMG tankers on random steps, ten-minute
    windows: the damping laws ran worse than the model in 27 % of the slices of windows under half
    full, one in ten of them 70 % above its error, and in 10 % of those of full windows, where they
    removed 42 % in the median)."""
    sample_time = piece["seconds"] / piece["samples"]
    held = result["window"]["end"] - result["window"]["start"] + sample_time
    return min(1.0, held / window_length)


def tight_turns(yaw_rate) -> np.ndarray:
    """The samples of a held-out slice at its tight turns: a turn rate (rad/s) at or above the
    slice's median turn rate."""
    turn_rate = np.abs(np.asarray(yaw_rate))
    return turn_rate >= np.median(turn_rate)


def slice_sums(
    times, sample_time: float, names: list[str], errors: list, gains: list, noise_floor: float, yaw_rate
) -> dict:
    """The sums of one held-out slice (see ``held_out_slice``) from its sample times (s), the
    yaw-rate errors (rad/s) of each row of ``names`` on them, the rows' training gains, the
    yaw-rate noise floor (rad/s) and the measured yaw rate (rad/s)."""
    squared = np.array(errors) ** 2
    tight = tight_turns(yaw_rate)
    n = squared.shape[1]
    rows = len(squared)
    pair_variance = np.zeros((rows, rows))
    for i in range(rows):
        for j in range(i + 1, rows):
            d = squared[i] - squared[j]
            spread = float(np.sum((d - d.mean()) ** 2))
            pair_variance[i, j] = pair_variance[j, i] = spread / effective_sample_fraction(d, max_lag=n // 4)
    return {
        "start": float(times[0]),
        "end": float(times[-1]),
        "samples": n,
        "seconds": n * sample_time,
        "names": list(names),
        "squares": squared.sum(axis=1).tolist(),
        "pair_variance": pair_variance.tolist(),
        "training_gain": [n * g for g in gains],
        "noise_squares": n * noise_floor**2,
        "tight_samples": int(tight.sum()),
        "tight_squares": squared[:, tight].sum(axis=1).tolist(),
    }


class PooledEvidence:
    """The held-out slices of one model on one vessel, summed (see ``held_out_slice``).

    Each slice counts by its samples times its weight, the share of the configured window its
    diagnosis held (``window_share``: a fit on a part of the window determines less), not by how
    far the model in force then missed: the first
    slices of a trip are held out by a window of a minute or two, whose fit misses by several times
    what a fit on ten minutes does, and summed as measured one such slice outweighs all the later
    ones (an MMG tanker on random steps: a speed law removing a third of the error in most slices
    read as t 2 for eleven minutes, the first slice's 42 s holding a third of the pooled squared
    error). So the judgement works on each slice's squared errors relative to its model's, and on
    the slices' own Diebold-Mariano t, combined as Stouffer's sum weighted by the square root of the
    samples (``t_statistic``); the error a crew reads (``error``, ``noise_floor``) stays the pooled
    root mean square.

    The ratios are pooled as a geometric mean (``log_ratios``: sample-weighted sums of their logs): a
    slice where a candidate ran at twice the model's error weighs as one where it ran at half. A
    window's candidate fitted on a few minutes can extrapolate far off in its held-out part (an MMG
    tanker's quadratic damping fitted on four minutes ran at 2.6 times the model's error in one
    slice and removed half of it in nine others); averaged as they are, that one slice held the
    candidate at no gain for the rest of the trip.
    """

    def __init__(self, names: list[str]):
        self.names = list(names)
        rows = len(names)
        self.samples = 0
        self.seconds = 0.0
        self.slices = 0
        self.start = math.inf
        self.weight = 0.0  # sum over slices of samples x the slice's weight
        self.log_ratios = np.zeros(
            rows
        )  # per row, sum over slices of weight x samples x log(its squared error / the model's)
        self.noise_log_ratio = 0.0  # the same for the noise floor
        self.model_squares = 0.0  # sum of the model's squared errors (rad^2/s^2)
        self.floor_squares = 0.0  # sum of the noise floor squared over the samples (rad^2/s^2)
        self.weighted_t = np.zeros((rows, rows))  # [i, j]: sum of weight x sqrt(samples) x t of j's error below i's
        self.t_weight = np.zeros((rows, rows))  # [i, j]: sum of weight^2 x samples over the slices where i and j differ
        self.training_gain_sum = np.zeros(rows)  # per row, sum of weight x the slice's training gain sum
        self.full_window_seconds = 0.0  # sum over slices of the slice's seconds x its weight
        self.tight_weight = 0.0  # sum over slices of the tight-turn samples x the slice's weight
        self.tight_log_ratios = np.zeros(rows)  # as log_ratios, on the slices' tight turns
        self.heading_runs = 0  # free runs pooled on heading
        self.heading_weight = 0.0  # sum of their weights
        self.heading_weight_squares = 0.0  # sum of their weights squared
        # per row, sum over runs of weight x log(its squared heading error / the model's)
        self.heading_log_ratios = np.zeros(rows)
        self.heading_log_ratio_squares = np.zeros(rows)  # the same with the log squared

    def add(self, piece: dict, weight: float = 1.0) -> None:
        """Add a held-out slice's sums (``held_out_slice``), its evidence counting ``weight`` (0 to 1)
        times its samples (``window_share``)."""
        samples, squares = piece["samples"], np.asarray(piece["squares"])
        self.samples += samples
        self.weight += weight * samples
        self.seconds += piece["seconds"]
        self.full_window_seconds += weight * piece["seconds"]
        self.slices += 1
        self.start = min(self.start, piece["start"])
        self.model_squares += squares[0]
        self.floor_squares += piece["noise_squares"]
        if squares[0] > 0:
            tiny = 1e-12 * squares[0]
            self.log_ratios += weight * samples * np.log(np.maximum(squares, tiny) / squares[0])
            self.noise_log_ratio += weight * samples * math.log(max(piece["noise_squares"], tiny) / squares[0])
        variance = np.asarray(piece["pair_variance"])
        differ = variance > 0
        t = np.zeros_like(variance)
        t[differ] = (squares[:, None] - squares[None, :])[differ] / np.sqrt(variance[differ])
        self.weighted_t += weight * math.sqrt(samples) * t
        self.t_weight += weight**2 * samples * differ
        self.training_gain_sum += weight * np.asarray(piece["training_gain"])
        tight_squares = np.asarray(piece["tight_squares"])
        if tight_squares[0] > 0:
            tight = piece["tight_samples"]
            self.tight_weight += weight * tight
            floor = 1e-12 * tight_squares[0]
            self.tight_log_ratios += weight * tight * np.log(np.maximum(tight_squares, floor) / tight_squares[0])
        for run in piece.get("run_heading_squares", []):
            run = np.asarray(run)
            if run[0] > 0:
                log_ratio = np.log(np.maximum(run, 1e-12 * run[0]) / run[0])
                self.heading_runs += 1
                self.heading_weight += weight
                self.heading_weight_squares += weight**2
                self.heading_log_ratios += weight * log_ratio
                self.heading_log_ratio_squares += weight * log_ratio**2

    def row(self, name: str) -> int:
        return self.names.index(name)

    @property
    def error(self) -> float:
        """Pooled held-out yaw-rate RMSE of the model in force (rad/s)."""
        return math.sqrt(self.model_squares / self.samples)

    @property
    def noise_floor(self) -> float:
        """Pooled yaw-rate noise floor (rad/s)."""
        return math.sqrt(self.floor_squares / self.samples)

    def _ratio(self, log_ratio: float) -> float:
        """The geometric mean over the slices (by weighted samples) of a squared error over the model's."""
        return math.exp(log_ratio / self.weight) if self.weight > 0 else 1.0

    def improvement(self, name: str) -> float:
        """Share of the pooled held-out yaw-rate error that adding ``name`` removes: ``1 - sqrt(m)``, m
        the geometric mean over the slices (by samples) of its squared error over the model's."""
        return 1.0 - math.sqrt(self._ratio(self.log_ratios[self.row(name)]))

    def tight_turn_improvement(self, name: str) -> float:
        """Share of the pooled held-out yaw-rate error at the tight turns (``tight_turns``) that adding
        ``name`` removes, pooled as ``improvement``."""
        if self.tight_weight <= 0:
            return 0.0
        return 1.0 - math.sqrt(math.exp(self.tight_log_ratios[self.row(name)] / self.tight_weight))

    def heading_improvement(self, name: str) -> float:
        """Share of the held-out heading error that adding ``name`` removes, pooled over the free runs:
        ``1 - sqrt(m)``, m the geometric mean over the runs (by weight) of its squared heading error
        over the model's."""
        if self.heading_weight <= 0:
            return 0.0
        return 1.0 - math.sqrt(math.exp(self.heading_log_ratios[self.row(name)] / self.heading_weight))

    def heading_t(self, name: str) -> float:
        """t that ``name``'s heading error lies below the model's: the runs' mean log ratio of their
        squared heading errors over its standard error (each free run one value, the runs weighted as
        their slices; 0 under ``MIN_HEADING_RUNS`` runs). A run starts from the measured state and its
        heading error grows with whatever the model misses, so one run is one measurement: the
        samples within it are not independent, and a t from them counts the same drift hundreds of
        times."""
        i = self.row(name)
        total, squares = self.heading_weight, self.heading_weight_squares
        if self.heading_runs < MIN_HEADING_RUNS or i == 0 or total**2 <= squares:
            return 0.0
        mean = self.heading_log_ratios[i] / total
        variance = max(self.heading_log_ratio_squares[i] / total - mean**2, 0.0) * total**2 / (total**2 - squares)
        if variance <= 0:
            return 0.0
        return float(-mean / math.sqrt(variance * squares / total**2))

    def training_gain(self, name: str) -> float:
        """Mean share (by weighted samples) of the training free runs' yaw-rate error ``name`` removes."""
        return float(self.training_gain_sum[self.row(name)] / self.weight) if self.weight > 0 else 0.0

    def excess_removed(self, name: str) -> float:
        """Share of the pooled held-out yaw-rate error above the noise floor that adding ``name``
        removes: ``1 - sqrt((S_name - N) / (1 - N))`` with ``S_name`` and ``N`` the geometric means
        over the slices of its squared error and of the noise floor's, each relative to the model's
        in its slice (``S_name - N`` taken as 0 below the floor); 0 when the model's
        error does not exceed the floor. The gyro's white noise is in every free run's yaw-rate
        error and no model removes it: where the model misses little against it (a gentle
        manoeuvre, a noisy gyro), the share of the total error an effect can remove stays small
        however certain the evidence, while the share of what a model can explain does not."""
        noise = self._ratio(self.noise_log_ratio)
        if noise >= 1.0:
            return 0.0
        return 1.0 - math.sqrt(max(self._ratio(self.log_ratios[self.row(name)]) - noise, 0.0) / (1.0 - noise))

    def removes_enough(self, name: str) -> bool:
        """``name`` removes at least ``MIN_IMPROVEMENT`` of the pooled yaw-rate error; or
        ``MOST_OF_THE_ERROR`` of the error above the noise floor with a clear gain on the training
        free runs (``CLEAR_TRAINING_GAIN``): ``diagnose``'s clear case, on the part of the error a
        model can explain; or ``SMALL_SHARE`` of it with a t beyond doubt (``CERTAIN_T``). A
        quick boat's cubic damping acts in its seldom tight turns: fitted with its base model
        converged, over 15 minutes it removed 7-12 % of a pooled error 1.0-1.1 times the floor at t
        8-11, and the share above a floor known only to a few percent swung between none and all of
        it; t grows with the minutes pooled, noise's does not."""
        return bool(
            self.improvement(name) >= MIN_IMPROVEMENT
            or (self.excess_removed(name) >= MOST_OF_THE_ERROR and self.training_gain(name) >= CLEAR_TRAINING_GAIN)
            or (self.improvement(name) >= SMALL_SHARE and self.t_statistic(MODEL, name) >= CERTAIN_T)
        )

    def t_statistic(self, worse: str, better: str) -> float:
        """t that ``better``'s squared held-out error lies below ``worse``'s: the slices' own
        Diebold-Mariano t combined as ``sum w_k sqrt(n_k) t_k / sqrt(sum w_k^2 n_k)`` (Stouffer, by
        samples ``n_k`` and the slices' weights ``w_k``), over the slices where the two runs differ (a
        slice where they run alike adds nothing)."""
        i, j = self.row(worse), self.row(better)
        weight = self.t_weight[i, j]
        if i == j or weight <= 0:
            return 0.0
        return float(self.weighted_t[i, j] / math.sqrt(weight))

    def clear_t(self, name: str) -> bool:
        """``name``'s t is significant: >= ``SIGNIFICANCE_T``. A pooled error a little above the
        noise floor on a minute or two of held-out data is what several candidates each remove a
        quarter of at t near 2 on a hull that lacks nothing (a USV sailing its true model over DDS:
        quadratic_yaw, gyro_bias, rudder_stall and rudder_delay at 20-28 %): a lower t there names
        noise."""
        return bool(self.t_statistic(MODEL, name) >= SIGNIFICANCE_T)

    def heading_significant(self, name: str) -> bool:
        """``name`` removes a significant share of the free runs' heading error: at least
        ``MIN_IMPROVEMENT`` of it at a heading t >= ``SIGNIFICANCE_T`` (``heading_t``), on a pool
        that ``determines``, with some of the yaw-rate error removed, held out and in training.
        A slow ship's missing effect moves its yaw rate by less than the gyro's noise, but the
        heading integrates that small, lasting error over a free run while the compass's noise does
        not grow (a ship with T1 36 s and a hidden cubic damping on a zigzag: the yaw-rate error 0.85
        times the floor for the whole trip, the cubic law removing 2-6 % of it and 1 % of the
        training free runs', and half of the heading error of its free runs). The heading is the
        yaw rate integrated, so an effect that truly lowers its error does not raise the yaw
        rate's."""
        return bool(
            self.determines
            and self.heading_improvement(name) >= MIN_IMPROVEMENT
            and self.heading_t(name) >= SIGNIFICANCE_T
            and self.improvement(name) > 0
            and self.training_gain(name) > 0
        )

    def heading_equivalents(self, leader: str) -> list[str]:
        """The candidates significant on heading (``heading_significant``) within
        ``EQUIVALENT_MARGIN`` of ``leader``'s share of the heading error; best first."""
        lead = self.heading_improvement(leader)
        group = [
            name
            for name in self.names[1:]
            if name != leader
            and self.heading_significant(name)
            and lead - self.heading_improvement(name) <= EQUIVALENT_MARGIN
        ]
        return sorted(group, key=lambda name: -self.heading_improvement(name))

    def holds(self, name: str) -> bool:
        """The pooled evidence still points to ``name``, named before: it removes some of the error
        at t >= ``HOLD_T``. Slices where its effect does not show dilute its share of the pooled
        error, and its t, but are no evidence against it: named at t 3, a t wavering between 2 and 3
        is the threshold's own noise (a tanker's hidden rudder offset, held only at t 3, changed its
        name four times in one trip as its t crossed 3 and back)."""
        on_yaw_rate = self.improvement(name) > 0 and self.t_statistic(MODEL, name) >= HOLD_T
        return bool(on_yaw_rate or (self.heading_improvement(name) > 0 and self.heading_t(name) >= HOLD_T))

    @property
    def determines(self) -> bool:
        """The pool holds ``MIN_HELD_OUT_S`` of held-out data counted as from full windows (each
        slice's seconds times its weight, ``window_share``), what a one-shot diagnosis needs. A
        window a fraction of its configured length long has not seen the hull's slow dynamics, and
        the free runs of its fit miss by what the fit did not determine; one such slice's t is the
        fit's luck (an MMG tanker on random steps, its ten-minute window two minutes full: a rudder
        offset removed 88 % of the 42 s held out, at t 3.2, and nothing in any later slice, while the
        damping laws it hid removed 60 % of the error on the hull's standard manoeuvres)."""
        return self.full_window_seconds >= MIN_HELD_OUT_S

    def significant(self, name: str) -> bool:
        """``name`` removes a significant share of the pooled error: enough of it (``removes_enough``)
        with a significant t (``clear_t``), its training free runs gaining (the rule of ``diagnose``),
        on a pool that ``determines``."""
        return bool(
            self.determines
            and self.removes_enough(name)
            and self.clear_t(name)
            and self.training_gain(name) >= MIN_TRAINING_GAIN
        )

    def rank(self, name: str) -> float:
        """Ranking score: the pooled improvement, each parameter costing ``PARSIMONY``."""
        return self.improvement(name) - PARSIMONY * len(EFFECTS[name].parameters)

    def equivalents(self, leader: str) -> list[str]:
        """The candidates the pool cannot tell from ``leader``: removing enough (``removes_enough``),
        within ``EQUIVALENT_MARGIN`` of ``leader``'s improvement (or above it) and with a held-out
        error ``leader``'s is not significantly below; best first."""
        lead = self.improvement(leader)
        group = [
            name
            for name in self.names[1:]
            if name != leader
            and self.removes_enough(name)
            and lead - self.improvement(name) <= EQUIVALENT_MARGIN
            and self.t_statistic(name, leader) < SIGNIFICANCE_T
        ]
        return sorted(group, key=lambda name: -self.rank(name))

    def summary(self, origin: str) -> dict:
        return {
            "since": origin,
            "start": self.start,
            "seconds": self.seconds,
            "slices": self.slices,
            "full_window_seconds": self.full_window_seconds,
            "held_out_error": self.error,
            "noise_floor": self.noise_floor,
            "heading_runs": self.heading_runs,
        }


def separation(group: list[str]) -> str:
    """What would tell the effects of ``group`` apart: what each one's error grows with, and the
    manoeuvres that bring the differences out."""
    grows = "; ".join(f"{name} follows {SIGNATURES.get(name, (EFFECTS[name].explanation, ''))[0]}" for name in group)
    manoeuvres = list(dict.fromkeys(SIGNATURES[name][1] for name in group if name in SIGNATURES))
    return f"{grows}: {' or '.join(manoeuvres) or 'another manoeuvre'} would tell them apart"


def _run(job: tuple) -> dict:
    return diagnose_window(*job)


# --- where diagnoses run ------------------------------------------------------------------
class InlineRunner:
    """Runs a diagnosis at once, in the caller's thread (replay: reproducible)."""

    busy = False

    def __init__(self):
        self._result = None

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
            _, model, effects, stamp, _ = job
            result = skipped(stamp, model, effects, f"diagnosis failed: {type(exc).__name__}: {exc}")
        connection.send(result)


def _send(connection, job: tuple) -> None:
    """Send ``job`` to the child; a child that ended meanwhile is the poll's news (``DiagnosisWorker.poll``)."""
    try:
        connection.send(job)
    except OSError:
        pass


class DiagnosisWorker:
    """Runs diagnoses in one child process at low priority, one at a time, so a refit never waits for one.

    The child runs at ``NICENESS`` and starts with ``start`` (the node: at its start, so that its
    imports run while the window fills) or at the first diagnosis (``spawn``: a fresh interpreter,
    never a fork of the ROS process and its threads).
    """

    def __init__(self):
        self._process = self._connection = None
        self._job = None  # (stamp, model, effects) of the diagnosis in progress

    @property
    def busy(self) -> bool:
        """A diagnosis is in progress."""
        return self._job is not None

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
        """Start a diagnosis in the child (starting the child if it is not running).

        Parameters
        ----------
        job : tuple
            (window Dataset, model, effects, stamp s, end of the last held-out data s), as
            ``OnlineDiagnosis`` queues it.
        """
        self.start()
        self._job = (job[3], job[1], job[2])
        # written from a thread of its own: a pipe takes 64 KiB before its reader must read (a 180 s
        # window at 10 Hz pickles to 87 kB), and a child still importing at low priority on a loaded
        # machine would hold the refit that submitted the job until it reads
        sender = threading.Thread(target=_send, args=(self._connection, job), name="ship_ident diagnosis job")
        sender.daemon = True
        sender.start()

    def poll(self) -> dict | None:
        """The finished diagnosis, or None while it runs (a dead child: a skipped record).

        Returns
        -------
        dict or None
            The diagnosis record (``diagnosis.onboard``'s JSON), or None while it runs or when none was
            submitted.
        """
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
    """An effect added by the node itself, on probation: the pooled held-out error before (rad/s)."""

    effect: str
    error_before: float
    diagnoses: int = 0


class OnlineDiagnosis:
    """The diagnosis on board: the identifier's window diagnosed every ``diagnosis_period``.

    Diagnoses the window every ``diagnosis_period`` (its configuration, read at each refit; 0: off)
    through ``runner``; pools the held-out evidence since the model or the vessel last changed and
    runs ``auto_add_effects``.

    ``after_refit(record, identifier)`` is called after every refit: it starts a due diagnosis,
    puts a finished one into ``record.diagnosis`` and the ``missing_effect`` WARN into
    ``record.conditions``, and returns the effects to set when auto-add adds or removes one
    (None otherwise).

    Parameters
    ----------
    runner : InlineRunner or DiagnosisWorker or None
        Where diagnoses run: inline by default (``replay``), a low-priority child on the node.
    node : str
        The node's name in the ``ros2 param set`` command of the record.
    """

    def __init__(self, runner=None, node: str = "/ship_ident"):
        self.runner = runner or InlineRunner()
        self.node = node
        self._next_due: float | None = None
        self._queued: deque = deque()  # jobs due while the runner was busy, oldest first
        self._pool: PooledEvidence | None = None  # held-out slices since the model or vessel changed
        self._origin = "the start"  # what started the pool
        self._held_out_until = -math.inf  # s: held-out data up to here are in the pool (or on their way)
        self._named: str | None = None  # the effect the pool named missing
        self._laws: Counter = Counter()  # damping laws the pooled diagnoses' fits holding both showed: how often
        self._warning: tuple | None = None  # ((model, effects), sentence) of the last missing_effect
        self._streak: tuple[str, int] = ("", 0)  # effect named in consecutive diagnoses, how many
        self._trial: Trial | None = None
        self._rejected: set[str] = set()  # effects auto-add removed (not added again)
        self._in_force: tuple | None = None  # (model, effects) at the last refit
        self._vessel_note: str | None = None  # the identifier's last vessel_changed sentence
        self._pool_from = -math.inf  # clock time (s) of the last vessel change: diagnoses due before it are not pooled
        self._asked: tuple | None = None  # effects auto-add asked for (its own change, not an outside one)
        self._left_pools: dict = {}  # (model, effects) -> the pool's state when that model left

    def after_refit(self, record, identifier) -> tuple | None:
        """After a refit: start a due diagnosis, report a finished one, and return any effects to set.

        A vessel_changed condition restarts the pooled evidence; a finished diagnosis goes into
        ``record.diagnosis`` and the ``missing_effect`` warning of the model in force into
        ``record.conditions``.

        Parameters
        ----------
        record : RefitRecord
            The refit's record (completed in place).
        identifier : OnlineIdentifier
            The identifier, for its configuration and its window.

        Returns
        -------
        tuple of str or None
            The effects auto-add sets (added or removed one); None when unchanged.
        """
        config = identifier.config
        structure = (config.model, tuple(config.effects))
        self._take_structure(structure)
        note = record.conditions.get("vessel_changed")
        if note is not None and note != self._vessel_note:
            self._restart_pool(VESSEL_CHANGED)
            self._pool_from = record.time
        self._vessel_note = note
        now = record.time
        finished = self.runner.poll()  # first: a diagnosis that just ended frees the runner
        if self._queued and not self.runner.busy:
            self.runner.submit(self._queued.popleft())
        if config.diagnosis_period > 0 and self._is_due(now, config.diagnosis_period):
            try:
                dataset = identifier.window_dataset(now)
            except DataError as exc:
                refusal = f"window unusable: {exc}"
            else:
                refusal = too_short(dataset)  # said here: no process started for it
            if refusal is None:
                job = (dataset, config.model, tuple(config.effects), now, self._held_out_until)
                self._held_out_until = float(dataset.time[-1])
                if len(self._queued) >= MAX_QUEUED:
                    late = self._queued.popleft()
                    refusal = f"the diagnosis due at {late[3]:.1f} s was dropped: the diagnosis process is behind"
                self._queued.append(job)
                if not self.runner.busy:
                    self.runner.submit(self._queued.popleft())
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
        """Stop the runner (the child process of a ``DiagnosisWorker``)."""
        self.runner.close()

    def _is_due(self, now: float, period: float) -> bool:
        """Whether a diagnosis is due at ``now`` (s): at whole multiples of ``period`` on the clock, so
        a crew reads one every full minute of a trip (a late refit moves only the one it is late for)."""
        if self._next_due is None or now < self._next_due - period:  # first call, or the clock went back
            self._next_due = (np.floor(now / period) + 1.0) * period
            return False
        if now < self._next_due:
            return False
        self._next_due = self._next_due + period if now - self._next_due < period else now + period
        return True

    def _restart_pool(self, origin: str) -> None:
        """Forget the pooled evidence (and the effect it named): ``origin`` says why."""
        if origin == VESSEL_CHANGED:
            self._left_pools.clear()
        self._pool = None
        self._origin = origin
        self._held_out_until = -math.inf
        self._named = None
        self._laws = Counter()
        self._streak = ("", 0)
        self._warning = None

    def _take_structure(self, structure: tuple) -> None:
        """``structure`` (model, effects) is in force; when it changed, the pool starts anew and a
        change from outside (not auto-add's own) ends a trial and forgives the removed effects."""
        if self._in_force is not None and structure != self._in_force:
            self._model_changed(structure)
        self._in_force = structure

    def _model_changed(self, structure: tuple) -> None:
        """A new model is in force: its own pool resumes where it was left, else one starts. The
        evidence a pool holds is that model's on this vessel, which has not changed since (a change
        clears the pools left), so a model back in force (an effect auto-add tried and removed)
        goes on from its evidence, and a candidate that edged ahead in the first slice after the
        trial does not displace the one its minutes of evidence named."""
        if self._in_force is not None:
            self._left_pools[self._in_force] = (
                self._pool,
                self._origin,
                self._held_out_until,
                self._named,
                self._laws,
            )
        left = self._left_pools.pop(structure, None)
        self._restart_pool(f"{'+'.join(structure[1]) or 'no effects'} came into force")
        if left is not None and left[0] is not None:
            self._pool, self._origin, self._held_out_until, self._named, self._laws = left
        if structure[1] != self._asked:
            self._trial = None
            self._rejected.clear()
        self._asked = None

    def finish(self, result: dict, config) -> tuple | None:
        """Take a finished diagnosis: pool its held-out slice, complete it, keep its warning, run auto-add.

        The result is completed in place (each candidate's ``pooled`` figures and pooled
        ``significant``, the pooled verdict and its sentence, the ``ros2 param set`` command). A skipped
        diagnosis, or one of another model than ``config``'s or due before the vessel last changed (it
        waited or ran meanwhile), changes nothing.

        Parameters
        ----------
        result : dict
            The finished diagnosis record.
        config : OnlineConfig
            The configuration in force (its model and effects).

        Returns
        -------
        tuple of str or None
            The effects auto-add sets; None when unchanged.
        """
        piece = result.pop("held_out_slice", None)
        structure = (result["structure"]["model"], tuple(result["structure"]["effects"]))
        current = structure == (config.model, tuple(config.effects)) and result["stamp"] >= self._pool_from
        if result["status"] != "done" or not current:
            return None
        self._take_structure(structure)
        if piece is not None:
            if self._pool is None or self._pool.names != piece["names"]:
                self._pool = PooledEvidence(piece["names"])
            self._pool.add(piece, window_share(result, piece, config.window_length))
            self._laws.update(result.get("damping_laws", []))
        pool = self._pool
        if pool is None:  # nothing fresh held out yet: the window's own verdict stands
            result["add_command"] = None
            return None
        # a loose fast pole (T2, m2) is the base model's, whichever effect is added: what counts is
        # whether the data determine the effect's own term
        undetermined = {
            c["effect"]
            for c in result["candidates"]
            if {p.name for p in EFFECTS[c["effect"]].parameters} & set(c.get("undetermined", []))
        }
        found, reversal = self._name(pool, undetermined)
        if found is not None and all(c["effect"] != found for c in result["candidates"]):
            result["candidates"].append(unjudged(found, result))
        self._mark(result, pool, found)
        result["pooled"] = pool.summary(self._origin)
        effects = structure[1]
        rests_on = f"{duration_text(pool.seconds)} of held-out data since {self._origin}"
        ratio = pool.error / pool.noise_floor if pool.noise_floor > 0 else math.inf
        if found is not None:
            top = next(c for c in result["candidates"] if c["effect"] == found)
            on_heading = not pool.significant(found) and pool.heading_t(found) >= HOLD_T
            group = pool.heading_equivalents(found) if on_heading else pool.equivalents(found)
            result["verdict"] = "missing_effect"
            result["near_equivalent"] = group
            result["add_command"] = add_command(self.node, effects + (found,))
            result["verdict_sentence"] = (
                self._heading_evidence(pool, found, rests_on, ratio, top["evidence"], group)
                if on_heading
                else self._yaw_rate_evidence(pool, found, rests_on, ratio, top["evidence"], group)
            ) + (
                (f"; {reversal}" if reversal else "")
                + (
                    "; auto-add tried it and removed it again (the held-out error did not fall with it): it is "
                    "not added again until the model is changed from outside"
                    if found in self._rejected
                    else ""
                )
            )
            self._warning = (structure, f"{result['verdict_sentence']}; add it: {result['add_command']}")
        else:
            result["add_command"] = None
            result["near_equivalent"] = []
            self._warning = None
            self._verdict_without(result, pool, rests_on, ratio)
        return self._auto_add(result, found, effects, config)

    def _name(self, pool: PooledEvidence, undetermined: set) -> tuple[str | None, str]:
        """The effect the pool names missing (None: none) and, when it differs from the one named
        before, why (the pooled evidence reversed); ``undetermined``: the candidates whose fit in the
        newest window leaves a parameter of its own undetermined (``_determined_lead``)."""
        ranked = sorted((n for n in pool.names[1:] if pool.significant(n)), key=lambda n: -pool.rank(n))
        on_heading = sorted(
            (n for n in pool.names[1:] if pool.heading_significant(n)), key=lambda n: -pool.heading_improvement(n)
        )
        named, reversal = self._named, ""
        if named is not None and pool.holds(named):
            rival = next(
                (
                    n
                    for n in ranked
                    if n != named
                    and pool.t_statistic(named, n) >= SIGNIFICANCE_T
                    and not self._law_prefers(pool, named, n)
                ),
                None,
            )
            if rival is not None:
                reversal = (
                    f"named instead of {named}: the pooled evidence reversed, {rival}'s held-out error is "
                    f"significantly below {named}'s (t {pool.t_statistic(named, rival):.1f})"
                )
                named = rival
        elif ranked or on_heading:
            if ranked:
                lead = self._law_lead(pool, self._determined_lead(pool, ranked[0], undetermined), undetermined)
                lead = self._tight_turn_lead(pool, lead, undetermined)
            else:  # named on the heading of the free runs alone: one whose own parameters the data determine
                lead = next((n for n in on_heading if n not in undetermined), on_heading[0])
            if named is not None and lead != named:
                reversal = (
                    f"named instead of {named}: the pooled evidence reversed, {named} now removes "
                    f"{100 * pool.improvement(named):.0f} % (t {pool.t_statistic(MODEL, named):.1f}), "
                    "not significantly"
                )
            named = lead
        else:
            return None, ""
        self._named = named
        return named, reversal

    @staticmethod
    def _determined_lead(pool: PooledEvidence, leader: str, undetermined: set) -> str:
        """``leader``, or, when its fit leaves a parameter of its own undetermined, the first of its
        pooled near-equivalents whose own parameters are determined and that is significant or removes
        at least as much as the leader (its training free runs gaining). The data do not tell them
        apart, the group's evidence is the leader's t, and an effect added with a parameter the data
        leave free gives the online estimate a free direction (nothing published): a rudder offset
        on a zigzag about one heading is a wind moment whose heading harmonics that sector cannot
        separate; a tanker's first two minutes credit a rudder stall pinned at its bound with 30 %
        at t 3.4 where its cross-flow drag, determined, removes 46 % at t 2.3."""
        if leader not in undetermined:
            return leader
        determined = (
            n
            for n in pool.equivalents(leader)
            if n not in undetermined
            and (
                pool.significant(n)
                or (pool.improvement(n) >= pool.improvement(leader) and pool.training_gain(n) >= MIN_TRAINING_GAIN)
            )
        )
        return next(determined, leader)

    def _law_lead(self, pool: PooledEvidence, leader: str, undetermined: set) -> str:
        """``leader``, or, when it is a yaw damping law, the best ranked damping law within
        ``EQUIVALENT_MARGIN`` of its share that the law shown most often by the pooled diagnoses'
        fits holding both laws (``damping_law``) admits, its own parameters determined, removing
        at least ``SMALL_SHARE`` of the pooled error at t >= ``SIGNIFICANCE_T``.
        Refitted apart, a quadratic damping, a cubic one and the cubic one of a course-unstable hull
        each predict the held-out turns within a few per cent of the others, and which predicts best
        is which search got closest to its optimum (a USV's hidden cubic damping, refitted alone,
        removed 27 % where the quadratic law removed 30 %, at t 3 between them); the shape of the
        damping against the turn rate and the sign of the linear damping are what tell the laws
        apart, and one search holding both reads them. The leader's significance says that a
        damping is missing and which law it takes is the fits', so the admitted law need not be
        significant alone: a share under ``MIN_IMPROVEMENT`` is credited alone only from
        ``CERTAIN_T``, and the same damping can reach it in one law's refits and not in the other's
        (a USV's hidden quadratic damping: the cubic law significant at t 7.3, the quadratic law,
        which the fits showed, removing as much at t 5.3)."""
        shown = self._shown_laws()
        if leader not in DAMPING_LAWS or not shown or leader in shown:
            return leader
        admitted = (
            n
            for n in sorted(shown & set(pool.names), key=lambda n: -pool.rank(n))
            if n not in undetermined
            and pool.improvement(n) >= SMALL_SHARE
            and pool.clear_t(n)
            and pool.training_gain(n) >= MIN_TRAINING_GAIN
            and pool.improvement(leader) - pool.improvement(n) <= EQUIVALENT_MARGIN
        )
        return next(admitted, leader)

    def _tight_turn_lead(self, pool: PooledEvidence, leader: str, undetermined: set) -> str:
        """Of ``leader`` and its pooled near-equivalents whose own parameters are determined and whose
        training free runs gain, the one removing most of the pooled error at the tight turns
        (``PooledEvidence.tight_turn_improvement``; ties keep ``leader``). Effects that fit a trip's
        turns alike part where the turn is tightest: a damping law's moment grows with the turn rate
        beyond the linear damping, a rudder stall caps the rudder's, an offset stays what it is, so the
        tight turns of the held-out data are the nearest the data come to the hard turns the model is
        later asked for (an MMG tanker on random steps: a rudder stall led damping laws by its share
        of the whole held-out error, 26 % against 24-25 %, while at the tight turns it removed 16 %
        and the laws 30-32 %; on the 35 deg turning circle the laws removed 65-67 %, the stall 49 %).
        A law the fits holding both laws show keeps its lead over a law they do not show
        (``_law_lead``: which of two laws refits better is their searches')."""
        shown = self._shown_laws()
        contenders = [
            n
            for n in (leader, *pool.equivalents(leader))
            if n == leader
            or (
                n not in undetermined
                and pool.training_gain(n) >= MIN_TRAINING_GAIN
                and not (leader in shown and n in DAMPING_LAWS and n not in shown)
            )
        ]
        return max(contenders, key=pool.tight_turn_improvement)

    def _shown_laws(self) -> set:
        """The damping laws the pooled diagnoses' fits holding both laws showed most often (none yet: empty)."""
        most = max(self._laws.values(), default=0)
        return {law for law, count in self._laws.items() if count == most > 0}

    def _law_prefers(self, pool: PooledEvidence, named: str, rival: str) -> bool:
        """Whether ``named`` stays before ``rival``, both damping laws, the pooled fits holding both
        laws not showing the rival's law: its lower error is then its search's, not its law's
        (``_law_lead``), and no reversal, when the fits show ``named``'s law, or when they show
        neither and the rival removes no more than ``EQUIVALENT_MARGIN`` beyond ``named``'s share:
        two near-equivalent laws the fits do not show trade places on their searches alone (an MMG
        tanker: the cubic law named, Norrbin's law below it at t 3.1 a minute later, back above it
        the minute after, while the fits showed the quadratic law)."""
        shown = self._shown_laws()
        if named not in DAMPING_LAWS or rival not in DAMPING_LAWS or rival in shown:
            return False
        return named in shown or pool.improvement(rival) - pool.improvement(named) <= EQUIVALENT_MARGIN

    @staticmethod
    def _yaw_rate_evidence(
        pool: PooledEvidence, found: str, rests_on: str, ratio: float, evidence: str, group: list[str]
    ) -> str:
        """The sentence of an effect named on the free runs' yaw rate, with the newest window's
        ``evidence`` and its near-equivalent ``group``."""
        return (
            f"{found} is missing: on the {rests_on} (held-out error {ratio:.1f} times the noise floor) "
            f"adding it removes {100 * pool.improvement(found):.0f} % of the yaw-rate error, "
            f"{100 * pool.excess_removed(found):.0f} % of what lies above the noise floor "
            f"(t {pool.t_statistic(MODEL, found):.1f}); {evidence}"
            + (
                f"; near-equivalent on these data: {', '.join(group)} ({OnlineDiagnosis._shares(pool, group)}); at "
                f"the tightest half of the held-out turns, where they part, {found} removes "
                f"{100 * pool.tight_turn_improvement(found):.0f} % ("
                + ", ".join(f"{n} {100 * pool.tight_turn_improvement(n):.0f} %" for n in group)
                + f"); {separation([found, *group])}"
                if group
                else ""
            )
        )

    @staticmethod
    def _heading_evidence(
        pool: PooledEvidence, found: str, rests_on: str, ratio: float, evidence: str, group: list[str]
    ) -> str:
        """The sentence of an effect named on the free runs' heading (``PooledEvidence.heading_significant``),
        with the newest window's ``evidence`` and its near-equivalent ``group``."""
        return (
            f"{found} is missing: on the {rests_on} the held-out yaw-rate error is {ratio:.2f} times the noise "
            f"floor, but the heading of the free runs drifts from the compass: adding it removes "
            f"{100 * pool.heading_improvement(found):.0f} % of their heading error over {pool.heading_runs} free "
            f"runs (t {pool.heading_t(found):.1f}) and {100 * pool.improvement(found):.0f} % of the yaw-rate error; "
            f"{evidence}"
            + (
                f"; near-equivalent on these data: {', '.join(group)} ("
                + ", ".join(f"{n} {100 * pool.heading_improvement(n):.0f} % of the heading error" for n in group)
                + f"); {separation([found, *group])}"
                if group
                else ""
            )
        )

    @staticmethod
    def _shares(pool: PooledEvidence, group: list[str]) -> str:
        return ", ".join(f"{n} {100 * pool.improvement(n):.0f} %" for n in group)

    @staticmethod
    def _mark(result: dict, pool: PooledEvidence, found: str | None) -> None:
        """Each candidate's pooled figures; ``significant`` becomes the pooled judgement (the effect
        ``found`` missing: while the pool holds it), the window's own kept as
        ``significant_in_window``; the candidates ranked by the pool, ``found`` first."""
        for candidate in result["candidates"]:
            name = candidate["effect"]
            candidate["significant_in_window"] = candidate["significant"]
            candidate["significant"] = name == found or pool.significant(name)
            candidate["pooled"] = {
                "improvement_yaw_rate": pool.improvement(name),
                "excess_removed": pool.excess_removed(name),
                "t_statistic": pool.t_statistic(MODEL, name),
                "training_gain": pool.training_gain(name),
                "tight_turn_improvement": pool.tight_turn_improvement(name),
                "improvement_heading": pool.heading_improvement(name),
                "heading_t": pool.heading_t(name),
            }
        result["candidates"].sort(key=lambda c: (c["effect"] != found, not c["significant"], -pool.rank(c["effect"])))

    def _verdict_without(self, result: dict, pool: PooledEvidence, rests_on: str, ratio: float) -> None:
        """The verdict when the pool names no effect: ``adequate`` when the pooled held-out error is
        within ``NOISE_MARGIN`` of the noise floor and no parameter is pinned at a bound, else
        ``unexplained`` with the pool's best candidate and what is missing to credit it."""
        pinned = result.get("pinned", [])
        if ratio <= NOISE_MARGIN and not pinned:
            result["verdict"] = "adequate"
            result["verdict_sentence"] = (
                f"on the {rests_on} the held-out error is the sensors' noise ({ratio:.2f} times the floor): "
                "nothing the catalogue knows is missing"
            )
            return
        result["verdict"] = "unexplained"
        parts = [f"on the {rests_on} the held-out yaw-rate error is {ratio:.1f} times the noise floor"] + pinned
        best = result["candidates"][0]["effect"] if result["candidates"] else None
        if best is None:
            tail = "; no catalogued effect is left to try"
        else:
            group = pool.equivalents(best) if pool.removes_enough(best) else []
            tail = (
                f"; no catalogued effect removes it significantly (best: {best} removes "
                f"{100 * pool.improvement(best):.0f} %, {100 * pool.excess_removed(best):.0f} % of what lies "
                f"above the noise floor, t {pool.t_statistic(MODEL, best):.1f}; significant takes "
                f"{100 * MIN_IMPROVEMENT:.0f} %, or {100 * MOST_OF_THE_ERROR:.0f} % above the floor with "
                f"{100 * CLEAR_TRAINING_GAIN:.0f} % off the training free runs, and t {SIGNIFICANCE_T:g}"
                + (
                    ""
                    if pool.determines
                    else f", on {MIN_HELD_OUT_S:.0f} s of held-out data counted as from full windows "
                    f"(so far {pool.full_window_seconds:.0f} s: each slice counts by the share of the window "
                    "its fit had)"
                )
                + ": more data, or a manoeuvre that excites it, would tell"
                + (f"; as good so far: {self._shares(pool, group)}; {separation([best, *group])}" if group else "")
                + ")"
            )
        result["verdict_sentence"] = "; ".join(parts) + tail

    def _auto_add(self, result: dict, found: str | None, effects: tuple, config) -> tuple | None:
        """Add the effect named in ``auto_add_after`` consecutive diagnoses; judge one added before."""
        trial = self._trial
        pool = self._pool
        if trial is not None and trial.effect in effects:
            trial.diagnoses += 1
            error = pool.error
            at_noise = error <= NOISE_MARGIN * pool.noise_floor
            if error <= (1.0 - MIN_IMPROVEMENT) * trial.error_before or at_noise:
                self._trial = None
                return self._announce(
                    result,
                    "kept",
                    trial.effect,
                    effects,
                    f"{trial.effect} kept: the pooled held-out yaw-rate error fell from "
                    f"{math.degrees(trial.error_before):.3f} to {math.degrees(error):.3f} deg/s "
                    f"(noise floor {math.degrees(pool.noise_floor):.3f} deg/s)",
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
                    f"{trial.effect} removed again: the pooled held-out yaw-rate error did not fall in "
                    f"{trial.diagnoses} diagnoses ({math.degrees(trial.error_before):.3f} before, "
                    f"{math.degrees(error):.3f} deg/s now, noise floor {math.degrees(pool.noise_floor):.3f})",
                )
            return None
        if not config.auto_add_effects or found is None or found in self._rejected:
            self._streak = ("", 0)
            return None
        count = self._streak[1] + 1 if self._streak[0] == found else 1
        self._streak = (found, count)
        if count < config.auto_add_after:
            return None
        self._trial = Trial(found, pool.error)
        return self._announce(
            result,
            "added",
            found,
            effects + (found,),
            f"{found} added by auto_add_effects: named in {count} consecutive diagnoses; removed again "
            f"unless the pooled held-out yaw-rate error ({math.degrees(pool.error):.3f} deg/s) falls by "
            f"{100 * MIN_IMPROVEMENT:.0f} % or to within {NOISE_MARGIN:g} times the noise floor within "
            f"{CHECK_DIAGNOSES} diagnoses",
        )

    def _announce(self, result: dict, action: str, effect: str, effects: tuple, sentence: str) -> tuple | None:
        """Record what auto-add did in the diagnosis; the effects to set (None: unchanged)."""
        result["auto_add"] = {"action": action, "effect": effect, "effects": list(effects), "sentence": sentence}
        if action == "kept":
            return None
        self._asked = effects
        return effects
