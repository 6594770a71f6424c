"""Every registered effect on every Nomoto base model is identifiable by output error.

For each effect, on a USV and on a slow ship (and, for the effects that free the linear yaw
damping, on a course-unstable hull and on a USV whose linear damping is weak and held by
quadratic drag), the Fisher information of the free-run (output-error) problem is computed on a
manoeuvre that excites the effect, at realistic sensor noise, with the parameters scaled by their
values and the initial states marginalised (``bench.crb.identifiability``). A parametrisation with
a free direction (parameters that move together without changing the motion, as the Nomoto form
with a free linear damping beside free K and T) has an unbounded condition number.
"""

from __future__ import annotations

import numpy as np
import pytest

from ship_ident.bench.crb import identifiability
from ship_ident.model.effects import EFFECTS
from ship_ident.model.simulator import Noise, Vessel, simulate
from ship_ident.model.structure import Structure

MAX_CONDITION = 1e8
MAX_RELATIVE_BOUND = 1.0  # a Cramer-Rao bound beyond the parameter's own value: not determined
RUDDER = np.radians(20.0)  # rad: the rudder of the manoeuvres' turns

# (Nomoto parameters, duration s, sample time s, speed m/s)
HULLS = {
    "usv": (dict(K=0.6, T1=2.0, T2=0.3, T3=0.6), 600.0, 0.1, 3.0),
    "ship": (dict(K=0.08, T1=40.0, T2=4.0, T3=8.0), 1800.0, 0.5, 6.0),
}


def effect_values(effect: str, nomoto: dict) -> dict:
    """The effect's parameters (Nomoto form's units) at a strength that matters: each a fraction of
    the turn rate r0 = K RUDDER the hull reaches or of its time constant."""
    r0 = nomoto["K"] * RUDDER
    amplitude = 0.3 * r0
    return {
        "rudder_offset": {"delta_r": 0.3 * r0 / nomoto["K"]},
        "cubic_yaw": {"alpha": 0.6 / r0**2},
        "rudder_delay": {"tau": min(0.3 * nomoto["T1"], 4.0)},
        "wind_yaw": {
            "wind_c1": amplitude,
            "wind_s1": -0.6 * amplitude,
            "wind_c2": 0.3 * amplitude,
            "wind_s2": 0.2 * amplitude,
        },
        "gyro_bias": {"r_bias": 4.0 * Noise().yaw_rate},
        "speed_dependence": {"n_K": 1.0, "n_T": 1.0},
        "course_instability": {"alpha": 0.3 / r0**2},  # carried into a3 by the form's conversion
        "quadratic_yaw": {"d_q": 0.6 / r0},
        "rudder_stall": {"c_stall": 0.8},
    }[effect]


def cases():
    """(model, effect, hull label, linear damping ratio): the ratio times the stable hull's a1 (the
    acceleration form's linear damping); 1 keeps the stable hull."""
    for model in ("nomoto1", "nomoto2"):
        for effect in EFFECTS:
            for hull in HULLS:
                yield model, effect, hull, 1.0
        yield model, "course_instability", "ship", -0.4  # a course-unstable tanker held by cubic damping
        yield model, "quadratic_yaw", "usv", -0.3  # a USV whose yaw-only linear damping is negative


def truth_and_data(model: str, effect: str, hull: str, ratio: float):
    nomoto, duration, sample_time, speed = HULLS[hull]
    structure = Structure(model, (effect,))
    values = dict(nomoto, T=nomoto["T1"] + nomoto["T2"] - nomoto["T3"], **effect_values(effect, nomoto))
    if effect == "course_instability":
        values["a3"] = values["alpha"] * (1.5 - ratio)  # the stronger, the more the reversed damping must be held
    truth = {k: v for k, v in structure.in_form(values).items() if k in structure.parameter_names}
    if structure.form == "acceleration":
        truth["a1"] *= ratio
    maneuver, amplitude = ("random", np.radians(35.0)) if effect == "rudder_stall" else ("mixed", None)
    vessel = Vessel(hull, hull, values, speed=speed)
    sim = simulate(
        maneuver,
        vessel,
        effects=(effect,),
        parameters=truth,
        duration=duration,
        sample_time=sample_time,
        noise=0.0,
        seed=1,
        amplitude=amplitude,
        model=model,
    )
    return structure, sim.truth, sim.dataset


@pytest.mark.parametrize(("model", "effect", "hull", "ratio"), list(cases()))
def test_every_effect_on_every_base_model_has_no_free_direction(model, effect, hull, ratio):
    structure, truth, data = truth_and_data(model, effect, hull, ratio)
    assert np.max(np.abs(data.yaw_rate)) < 1.0  # the hull stays bounded on its manoeuvre
    noise = Noise()
    condition, relative = identifiability(structure, truth, data, noise.heading, noise.yaw_rate)
    print(model, effect, hull, ratio, f"condition {condition:.3g}", {k: round(v, 4) for k, v in relative.items()})
    assert condition < MAX_CONDITION
    assert max(relative.values()) < MAX_RELATIVE_BOUND, relative


def test_a_free_linear_damping_beside_nomoto_k_and_t_is_caught():
    """The check itself: the Nomoto form with its linear damping freed, T r' + n1 r + n3 r^3 = K delta,
    is unchanged when K, T, n1 and n3 are multiplied by one number; its information is singular."""
    from ship_ident.model.effects import CubicYaw, ForcingTerm, Parameter, register_effect

    class FreeLinearDamping(CubicYaw):
        name = "free_linear_damping"
        parameters = (Parameter("n1", "-", "linear damping relative to the model's", 1.0, -3.0, 3.0),)

        def forcing_terms(self, p):
            return [ForcingTerm(1.0 - p["n1"], r_power=1)]

    register_effect(FreeLinearDamping())
    try:
        structure = Structure("nomoto1", ("free_linear_damping",))
        nomoto, duration, sample_time, speed = HULLS["usv"]
        values = dict(nomoto, T=2.3, n1=0.7)
        sim = simulate("mixed", Vessel("usv", "usv", values, speed=speed), effects=(), duration=duration, noise=0.0)
        condition, relative = identifiability(structure, values, sim.dataset, Noise().heading, Noise().yaw_rate)
        assert condition > MAX_CONDITION or max(relative.values()) > MAX_RELATIVE_BOUND
    finally:
        EFFECTS.pop("free_linear_damping", None)
