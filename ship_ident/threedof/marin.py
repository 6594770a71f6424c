"""KVLCC2 free-running records of MARIN (SIMMAN 2008) as 3-DOF Records."""

from __future__ import annotations

import numpy as np

from .model import Record


def load_marin_raw(path: str) -> Record:
    """Read a MARIN/SIMMAN free-running ``.dat`` file (full scale) into a body-fixed SI Record.

    Columns: t, x0, y0, phi (deg), psi (deg), dx0/dt, dy0/dt (m/s, earth-fixed),
    p (deg/s), r (deg/s), delta (deg, positive to port), n (rpm). The earth-fixed
    velocity is rotated into surge u = x' cos psi + y' sin psi and sway
    v = -x' sin psi + y' cos psi; the rudder sign is flipped (positive to starboard).
    The printed time has 3 significant figures, so the grid is rebuilt as
    t0 + i h with h the least-squares slope of the printed times.
    """
    rows = []
    with open(path, encoding="latin-1") as handle:
        for line in handle.readlines()[3:]:
            fields = line.split()
            if fields:
                rows.append([float(f) for f in fields])
    data = np.array(rows)
    if data.ndim != 2 or data.shape[1] != 11:
        raise ValueError(f"{path}: expected 11 tab-separated columns after a 3-line header")
    index = np.arange(len(data))
    step, start = np.polyfit(index, data[:, 0], 1)
    psi = np.radians(data[:, 4])
    x_dot, y_dot = data[:, 5], data[:, 6]
    return Record(
        time=start + step * index,
        surge=x_dot * np.cos(psi) + y_dot * np.sin(psi),
        sway=-x_dot * np.sin(psi) + y_dot * np.cos(psi),
        yaw_rate=np.radians(data[:, 8]),
        heading=psi,
        rudder=-np.radians(data[:, 9]),
        propeller_rate=data[:, 10] / 60.0,
        meta={"source": str(path)},
    )


def approach_speed(record: Record, duration: float = 3.0) -> float:
    """Mean surge speed (m/s) over the first ``duration`` seconds (before the rudder is executed)."""
    return float(np.mean(record.surge[record.time - record.time[0] <= duration]))
