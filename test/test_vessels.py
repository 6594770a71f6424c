"""Randomised vessels: the simulator's manoeuvres and vessel draws, fits that converge on any
vessel, and a small fixed-seed sample of ``ship-ident bench vessels`` judged against the truth."""

import numpy as np
import pytest

from ship_ident.bench import vessels
from ship_ident.bench.peers import dataset_samples
from ship_ident.estimators import make_estimator
from ship_ident.model.effects import EFFECTS
from ship_ident.model.simulator import _EFFECT_TRUTH, Noise, Vessel, random_vessel, simulate
from ship_ident.model.structure import Structure
from ship_ident.online import uncertainty
from ship_ident.online.identifier import OnlineIdentifier

pytestmark = pytest.mark.slow  # random vessels through the online schedule

STRUCTURE = Structure("nomoto2", ["rudder_offset", "cubic_yaw"])


@pytest.mark.parametrize("maneuver", ["steps", "steady_turns", "legs"])
def test_new_manoeuvres_keep_every_random_vessel_finite_and_excite_it(maneuver):
    for seed in range(4):
        vessel = random_vessel(np.random.default_rng(seed), "usv")
        sim = simulate(maneuver, vessel, duration=400.0, sample_time=0.2, seed=seed)
        assert np.all(np.isfinite(sim.true_yaw_rate)), vessel.name
        assert np.degrees(np.std(sim.true_rudder)) > 1.0, vessel.name


def test_random_vessels_hold_a_steady_turn_at_full_rudder():
    """alpha r^2 >= -0.1 at the turn rate of full rudder, so r + alpha r^3 = K delta has a stable
    root for every rudder the gear can give (the steady turn exists while -alpha (K d)^2 < 4/27)."""
    for seed in range(200):
        v = random_vessel(np.random.default_rng(seed))
        damping = v.parameters["alpha"] * (v.parameters["K"] * v.rudder_limit) ** 2
        assert -0.1 <= damping <= 0.5


def test_cubic_yaw_is_bounded_by_the_turn_rates_of_the_data():
    sim = simulate("steps", "seed001", duration=120.0, seed=3)
    r_max = np.max(np.abs(sim.dataset.yaw_rate))
    lower, upper = STRUCTURE.bounds(["K", "alpha"], sim.dataset)
    assert lower[1] == pytest.approx(-1.0 / (3.0 * r_max**2))
    assert lower[1] < sim.truth["alpha"]  # seed 001's own negative alpha stays inside
    assert upper[1] == EFFECTS["cubic_yaw"].parameters[0].upper
    assert lower[0] == STRUCTURE.parameter("K").lower  # the other bounds are the physical ones


def test_pem_fit_converges_where_t3_nearly_cancels_t2():
    """A boat of the issue's ranges (T3 close to T2: nearly first order): the default fit used to
    crawl up the T2 = T3 valley for 30 iterations and end oe_not_converged with T2 at 0.06 s;
    the rescue (a look along the valley, then a gentler search) reaches the optimum."""
    truth = dict(_EFFECT_TRUTH, K=0.1885, T1=5.131, T2=1.262, T3=1.664, T=4.729, alpha=0.0, delta_r=0.0)
    vessel = Vessel("issue", "issue-range boat", truth, seed_effects=("rudder_offset", "cubic_yaw"))
    sim = simulate("steps", vessel, duration=250.0, seed=3)
    window = sim.dataset.slice(700, 2500)
    estimate = make_estimator("rwlssvm+pem").fit(STRUCTURE, window)
    assert estimate.ok and not estimate.flags, estimate.flags
    assert abs(estimate.parameters["K"] / truth["K"] - 1) < 0.01
    assert abs(estimate.parameters["T1"] / truth["T1"] - 1) < 0.03
    assert estimate.info["iterations"] > 30  # the first 30 iterations did not converge


