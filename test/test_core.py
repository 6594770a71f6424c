"""The numeric core against exact solutions: integrator, resampling, structure."""

from dataclasses import replace

import numpy as np
import pytest
from scipy import signal

from ship_ident.model import structure as structure_module
from ship_ident.model.dataset import DataError, Dataset, cut_segments, median_above, resample_series
from ship_ident.model.filters import convolve_columns, savgol
from ship_ident.model.simulator import simulate
from ship_ident.model.structure import Structure, StructureError


def _dataset(time, rudder):
    zeros = np.zeros_like(time)
    return Dataset(time=time, rudder=rudder, heading=zeros, yaw_rate=zeros)


def test_nomoto1_step_response_matches_closed_form():
    h, K, T, delta = 0.1, 0.4, 3.0, np.radians(10)
    time = np.arange(0, 30, h)
    rudder = np.full_like(time, delta)
    psi, r = Structure("nomoto1").simulate({"K": K, "T": T}, _dataset(time, rudder))
    exact_r = K * delta * (1 - np.exp(-time / T))
    exact_psi = K * delta * (time - T * (1 - np.exp(-time / T)))
    assert np.max(np.abs(r - exact_r)) < 1e-9
    assert np.max(np.abs(psi - exact_psi)) < 1e-8


def test_nomoto2_matches_lti_simulation_with_first_order_hold():
    h = 0.1
    p = {"K": 0.5883, "T1": 1.4397, "T2": 0.1202, "T3": 0.0440}
    time = np.arange(0, 60, h)
    rudder = np.radians(20) * np.sin(0.4 * time) * (time > 2)
    _, r = Structure("nomoto2").simulate(p, _dataset(time, rudder))
    system = signal.lti([p["K"] * p["T3"], p["K"]], [p["T1"] * p["T2"], p["T1"] + p["T2"], 1.0])
    fine = np.arange(0, 60 - h + 1e-9, 0.001)
    _, r_exact, _ = signal.lsim(system, np.interp(fine, time, rudder), fine)
    assert np.max(np.abs(r[:-1] - np.interp(time[:-1], fine, r_exact))) < 2e-5 * np.max(np.abs(r))


def test_a_slow_ships_pole_the_samples_cannot_resolve_is_stepped_exactly(monkeypatch):
    """A slow ship with a rudder offset (no forcing term: linear in its state), its fast pole 10 ms
    at 0.37 s samples (RK4 would need 56 substeps per sample): one exact step per sample, equal to
    scipy's lsim with the rudder linear between samples at rounding level, and to RK4's many
    substeps; a course-unstable run that blows up is NaN from there on."""
    h = 0.37
    time = np.arange(0, 600, h)
    rudder = np.radians(10) * np.sign(np.sin(0.05 * time))
    data = _dataset(time, rudder)
    p = {"K": 0.06, "T1": 20.0, "T2": 0.01, "T3": 0.5, "delta_r": 0.01}
    offset = Structure("nomoto2", ["rudder_offset"])
    start = [(0.0, 0.0, p["K"] * p["T3"] * p["delta_r"] / (p["T1"] * p["T2"]))]  # lsim's zero state under the offset
    _, r = offset.simulate(p, data, initial=start)
    system = signal.lti([p["K"] * p["T3"], p["K"]], [p["T1"] * p["T2"], p["T1"] + p["T2"], 1.0])
    _, r_lsim, _ = signal.lsim(system, rudder + p["delta_r"], time)
    assert np.max(np.abs(r - r_lsim)) < 1e-9 * np.max(np.abs(r))
    _, r_runs = offset.simulate_runs([p, dict(p, T1=-20.0)], data)
    blown = np.flatnonzero(np.isnan(r_runs[1]))
    assert 0 < blown[0] and blown[-1] == len(time) - 1 and np.all(np.diff(blown) == 1)
    monkeypatch.setattr(structure_module, "EXACT_STEP_SUBSTEPS", 10**9)  # RK4 from here on
    _, r_rk4 = offset.simulate(p, data, initial=start)
    assert np.max(np.abs(r - r_rk4)) < 1e-9 * np.max(np.abs(r))
    _, r_runs_rk4 = offset.simulate_runs([p, dict(p, T1=-20.0)], data)
    assert abs(np.flatnonzero(np.isnan(r_runs_rk4[1]))[0] - blown[0]) <= 1


