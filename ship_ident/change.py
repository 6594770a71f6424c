"""Has the vessel changed? A model's out-of-sample free-run error on the newest data.

A hull that is loaded, fouled or damaged mid-trip answers its rudder
differently; a sliding window of ``window_length`` s mixes the old and new
response until the old data have left it. Here a model is run free from the
measured state over blocks of ``length`` s (restarting at each block) and
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
a row, the vessel has changed. Where it changed is found in the newest
2 ``length`` s of that free run: the split of greatest likelihood for a step
in the error's variance; the window then restarts there.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import replace

import numpy as np

from .dataset import Dataset
from .signals import noise_level
from .structure import Structure

CONFIRMATIONS = 2                 # refits in a row above the ratio before a change is declared
MEDIAN_OF_CHI2_1 = 0.4549         # median of e^2 / sigma^2 for Gaussian e
MIN_LEVEL = math.radians(0.01) ** 2  # (rad/s)^2: no yaw-rate sensor resolves finer errors
# A reference model must be well determined: relative standard errors at most these (a window of
# steady turning gives a K to 10-25 % and T1 to 60-400 %, and any new rudder motion surprises it).
REFERENCE_RELATIVE_ERRORS = {"K": 0.05, "T": 0.2, "T1": 0.2}


def whole_blocks(dataset: Dataset, n: int, offset: int = 0) -> tuple:
    """Half-open index ranges of whole blocks of n samples inside the dataset's segments."""
    return tuple((a, a + n) for start, stop in dataset.segments
                 for a in range(start + offset, stop - n + 1, n))


def block_errors(structure: Structure, params: dict, dataset: Dataset, blocks: tuple) -> np.ndarray:
    """Robust mean square (rad^2/s^2) of the free-run yaw-rate error in each block, the model
    restarted from the measured state at each block start."""
    if not blocks:
        return np.zeros(0)
    _, r = structure.simulate(params, replace(dataset, segments=blocks))
    squared = (r - dataset.yaw_rate) ** 2
    return np.array([np.median(squared[a:b]) / MEDIAN_OF_CHI2_1 for a, b in blocks])


class ChangeDetector:
    """Declares a change when the newest ``length`` s of free-run error, of the newest model
    fitted before them, exceed ``ratio`` times that model's usual level on CONFIRMATIONS
    refits in a row (see the module docstring)."""

    def __init__(self, ratio: float, length: float):
        self.ratio = ratio      # mean-square ratio (dimensionless); 0: never
        self.length = length    # s
        self.references = deque()  # (window end s, parameters, usual level (rad/s)^2), oldest first
        self.votes = 0

    def calibrate(self, structure: Structure, estimate, dataset: Dataset) -> None:
        """Learn the usual error level of a just-accepted estimate on its own (full) window; an
        estimate less well determined than REFERENCE_RELATIVE_ERRORS is not a reference."""
        params, errors = estimate.parameters, estimate.std_errors
        if not all(errors.get(name, math.inf) <= limit * abs(params[name])
                   for name, limit in REFERENCE_RELATIVE_ERRORS.items() if name in params):
            return
        n = int(round(self.length / dataset.sample_time))
        blocks = whole_blocks(dataset, n) + whole_blocks(dataset, n, n // 2)
        errors = block_errors(structure, params, dataset, blocks)
        if len(errors):
            floor = max(noise_level(dataset.yaw_rate, 0.0) ** 2, MIN_LEVEL)
            self.references.append((float(dataset.time[-1]), params, max(float(np.median(errors)), floor)))

    def forget(self) -> None:
        self.references.clear()
        self.votes = 0

    def _reference(self, before: float):
        """The newest reference fitted on data ending at or before ``before`` (s), or None."""
        while len(self.references) > 1 and self.references[1][0] <= before:
            self.references.popleft()
        return self.references[0] if self.references and self.references[0][0] <= before else None

    def test(self, structure: Structure, dataset: Dataset) -> tuple[float, float | None]:
        """(ratio of the newest block's error to the usual level, time (s) the vessel changed or None).
        The newest block is out of sample: the model is the newest one fitted before it began."""
        n = int(round(self.length / dataset.sample_time))
        start, stop = dataset.segments[-1]
        reference = self._reference(float(dataset.time[stop - n])) if stop - start >= n else None
        if not self.ratio or reference is None:
            return math.nan, None
        _, params, level = reference
        newest = block_errors(structure, params, dataset, ((stop - n, stop),))
        ratio = float(newest[0]) / level
        self.votes = self.votes + 1 if ratio > self.ratio else 0
        if self.votes < CONFIRMATIONS:
            return ratio, None
        self.forget()
        a = max(start, stop - 2 * n)
        _, r = structure.simulate(params, dataset.slice(a, stop))
        squared = np.minimum((r - dataset.yaw_rate[a:stop]) ** 2, 100 * self.ratio * level)
        return ratio, float(dataset.time[a + variance_change_point(squared)])


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
