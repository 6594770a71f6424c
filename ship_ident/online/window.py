"""The sliding window of one input: (time s, value SI) pairs in a preallocated array.

The online identifier keeps one ``SampleWindow`` per role. Samples are appended at the end of a
buffer of twice the window's capacity; the oldest leave by moving the start index (pruning by time,
or the capacity reached), and when the buffer's end is reached the live rows move back to its front
(once per capacity appends). The window is handed out as contiguous (n, 2) arrays, so a refit or a
change watch reads it without converting Python objects, and a watch reads only its newest rows
(found by bisection: the stamps of one input increase, ``input_checks.order_rejection``).
"""

from __future__ import annotations

import numpy as np


class SampleWindow:
    """The newest ``capacity`` (time s, value) samples of one input, oldest first.

    Parameters
    ----------
    capacity : int
        Most samples kept; appending to a full window drops its oldest sample.
    """

    def __init__(self, capacity: int):
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1 sample, got {capacity}")
        self.capacity = capacity
        self._rows = np.empty((2 * capacity, 2))
        self._start = 0  # index of the oldest live row
        self._end = 0  # one past the newest live row

    def __len__(self) -> int:
        return self._end - self._start

    def append(self, time: float, value: float) -> None:
        """Add a sample at the end, the oldest dropped when the window is full.

        Parameters
        ----------
        time : float
            Its stamp (s), after the newest one's.
        value : float
            Its value (SI).
        """
        if self._end - self._start == self.capacity:
            self._start += 1
        if self._end == len(self._rows):
            live = self._end - self._start
            self._rows[:live] = self._rows[self._start : self._end]
            self._start, self._end = 0, live
        self._rows[self._end] = time, value
        self._end += 1

    def clear(self) -> None:
        """Drop every sample."""
        self._start = self._end = 0

    def prune(self, oldest: float) -> None:
        """Drop the samples stamped before ``oldest``.

        Parameters
        ----------
        oldest : float
            The oldest stamp kept (s).
        """
        self._start += int(np.searchsorted(self._rows[self._start : self._end, 0], oldest, side="left"))

    def array(self, oldest: float = -np.inf) -> np.ndarray:
        """A copy of the samples stamped at or after ``oldest``, oldest first.

        Parameters
        ----------
        oldest : float
            The oldest stamp returned (s); all samples by default.

        Returns
        -------
        numpy.ndarray
            (n, 2) rows of (time s, value SI).
        """
        live = self._rows[self._start : self._end]
        if oldest > -np.inf:
            live = live[int(np.searchsorted(live[:, 0], oldest, side="left")) :]
        return live.copy()
