"""Every estimator against known truth on simulated data, and the LS-SVM identities."""

from dataclasses import replace

import numpy as np
import pytest

from ship_ident.estimators import OutputError, make_estimator, method_names
from ship_ident.estimators.base import scaled_inverse
from ship_ident.estimators.lssvm import (
    OLS,
    lssvm_dual_bias_free,
    lssvm_dual_with_bias,
    lssvm_primal_with_bias,
    ridge_primal,
)
from ship_ident.estimators.output_error import fold_inverse
from ship_ident.estimators.shooting import ShootingProblem, normal_equations
from ship_ident.model.simulator import simulate
from ship_ident.model.structure import Structure

REGRESSIONS = ("ols", "lssvm", "rlssvm", "rwlssvm", "tlssvm")


def rel(est, truth, name):
    return abs(est.parameters[name] / truth[name] - 1)


@pytest.fixture(scope="module")
def clean():
    """Noise-free 20/20 zigzag of seed 001's vessel, h = 0.1 s (the seed-table2 data, shorter)."""
    return simulate("zigzag20", noise=0.0, duration=300.0, seed=0)


@pytest.fixture(scope="module")
def noisy():
    """Mixed manoeuvre with realistic noise: rudder 0.1 deg, heading 0.1 deg, yaw rate 0.2 deg/s."""
    return simulate("mixed", noise=1.0, duration=600.0, seed=1)


@pytest.mark.parametrize("method", REGRESSIONS)
def test_regressions_recover_gain_and_time_constant_noise_free(clean, method):
    est = make_estimator(method).fit(clean.structure, clean.dataset)
    t = clean.truth
    assert rel(est, t, "K") < 0.01 and rel(est, t, "T1") < 0.02
    if method == "lssvm":  # the bias swallows the offset's constant column: delta_r is lost (-100 %)
        assert est.parameters["delta_r"] == 0.0
    else:
        assert rel(est, t, "delta_r") < 0.01
    assert np.isfinite(est.std_errors["K"]) and np.isfinite(est.std_errors["T1"])
    assert all(np.isfinite(v) for v in est.std_errors.values()) or method == "lssvm"


@pytest.mark.parametrize("method", REGRESSIONS)
def test_regressions_recover_gain_and_time_constant_with_noise(noisy, method):
    est = make_estimator(method).fit(noisy.structure, noisy.dataset)
    assert rel(est, noisy.truth, "K") < 0.02 and rel(est, noisy.truth, "T1") < 0.03
    assert np.isfinite(est.std_errors["K"]) and est.std_errors["K"] > 0


def test_lssvm_with_bias_gives_zero_rudder_offset_exactly(clean):
    est = make_estimator("lssvm").fit(clean.structure, clean.dataset)
    assert est.parameters["delta_r"] == 0.0


def test_output_error_recovers_all_parameters_noise_free(clean):
    est = make_estimator("rwlssvm+oe").fit(clean.structure, clean.dataset)
    t = clean.truth
    for name in ("K", "T1", "delta_r"):
        assert rel(est, t, name) < 0.005, name
    assert rel(est, t, "alpha") < 0.05
    assert rel(est, t, "T2") < 0.10 and rel(est, t, "T3") < 0.10


def test_output_error_meets_noisy_targets_and_std_errors_are_finite(noisy):
    est = make_estimator("rwlssvm+oe").fit(noisy.structure, noisy.dataset)
    t, p = noisy.truth, est.parameters
    assert rel(est, t, "K") < 0.01 and rel(est, t, "T1") < 0.03 and rel(est, t, "delta_r") < 0.03
    t_eff = t["T1"] + t["T2"] - t["T3"]
    assert abs((p["T1"] + p["T2"] - p["T3"]) / t_eff - 1) < 0.02
    assert all(np.isfinite(s) and s >= 0 for s in est.std_errors.values())
    assert abs(p["K"] - t["K"]) < 4 * est.std_errors["K"]
    assert est.ok


def test_prediction_error_handles_a_noisy_rudder_sensor():
    """0.5 deg rudder noise: the innovation-whitened fit keeps K and T1 near the truth, where
    the output-error fit drifts by several percent (measured over seeds: 4.5 % against 0.5 % rms)."""
    from ship_ident.model.simulator import Noise

    sim = simulate("zigzag20", noise=Noise(rudder=np.radians(0.5)), duration=600.0, seed=200)
    pem = make_estimator("rwlssvm+pem").fit(sim.structure, sim.dataset)
    oe = make_estimator("rwlssvm+oe").fit(sim.structure, sim.dataset)
    assert rel(pem, sim.truth, "K") < 0.015 and rel(pem, sim.truth, "T1") < 0.025
    assert rel(pem, sim.truth, "K") < rel(oe, sim.truth, "K")
    assert pem.method == "rwlssvm+pem" and all(np.isfinite(v) for v in pem.std_errors.values())