def _fed_identifier(seed: int, end: float, whole: bool = False):
    """The online core (the case's configuration) fed, without refits, with ``bench vessels``' case
    ``seed`` (steady) up to ``end`` (s), and the case's truth; ``whole``: the bench's own record (the
    case's duration simulated, its noise as the bench drew it), else one that ends at ``end``."""
    case = vessels.draw_case(seed, quick=True)
    sim = simulate(
        case["maneuver"],
        case["vessel"],
        duration=case["duration"] if whole else end + 1.0,
        sample_time=case["config"].sample_time,
        noise=Noise().scaled(case["noise"]),
        seed=seed,
    )
    identifier = OnlineIdentifier(case["config"])
    for sample in dataset_samples(sim.dataset):
        if sample.time <= end:
            identifier.add(sample)
    return identifier, sim.truth


def test_slow_ship_whose_yaw_rate_is_buried_in_its_noise_is_used():
    """``bench vessels`` seed 75905: a ship (K 0.083 1/s, T1 15 s, T3 5.8 s) on straight legs at 1.75x
    the realistic noise. Its yaw rate spread hardly rises above its noise, but the heading
    determines K and T1 (Cramer-Rao bound 0.4 % and 3 %). The regression start put T1 at its
    0.01 s floor, the prediction-error filter was built there, and every refit of the online core
    was refused (too_little_excitation with standard errors of 1e13, or oe_not_converged). Now the
    first refit of a full window is published OK, the truth within its 95 % intervals."""
    end = 512.0
    identifier, truth = _fed_identifier(75905, end)
    record = identifier.refit(end).to_json()
    assert record["new_estimate"] and record["status"] == "OK", record["conditions"]
    for name in ("K", "T1"):
        error = abs(record["parameters"][name] - truth[name])
        assert error <= 1.96 * record["std_errors"][name], name
    assert record["std_errors"]["K"] < 0.01 * truth["K"]


def test_a_slow_ship_search_crawling_along_its_valley_goes_on_to_the_optimum():
    """``bench vessels`` seed 3602010550: a ship (K 0.040 1/s, T1 36 s, T2 6.5 s, T3 4.3 s) on steps.
    Its cold search crawled along the T1-T2-T3-alpha valley and ended oe_not_converged after 30
    iterations (T2 3.2 s, T3 1.4 s, alpha 228): 95 of 95 refits refused. Near the noise, it now
    goes on gently and converges (48 iterations), K and T1 within 2 % of the truth."""
    identifier, truth = _fed_identifier(3602010550, 1500.0)
    window, config = identifier.window_dataset(1500.0), identifier.config
    estimate = make_estimator(config.method).fit(config.structure(), window)
    assert "oe_not_converged" not in estimate.flags and estimate.info["iterations"] > 30
    assert estimate.parameters["K"] == pytest.approx(truth["K"], rel=0.02)
    assert estimate.parameters["T1"] == pytest.approx(truth["T1"], rel=0.02)


def test_a_slow_ship_is_fitted_cold_from_a_regression_start_that_missed_it():
    """``bench vessels`` seed 315185517: a ship (K 0.103 1/s, T1 64 s, T2 8.2 s) in the mixed
    manoeuvre, its first 2000 s. The regression start has complex time constants (T1 0.04 s), and
    the starts at slow time constants lost: their gain was polished together with the rudder offset,
    whose column at a gain 15 times too small is tiny, so the step sent the offset to its bound and
    was refused. Every start-up refit of 2000 s was refused (poor_fit, cost 120 times the noise).
    The gain is now polished first, and the cold fit finds the ship."""
    identifier, truth = _fed_identifier(315185517, 2000.0, whole=True)
    window, config = identifier.window_dataset(2000.0), identifier.config
    estimate = make_estimator(config.method).fit(config.structure(), window)
    assert estimate.info["cost_ratio"] < 1.0 and "oe_not_converged" not in estimate.flags
    assert estimate.parameters["K"] == pytest.approx(truth["K"], rel=0.02)
    assert estimate.parameters["T1"] == pytest.approx(truth["T1"], rel=0.03)


