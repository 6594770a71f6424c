"""Multiple shooting: the model run free over blocks of the data, each block from its own initial state.

A free run over a long record drifts with every small error of the model (and a course-unstable or
slow hull's far more), and the cost of one long run is a narrow, curved valley in the parameters.
Multiple shooting (Bock, 1983) cuts the record into blocks, starts each block's run from an unknown
state of its own (heading, yaw rate and, second order, yaw acceleration) and fits those states with
the parameters: the unknowns are

    x = [free parameters, block 0's state, block 1's state, ...]

and a block's state touches only that block's samples, so the Jacobian's state columns are found
for every block at once, one run per state component (``difference_points``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numba import njit
from scipy import sparse

from ..model.dataset import Dataset
from ..model.structure import Structure

STEP_SHARE = 1e-6  # forward-difference step: this share of each unknown's magnitude ...
STEP_FLOOR = 1e-2  # ... or of this (SI units) for an unknown near zero


class ShootingProblem:
    """The unknowns, free runs and finite-difference Jacobian of a multiple-shooting fit.

    Parameters
    ----------
    structure : Structure
        The model whose parameters ``names`` are fitted.
    dataset : Dataset
        The data; its segments are replaced by ``blocks`` for the runs.
    blocks : sequence of (int, int)
        Half-open sample index ranges, each run free from its own state.
    names : sequence of str
        The fitted parameters, in the order of the unknowns.
    fixed : dict
        The values of every other parameter the model needs (SI units).
    """

    def __init__(self, structure: Structure, dataset: Dataset, blocks, names, fixed: dict):
        self.structure = structure
        self.dataset = dataset
        self.blocks = tuple(blocks)
        self.names = list(names)
        self.fixed = dict(fixed)
        self.shots = replace(dataset, segments=self.blocks)
        self.n_params = len(self.names)
        self.n_state = structure.order + 1  # heading, yaw rate (and yaw acceleration)
        self.owner = np.full(dataset.n_samples, -1, dtype=np.int64)  # each sample's block, -1 outside
        for i, (a, b) in enumerate(self.blocks):
            self.owner[a:b] = i
        self._state_layout = None  # ``_state_entries`` of the last columns, with them

    @property
    def size(self) -> int:
        """Number of unknowns: the parameters and every block's state."""
        return self.n_params + self.n_state * len(self.blocks)

    def initial_states(self, yaw_rate_bias: float) -> np.ndarray:
        """Each block's starting state from the data, yaw acceleration zero.

        Its first heading (rad) and yaw rate (rad/s) measured, less the sensor's ``yaw_rate_bias``.

        Parameters
        ----------
        yaw_rate_bias : float
            The yaw-rate sensor's bias (rad/s).

        Returns
        -------
        numpy.ndarray
            One row per block, ``n_state`` columns: heading (rad), yaw rate (rad/s)[, yaw acceleration
            rad/s^2].
        """
        d = self.dataset
        return np.array([[d.heading[a], d.yaw_rate[a] - yaw_rate_bias, 0.0][: self.n_state] for a, _ in self.blocks])

    def unpack(self, x: np.ndarray) -> tuple[dict, list]:
        """The parameter set and each block's initial state of the unknowns ``x``.

        Parameters
        ----------
        x : numpy.ndarray
            The unknowns: the fitted parameters, then each block's state.

        Returns
        -------
        params : dict
            ``fixed`` with the fitted ones of ``x`` (SI units).
        states : list of tuple
            Each block's (heading rad, yaw rate rad/s, yaw acceleration rad/s^2; 0 for first order).
        """
        states = np.asarray(x[self.n_params :]).reshape(-1, self.n_state)
        return self.parameters(x), [(s[0], s[1], s[2] if self.n_state == 3 else 0.0) for s in states]

    def parameters(self, x: np.ndarray) -> dict:
        """The parameter set of the unknowns ``x``: ``fixed`` with the fitted ones.

        Parameters
        ----------
        x : numpy.ndarray
            The unknowns: the fitted parameters, then each block's state.

        Returns
        -------
        dict
            The parameters (SI units).
        """
        params = dict(self.fixed)
        params.update(zip(self.names, x[: self.n_params]))
        return params

    def simulate(self, points, substeps: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The blocks' free runs for several unknown vectors (one row each), in one compiled call.

        Parameters
        ----------
        points : sequence of numpy.ndarray
            Unknown vectors.
        substeps : int or None
            Integration substeps per sample (default: the fastest time constant's).

        Returns
        -------
        heading, yaw_rate : numpy.ndarray
            (len(points), n) heading (rad) and measured yaw rate (rad/s) of the runs.
        """
        initial = np.zeros((len(points), len(self.blocks), 3))  # a first-order run's yaw acceleration: 0
        initial[:, :, : self.n_state] = np.array(points)[:, self.n_params :].reshape(len(points), -1, self.n_state)
        return self.structure.simulate_runs([self.parameters(x) for x in points], self.shots, initial, substeps)

    @staticmethod
    def steps(x: np.ndarray) -> np.ndarray:
        """Forward-difference steps of the unknowns: STEP_SHARE of their magnitude, at least of STEP_FLOOR.

        Parameters
        ----------
        x : numpy.ndarray
            The unknowns.

        Returns
        -------
        numpy.ndarray
            One step per unknown (the unknown's unit).
        """
        return STEP_SHARE * np.maximum(np.abs(x), STEP_FLOOR)

    def difference_points(self, x: np.ndarray, upper: np.ndarray, chosen) -> tuple[list, np.ndarray]:
        """The unknowns to run for the Jacobian at ``x``, and the steps.

        Parameters
        ----------
        x : ndarray
            The unknowns.
        upper : ndarray
            Upper bounds of the parameters: a step that would cross one is taken backwards (a hull
            beyond its physical range may not even run).
        chosen : sequence of int
            The parameters whose columns are wanted.

        Returns
        -------
        points : list of ndarray
            One point per chosen parameter, then one per state component, that component moved
            in every block at once (the blocks' runs touch disjoint samples).
        steps : ndarray
            The nominal step of every unknown.
        """
        steps = self.steps(x)
        points = []
        for j in chosen:
            moved = x.copy()
            moved[j] += steps[j] if x[j] + steps[j] <= upper[j] else -steps[j]
            points.append(moved)
        p, n = self.n_params, self.n_state
        for c in range(n):
            moved = x.copy()
            moved[p + c :: n] += steps[p + c :: n]
            points.append(moved)
        return points, steps

    def columns(self, row_blocks: np.ndarray) -> np.ndarray:
        """The Jacobian's possibly nonzero columns of each residual row: every parameter, then its block's state.

        Rows outside every block (``row_blocks`` -1) have no state derivative: their zero values are kept
        in block 0's columns.

        Parameters
        ----------
        row_blocks : numpy.ndarray
            The block of each residual row (-1: none).

        Returns
        -------
        numpy.ndarray
            (rows, n_params + n_state) column indices (int64).
        """
        p, n = self.n_params, self.n_state
        out = np.empty((len(row_blocks), p + n), dtype=np.int64)
        out[:, :p] = np.arange(p)
        out[:, p:] = p + n * np.maximum(row_blocks, 0)[:, None] + np.arange(n)
        return out

    def jacobian(self, x, points, steps, differences, chosen, columns, sparse_matrix: bool = False):
        """The forward-difference Jacobian of the residuals at ``x``.

        Parameters
        ----------
        x, points, steps : ndarray, list, ndarray
            The unknowns, and ``difference_points``' points and steps.
        differences : ndarray
            Residuals at each point less those at ``x``, one row per point.
        chosen : sequence of int
            The parameters ``points`` moved; the others' columns are zero.
        columns : ndarray
            ``columns`` of the residual rows.
        sparse_matrix : bool
            Return a CSR matrix (many blocks: cheaper products) instead of a dense array.

        Returns
        -------
        ndarray or scipy.sparse.csr_matrix
            d residual / d unknown, residual rows by unknowns. A parameter's column is divided by
            the step as represented (x + h - x, not h: no rounding error of order eps |x| / h).
        """
        p = self.n_params
        m, varied = len(chosen), list(chosen)
        moved = np.array([point[j] for point, j in zip(points, varied)])
        parameter_values = (differences[:m] / (moved - x[varied])[:, None]).T
        shape = (len(columns), len(x))
        if sparse_matrix:
            values = np.zeros(columns.shape)
            values[:, varied] = parameter_values
            values[:, p:] = differences[m:].T / steps[columns[:, p:]]
            row_starts = np.arange(0, values.size + 1, columns.shape[1])
            return sparse.csr_matrix((values.ravel(), columns.ravel(), row_starts), shape=shape)
        dense = np.zeros(shape)  # the parameters' columns are the first p
        dense[:, varied] = parameter_values
        entries, unknowns = self._state_entries(columns, len(x))
        dense.reshape(-1)[entries] = differences[m:].ravel() / steps[unknowns]
        return dense

    def _state_entries(self, columns: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
        """Where the state derivatives of the residual rows of ``columns`` go: their flat indices in
        the dense (rows x ``size``) Jacobian and the unknowns they belong to, both in the order of
        the differences' state rows (state component by component, each over every residual row);
        kept for the ``columns`` of the last call, which a search passes at every step."""
        if self._state_layout is None or self._state_layout[0] is not columns:
            unknowns = columns[:, self.n_params :].T
            entries = np.arange(len(columns)) * size + unknowns
            self._state_layout = (columns, entries.ravel(), unknowns.ravel())
        return self._state_layout[1], self._state_layout[2]


def normal_equations(jacobian, residuals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Gauss-Newton gradient ``J' f`` and the normal matrix ``J' J`` (dense) of a search step.

    A sparse Jacobian (``ShootingProblem.jacobian``'s: as many entries in every row, its columns
    sorted) is summed in one compiled pass over its rows (``_sparse_normal_equations``), each sum
    in row order as scipy's sparse products add them, so they are the same numbers without the
    transposed and product matrices being built.

    Parameters
    ----------
    jacobian : numpy.ndarray or scipy.sparse.csr_matrix
        d residual / d unknown, residual rows by unknowns.
    residuals : numpy.ndarray
        The residual vector.

    Returns
    -------
    gradient : numpy.ndarray
        ``J' f`` (one per unknown).
    normal : numpy.ndarray
        ``J' J`` (unknowns x unknowns).
    """
    if not sparse.issparse(jacobian):
        return jacobian.T @ residuals, jacobian.T @ jacobian
    rows, size = jacobian.shape
    values, columns = jacobian.data.reshape(rows, -1), jacobian.indices.reshape(rows, -1)
    return _sparse_normal_equations(values, columns, residuals, size)


@njit(cache=True)
def _sparse_normal_equations(values, columns, residuals, size):
    """``normal_equations`` of a Jacobian whose row ``k`` holds ``values[k]`` in ``columns[k]``.

    Successive rows with the same columns (one shooting interval's) are added into a compact copy
    of their entries, taken from the sums and put back when the columns change: every sum still
    adds its rows one by one in row order, and the inner loop runs over contiguous memory."""
    rows, width = values.shape
    gradient = np.zeros(size)
    normal = np.zeros((size, size))
    local = np.empty((width, width))
    local_gradient = np.empty(width)
    start = 0
    while start < rows:
        stop = start + 1
        while stop < rows and _same_columns(columns, stop, start):
            stop += 1
        index = columns[start]
        for a in range(width):
            local_gradient[a] = gradient[index[a]]
            for b in range(width):
                local[a, b] = normal[index[a], index[b]]
        for row in range(start, stop):
            f = residuals[row]
            for a in range(width):
                va = values[row, a]
                local_gradient[a] += va * f
                for b in range(width):
                    local[a, b] += va * values[row, b]
        for a in range(width):
            gradient[index[a]] = local_gradient[a]
            for b in range(width):
                normal[index[a], index[b]] = local[a, b]
        start = stop
    return gradient, normal


@njit(cache=True)
def _same_columns(columns, row, other):
    """Whether rows ``row`` and ``other`` of ``columns`` are equal."""
    for a in range(columns.shape[1]):
        if columns[row, a] != columns[other, a]:
            return False
    return True
