"""The rudder-noise model: its Kalman innovations are white on real simulated records, the
Cramer-Rao bound that carries it, and the prediction-error estimator that reaches that bound."""

import numpy as np
import pytest

from ship_ident.bench.crb import cramer_rao_bound
from ship_ident.estimators import make_estimator
from ship_ident.estimators.base import fit_substeps
from ship_ident.estimators.innovations import innovation_filter, noise_model
from ship_ident.model.dataset import Dataset
from ship_ident.model.simulator import Noise, simulate
from ship_ident.model.structure import Structure

NOISE = Noise()


def true_rudder_record(sim) -> Dataset:
    d = sim.dataset
    return Dataset(
        time=d.time, rudder=sim.true_rudder, heading=sim.true_heading, yaw_rate=sim.true_yaw_rate, meta=d.meta
    )


def test_innovations_of_a_free_run_on_the_noisy_rudder_are_white():
    """The simulator's hull (fine step, true rudder) against our free run on the measured rudder:
    the error is a coloured walk; the filter of the true model whitens it to unit variance."""
    sim = simulate("zigzag20", noise=NOISE, duration=600.0, seed=3)
    h, truth = sim.dataset.sample_time, sim.truth
    psi, r = sim.structure.simulate(truth, sim.dataset, initial=[(0.0, 0.0, 0.0)], substeps=fit_substeps(h, truth))
    errors = np.column_stack([sim.dataset.heading - psi, sim.dataset.yaw_rate - r])
    kalman = innovation_filter(
        noise_model(Structure("nomoto2"), truth, h, fit_substeps(h, truth), NOISE.rudder, NOISE.heading, NOISE.yaw_rate)
    )
    white = kalman.whiten(errors)
    assert np.std(errors[:, 0]) > 1.3 * NOISE.heading  # the rudder-noise walk is there
    np.testing.assert_allclose(white.var(axis=0), 1.0, atol=0.06)
    for i in range(2):
        assert abs(np.corrcoef(white[:-1, i], white[1:, i])[0, 1]) < 0.05
        assert abs(np.corrcoef(white[:-20, i], white[20:, i])[0, 1]) < 0.05


def test_the_runs_of_a_jacobian_are_whitened_together_to_the_same_numbers():
    """Several free runs' errors whitened in one call (two at a time, interleaved) give every run
    the very residual vector it gets alone, block by block, odd run included."""
    sim = simulate("zigzag20", noise=NOISE, duration=120.0, seed=3)
    h, truth = sim.dataset.sample_time, sim.truth
    kalman = innovation_filter(
        noise_model(Structure("nomoto2"), truth, h, fit_substeps(h, truth), NOISE.rudder, NOISE.heading, NOISE.yaw_rate)
    )
    runs = [dict(truth, K=truth["K"] * (1 + 0.01 * k)) for k in range(5)]
    psi, r = sim.structure.simulate_runs(runs, sim.dataset)
    heading_errors, yaw_rate_errors = psi - sim.dataset.heading, r - sim.dataset.yaw_rate
    n = sim.dataset.n_samples
    blocks = np.array([[0, n // 3], [n // 3, n]], dtype=np.int64)
    together = kalman.whiten_blocks_rows(heading_errors, yaw_rate_errors, blocks)
    alone = [kalman.whiten_blocks(heading_errors[k], yaw_rate_errors[k], blocks) for k in range(5)]
    assert together.shape == (5, 2 * n)
    assert all(np.array_equal(together[k], alone[k]) for k in range(5))
    assert len({float(row[n // 2]) for row in together}) == 5  # the runs differ


def test_bound_with_rudder_noise_tends_to_the_known_rudder_bound():
    sim = simulate("zigzag20", noise=0.0, duration=300.0, seed=0)
    exact = true_rudder_record(sim)
    args = (sim.structure, sim.truth, exact, [(0.0, 0.0, 0.0)], NOISE.heading, NOISE.yaw_rate)
    known = cramer_rao_bound(*args)
    tiny = cramer_rao_bound(*args, rudder_noise=1e-7)
    noisy = cramer_rao_bound(*args, rudder_noise=NOISE.rudder)
    for name in known:
        assert tiny[name] == pytest.approx(known[name], rel=1e-3), name
        assert noisy[name] > known[name], name
    assert noisy["delta_r"] > 1.3 * known["delta_r"]  # the offset competes with the rudder noise most


@pytest.mark.slow
def test_prediction_error_reaches_the_bound_with_a_noisy_rudder():
    """12 noise seeds of a 180 s 20/20 zigzag (rudder 0.1 deg): the prediction-error refinement is
    within 1.3x of the bound on K and on T1+T2-T3, the output-error one is not (it is biased; measured
    RMS/CRB: +pem 0.91 on K, 0.88 on T1+T2-T3; +oe 1.60 and 1.55)."""
    quantities = ("K", "T1+T2-T3")
    errors = {m: {q: [] for q in quantities} for m in ("rwlssvm+pem", "rwlssvm+oe")}
    bounds = {q: [] for q in quantities}
    for seed in range(12):
        sim = simulate("zigzag20", noise=NOISE, duration=180.0, seed=1000 + seed)
        b = cramer_rao_bound(
            sim.structure,
            sim.truth,
            true_rudder_record(sim),
            [(0.0, 0.0, 0.0)],
            NOISE.heading,
            NOISE.yaw_rate,
            NOISE.rudder,
        )
        truth = with_time_constant(sim.truth)
        for q in quantities:
            bounds[q].append(b[q])
        for method, by_quantity in errors.items():
            found = with_time_constant(make_estimator(method).fit(sim.structure, sim.dataset).parameters)
            for q in quantities:
                by_quantity[q].append(found[q] - truth[q])
    rms = {
        m: {q: float(np.sqrt(np.mean(np.square(e[q])) / np.mean(np.square(bounds[q])))) for q in quantities}
        for m, e in errors.items()
    }
    print("RMS error / CRB:", rms)
    for q in quantities:
        assert rms["rwlssvm+pem"][q] < 1.3 < rms["rwlssvm+oe"][q], (q, rms)


def with_time_constant(parameters: dict) -> dict:
    """The parameters with T1+T2-T3 (s), the first-order equivalent time constant."""
    return dict(parameters, **{"T1+T2-T3": parameters["T1"] + parameters["T2"] - parameters["T3"]})


def test_noise_model_without_rudder_noise_is_plain_weighting():
    sim = simulate("zigzag20", noise=0.0, duration=60.0, seed=0)
    model = noise_model(Structure("nomoto2"), sim.truth, 0.1, 2, 0.0, NOISE.heading, NOISE.yaw_rate)
    errors = np.random.default_rng(0).normal(size=(500, 2)) * [NOISE.heading, NOISE.yaw_rate]
    np.testing.assert_allclose(
        innovation_filter(model).whiten(errors), errors / [NOISE.heading, NOISE.yaw_rate], rtol=1e-6
    )