def test_a_search_at_the_valley_foot_is_carried_up_the_valley_with_t2_held():
    """``bench vessels`` seed 1753784558: a ship (T1 21 s, T2 2.4 s, T3 2.9 s) in 20/20 zigzags at half
    the noise. Its cold search started with T2 near zero and crawled up the T2 = T3 valley for 90
    iterations, ending oe_not_converged at T2 0.1 s: 94 of 96 well-excited refits refused. Each
    variant along the valley is now searched with T2 held, the gain, T1 and alpha following it, and
    the search converges at the optimum."""
    identifier, truth = _fed_identifier(1753784558, 800.0, whole=True)
    window, config = identifier.window_dataset(800.0), identifier.config
    estimate = make_estimator(config.method).fit(config.structure(), window)
    assert "oe_not_converged" not in estimate.flags
    assert estimate.parameters["K"] == pytest.approx(truth["K"], rel=0.01)
    assert estimate.parameters["T1"] == pytest.approx(truth["T1"], rel=0.02)
    assert estimate.parameters["T2"] == pytest.approx(truth["T2"], rel=0.15)


def test_a_warm_start_with_a_long_rudder_lead_is_fitted_before_it_is_judged():
    """``bench vessels`` seed 3602010556: a ship (T1 29 s) on legs whose last good estimate had
    T2 7.9 s and T3 10.3 s. Started from the data's interval states (yaw acceleration 0), that
    estimate's free run sat 170 times the noise away, behind a regression start at T1 = 0.01 s,
    and the warm refit ended there. With its gain, rudder offset and states fitted first it is
    chosen, and the refit lands near the truth; the diagnosis's search (no exploring) keeps the
    old comparison."""
    identifier, truth = _fed_identifier(3602010556, 1104.5)
    window, config = identifier.window_dataset(1104.5), identifier.config
    last_good = dict(truth, K=0.0367, T1=28.95, T2=7.854, T3=10.319, delta_r=-0.0156, alpha=-31.88)
    warm = make_estimator(config.method).fit(config.structure(), window, starts=(last_good,))
    assert warm.parameters["T1"] == pytest.approx(truth["T1"], rel=0.1), warm.flags
    assert warm.parameters["K"] == pytest.approx(truth["K"], rel=0.02)
    unpolished = make_estimator(config.method, explore=False).fit(config.structure(), window, starts=(last_good,))
    assert unpolished.parameters["T1"] < 1.0  # the regression start's basin


def test_time_constants_on_the_fold_are_not_published_as_known():
    """``bench vessels`` seed 619072864: a USV whose rudder lead outruns its pole (T1 1.26 s, T2
    0.33 s, T3 2.27 s) on legs. Searches ended on the fold T1 = T2 = 0.68 s, where only their sum and
    product are determined, and T1 was published OK with +- 1 % (48 % off). The fit now says
    repeated_time_constants with infinite errors, and the online core keeps no such estimate."""
    identifier, truth = _fed_identifier(619072864, 150.0)
    window, config = identifier.window_dataset(150.0), identifier.config
    estimate = make_estimator(config.method).fit(config.structure(), window)
    assert "repeated_time_constants" in estimate.flags
    assert estimate.parameters["T1"] == pytest.approx(estimate.parameters["T2"], rel=0.01)
    assert estimate.std_errors["T1"] == estimate.std_errors["T2"] == float("inf")
    record = identifier.refit(150.0)
    assert not record.new_estimate and "repeated_time_constants" in record.verdicts["poor_fit"].figures["at_bounds"]


def test_the_larger_time_constant_is_reported_as_T1():
    """``bench vessels`` seed 619072891 (a USV with T1 1.44 s, T2 0.42 s, T3 1.99 s in steady turns):
    warm refits from an estimate with the two time constants the other way round (T1 0.42 s, T2
    1.48 s) stayed so, and T1 = 0.42 s was published OK. The model is symmetric in them; the fit
    reports T1 >= T2."""
    identifier, truth = _fed_identifier(619072891, 120.0)
    window, config = identifier.window_dataset(120.0), identifier.config
    swapped = dict(truth, K=0.1607, T1=0.4197, T2=1.48, T3=1.998, delta_r=-0.001, alpha=34.4)
    estimate = make_estimator(config.method).fit(config.structure(), window, starts=(swapped,))
    assert estimate.parameters["T1"] == pytest.approx(truth["T1"], rel=0.1)
    assert estimate.parameters["T2"] == pytest.approx(truth["T2"], rel=0.2)