def test_runs_side_by_side_equal_one_run_per_segment():
    """The vector path (several runs and segments as lanes) against the scalar one (one lane per call),
    with forcing terms of every kind, and a run that blows up: NaN from the same sample on."""
    sim = simulate("mixed", "seed001", effects=["rudder_offset", "cubic_yaw", "wind_yaw"], duration=120, seed=2)
    data, structure = sim.dataset, Structure("nomoto2", ["rudder_offset", "cubic_yaw", "wind_yaw"])
    shots = replace(data, segments=((0, 300), (300, 700), (700, 701), (701, data.n_samples)))
    truth = {n: sim.truth[n] for n in structure.parameter_names}
    runs = [truth, dict(truth, K=0.8, T2=0.3, alpha=-0.5), dict(truth, alpha=-3000.0)]
    initials = [
        [(data.heading[a], data.yaw_rate[a] + 0.01 * k, 0.002 * k) for a, _ in shots.segments] for k in range(len(runs))
    ]
    psi, r = structure.simulate_runs(runs, shots, initials, substeps=3)
    for params, initial, psi_run, r_run in zip(runs, initials, psi, r):
        for (a, b), state in zip(shots.segments, initial):
            alone = replace(data, segments=((a, b),))
            psi_one, r_one = structure.simulate(params, alone, initial=[state], substeps=3)
            np.testing.assert_allclose(psi_run[a:b], psi_one[a:b], rtol=1e-9, atol=1e-12)  # NaN included
            np.testing.assert_allclose(r_run[a:b], r_one[a:b], rtol=1e-9, atol=1e-12)
    blown = np.flatnonzero(np.isnan(psi[2, 701:]))
    assert 0 < blown[0] and np.all(np.diff(blown) == 1) and blown[-1] == data.n_samples - 702
    assert not np.any(np.isnan(psi[:2]))


def test_simulated_heading_is_wrapped_but_dataset_unwrapped():
    sim = simulate("turning", "seed001", duration=120, noise=0.0)
    wrapped = sim.dataset.meta["wrapped_heading"]
    assert np.all(wrapped <= np.pi) and np.all(wrapped > -np.pi)
    assert np.ptp(sim.dataset.heading) > 2 * np.pi  # a turning circle goes round
    assert np.allclose(np.mod(sim.dataset.heading - wrapped + np.pi, 2 * np.pi) - np.pi, 0, atol=1e-9)


def test_simulator_noise_levels_are_as_configured():
    clean = simulate("random", "seed001", duration=300, noise=0.0, seed=3)
    noisy = simulate("random", "seed001", duration=300, noise=1.0, seed=3)
    assert np.std(noisy.dataset.yaw_rate - clean.dataset.yaw_rate) == pytest.approx(np.radians(0.2), rel=0.05)
    assert np.std(noisy.dataset.rudder - clean.dataset.rudder) == pytest.approx(np.radians(0.1), rel=0.05)


def test_rudder_is_rate_limited_and_saturated():
    sim = simulate("zigzag20", "seed001", duration=120, noise=0.0)
    rate = np.abs(np.diff(sim.true_rudder)) / 0.1
    assert rate.max() <= np.radians(20.0) + 1e-9
    assert np.abs(sim.true_rudder).max() <= np.radians(35.0) + 1e-12
    assert np.abs(sim.true_rudder).max() == pytest.approx(np.radians(20.0), abs=1e-9)


