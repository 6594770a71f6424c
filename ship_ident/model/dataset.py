"""Steering data on a uniform time grid: the one input type of the numeric core.

Units are SI throughout: time in s, rudder angle in rad, heading in rad
(unwrapped, NED: positive clockwise seen from above), yaw rate in rad/s,
forward speed in m/s. A positive rudder angle gives a positive yaw rate.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from .noise import SENSOR_RESOLUTION, median, noise_level


class DataError(ValueError):
    """Input data that cannot be used; the message says what is wrong and what to do."""


CUT_ALIGNMENTS = ("even", "start", "end")


def cut_segments(
    segments, samples: int, min_samples: int = 1, align: str = "even", offset: int = 0, whole: bool = False
) -> tuple:
    """Cut each segment into pieces of about ``samples``; no piece crosses a gap.

    Free runs, shooting intervals and test blocks are all cut here.

    Parameters
    ----------
    segments : sequence of (int, int)
        Half-open sample index ranges ``[a, b)`` of contiguous data.
    samples : int
        Samples per piece.
    min_samples : int
        Pieces shorter than this are dropped.
    align : {"even", "start", "end"}
        "even": near-equal pieces covering the segment (a short segment is one piece); "start":
        pieces of exactly ``samples`` from ``offset`` samples into the segment, the last one
        shorter; "end": pieces of exactly ``samples`` counted back from the segment's end, the first
        one shorter (the newest piece, where a changed hull shows first, is a whole one: cut from the
        start, 30.5 s after a change would leave a newest piece of 0.5 s, too short to show it).
    offset : int
        Samples skipped at each segment's start ("start" only).
    whole : bool
        Drop the shorter piece: every piece has exactly ``samples`` (with "start" or "end").

    Returns
    -------
    tuple of (int, int)
        The pieces' half-open index ranges, in time order.
    """
    if align not in CUT_ALIGNMENTS:
        raise ValueError(f"align must be one of {', '.join(CUT_ALIGNMENTS)}, not {align!r}")
    if whole:
        min_samples = max(min_samples, samples)
    out = []
    for a, b in segments:
        if align == "even":
            count = max(1, int(round((b - a) / samples)))
            edges = [int(e) for e in np.linspace(a, b, count + 1).round()]
            pieces = zip(edges[:-1], edges[1:])
        elif align == "start":
            pieces = ((s, min(s + samples, b)) for s in range(a + offset, b, samples))
        else:
            pieces = ((max(e - samples, a), e) for e in reversed(range(b, a, -samples)))
        out += [(lo, hi) for lo, hi in pieces if hi - lo >= min_samples]
    return tuple(out)


@dataclass(frozen=True)
class Dataset:
    """Uniformly sampled steering record.

    ``segments`` lists half-open index ranges ``[start, stop)`` of contiguous
    data; a gap in the source (longer than the gap threshold) splits the
    record, and nothing is integrated or differentiated across a gap.
    """

    time: np.ndarray  # s, uniform step sample_time within each segment
    rudder: np.ndarray  # rad
    heading: np.ndarray  # rad, unwrapped
    yaw_rate: np.ndarray  # rad/s
    speed: np.ndarray | None = None  # m/s
    segments: tuple[tuple[int, int], ...] = ()
    gaps: tuple[tuple[float, float], ...] = ()  # (start s, end s) of gaps in the source
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        n = len(self.time)
        for name in ("rudder", "heading", "yaw_rate"):
            if len(getattr(self, name)) != n:
                raise DataError(f"{name} has {len(getattr(self, name))} samples, time has {n}")
        if self.speed is not None and len(self.speed) != n:
            raise DataError(f"speed has {len(self.speed)} samples, time has {n}")
        if not self.segments:
            object.__setattr__(self, "segments", ((0, n),) if n else ())

    @property
    def n_samples(self) -> int:
        """The number of samples."""
        return len(self.time)

    def noise_std(self, name: str, floor: float = SENSOR_RESOLUTION) -> float:
        """White-noise std of a measured signal, at least ``floor``; estimated once per dataset.

        Parameters
        ----------
        name : str
            ``rudder`` or ``heading`` (rad), or ``yaw_rate`` (rad/s).
        floor : float
            The smallest value returned (the sensor's resolution, in the signal's unit).

        Returns
        -------
        float
            The std (``noise.noise_level``) in the signal's unit.
        """
        levels = self._noise_levels
        if name not in levels:
            levels[name] = noise_level(getattr(self, name), 0.0)
        return max(levels[name], floor)

    @cached_property
    def _noise_levels(self) -> dict:
        """Noise stds estimated so far, by signal name (filled by ``noise_std``)."""
        return {}

    @cached_property
    def derived(self) -> dict:
        """Results computed from this dataset alone, kept by what they are and their arguments.

        Filled by their makers (``signals.compute_signals``): a dataset is never changed once made.
        """
        return {}

    @cached_property
    def sample_time(self) -> float:
        """Sample time in s (the grid step; computed once per dataset)."""
        if self.n_samples < 2:
            return float(self.meta.get("sample_time", 0.1))
        start, stop = max(self.segments, key=lambda s: s[1] - s[0])
        return float(median(np.diff(self.time[start:stop]))) if stop - start > 1 else float(median(np.diff(self.time)))

    @property
    def duration(self) -> float:
        """The time from the first sample to the last (s), gaps included."""
        return float(self.time[-1] - self.time[0]) if self.n_samples else 0.0

    def slice(self, start: int, stop: int) -> Dataset:
        """The samples ``[start, stop)`` as a new Dataset, segments and recordings' sample ranges clipped.

        Parameters
        ----------
        start, stop : int
            Sample indices, half-open.

        Returns
        -------
        Dataset
            The slice (``meta["recordings"]`` clipped to it).
        """
        segs = tuple(
            (max(a, start) - start, min(b, stop) - start) for a, b in self.segments if min(b, stop) > max(a, start)
        )
        meta = self.meta
        if "recordings" in meta:
            meta = dict(
                meta,
                recordings=[
                    dict(r, start=max(r["start"], start) - start, stop=min(r["stop"], stop) - start)
                    for r in meta["recordings"]
                    if min(r["stop"], stop) > max(r["start"], start)
                ],
            )
        return replace(
            self,
            meta=meta,
            time=self.time[start:stop],
            rudder=self.rudder[start:stop],
            heading=self.heading[start:stop],
            yaw_rate=self.yaw_rate[start:stop],
            speed=None if self.speed is None else self.speed[start:stop],
            segments=segs,
            gaps=tuple(g for g in self.gaps if stop > start and self.time[start] <= g[0] <= self.time[stop - 1]),
        )

    def segment_datasets(self, min_samples: int = 2) -> list[Dataset]:
        """Each contiguous segment as its own Dataset.

        Parameters
        ----------
        min_samples : int
            Segments shorter than this are left out.

        Returns
        -------
        list of Dataset
            The segments, in time order.
        """
        return [self.slice(a, b) for a, b in self.segments if b - a >= min_samples]

    def check_finite(self) -> None:
        """Raise DataError when any signal holds NaN or Inf."""
        for name in ("time", "rudder", "heading", "yaw_rate", "speed"):
            values = getattr(self, name)
            if values is not None and not np.all(np.isfinite(values)):
                bad = int(np.count_nonzero(~np.isfinite(values)))
                raise DataError(f"{name} holds {bad} NaN/Inf samples; clean the data or let the reader drop them")


def resample_series(
    series: dict[str, tuple[np.ndarray, np.ndarray]],
    sample_time: float,
    gap_threshold: float | None = None,
    unwrap_heading: bool = True,
    meta: dict | None = None,
) -> Dataset:
    """Turn asynchronous time series into one uniformly sampled Dataset.

    Parameters
    ----------
    series : dict
        ``rudder``, ``heading`` and ``yaw_rate`` (optionally ``speed``) to ``(stamps_s, values)``,
        SI units.
    sample_time : float
        Grid step (s).
    gap_threshold : float or None
        Longest stretch without a sample that is not a gap (s; default 5 sample times).
    unwrap_heading : bool
        Unwrap the heading before interpolating it.
    meta : dict or None
        Facts about the source, kept in ``Dataset.meta``.

    Returns
    -------
    Dataset
        The signals on the grid, cut into segments at the gaps (``resample_signals``).
    """
    time, values, segments, gaps = resample_signals(series, sample_time, gap_threshold, unwrap_heading)
    return Dataset(
        time=time,
        rudder=values["rudder"],
        heading=values["heading"],
        yaw_rate=values["yaw_rate"],
        speed=values.get("speed"),
        segments=segments,
        gaps=gaps,
        meta=dict(meta or {}, sample_time=sample_time),
    )


# A signal sampled at least this many times per grid step is averaged over each step, not
# interpolated (``on_grid``)
SAMPLES_TO_AVERAGE = 2.0


def median_above(values: np.ndarray, threshold: float) -> bool:
    """Whether the median of ``values`` (finite, at least one) exceeds ``threshold``: counted, as
    the median exceeds it exactly when the middle value (both middle values of an even count) does;
    the median itself is taken only when the two middle values of an even count straddle it.

    Parameters
    ----------
    values : ndarray
        Finite values (a signal's stamp steps, s).
    threshold : float
        The value compared with (s).

    Returns
    -------
    bool
        ``np.median(values) > threshold``.
    """
    n, above = len(values), int(np.count_nonzero(values > threshold))
    if n % 2 or above != n // 2:
        return above > n // 2
    return bool(np.median(values) > threshold)


def on_grid(
    stamps: np.ndarray, values: np.ndarray, steps: np.ndarray, grid: np.ndarray, sample_time: float
) -> np.ndarray:
    """A signal (sorted ``stamps`` in s, ``values``, the ``steps`` between the stamps in s) at the
    ``grid`` points: its linear interpolant's mean over the step [t - h/2, t + h/2] around each
    point (h = ``sample_time``; the step shrinks symmetrically at the span's ends) when its median stamp step is at most
    1/SAMPLES_TO_AVERAGE of h, else the interpolant itself. Interpolating a fast signal keeps one
    sample in h / step and throws the rest away: a slow ship's 1 s grid on 10 Hz sensors kept a
    tenth of the data, and its estimates scattered sqrt(10) times wider than the data allow; the
    step mean keeps the sensor noise white and divides its variance by the samples averaged, and
    it shifts a smooth signal by only h^2 / 24 times its second derivative."""
    if len(stamps) < 2 or median_above(steps, sample_time / SAMPLES_TO_AVERAGE):
        return np.interp(grid, stamps, values)
    slopes = np.diff(values) / steps
    integral = np.concatenate(([0.0], np.cumsum(0.5 * (values[:-1] + values[1:]) * steps)))

    def primitive(t):  # the interpolant's integral from stamps[0] to t (t within the stamps' span)
        i = np.clip(np.searchsorted(stamps, t, side="right") - 1, 0, len(stamps) - 2)
        dt = t - stamps[i]
        return integral[i] + dt * (values[i] + 0.5 * slopes[i] * dt)

    half = np.clip(np.minimum(grid - stamps[0], stamps[-1] - grid), 0.0, 0.5 * sample_time)  # symmetric at the ends
    means = (primitive(grid + half) - primitive(grid - half)) / np.where(half > 0, 2 * half, 1.0)
    return np.where(half > 0, means, np.interp(grid, stamps, values))


def resample_signals(
    series: dict[str, tuple[np.ndarray, np.ndarray]],
    sample_time: float,
    gap_threshold: float | None = None,
    unwrap_heading: bool = True,
    required=("rudder", "heading", "yaw_rate"),
):
    """Asynchronous time series on one uniform grid.

    Non-finite samples are dropped, stamps sorted and de-duplicated. The grid covers the span where
    every signal has data; values are linearly interpolated (heading after unwrapping), or averaged
    over each grid step when sampled faster (``on_grid``). Where any signal has no sample for
    longer than ``gap_threshold`` the grid is cut: the gap is reported in ``gaps`` and the
    segments on each side stay apart.

    Parameters
    ----------
    series : dict
        ``rudder``, ``heading``, ``yaw_rate`` (and optionally ``speed``, or any other signal) to
        ``(stamps_s, values)``.
    sample_time : float
        Grid step (s).
    gap_threshold : float or None
        Longest stretch without a sample that is not a gap (s; default 5 sample times).
    unwrap_heading : bool
        Unwrap the heading (rad) before interpolating it.
    required : sequence of str
        Signals that must be in ``series``.

    Returns
    -------
    time : ndarray
        The grid (s).
    values : dict
        Each signal on the grid.
    segments : tuple of (int, int)
        Half-open index ranges of contiguous data.
    gaps : list
        The gaps found.
    """
    if sample_time <= 0:
        raise DataError(f"sample_time must be > 0 s, got {sample_time}")
    gap_threshold = 5 * sample_time if gap_threshold is None else gap_threshold
    clean: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}  # stamps, values, steps between the stamps
    for name, (stamps, values) in series.items():
        stamps = np.asarray(stamps, dtype=float)
        values = np.asarray(values, dtype=float)
        ok = np.isfinite(stamps) & np.isfinite(values)
        if not ok.all():
            stamps, values = stamps[ok], values[ok]
        steps = np.diff(stamps)
        if not np.all(steps > 0):  # an online window's stamps already increase
            order = np.argsort(stamps, kind="stable")
            stamps, values = stamps[order], values[order]
            keep = np.concatenate(([True], np.diff(stamps) > 0)) if len(stamps) else np.zeros(0, bool)
            stamps, values = stamps[keep], values[keep]
            steps = np.diff(stamps)
        if name == "heading" and unwrap_heading and len(values):
            values = np.unwrap(values)
        clean[name] = (stamps, values, steps)
    for name in required:
        if name not in clean or len(clean[name][0]) < 2:
            raise DataError(f"no usable {name} samples (need at least 2 finite samples)")
    start = max(s[0] for s, _, _ in clean.values())
    stop = min(s[-1] for s, _, _ in clean.values())
    if stop - start < 2 * sample_time:
        raise DataError("the signals do not overlap in time; check topic names and clocks")
    grid = start + sample_time * np.arange(int(np.floor((stop - start) / sample_time + 1e-9)) + 1)
    valid = np.ones(len(grid), dtype=bool)
    gaps: list[tuple[float, float]] = []
    for stamps, _, steps in clean.values():
        for i in np.flatnonzero(steps > gap_threshold):
            a, b = stamps[i], stamps[i + 1]
            gaps.append((float(a), float(b)))
            valid &= ~((grid > a) & (grid < b))
    out = {name: on_grid(*signal, grid, sample_time) for name, signal in clean.items()}
    if not gaps:  # one segment: every grid point kept
        return grid, out, ((0, len(grid)),), ()
    edges = np.diff(np.concatenate(([0], valid.astype(np.int8), [0])))  # +1 where a run of valid points starts
    keep_idx = np.flatnonzero(valid)
    remap = np.full(len(grid), -1)
    remap[keep_idx] = np.arange(len(keep_idx))
    segments = [
        (int(remap[a]), int(remap[b - 1]) + 1) for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1))
    ]
    gaps = sorted(set(gaps))
    return grid[keep_idx], {name: values[keep_idx] for name, values in out.items()}, tuple(segments), tuple(gaps)


def resampled(dataset: Dataset, sample_time: float) -> Dataset:
    """The dataset on the grid step ``sample_time`` (s), each segment interpolated on its own
    (nothing bridges a gap); unchanged when its step already is ``sample_time``."""
    if np.isclose(dataset.sample_time, sample_time, rtol=1e-3):
        return dataset
    parts = []
    for part in dataset.segment_datasets():
        signals = {
            name: (part.time, getattr(part, name))
            for name in ("rudder", "heading", "yaw_rate", "speed")
            if getattr(part, name) is not None
        }
        if part.duration >= 2 * sample_time:
            parts.append(resample_series(signals, sample_time, unwrap_heading=False))
    if not parts:
        raise DataError(
            f"{dataset.meta.get('source', 'a recording')} has no stretch of "
            f"{2 * sample_time:g} s to resample onto a {sample_time:g} s step"
        )
    return _concatenate(parts, [p.time for p in parts], dataset.gaps, dict(dataset.meta, sample_time=sample_time))


def join_recordings(
    recordings: list[Dataset], names: list[str] | None = None, sample_time: float | None = None
) -> Dataset:
    """Several recordings as one Dataset, each its own segment(s), never bridged.

    All are brought onto one grid step and laid one after another in time, two steps apart.

    Parameters
    ----------
    recordings : list of Dataset
        The recordings, in order.
    names : list of str or None
        Their names (default: each recording's ``meta["source"]``).
    sample_time : float or None
        The common grid step (s; default the first recording's).

    Returns
    -------
    Dataset
        The joined data; ``meta["recordings"]`` lists each recording as ``{"name", "start",
        "stop"}`` (sample indices, stop exclusive), a single recording too.
    """
    if not recordings:
        raise DataError("no recordings given; name at least one bag or CSV file")
    names = (
        list(names)
        if names is not None
        else [str(r.meta.get("source", f"recording {i + 1}")) for i, r in enumerate(recordings)]
    )
    if len(names) != len(recordings):
        raise ValueError(f"{len(names)} names for {len(recordings)} recordings")
    h = recordings[0].sample_time if sample_time is None else float(sample_time)
    recordings = [resampled(r, h) for r in recordings]
    times, gaps, entries, start, t0 = [], [], [], 0, float(recordings[0].time[0])
    for name, r in zip(names, recordings):
        shift = t0 - r.time[0]
        if times:
            gaps.append((float(times[-1][-1]), t0))
        times.append(r.time + shift)
        gaps += [(g0 + shift, g1 + shift) for g0, g1 in r.gaps]
        entries.append({"name": name, "start": start, "stop": start + r.n_samples})
        start += r.n_samples
        t0 = float(r.time[-1] + shift + 2 * h)
    return _concatenate(recordings, times, gaps, dict(recordings[0].meta, sample_time=h, recordings=entries))


def _concatenate(parts: list[Dataset], times: list[np.ndarray], gaps, meta: dict) -> Dataset:
    """``parts`` one after another on the given ``times`` (s), their segments kept apart; the speed
    only when every part has one."""
    segments, start = [], 0
    for part in parts:
        segments += [(a + start, b + start) for a, b in part.segments]
        start += part.n_samples

    def join(name: str) -> np.ndarray:
        return np.concatenate([getattr(p, name) for p in parts])

    speed = None if any(p.speed is None for p in parts) else join("speed")
    return Dataset(
        np.concatenate(times),
        join("rudder"),
        join("heading"),
        join("yaw_rate"),
        speed,
        tuple(segments),
        tuple(sorted(gaps)),
        meta,
    )