def test_t1_is_published_with_its_slide_along_the_t2_t3_valley():
    """When the second pole T2 cannot be told from zero, T1 is published with its slide along the
    T2 = T3 valley, read off the cost's profile over T2 (T2 held at its floor and at 10-50 % of T1,
    T3 moved with it, every point weighed alike). ``bench vessels`` seed 128754784 (T1 1.15 s, T2
    0.27 s, T3 0.60 s) at 100 s: T1 1.04 s with T2 0.01 +- 0.11 s, and the cost hardly rises up to
    T2 = 0.36 s, where T1 is 1.38 s: T1 is known to a third and covers the truth. Seed 2903470093
    (T2 0.42 s, T3 0.44 s: pole and zero cancel): T2 0.01 +- 0.24 s, but T1 moves by 1 % up to T2 =
    2.2 s and keeps its own error. A window that determines T2 keeps T1's error."""
    from ship_ident.online.uncertainty import first_order_valley

    for seed, end, least, most in ((128754784, 100.0, 0.15, 0.5), (2903470093, 300.0, 0.0, 0.01)):
        identifier, truth = _fed_identifier(seed, end, whole=True)
        window, config = identifier.window_dataset(end), identifier.config
        estimator, structure = make_estimator(config.method), config.structure()
        estimate = estimator.fit(structure, window)
        errors = estimate.std_errors
        assert 1.96 * errors["T2"] > estimate.parameters["T2"], seed  # T2 cannot be told from zero
        valley = first_order_valley(estimate, errors, estimator, structure, window)
        t1, s_t1 = estimate.parameters["T1"], valley["T1"]
        assert least < s_t1 / t1 < most, (seed, s_t1)
        assert abs(t1 - truth["T1"]) < 1.96 * s_t1, seed
        assert {k: v for k, v in valley.items() if k != "T1"} == {k: v for k, v in errors.items() if k != "T1"}
        determined = dict(errors, T2=0.1 * estimate.parameters["T2"])
        assert first_order_valley(estimate, determined, estimator, structure, window) == determined


def test_t1_far_up_the_valley_from_its_t2_interval_is_not_published_as_known():
    """``bench vessels`` seed 128754784 at 485 s, warm from the estimate in force: T1 0.97 +- 0.04 s,
    T2 0.12 +- 0.08 s (truth 1.15 s, 0.27 s). The online core published T1 17 % off as OK here at
    +- 3.7 %: T2's 95 % end alone, the one point it held, moved T1 by a few per cent. Along the
    profile T1 reaches 1.11 s within the 95 % region and 1.33 s at 3 standard errors: T1 is
    published to about 12 %, which covers the truth."""
    from ship_ident.online.uncertainty import first_order_valley

    identifier, truth = _fed_identifier(128754784, 485.0, whole=True)
    window, config = identifier.window_dataset(485.0), identifier.config
    estimator, structure = make_estimator(config.method), config.structure()
    in_force = dict(K=0.1534, T1=0.948, T2=0.0439, T3=0.2099, delta_r=0.02408, alpha=16.46)
    estimate = estimator.fit(structure, window, starts=(in_force,))
    t1 = estimate.parameters["T1"]
    assert abs(t1 - truth["T1"]) > 0.1 * truth["T1"]  # the window's estimate is 15 % off
    assert estimate.std_errors["T1"] < 0.05 * t1  # at 4 % of its own error
    s_t1 = first_order_valley(estimate, estimate.std_errors, estimator, structure, window)["T1"]
    assert 0.08 < s_t1 / t1 < 0.2 and abs(t1 - truth["T1"]) < 1.96 * s_t1