def test_resample_splits_gaps_sorts_and_unwraps():
    t = np.arange(0, 100, 0.05)
    keep = (t < 40) | (t > 50)  # a 10 s dropout of the yaw rate
    heading = np.mod(0.2 * t + np.pi, 2 * np.pi) - np.pi
    series = {
        "rudder": (t[::-1], np.sin(t)[::-1]),  # out of order
        "heading": (np.concatenate([t, t[:5]]), np.concatenate([heading, heading[:5]])),  # duplicates
        "yaw_rate": (t[keep], np.full(keep.sum(), 0.2)),
    }
    ds = resample_series(series, 0.1)
    assert len(ds.segments) == 2
    assert len(ds.gaps) == 1 and ds.gaps[0][0] == pytest.approx(39.95) and ds.gaps[0][1] == pytest.approx(50.05)
    assert not np.any((ds.time > 40) & (ds.time < 50))
    assert np.allclose(np.diff(ds.heading[ds.segments[0][0] : ds.segments[0][1]]), 0.02, atol=1e-9)
    assert np.allclose(ds.rudder, np.sin(ds.time), atol=2e-3)


def test_a_signal_sampled_faster_than_the_grid_is_averaged_over_each_step():
    """10 Hz samples on a 1 s grid: each grid value is the mean over its step, so white noise falls
    by sqrt(10) (interpolation keeps one sample in ten and all its noise); a ramp stays exact to
    the grid's ends; a signal sampled at the grid's own rate is interpolated, not smoothed."""
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 600.0, 0.1)
    slow = 0.3 * np.sin(0.05 * t)
    series = {
        "rudder": (t, slow + 0.01 * rng.standard_normal(len(t))),
        "heading": (t, 0.02 * t),
        "yaw_rate": (t[::10], slow[::10]),
    }
    ds = resample_series(series, 1.0)
    truth = 0.3 * np.sin(0.05 * ds.time)
    assert np.std(ds.rudder - truth) == pytest.approx(0.01 / np.sqrt(10), rel=0.1)
    assert np.allclose(ds.heading, 0.02 * ds.time, atol=1e-12)
    assert np.allclose(ds.yaw_rate, truth, atol=1e-12)


def test_median_above_a_threshold_is_counted_as_the_median_decides_it():
    """Stamp steps of 0.05 s and 0.1 s against half a 0.1 s grid step, odd and even counts, the two
    middle values of an even count either side of it or on it: the count decides as the median does."""
    rng = np.random.default_rng(11)
    for _ in range(2000):
        steps = rng.choice([0.05, 0.0999, 0.1, 0.2], size=rng.integers(1, 9))
        for threshold in (0.05, 0.1, float(rng.choice(steps))):
            assert median_above(steps, threshold) == (np.median(steps) > threshold), (steps, threshold)


def test_resample_rejects_nonoverlapping_and_missing_signals():
    t = np.arange(0, 10, 0.1)
    with pytest.raises(DataError, match="no usable yaw_rate"):
        resample_series({"rudder": (t, t), "heading": (t, t), "yaw_rate": (t[:1], t[:1])}, 0.1)
    with pytest.raises(DataError, match="do not overlap"):
        resample_series({"rudder": (t, t), "heading": (t + 100, t), "yaw_rate": (t, t)}, 0.1)


def test_structure_rejects_unknown_names_and_lists_parameters():
    with pytest.raises(StructureError, match="unknown effect 'wind'"):
        Structure("nomoto2", ["wind"])
    with pytest.raises(StructureError, match="unknown model"):
        Structure("nomoto3")
    s = Structure("nomoto2", "rudder_offset,cubic_yaw")
    assert s.parameter_names == ["K", "T1", "T2", "T3", "delta_r", "alpha"]
    assert Structure("nomoto1", ["speed_dependence"]).fixed_names == ["U_ref"]


