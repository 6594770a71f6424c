"""A fixed-seed sample of ``ship-ident bench hidden-effects``: effects hidden on random vessels."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from ship_ident.bench.hidden_effects import best_base_errors, draw_case, run_case, true_improvement
from ship_ident.diagnosis.damping_law import damping_law
from ship_ident.diagnosis.diagnose import DEFAULT_METHOD, diagnose, free_run, split, undetermined, windows
from ship_ident.estimators import make_estimator
from ship_ident.model.simulator import Vessel, simulate
from ship_ident.model.structure import Structure, nomoto_parameters

pytestmark = pytest.mark.slow  # each case simulates and diagnoses a whole recording

# (case seed, hidden effects): USVs drawn by simulator.random_vessel, replayable by seed
CASES = [(1469265226, ("rudder_offset",)), (644602188, ("wind_yaw",)), (1753345572, ("speed_dependence",))]


@pytest.mark.parametrize("seed,hidden", CASES)
def test_hidden_effect_is_named_first_and_fixed(seed, hidden):
    row = run_case(seed, hidden)
    print(row)
    assert row["fair"] and row["true_improvement"] >= 0.5
    assert row["named_first"] and row["fixed"]


def test_nothing_hidden_on_a_slow_ship_is_not_a_missing_effect():
    """A slow ship on a 10/10 zigzag: its first fit stops in a local minimum (T1 = T2 = 3.3 s against
    20.6 s, a fit residual 12 noise levels). The candidates' fits escape it, course_instability with
    n1 = 0.15: a stable rescaled Nomoto model, whose equivalent start refits the model itself near
    the truth (K 0.062 against 0.063 1/s), so no candidate is credited with the first fit's failure."""
    row = run_case(1251001414, ())
    print(row)
    assert row["verdict"] != "missing_effect"


def test_a_usv_course_instability_a_quadratic_damping_runs_closer_to_is_not_a_fair_case():
    """A USV on a 20/20 zigzag whose linear yaw damping is reversed and held by a cubic one: its
    true model at the known parameters removes 62 % of the held-out error, a quadratic yaw damping
    fitted on the training part 89 %. The held-out data point to the quadratic damping, not to the
    effect hidden: the case is not counted fair (the true model removes half, and is counted in the
    figure beside it)."""
    row = run_case(1889650729, ("course_instability",))
    print(row)
    assert row["truth_removes_half"] and row["true_improvement"] == pytest.approx(0.62, abs=0.02)
    assert row["top"] == "quadratic_yaw" and row["rival_improvement"] > row["true_improvement_over_diagnosed"] + 0.2
    assert not row["fair"]


def test_a_long_rudder_delay_on_a_quick_boat_is_found():
    """A 1.9 s dead time on a boat with T1 = 3.8 s and T3 = 0.07 s: fitted without it, the delay
    hides in T2 and T3 (T1 = T2 = 2.9 s, T3 = 0), where a search from tau = 0 stops at 0.7 s; the
    dead time profiled over a grid is found and removes most of the held-out error."""
    vessel = Vessel(
        "quick",
        "a quick boat with a long steering dead time",
        dict(K=0.594, T1=3.845, T2=0.2, T3=0.069, tau=1.869),
        speed=3.0,
        rudder_rate=np.radians(20.0),
    )
    sim = simulate("random", vessel, effects=("rudder_delay",), duration=600.0, seed=6)
    result = diagnose(sim.dataset, workers=1)
    top = result.candidates[0]
    print(top.effect, top.improvement_yaw_rate, top.t_statistic, top.estimate.parameters)
    assert top.effect == "rudder_delay" and top.significant and result.verdict == "missing_effect"
    assert top.improvement_yaw_rate > 0.7  # measured: 79 %
    assert top.estimate.parameters["tau"] == pytest.approx(1.869, rel=0.1)


def test_a_gyro_bias_on_a_slow_ship_is_judged_against_the_refitted_model():
    """A slow ship (T1 = 68 s) with a 0.73 deg/s gyro bias, 20 minutes of mixed manoeuvres: the first
    fit stops 18 noise levels from the training data, and every candidate would "remove" most of the
    error by escaping that minimum. The model refitted from the candidates' starts (2.4 noise
    levels), with the candidates refitted from it, names gyro_bias first, the bias and the hull
    within 2 % (measured: 1 %, and 92 % of the held-out heading error removed)."""
    _, _, sim = draw_case(828086076, ("gyro_bias",), duration=1200.0)
    said = []
    result = diagnose(sim.dataset, "nomoto2", (), workers=1, progress=said.append)
    assert any("found a better start for nomoto2 itself" in line for line in said), said
    top = result.candidates[0]
    assert result.verdict == "missing_effect" and top.effect == "gyro_bias" and top.significant
    assert top.improvement > 0.8
    for name in ("r_bias", "K", "T1"):
        assert top.estimate.parameters[name] == pytest.approx(sim.truth[name], rel=0.02), name