def test_k_and_t1_are_published_with_their_slide_along_the_cubic_damping():
    """``bench vessels`` seed 3133699670 (a ship, T1 75 s, alpha 26.5, 20/20 zigzag at 2.3x the
    realistic noise): the first full window (0-1800 s) gives alpha 150 +- 43 with K 5.8 % and T1
    7.5 % off at +- 2.1 % and 3.1 %; online, T1 11 % off was published OK at +- 3.4 %. The cost
    hardly rises towards a larger damping, which a larger gain and a slower hull make up for: along
    alpha's profile K is known to about 4 % and T1 to about 7 %, which cover the truth."""
    from ship_ident.estimators.base import TRUSTED_RELATIVE_ERRORS
    from ship_ident.online.uncertainty import cubic_damping_slides

    identifier, truth = _fed_identifier(3133699670, 1800.0, whole=True)
    window, config = identifier.window_dataset(1800.0), identifier.config
    estimator, structure = make_estimator(config.method), config.structure()
    estimate = estimator.fit(structure, window, starts=(truth,))
    parameters, errors = estimate.parameters, estimate.std_errors
    assert errors["T1"] < TRUSTED_RELATIVE_ERRORS["T1"] * parameters["T1"]  # trusted on its own errors
    assert abs(parameters["T1"] / truth["T1"] - 1) > 0.05
    slid = cubic_damping_slides(estimate, errors, estimator, structure, window)
    for name in ("K", "T1"):
        assert slid[name] > 1.5 * errors[name], name
        assert abs(parameters[name] - truth[name]) < 1.96 * slid[name], name
    assert slid["T1"] > TRUSTED_RELATIVE_ERRORS["T1"] * parameters["T1"]
    assert {k: v for k, v in slid.items() if k not in ("K", "T1")} == {
        k: v for k, v in errors.items() if k not in ("K", "T1")
    }


def test_a_start_up_window_is_checked_along_the_cubic_damping(monkeypatch):
    """``bench vessels`` seed 3309800875 (a USV in steady turns at 2.6x the realistic noise): the first
    110 s window puts T1 11 % low at +- 2.6 %, with the cubic damping far off (alpha -9.7 +- 2.2 for a
    true -1.0). A start-up window is trusted at the full limits, but checked along alpha from half of
    them: T1 slides along it, and is published WARN at +- 5 % (the truth 2.6 of its errors away, not
    4.9). Checked only from 3/4 of the limits, as a full window is, it was published OK."""
    identifier, truth = _fed_identifier(3309800875, 110.0, whole=True)
    refit = identifier.refit(110.0)
    record = refit.to_json()
    t1, t1_error = record["parameters"]["T1"], record["std_errors"]["T1"]
    assert abs(t1 / truth["T1"] - 1) > 0.08
    assert record["new_estimate"] and record["status"] == "WARN", record["conditions"]
    assert refit.verdicts["uncertain_estimate"].figures["loose"] == ["T1"]
    assert abs(t1 - truth["T1"]) < 3.0 * t1_error
    monkeypatch.setattr(uncertainty, "START_UP_ALPHA_CHECK_SHARE", uncertainty.ALPHA_CHECK_SHARE)
    identifier, truth = _fed_identifier(3309800875, 110.0, whole=True)
    unchecked = identifier.refit(110.0).to_json()
    assert unchecked["status"] == "OK", unchecked["conditions"]
    assert unchecked["std_errors"]["T1"] < 0.04 * unchecked["parameters"]["T1"]


def test_a_start_up_window_at_the_foot_of_the_valley_publishes_t1_with_its_slide():
    """``bench vessels`` seed 315185512 (a USV with T1 5.13 s, T2 1.39 s, T3 1.52 s, zigzag 10/10): the
    first 65 s window ends at T2 0.01 +- 0.26 s with T1 12 % off, and T1 slides only 1.7 % along the
    valley to T2's 95 % end. The profile up the valley (T2 up to half of T1) moves it further: T1 is
    published with an error that covers the truth, as WARN."""
    identifier, truth = _fed_identifier(315185512, 65.0, whole=True)
    refit = identifier.refit(65.0)
    record = refit.to_json()
    assert record["new_estimate"] and record["status"] == "WARN", record["conditions"]
    assert "T1" in refit.verdicts["uncertain_estimate"].figures["loose"]
    assert abs(record["parameters"]["T1"] - truth["T1"]) < 1.96 * record["std_errors"]["T1"]


def test_ship_configuration_follows_the_hull():
    ship = random_vessel(np.random.default_rng(5), "ship")
    config = vessels.config_for(ship)
    assert config.window_length == pytest.approx(min(30 * ship.parameters["T1"], 1800.0))
    assert config.refit_period == pytest.approx(config.window_length / 36)
    assert config.gap_threshold >= config.sample_time
    assert vessels.config_for(random_vessel(np.random.default_rng(0), "usv")) == vessels.DEFAULTS