@pytest.mark.parametrize("weighted", [False, True])
def test_bias_free_primal_equals_dual(weighted):
    rng = np.random.default_rng(3)
    X = rng.normal(size=(60, 5)) * [1, 10, 0.1, 3, 1]
    y = X @ rng.normal(size=5) + 0.1 * rng.normal(size=60)
    v = rng.uniform(0.1, 1.0, size=60) if weighted else None
    w_primal, _ = ridge_primal(X, y, 50.0, v)
    np.testing.assert_allclose(w_primal, lssvm_dual_bias_free(X, y, 50.0, v), rtol=1e-9, atol=1e-12)


def test_lssvm_dual_with_bias_equals_primal_and_zeroes_constant_column():
    rng = np.random.default_rng(4)
    X = np.column_stack([rng.normal(size=(50, 3)), np.ones(50)])
    y = X @ np.array([1.0, -2.0, 0.5, 3.0]) + 0.05 * rng.normal(size=50)
    w_dual, b_dual, alpha = lssvm_dual_with_bias(X, y, 100.0)
    w_primal, b_primal = lssvm_primal_with_bias(X, y, 100.0)
    np.testing.assert_allclose(w_dual, w_primal, rtol=1e-9, atol=1e-12)
    assert b_dual == pytest.approx(b_primal, rel=1e-9)
    assert abs(alpha.sum()) < 1e-10 and abs(w_dual[3]) < 1e-10


def test_tlssvm_reports_truncation_level(noisy):
    for rule in ("gcv", "lcurve", "picard"):
        est = make_estimator("tlssvm", rule=rule).fit(noisy.structure, noisy.dataset)
        assert 1 <= est.info["truncation"] <= est.info["of"] == len(est.info["columns"])


def test_rwlssvm_is_deterministic_for_a_seed(noisy):
    a = make_estimator("rwlssvm", seed=7).fit(noisy.structure, noisy.dataset)
    b = make_estimator("rwlssvm", seed=7).fit(noisy.structure, noisy.dataset)
    assert a.parameters == b.parameters