def delay_candidate(seed: int):
    """The rudder_delay candidate of ``diagnose`` on the case hiding a rudder delay drawn from ``seed``,
    and the case's truth."""
    _, _, sim = draw_case(seed, ("rudder_delay",))
    result = diagnose(sim.dataset, "nomoto2", (), workers=1)
    return next(c for c in result.candidates if c.effect == "rudder_delay"), result, sim.truth


def test_a_long_rudder_delay_on_a_slow_ship_is_found():
    """A 4.3 s dead time on a ship with T1 = 16.9 s and a 8.6 s rudder lead (20/20 zigzag): the model
    without the delay shows their difference, and the delay's candidate, started with the lead given
    back, recovers the hull (measured: tau 4.34 s, T3 8.45 s, T1 16.8 s)."""
    candidate, _, truth = delay_candidate(795728401)
    for name in ("K", "T1", "T3", "tau"):
        assert candidate.estimate.parameters[name] == pytest.approx(truth[name], rel=0.05), name


def test_a_rudder_delay_beside_a_rudder_lead_on_a_usv_is_named_and_fixed():
    """A 0.73 s dead time on a USV with a 1.37 s rudder lead (random steps): fitted without it, the
    model pins T3 at 0; a search from the model with the delay added alone stops at a fifth of the
    delay (8 % of the error removed). Started with the lead given back, it finds the hull and the
    delay is named missing (measured: 57 % of the held-out yaw-rate error removed)."""
    candidate, result, truth = delay_candidate(478660289)
    assert result.verdict == "missing_effect" and result.candidates[0] is candidate
    assert candidate.improvement_yaw_rate > 0.5
    assert candidate.estimate.parameters["tau"] == pytest.approx(truth["tau"], rel=0.05)


def damping_diagnosis(seed: int, hidden: str):
    """The diagnosis of a damping law hidden on a vessel drawn from ``seed``, and its true parameters."""
    _, _, sim = draw_case(seed, (hidden,))
    return diagnose(sim.dataset, "nomoto2", (), workers=1), sim.truth


def test_a_quadratic_damping_on_a_usv_is_named_before_the_cubic_laws():
    """Random steps on a USV with cross-flow drag: refitted alone, the cubic law and the course
    instability each remove 70 % of the held-out error and the quadratic law 62 %, nearly one model.
    The fit holding both laws carries the damping in its quadratic term, so quadratic_yaw is named
    first, the cubic laws beside it as near-equivalent, and its linear damping within 15 % of the truth."""
    result, truth = damping_diagnosis(861563203, "quadratic_yaw")
    first = result.candidates[0]
    assert first.effect == "quadratic_yaw" and {"cubic_yaw", "course_instability"} <= set(first.near_equivalent)
    law = first.damping_law
    assert law.laws == ("quadratic_yaw",) and law.quadratic > 2 * law.cubic
    assert law.linear_damping == pytest.approx(truth["a1"], rel=0.15)
    assert "quadratic term" in law.sentence()


def test_a_cubic_damping_on_a_course_stable_ship_is_named_before_the_quadratic_law():
    """Random steps on a ship (T1 18 s) whose damping grows with the turn rate cubed: the three laws
    remove 65-67 % each, the quadratic one the most. The fit holding both puts the growth in the cubic
    term with a positive linear damping (course-stable), so cubic_yaw is named, not course_instability."""
    result, truth = damping_diagnosis(2055341218, "cubic_yaw")
    first = result.candidates[0]
    assert first.effect == "cubic_yaw"
    law = first.damping_law
    assert law.laws == ("cubic_yaw",) and law.cubic > law.quadratic
    assert law.linear_damping > 10 * law.linear_damping_std


def test_a_course_unstable_usv_keeps_its_name_beside_the_quadratic_law():
    """A course-unstable USV on a mixed manoeuvre: the quadratic law, with a negative linear damping
    of its own, is near-equivalent; the fit holding both laws finds the linear damping negative,
    within 10 % of the truth, and the damping cubic, so course_instability stays first."""
    result, truth = damping_diagnosis(740706857, "course_instability")
    first = result.candidates[0]
    assert first.effect == "course_instability" and "quadratic_yaw" in first.near_equivalent
    assert first.damping_law.laws == ("course_instability",)
    assert first.damping_law.linear_damping == pytest.approx(truth["a1"], rel=0.1)