def test_parameter_change_midway_keeps_motion_continuous():
    sim = simulate(
        "random", "seed001", duration=200, noise=0.0, seed=4, change=(100.0, {"K": 0.5883 * 0.7, "T1": 1.4397 * 1.3})
    )
    r = sim.true_yaw_rate
    i = 1000
    assert abs(r[i + 1] - r[i]) < 5 * np.median(np.abs(np.diff(r))) + 1e-3
    assert sim.info["truth_after"]["K"] == pytest.approx(0.5883 * 0.7)
    # before the change the motion is the old vessel's; 20 s (14 T1) after it, the new vessel's
    # (the yaw rate forgets its start), and no longer the old one's
    held = simulate("random", "seed001", duration=200, noise=0.0, seed=4)
    new = simulate("random", "seed001", duration=200, noise=0.0, seed=4, parameters=sim.info["truth_after"])
    assert np.allclose(r[:i], held.true_yaw_rate[:i])
    settled = slice(i + 200, None)
    assert np.max(np.abs(r[settled] - new.true_yaw_rate[settled])) < 1e-4  # rad/s
    assert np.max(np.abs(r[settled] - held.true_yaw_rate[settled])) > 0.01  # rad/s: the gain fell 30 %


def test_segments_are_cut_into_near_equal_or_whole_pieces_that_never_cross_a_gap():
    segments = ((0, 100), (120, 125))
    assert cut_segments(segments, 30) == ((0, 33), (33, 67), (67, 100), (120, 125))
    assert cut_segments(segments, 30, min_samples=6) == ((0, 33), (33, 67), (67, 100))
    assert cut_segments(segments, 30, align="start", whole=True) == ((0, 30), (30, 60), (60, 90))
    assert cut_segments(segments, 30, align="start", offset=15, whole=True) == ((15, 45), (45, 75))
    assert cut_segments(segments, 30, align="start") == ((0, 30), (30, 60), (60, 90), (90, 100), (120, 125))
    # the newest piece of each segment is whole, the first one shorter
    assert cut_segments(segments, 30, align="end") == ((0, 10), (10, 40), (40, 70), (70, 100), (120, 125))
    assert cut_segments(segments, 30, min_samples=6, align="end") == ((0, 10), (10, 40), (40, 70), (70, 100))
    assert cut_segments(segments, 30, align="end", whole=True) == ((10, 40), (40, 70), (70, 100))


@pytest.mark.parametrize("deriv", [0, 1, 2])
def test_savitzky_golay_is_exact_on_a_polynomial_of_its_degree_to_both_ends(deriv):
    """A quartic sampled every 0.1 s: the degree-4 filter returns it, or its derivatives, exactly,
    inside and within half a window of either end."""
    h = 0.1
    t = np.arange(200) * h
    coefficients = np.array([0.002, -0.03, 0.1, 0.5, -1.0])  # t^4 .. t^0
    polynomial = np.polyder(coefficients, deriv) if deriv else coefficients
    assert savgol(np.polyval(coefficients, t), 21, 4, deriv, h) == pytest.approx(np.polyval(polynomial, t), abs=1e-8)


@pytest.mark.parametrize("taps", [5, 601])
def test_centred_convolution_of_columns_matches_the_sum_over_the_taps(taps):
    """Short kernels directly, long ones through the FFT: each output sample is the sum of the taps
    times the samples they cover (zeros beyond the ends), for columns shorter than the kernel too."""
    rng = np.random.default_rng(5)
    kernel = rng.standard_normal(taps)
    for rows in (40, 1000):
        signals = rng.standard_normal((rows, 3))
        half = taps // 2
        padded = np.vstack([np.zeros((half, 3)), signals, np.zeros((half, 3))])
        expected = np.array([kernel[::-1] @ padded[k : k + taps] for k in range(rows)])
        assert convolve_columns(signals, kernel) == pytest.approx(expected, abs=1e-9)