def test_rwlssvm_is_robust_to_yaw_rate_spikes(noisy):
    clean_k = make_estimator("rwlssvm").fit(noisy.structure, noisy.dataset).parameters["K"]
    rng = np.random.default_rng(5)
    yaw_rate = noisy.dataset.yaw_rate.copy()
    spikes = rng.choice(len(yaw_rate), size=len(yaw_rate) // 100, replace=False)
    yaw_rate[spikes] += 50 * np.radians(0.2) * rng.choice([-1.0, 1.0], size=len(spikes))
    spiky = replace(noisy.dataset, yaw_rate=yaw_rate)
    est = make_estimator("rwlssvm").fit(noisy.structure, spiky)
    assert abs(est.parameters["K"] / clean_k - 1) < 0.03
    assert est.info["downweighted"] > 0


def test_straight_course_is_flagged_low_excitation():
    sim = simulate("zigzag10", noise=1.0, duration=200.0, seed=2, amplitude=np.radians(0.2))
    est = make_estimator("rwlssvm").fit(Structure("nomoto2", ["rudder_offset"]), sim.dataset)
    assert "low_excitation" in est.flags and not est.ok


def test_method_names_all_build():
    for name in method_names():
        assert make_estimator(name).name == name


def test_refinement_searches_from_given_starts_and_a_regression_ignores_them(noisy):
    """One Levenberg-Marquardt step: from the truth (a given start) it ends closer to the data and
    to T2, T3 than from the least-squares start alone (biased by the yaw-rate noise; its gain and
    states polished, it starts close to the data already, so the cost gains little). A
    regression has no search: starts change nothing."""
    truth = {n: noisy.truth[n] for n in noisy.structure.parameter_names}
    cold = OutputError(OLS(), max_iterations=1).fit(noisy.structure, noisy.dataset)
    warm = OutputError(OLS(), max_iterations=1).fit(noisy.structure, noisy.dataset, starts=(truth,))
    assert warm.info["cost_ratio"] < cold.info["cost_ratio"]
    assert rel(warm, truth, "T2") < 0.5 * rel(cold, truth, "T2")
    assert rel(warm, truth, "T3") < 0.5 * rel(cold, truth, "T3")
    plain = make_estimator("rlssvm")
    far = dict(truth, K=10 * truth["K"])
    assert plain.fit(noisy.structure, noisy.dataset, starts=(far,)).parameters == (
        plain.fit(noisy.structure, noisy.dataset).parameters
    )


def test_neutral_effect_start_simulates_as_the_model_without_the_effects(clean):
    bare = Structure("nomoto2", ())
    base = {n: clean.truth[n] for n in bare.parameter_names}
    full = Structure("nomoto2", ["rudder_offset", "cubic_yaw", "wind_yaw", "rudder_delay"])
    psi_bare, r_bare = bare.simulate(base, clean.dataset)
    psi, r = full.simulate(full.neutral_effect_start(base), clean.dataset)
    assert np.max(np.abs(psi - psi_bare)) < 1e-12 and np.max(np.abs(r - r_bare)) < 1e-12


def test_rwlssvm_needs_the_sample_time_of_the_rows(noisy):
    with pytest.raises(ValueError, match="sample time"):
        make_estimator("rwlssvm").solve(np.eye(3), np.ones(3))


def test_standard_errors_keep_a_weak_direction_among_strong_ones():
    """J'J with one column 1e-9 of the others (alpha's sensitivity beside a yaw-rate state's on a
    slow ship): its inverse, scaled, matches the exact one, where a pseudo-inverse gives the weak
    direction no variance at all."""
    rng = np.random.default_rng(0)
    J = rng.normal(size=(500, 4)) * np.array([1.0, 1.0, 1.0, 1e-9])
    exact = np.linalg.inv(J.T @ J)
    assert np.allclose(scaled_inverse(J.T @ J), exact, rtol=1e-6)
    assert np.linalg.pinv(J.T @ J)[3, 3] < 1e-3 * exact[3, 3]


def test_a_slow_ship_is_shot_over_intervals_of_its_own_time_scale():
    """bench vessels' ship of seed 1820632815 (T1 66 s, 2.3x the realistic noise, 1 s steps): its
    regression start misses the time scale (T1 at 0.01 s), the search finds the hull and fits again
    on shooting intervals of 3 T1: K and T1 within 1.5 % and 2.5 % (on the default 120 s intervals,
    each restarting from its own state, they were 2.6 % and 6.4 % off here, 1.3 % and 2.8 % RMS
    over noise seeds; now 0.4 % and 0.8 %, at their standard errors)."""
    from ship_ident.bench.vessels import draw_case
    from ship_ident.model.simulator import Noise

    case = draw_case(1820632815, quick=True)
    vessel, config = case["vessel"], case["config"]
    sim = simulate(
        case["maneuver"],
        vessel,
        duration=1.5 * config.window_length,
        sample_time=config.sample_time,
        noise=Noise().scaled(case["noise"]),
        seed=1820632815,
    )
    n = int(config.window_length / config.sample_time)
    window = sim.dataset.slice(len(sim.dataset.time) - n, len(sim.dataset.time))
    est = make_estimator(config.method).fit(config.structure(), window)
    truth = sim.truth
    assert est.ok and est.info["shooting_s"] >= 0.9 * 3 * truth["T1"]
    assert est.parameters["K"] == pytest.approx(truth["K"], rel=0.015)
    assert est.parameters["T1"] == pytest.approx(truth["T1"], rel=0.025)


def test_the_covariance_on_the_fold_of_two_equal_poles_keeps_the_rest_determined():
    """Two unknowns the residuals depend on only through their sum (nomoto2's poles at T1 = T2):
    their errors are infinite, and the third unknown's variance is that of the model with the
    sum as one unknown, not rounding spread by a singular inverse."""
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=200), rng.normal(size=200)
    J = np.column_stack([a, b, b])
    inverse, free = fold_inverse(J.T @ J)
    reduced = np.linalg.inv(np.column_stack([a, b]).T @ np.column_stack([a, b]))
    assert free.tolist() == [False, True, True]
    assert inverse[0, 0] == pytest.approx(reduced[0, 0], rel=1e-9)
    full_rank, none_free = fold_inverse(np.column_stack([a, b]).T @ np.column_stack([a, b]))
    assert not none_free.any() and full_rank == pytest.approx(reduced, rel=1e-9)


def test_a_ships_long_window_sums_its_sparse_normal_equations_as_scipys_products_do():
    """A ten-minute window on 29 s shooting intervals with gaps between them (rows outside every
    interval keep explicit zeros): J'f and J'J from the compiled pass equal scipy's sparse products
    to the last bit, for a search step and for a polishing step's subset of columns."""
    sim = simulate("mixed", duration=600.0, seed=2)
    structure = Structure("nomoto2")
    problem = ShootingProblem(
        structure, sim.dataset, [(a, a + 290) for a in range(0, 5700, 300)], structure.free_names, {}
    )
    rng = np.random.default_rng(0)
    x = rng.standard_normal(problem.size)
    chosen = tuple(range(problem.n_params))
    points, steps = problem.difference_points(x, np.full(problem.n_params, np.inf), chosen)
    rows = 2 * sim.dataset.n_samples
    columns = problem.columns(np.concatenate([problem.owner, problem.owner]))
    jacobian = problem.jacobian(
        x, points, steps, rng.standard_normal((len(points), rows)), chosen, columns, sparse_matrix=True
    )
    f = rng.standard_normal(rows)
    for matrix in (jacobian, jacobian[:, [0, *range(problem.n_params, problem.size)]]):
        gradient, normal = normal_equations(matrix, f)
        assert np.array_equal(gradient, matrix.T @ f)
        assert np.array_equal(normal, (matrix.T @ matrix).toarray())