def test_a_usv_modelled_with_its_cross_flow_drag_has_its_damping_law_read_with_the_drag_in_force():
    """The damping-law fit holds both laws: on a model that already holds the quadratic one (a crew
    added it) it adds only the cubic one, and reads the same USV's law as quadratic."""
    _, _, sim = draw_case(861563203, ("quadratic_yaw",))
    estimate = make_estimator(DEFAULT_METHOD).fit(Structure("nomoto2", ("quadratic_yaw",)), sim.dataset)
    law = damping_law(estimate, sim.dataset, [estimate.parameters], DEFAULT_METHOD)
    assert law is not None and law.laws == ("quadratic_yaw",)


def test_a_rudder_delay_half_the_time_constant_on_a_usv_is_found_where_the_fit_without_it_sees_no_hull():
    """A 3.9 s dead time on a USV with T1 8 s (10/10 zigzag): the model fitted without it answers no
    rudder at all (K 0, T1 = T2 = 0.01 s), so its time constant bounds no delay. The delays profiled
    reach the bound all the same, and the delay is named missing with the hull and the delay found."""
    _, _, sim = draw_case(1273276384, ("rudder_delay",))
    result = diagnose(sim.dataset, "nomoto2", (), workers=1)
    first = result.candidates[0]
    assert result.verdict == "missing_effect" and first.effect == "rudder_delay"
    assert first.improvement > 0.5
    assert first.estimate.parameters["tau"] == pytest.approx(sim.truth["tau"], rel=0.1)
    assert first.estimate.parameters["K"] == pytest.approx(sim.truth["K"], rel=0.1)


def test_a_cubic_damping_on_a_quick_usv_whose_fit_stops_on_the_equal_poles_fold_is_found_across_it():
    """A USV with T1 1.4 s, T2 0.34 s, T3 1.3 s and a cubic damping: cubic_yaw's Nomoto search stops
    with its two poles equal, where only their sum and product are determined. Searched on across
    the fold in the acceleration form, it is named with every parameter determined: K and the time
    constants within 2 % of the truth, the cubic damping (per unit yaw inertia) within 6 %."""
    _, _, sim = draw_case(1506601801, ("cubic_yaw",))
    result = diagnose(sim.dataset, "nomoto2", (), workers=1)
    first = result.candidates[0]
    assert result.verdict == "missing_effect" and first.effect == "cubic_yaw"
    assert first.estimate.structure.form == "acceleration" and undetermined(first.estimate) == []
    found, truth = nomoto_parameters(first.estimate.parameters), sim.truth
    for name in ("K", "T1", "T2", "T3"):
        assert found[name] == pytest.approx(truth[name], rel=0.02), name
    inertia = truth["T1"] + truth["T2"]
    assert first.estimate.parameters["alpha"] == pytest.approx(truth["alpha"] / inertia, rel=0.06)


def test_a_usv_fitted_on_its_fold_is_judged_fair_against_its_base_model_refitted_from_the_truth():
    """A USV (T1 3.6 s, T2 1.05 s) with nothing hidden whose base fit is put on the fold T2 = 0
    (T1 + T2 - T3 kept): its true model "removes" 84 % of that fit's held-out error, all of it what
    the base model refitted from the vessel's true time constants removes too. Against the best
    base-model fit the true model gains nothing, so a case whose effect would only gain that is not
    counted fair."""
    vessel, _, sim = draw_case(4, (), duration=600.0, vessel_kind="usv")
    structure = Structure("nomoto2")
    truth = {name: vessel.parameters[name] for name in structure.parameter_names}
    fast = 0.01 * truth["T1"]
    folded = dict(truth, T1=truth["T1"] + truth["T2"] - truth["T3"] - fast + 0.3 * fast, T2=fast, T3=0.3 * fast)
    training, rest = split(sim.dataset)
    held_out = windows(rest, 60.0)
    fitted = SimpleNamespace(structure=structure, training=training, held_out=held_out)
    fitted.run = free_run(structure, folded, held_out)
    best = best_base_errors(fitted, vessel)
    over_folded = true_improvement(fitted, (), truth)
    assert over_folded > 0.5
    assert best["rmse_heading"] < 0.5 * fitted.run.fit["rmse_heading"]
    assert true_improvement(fitted, (), truth, best) < 0.1