def test_a_step_case_counts_for_recovery_when_its_new_data_determine_k():
    """Only windows a full window after the change see the new hull alone; one whose Cramer-Rao
    bound puts K within half the 3 % the node trusts determines the new gain (bench vessels seed
    2903470081: every bound 8-9 %, the case has no recovery time)."""
    case = {"change_time": 270.0, "window_s": 180.0, "refits": []}
    for time, k_bound in ((300.0, 0.01), (455.0, 0.016), (460.0, None)):
        crb = None if k_bound is None else {"K": k_bound, "T1": 0.3}
        case["refits"].append({"time": time, "crb": crb})
    assert not vessels.determined_after_change(case)  # 300 s is before the new data fill a window
    case["refits"][1]["crb"]["K"] = 0.014
    assert vessels.determined_after_change(case)


def test_a_window_whose_lead_can_cancel_either_pole_is_not_counted_as_well_excited():
    """``bench vessels`` seed 1764177411 (a USV with T2 1.16 s, T3 1.23 s in steady turns): at 120 s
    the window's Cramer-Rao bound puts T1 within 0.6 %, but the lead that cancels the fast pole can
    cancel the slow one instead, and T1 held 10 % either side of the truth fits as well (chi2 rise
    about 0.1): the window does not determine T1, and its refused refits are not counted as
    rejected well-excited ones. On a hull without that valley (seed 1764177390, steps) the same
    profile rises far past the 95 % region (chi2 58 and 65)."""
    identifier, truth = _fed_identifier(1764177411, 120.0, whole=True)
    assert vessels._t1_profile_rise(identifier, 120.0, truth) < vessels.WELL_EXCITED_PROFILE_RISE
    identifier, truth = _fed_identifier(1764177390, 150.0, whole=True)
    assert vessels._t1_profile_rise(identifier, 150.0, truth) > 25.0
    crb = {"K": 0.004, "T1": 0.006}
    assert vessels.well_excited({"crb": crb, "t1_profile_rise": None})  # a step case: the bound alone
    assert not vessels.well_excited({"crb": crb, "t1_profile_rise": 0.1})


def test_bench_vessels_fixed_seed_sample_against_the_truth():
    """Two USVs, quick runs (three windows): a steady one and one whose K falls 30 % mid-run."""
    cases = [vessels.run_case(seed, quick=True) for seed in (1007, 1000)]
    steady, step = cases
    assert not steady["step"] and step["step"]
    summary = vessels.summarise(cases)
    assert summary["steady"]["K"]["share_off"] == 0.0 and summary["steady"]["K"]["worst_percent"] < 10
    assert summary["steady"]["T1"]["worst_percent"] < 10
    assert summary["well_excited"]["refits"] > 50 and summary["well_excited"]["share_rejected"] <= 0.05
    assert summary["coverage"]["K"] > 0.8
    assert summary["recovery"]["worst_s"] <= step["window_s"] + step["refit_period_s"]
    assert summary["false_changes_per_hour"] == 0.0
    assert summary["recovery"]["quick_hull_cases"] == 1 and summary["recovery"]["undetermined_seeds"] == []
    assert summary["recovery"]["quick_hull_median_s"] == summary["recovery"]["median_s"]
    # the K followed after the step, published WARN, is covered by its interval (62 % before its errors
    # carried the held hull's)
    assert summary["recovery"]["followed_refits"] > 50 and summary["recovery"]["followed_coverage"]["K"] > 0.9
    brief = vessels._brief(steady)
    assert len(brief["refits"]) == len(steady["refits"])
    assert sum(r["well_excited"] for r in brief["refits"]) == sum(map(vessels.well_excited, steady["refits"]))
    text = vessels.render(
        {
            "summary": summary,
            "cases": [vessels._brief(c) for c in cases],
            "well_excited_crb": vessels.WELL_EXCITED,
            "seed": 1000,
        }
    )
    assert "seed 1007 usv(" in text and "95 % coverage" in text
