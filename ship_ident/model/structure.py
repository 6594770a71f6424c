"""Model structure: a Nomoto base model plus effects.

The base models are Nomoto's first- and second-order steering models (Nomoto, Taguchi, Honda and
Hirano, "On the steering qualities of ships", 1957); the cubic yaw damping and the acceleration form
below are Norrbin's nonlinear model (Norrbin, "Theory and observations on the use of a mathematical
model for ship manoeuvring in deep and confined waters", 1970).

The structure knows the parameters (names, units, physical bounds), how to
simulate the model free from measured rudder (``simulate``) and how to
write the ODE as an equation-error regression ``r = X w`` and map ``w``
back to physical parameters in closed form.

Regression (continuous time, on smoothed derivatives, see signals.py):

    nomoto1:  r = -T r' + K d + (effect columns)
    nomoto2:  r = -T1 T2 r'' - (T1 + T2) r' + K d + K T3 d' + (effect columns)

so w = [-T1 T2, -(T1 + T2), K, K T3, ...] and T1, T2 are the roots of
x^2 - (T1 + T2) x + T1 T2 = 0 (T1 >= T2).

The Nomoto form divides the yaw equation by its linear damping. Where that
damping is weak (a USV in fast turns, held by quadratic drag) or negative (a
course-unstable ship, held by its cubic damping), K and the time constants
run off to infinity while the data still determine the equation divided by
the coefficient of r' instead (the yaw inertia of a first-order hull, T1 + T2
of a second-order one: dividing by T1 T2 would spread a loosely known fast
pole over every parameter). A structure with an effect that frees the linear
damping (``Effect.frees_linear_damping``) is therefore fitted in that
*acceleration form* (Norrbin's form), and so is one whose Nomoto search stopped
on the fold T1 = T2 (``acceleration``: the acceleration form has no fold):

    nomoto1:  r' = b delta - a1 r + G
    nomoto2:  r' = -m2 r'' - a1 r + b0 delta + b1 delta' + G

with a1 of either sign and G the effects' forcing in the same units. Where
a1 > 0 it is the Nomoto model: K = b / a1, T = 1 / a1 (first order);
K = b0 / a1, T1 + T2 = 1 / a1, T1 T2 = m2 / a1, T3 = b1 / b0 (second order),
published beside the fitted parameters (``nomoto_parameters``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .dataset import DataError, Dataset
from .effects import EFFECTS, Effect, ForcingTerm, Parameter
from .integrate import TERM_FIELDS, simulate_kernel, substeps_for
from .linear_step import simulate_linear_kernel

BASE_MODELS: dict[str, tuple[Parameter, ...]] = {
    "nomoto1": (
        Parameter("K", "1/s", "rudder gain: steady yaw rate per rudder angle", 0.5, 1e-6, 100.0),
        Parameter("T", "s", "yaw time constant", 5.0, 0.01, 1e3),
    ),
    "nomoto2": (
        Parameter("K", "1/s", "rudder gain: steady yaw rate per rudder angle", 0.5, 1e-6, 100.0),
        Parameter("T1", "s", "slow yaw time constant", 5.0, 0.01, 1e3),
        Parameter("T2", "s", "fast yaw time constant (no hull answers faster than 10 ms)", 0.5, 0.01, 1e3),
        Parameter("T3", "s", "rudder lead time constant", 0.1, 0.0, 1e3),
    ),
}
# The acceleration form's base parameters (see the module docstring): rudder gains and dampings per
# unit of r's coefficient. The rudder's yaw acceleration is positive (K > 0), the fast pole's time m2
# too; the linear damping a1 may take either sign.
ACCELERATION_MODELS: dict[str, tuple[Parameter, ...]] = {
    "nomoto1": (
        Parameter("b", "1/s^2", "rudder's yaw acceleration per rudder angle (K / T)", 0.1, 1e-8, 1e3),
        Parameter(
            "a1", "1/s", "linear yaw damping per unit yaw inertia (1 / T; below 0: course-unstable)", 0.2, -10.0, 100.0
        ),
    ),
    "nomoto2": (
        Parameter("b0", "1/s^2", "rudder's yaw acceleration per rudder angle (K / (T1 + T2))", 0.1, 1e-8, 1e3),
        Parameter("b1", "1/s", "rudder's yaw acceleration per rudder rate (K T3 / (T1 + T2))", 0.0, 0.0, 1e3),
        Parameter("m2", "s", "fast pole's time (T1 T2 / (T1 + T2))", 0.1, 1e-3, 1e3),
        Parameter("a1", "1/s", "linear yaw damping (1 / (T1 + T2); below 0: course-unstable)", 0.05, -10.0, 100.0),
    ),
}
NOMOTO_NAMES = ("K", "T", "T1", "T2", "T3")
# The samples cannot tell a pole faster than this share of the sample time from none (5 % of its
# response is left after one sample): a fit in the acceleration form holds its fast pole's time m2 at or
# above it (``bounds``). Below it such a pole would only cost RK4 substeps (RK4 is stable for steps up
# to 2.8 of the fastest time constant: a 1 ms pole needs hundreds in a ship's 0.5 s sample), and a
# slow ship's search stopped there, its lead nearly cancelling the pole, far from the fast pole its
# data hold. The Nomoto form's T2 keeps its physical floor: there a pole the window cannot resolve
# shows as T2 near zero with an error that reaches it, which the T2 = T3 valley profile turns into
# T1's error (``online.uncertainty``); held at this share, a USV's start-up window was fitted in another
# minimum, T2 seemingly determined, and T1 published 10 % off as OK.
UNRESOLVED_POLE_SHARE = 1.0 / 3.0
POLE_NAMES = ("m2",)  # the fast poles held at UNRESOLVED_POLE_SHARE of the sample time
# Free runs that take this many RK4 substeps per sample or more (``fit_substeps``' 1.5 per time
# constant) hold a pole quicker than about a third of the sample time: the samples cannot resolve
# it and RK4 spends its substeps on that pole's stability alone (a ship's 10 ms T2 at 0.37 s costs
# it 56). A model without forcing terms, linear in its state, runs there on one exact step per
# sample (``linear_step``).
EXACT_STEP_SUBSTEPS = 5
ACCELERATION_NAMES = ("b", "b0", "b1", "m2", "a1")
NOMOTO_TIME_CONSTANT_LIMIT = 1e3  # s, T and T1's upper bound: a slower hull is published without them


class StructureError(ValueError):
    """An unknown model or effect name, or an effect that the data cannot support."""


@dataclass
class Regression:
    """Equation-error regression ``y = X w`` with named columns on the usable rows."""

    X: np.ndarray
    y: np.ndarray
    columns: list[str]
    fixed: dict  # parameters found before the regression (e.g. gyro bias, reference speed)
    signals: object


class Structure:
    """A base model (``nomoto1``/``nomoto2``) and a list of effects.

    ``acceleration`` holds it in the acceleration form whatever its effects (a Nomoto search that
    stopped on the fold T1 = T2 goes on there).
    """

    def __init__(self, model: str = "nomoto2", effects=(), acceleration: bool = False):
        if model not in BASE_MODELS:
            raise StructureError(f"unknown model {model!r}; choose from {', '.join(BASE_MODELS)}")
        effects = parse_effects(effects)
        self.model = model
        self.effect_names = tuple(effects)
        self.effects: tuple[Effect, ...] = tuple(EFFECTS[e] for e in effects)
        for effect in self.effects:
            clash = [e for e in effect.replaces if e in self.effect_names]
            if clash:
                raise StructureError(
                    f"{effect.name} includes {clash[0]}'s term (the same term twice has no unique fit); list one"
                )
        self.acceleration = acceleration
        self.form = "acceleration" if acceleration or any(e.frees_linear_damping for e in self.effects) else "nomoto"
        base = ACCELERATION_MODELS[model] if self.form == "acceleration" else BASE_MODELS[model]
        self.base_names = [p.name for p in base]
        self.parameters: tuple[Parameter, ...] = base + tuple(p for e in self.effects for p in e.parameters)
        self.parameter_names = [p.name for p in self.parameters]
        self.fixed_names = [n for e in self.effects for n in getattr(e, "fixed", ())]
        self.free_names = [n for n in self.parameter_names if n not in self.fixed_names]

    @property
    def order(self) -> int:
        """The base model's order: 1 for nomoto1 (one time constant T), 2 for nomoto2 (T1, T2, T3)."""
        return 1 if self.model == "nomoto1" else 2

    @property
    def needs_speed(self) -> bool:
        """Whether an effect needs the measured speed (speed_dependence)."""
        return any(e.needs_speed for e in self.effects)

    def with_effects(self, effects) -> Structure:
        """The same base model with other effects.

        Parameters
        ----------
        effects : sequence of str
            Effect names (EFFECTS).

        Returns
        -------
        Structure
            The new structure (in the acceleration form where this one is held there).
        """
        return Structure(self.model, list(effects), self.acceleration)

    def adding(self, effect: str) -> Structure:
        """This structure with ``effect`` added, in place of the effects whose term it includes.

        Parameters
        ----------
        effect : str
            The effect's name.

        Returns
        -------
        Structure
            The new structure.
        """
        replaced = EFFECTS[effect].replaces
        return self.with_effects([e for e in self.effect_names if e not in replaced] + [effect])

    def neutral_effect_start(self, base: dict) -> dict:
        """A start for this structure from the parameters of the model without some of its effects.

        The base converted to this structure's form, the missing effects' parameters at their neutral
        values, where they do nothing, so the start simulates exactly as the model it came from (a cubic
        damping carried over into a course instability).

        Parameters
        ----------
        base : dict
            The nested model's parameters, in either form (SI units).

        Returns
        -------
        dict
            Every parameter of this structure (SI units).
        """
        start = self.in_form(base)
        for effect in self.effects:
            start.update({k: v for k, v in effect.neutral().items() if k not in start})
        return start

    def in_form(self, params: dict) -> dict:
        """Parameters (either form) with the base parameters and the effects' forcing in this structure's form.

        Nomoto to acceleration divides the yaw equation by T (T1 T2); back, by the linear damping a1,
        which must be positive (else the Nomoto form does not exist and ``params`` are returned as they
        are): first order, Norrbin's r' = b delta - a1 r + G against Nomoto's T r' + r = K delta + T G,
        K = b / a1 and T = 1 / a1.

        Parameters
        ----------
        params : dict
            The model's parameters (SI units).

        Returns
        -------
        dict
            The parameters in this structure's form (SI units).
        """
        out = dict(params)
        if self.form == "acceleration" and "a1" not in params:
            for name in NOMOTO_NAMES:
                out.pop(name, None)
            inertia = params["T"] if self.order == 1 else params["T1"] + params["T2"]
            if self.order == 1:
                out.update(b=params["K"] / inertia, a1=1.0 / inertia)
            else:
                out.update(
                    b0=params["K"] / inertia,
                    b1=params["K"] * params["T3"] / inertia,
                    m2=params["T1"] * params["T2"] / inertia,
                    a1=1.0 / inertia,
                )
            scale = 1.0 / inertia
        elif self.form == "nomoto" and "K" not in params:
            nomoto = nomoto_parameters(params)
            if not nomoto:
                return out
            for name in ACCELERATION_NAMES:
                out.pop(name, None)
            out.update(nomoto)
            scale = 1.0 / params["a1"]
        else:
            scale = 1.0
        for effect in EFFECTS.values():
            for name in effect.forcing_parameters:
                if name in out:
                    out[name] = out[name] * scale
        for effect in EFFECTS.values():  # a term one effect includes of another carries over
            for replaced, names in effect.replaces.items():
                pairs = names.items() if effect in self.effects else [(b, a) for a, b in names.items()]
                if effect in self.effects or replaced in self.effect_names:
                    out.update({new: out[old] for old, new in pairs if old in out and new not in out})
        return out

    def label(self) -> str:
        """The structure's name, 'model+effect+...' (as ``--model`` and ``--effects`` give it).

        Returns
        -------
        str
            The label.
        """
        return "+".join((self.model,) + self.effect_names)

    def to_json(self) -> dict:
        """The structure as the JSON records give it.

        Returns
        -------
        dict
            {'model': name, 'effects': [names]}.
        """
        return {"model": self.model, "effects": list(self.effect_names)}

    def parameter(self, name: str) -> Parameter:
        """The ``Parameter`` (unit, description, bounds, initial value) of one of the structure's parameters.

        Parameters
        ----------
        name : str
            The parameter's name.

        Returns
        -------
        Parameter
            Its definition.
        """
        return next(p for p in self.parameters if p.name == name)

    def initial_parameters(self) -> dict:
        """Every parameter at its initial value (a typical hull's).

        Returns
        -------
        dict
            Parameter -> value (SI units).
        """
        return {p.name: p.initial for p in self.parameters}

    def bounds(self, names=None, dataset: Dataset | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of parameters: the physical ones, narrowed by the data's.

        With ``dataset``, the fast poles (POLE_NAMES) are at least UNRESOLVED_POLE_SHARE of its sample
        time, and every effect's ``data_bounds`` narrows them (e.g. cubic_yaw: stable over the turn rates the
        data reach).

        Parameters
        ----------
        names : sequence of str or None
            The parameters (default: the free ones).
        dataset : Dataset or None
            The data whose bounds apply (None: the physical bounds alone).

        Returns
        -------
        lower, upper : numpy.ndarray
            Bounds per parameter (SI units).
        """
        names = self.free_names if names is None else names
        limits = {n: (self.parameter(n).lower, self.parameter(n).upper) for n in names}
        if dataset is not None:  # a fast pole the samples cannot resolve is held at the fastest they do
            floor = UNRESOLVED_POLE_SHARE * dataset.sample_time
            limits.update({n: (max(lo, floor), hi) for n, (lo, hi) in limits.items() if n in POLE_NAMES})
        if dataset is not None and self.form == "nomoto":  # data bounds are stated in the Nomoto form
            for effect in self.effects:
                data_bounds = getattr(effect, "data_bounds", None)
                for n, (lo, hi) in (data_bounds(dataset) if data_bounds else {}).items():
                    if n in limits:
                        limits[n] = (max(lo, limits[n][0]), min(hi, limits[n][1]))
        return np.array([limits[n][0] for n in names]), np.array([limits[n][1] for n in names])

    def check_data(self, dataset: Dataset) -> None:
        """Check that the data carry what the structure needs.

        Parameters
        ----------
        dataset : Dataset
            The data.

        Raises
        ------
        StructureError
            When an effect needs the speed and the data have none.
        """
        if self.needs_speed and dataset.speed is None:
            raise StructureError("speed_dependence needs a speed signal; record /usv/speed or add a speed column")

    # --- simulation -------------------------------------------------------
    def simulate(
        self, params: dict, dataset: Dataset, initial: list | None = None, substeps: int | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Free-run heading and measured yaw rate from the measured rudder.

        Each segment starts from ``initial[i] = (psi0, r0, rdot0)`` (true
        hull states) or, by default, from the measured heading and yaw rate at
        its first sample with r' = 0.

        Parameters
        ----------
        params : dict
            The model's parameters (SI units).
        dataset : Dataset
            The data (its rudder drives the run; rad).
        initial : list of tuple or None
            Each segment's initial heading (rad), yaw rate (rad/s) and yaw acceleration (rad/s^2).
        substeps : int or None
            RK4 steps per sample (default: from the fastest time constant).

        Returns
        -------
        heading, yaw_rate : numpy.ndarray
            Heading (rad) and the yaw rate the sensor would read (rad/s), NaN outside the segments.
        """
        psi, r = self.simulate_runs([params], dataset, None if initial is None else [initial], substeps)
        return psi[0], r[0]

    def simulate_runs(
        self,
        param_sets: list,
        dataset: Dataset,
        initials: list | np.ndarray | None = None,
        substeps: int | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``simulate`` for several parameter sets (and initial states) at once, in one compiled call.

        The runs advance side by side: far cheaper than one call each, e.g. for a Jacobian.

        Parameters
        ----------
        param_sets : list of dict
            Parameter sets (SI units).
        dataset : Dataset
            The data.
        initials : list, numpy.ndarray or None
            Per run, each segment's initial state (as ``simulate``'s ``initial``; an array: runs x
            segments x 3).
        substeps : int or None
            RK4 steps per sample, shared (default: that of the fastest time constant of all runs); from
            EXACT_STEP_SUBSTEPS on, a model without forcing terms steps exactly instead, every run alike.

        Returns
        -------
        heading, yaw_rate : numpy.ndarray
            (runs, n) heading (rad) and measured yaw rate (rad/s).
        """
        self.check_data(dataset)
        h = dataset.sample_time
        substeps = substeps or substeps_for(h, min(self.fastest_time_constant(p) for p in param_sets))
        runs = len(param_sets)
        rudder = np.empty((runs, dataset.n_samples))
        gain, tscale = np.ones_like(rudder), np.ones_like(rudder)  # unless an effect scales with the speed
        scaled = False
        for k, p in enumerate(param_sets):
            rudder[k] = self.effective_rudder(p, dataset.time, dataset.rudder)
            scales = None if dataset.speed is None else self.speed_scales(p, dataset.speed)
            if scales is not None:
                gain[k], tscale[k] = scales
                scaled = True
        kernels = [self.kernel(p) for p in param_sets]
        coef = np.array([[t.coefficient for t in ts] for _, ts in kernels], dtype=float).reshape(runs, -1)
        ints = [np.array([getattr(t, f) for t in kernels[0][1]], dtype=np.int64) for f in TERM_FIELDS]
        constants = np.array([c for c, _ in kernels], dtype=float)
        bounds = np.array(dataset.segments, dtype=np.int64).reshape(-1, 2)
        if initials is None:
            initials = [
                [(dataset.heading[a], dataset.yaw_rate[a] - self.yaw_rate_bias(p), 0.0) for a, _ in dataset.segments]
                for p in param_sets
            ]
        initial = np.array(initials, dtype=float).reshape(runs, len(bounds), 3)
        if substeps >= EXACT_STEP_SUBSTEPS and not (scaled or kernels[0][1]):
            psi_out, r_out = simulate_linear_kernel(self.order, h, rudder, constants, bounds, initial)
        else:
            psi_out, r_out = simulate_kernel(
                self.order, h, rudder, gain, tscale, constants, bounds, initial, coef, *ints, substeps
            )
        for k, p in enumerate(param_sets):
            r_out[k] = self.measured_yaw_rate(r_out[k], p)
        return psi_out, r_out

    def kernel(self, params: dict) -> tuple[tuple[float, float, float, float], list[ForcingTerm]]:
        """The integrator's constants (K, T1, T2, T3) and forcing terms for ``params``.

        The integrator solves the Nomoto form. The acceleration form multiplied by a positive
        number m is that form with K = m b0, T1 + T2 = m, T1 T2 = m m2 (T1 = T2 = 2 m2: m = 4 m2)
        and T3 = b1 / b0 (first order: T = m = 1 / max(|a1|, 1e-3 1/s), K = m b), its linear damping
        moved to the forcing as (1 - m a1) r and the effects' forcing times m.

        Parameters
        ----------
        params : dict
            The model's parameters (SI units).

        Returns
        -------
        constants : tuple of float
            K (1/s), T1, T2, T3 (s).
        terms : list of ForcingTerm
            The forcing terms (rad/s).
        """
        terms = [t for e in self.effects for t in e.forcing_terms(params)]
        if self.form == "nomoto":
            if self.order == 1:
                return (params["K"], params["T"], 0.0, 0.0), terms
            return (params["K"], params["T1"], params["T2"], params["T3"]), terms
        if self.order == 1:
            inertia = 1.0 / max(abs(params["a1"]), 1e-3)
            constants = (inertia * params["b"], inertia, 0.0, 0.0)
        else:
            inertia = 4.0 * params["m2"]
            constants = (inertia * params["b0"], 2.0 * params["m2"], 2.0 * params["m2"], params["b1"] / params["b0"])
        scaled = [replace(t, coefficient=inertia * t.coefficient) for t in terms]
        return constants, [ForcingTerm(1.0 - inertia * params["a1"], r_power=1), *scaled]

    def fastest_time_constant(self, params: dict) -> float:
        """The fastest time scale of the linear model, which sets the integration step.

        Parameters
        ----------
        params : dict
            The model's parameters (SI units).

        Returns
        -------
        float
            The time constant (s).
        """
        if self.form == "nomoto":
            return params["T"] if self.order == 1 else min(params["T1"], params["T2"])
        return fastest_time_constant({n: params[n] for n in self.base_names})

    def effective_inputs(
        self, params: dict, time: np.ndarray, rudder: np.ndarray, speed: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The rudder angle acting on the hull and the multipliers of K and of the time constants.

        After every effect's rudder and speed hooks.

        Parameters
        ----------
        params : dict
            The model's parameters (SI units).
        time : numpy.ndarray
            Sample times (s).
        rudder : numpy.ndarray
            The measured rudder angle (rad).
        speed : numpy.ndarray or None
            The measured speed (m/s).

        Returns
        -------
        rudder, gain_scale, time_scale : numpy.ndarray
            The effective rudder (rad) and the per-sample multipliers (dimensionless).
        """
        scales = None if speed is None else self.speed_scales(params, speed)
        if scales is None:
            scales = np.ones(len(time)), np.ones(len(time))
        return self.effective_rudder(params, time, rudder), *scales

    def effective_rudder(self, params: dict, time: np.ndarray, rudder: np.ndarray) -> np.ndarray:
        """The rudder angle acting on the hull (rad), after every effect's rudder hook.

        Parameters
        ----------
        params : dict
            The model's parameters (SI units).
        time : numpy.ndarray
            Sample times (s).
        rudder : numpy.ndarray
            The measured rudder angle (rad).

        Returns
        -------
        numpy.ndarray
            The effective rudder angle (rad).
        """
        for effect in self.effects:
            rudder = effect.effective_rudder(time, rudder, params)
        return rudder

    def speed_scales(self, params: dict, speed: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """The per-sample multipliers of K and of the time constants, or None when both are 1.

        Each the product of every effect's speed hook (dimensionless).

        Parameters
        ----------
        params : dict
            The model's parameters (SI units).
        speed : numpy.ndarray
            The measured speed (m/s).

        Returns
        -------
        tuple of numpy.ndarray or None
            (gain multiplier, time-constant multiplier) per sample, or None.
        """
        product = None
        for effect in self.effects:
            scales = effect.speed_scales(speed, params)
            if scales is not None:
                product = scales if product is None else (product[0] * scales[0], product[1] * scales[1])
        return product

    def yaw_rate_bias(self, params: dict) -> float:
        """What the yaw-rate sensor reads when the hull does not turn (gyro bias).

        Parameters
        ----------
        params : dict
            The model's parameters (SI units).

        Returns
        -------
        float
            The bias (rad/s).
        """
        return float(self.measured_yaw_rate(np.zeros(1), params)[0])

    def measured_yaw_rate(self, r: np.ndarray, params: dict) -> np.ndarray:
        """What the yaw-rate sensor reads when the hull turns at ``r``, after every effect's sensor hook.

        Parameters
        ----------
        r : numpy.ndarray
            The hull's true yaw rate (rad/s).
        params : dict
            The model's parameters (SI units).

        Returns
        -------
        numpy.ndarray
            The reading (rad/s).
        """
        for effect in self.effects:
            r = effect.measured_yaw_rate(r, params)
        return r

    # --- regression -------------------------------------------------------
    def regression(self, signals) -> Regression:
        """The equation-error regression ``r = X w`` on the usable rows; effects may fix parameters first.

        Parameters
        ----------
        signals : Signals
            Smoothed signals and derivatives (``compute_signals``).

        Returns
        -------
        Regression
            X, y and the column names, with the fixed parameters.
        """
        fixed = {}
        for effect in self.effects:
            fixed.update(effect.prepare(signals))
        s = signals
        scale_k = s.base_column_scales.get("K", 1.0)
        scale_t = s.base_column_scales.get("T", 1.0)
        if self.form == "acceleration":  # r' on the left (speed scales left to the search)
            y = s.r_dot
            cols = {"r": s.r, "delta": s.delta} if self.order == 1 else {"r''": s.r_ddot, "r": s.r, "delta": s.delta}
            if self.order == 2:
                cols["delta'"] = s.delta_dot
        elif self.order == 1:
            y = s.r
            cols = {"r'": s.r_dot * scale_t, "delta": s.delta * scale_k}
        else:
            y = s.r
            cols = {
                "r''": s.r_ddot * scale_t**2,
                "r'": s.r_dot * scale_t,
                "delta": s.delta * scale_k,
                "delta'": s.delta_dot,
            }
        for effect in self.effects:
            cols.update(effect.regressors(s))
        rows = s.rows
        X = np.column_stack([np.broadcast_to(c, s.r.shape)[rows] for c in cols.values()])
        return Regression(X=X, y=y[rows], columns=list(cols), fixed=fixed, signals=s)

    def parameters_from_coefficients(self, w: np.ndarray, regression: Regression) -> tuple[dict, list[str]]:
        """Closed-form map from regression coefficients to physical parameters, with flags.

        Parameters
        ----------
        w : numpy.ndarray
            The regression coefficients.
        regression : Regression
            The regression they solve (its columns).

        Returns
        -------
        parameters : dict
            The physical parameters (SI units).
        flags : list of str
            What the map found ('complex_time_constants', 'K_out_of_bounds', ...).
        """
        c = dict(zip(regression.columns, w))
        flags = []
        base = {"K": c["delta"]}
        if self.form == "acceleration":
            if self.order == 1:
                base = {"b": c["delta"], "a1": -c["r"]}
            else:
                base = {"b0": c["delta"], "b1": c["delta'"], "m2": -c["r''"], "a1": -c["r"]}
            base["K"] = c["delta"]  # the effects' rudder-side terms are relative to the rudder's coefficient
        elif self.order == 1:
            base["T"] = -c["r'"]
        else:
            total, product = -c["r'"], -c["r''"]
            disc = total * total - 4 * product
            if disc < 0:
                flags.append("complex_time_constants")
                base["T1"] = base["T2"] = total / 2
            else:
                base["T1"] = (total + np.sqrt(disc)) / 2
                base["T2"] = (total - np.sqrt(disc)) / 2
            base["T3"] = c["delta'"] / c["delta"] if c["delta"] != 0 else 0.0
        params = {n: base[n] for n in self.base_names}
        for effect in self.effects:
            params.update(effect.from_coefficients(c, base))
        params.update(regression.fixed)
        for p in self.parameters:
            if not p.lower <= params[p.name] <= p.upper:
                flags.append(f"{p.name}_out_of_bounds")
        return params, flags

    def clip_to_bounds(self, params: dict) -> dict:
        """Parameters moved just inside their physical bounds (K > 0, T > 0, T3 >= 0, ...).

        Parameters
        ----------
        params : dict
            The model's parameters (SI units).

        Returns
        -------
        dict
            The parameters inside their bounds; a non-finite value replaced by its initial one.
        """
        out = dict(params)
        for p in self.parameters:
            v = out[p.name]
            if not np.isfinite(v):
                v = p.initial
            span = 1e-6 * max(1.0, abs(v))
            lo = p.lower + (span if np.isfinite(p.lower) and p.lower > 0 else 0.0)
            out[p.name] = float(np.clip(v, lo, p.upper))
        return out


def fastest_time_constant(params: dict) -> float:
    """The fastest time scale of a base model's parameters, in either form.

    Parameters
    ----------
    params : dict
        A parameter set (SI units) of the Nomoto or the acceleration form.

    Returns
    -------
    float
        The smallest of T, T1 and T2 given (s), or the fast pole's time of the acceleration form
        (1 / |a1| first order; min(m2, sqrt(m2 / |a1|)), at least 1 ms, second order).
    """
    nomoto = [params[n] for n in ("T", "T1", "T2") if n in params]
    if nomoto:
        return float(min(nomoto))
    if "m2" in params:
        return float(max(min(params["m2"], np.sqrt(params["m2"] / max(abs(params["a1"]), 1e-12))), 1e-3))
    return float(1.0 / max(abs(params["a1"]), 1e-3))


def nomoto_parameters(params: dict) -> dict:
    """K and the time constants of an acceleration-form parameter set, where they exist.

    They exist for a positive linear damping a1 (first order: K = b / a1, T = 1 / a1) with real
    time constants (second order: T1, T2 the roots of x^2 - x / a1 + m2 / a1, T3 = b1 / b0) and
    T (T1) below ``NOMOTO_TIME_CONSTANT_LIMIT``; a course-unstable hull has no K.

    Parameters
    ----------
    params : dict
        Parameters of the acceleration form (b, a1 or b0, b1, m2, a1; SI units).

    Returns
    -------
    dict
        K (1/s) and T, or T1, T2, T3 (s); empty where they do not exist.
    """
    a1 = params["a1"]
    if not a1 * NOMOTO_TIME_CONSTANT_LIMIT > 1.0:
        return {}
    if "b" in params:
        return {"K": params["b"] / a1, "T": 1.0 / a1}
    total, product = 1.0 / a1, params["m2"] / a1
    disc = total * total - 4.0 * product
    if disc < 0:
        return {}
    t1, t2 = (total + np.sqrt(disc)) / 2.0, (total - np.sqrt(disc)) / 2.0
    if t1 > NOMOTO_TIME_CONSTANT_LIMIT:
        return {}
    return {"K": params["b0"] / a1, "T1": t1, "T2": t2, "T3": params["b1"] / params["b0"]}


def nomoto_view(params: dict, covariance: np.ndarray | None, names: list, std_errors: dict) -> tuple[dict, dict]:
    """K and the time constants of an acceleration-form fit, with standard errors by the delta method.

    Parameters
    ----------
    params : dict
        The fitted acceleration-form parameters (SI units).
    covariance : ndarray or None
        Covariance of the parameters ``names``; None: the errors taken as independent.
    names : list of str
        The fitted parameters, in the order of ``covariance``.
    std_errors : dict
        Their standard errors, used when ``covariance`` is None.

    Returns
    -------
    values, errors : dict, dict
        ``nomoto_parameters`` (1/s, s) and their standard errors; both empty where the hull has no
        Nomoto form (course-unstable, or complex time constants).
    """
    values = nomoto_parameters(params)
    if not values:
        return {}, {}
    fitted = [n for n in names if n in ACCELERATION_NAMES]
    gradient = np.zeros((len(values), len(fitted)))
    for j, name in enumerate(fitted):
        step = 1e-6 * max(abs(params[name]), 1e-9)
        moved = nomoto_parameters(dict(params, **{name: params[name] + step}))
        if not moved:
            moved = nomoto_parameters(dict(params, **{name: params[name] - step}))
            step = -step
        gradient[:, j] = [(moved[k] - values[k]) / step for k in values]
    if covariance is not None:
        index = [names.index(n) for n in fitted]
        cov = covariance[np.ix_(index, index)]
    else:
        cov = np.diag([std_errors.get(n, np.inf) ** 2 for n in fitted])
    with np.errstate(invalid="ignore"):
        variance = np.einsum("ij,jk,ik->i", gradient, cov, gradient)
    errors = {k: float(np.sqrt(v)) if np.isfinite(v) and v >= 0 else float("inf") for k, v in zip(values, variance)}
    return {k: float(v) for k, v in values.items()}, errors


def parse_effects(effects) -> tuple[str, ...]:
    """Effect names from the command line or a configuration.

    Parameters
    ----------
    effects : str, sequence of str or None
        A comma-separated string or a sequence of names ("", None or (): no effects).

    Returns
    -------
    tuple of str
        The names, in the order given.

    Raises
    ------
    StructureError
        For a name not in ``effects.EFFECTS`` (naming those) or one listed twice.
    """
    items = (effects or "").split(",") if isinstance(effects, str) or effects is None else effects
    names = tuple(str(e).strip() for e in items if str(e).strip())
    unknown = [e for e in names if e not in EFFECTS]
    if unknown:
        raise StructureError(f"unknown effect {unknown[0]!r}; choose from {', '.join(EFFECTS)}")
    if len(set(names)) != len(names):
        raise StructureError(f"effect listed twice: {', '.join(names)}")
    return names


def require_samples(dataset: Dataset, minimum: int = 20) -> None:
    """Refuse a dataset too short to fit.

    Parameters
    ----------
    dataset : Dataset
        The data to fit.
    minimum : int
        Fewest samples accepted.

    Raises
    ------
    DataError
        With fewer samples.
    """
    if dataset.n_samples < minimum:
        raise DataError(f"only {dataset.n_samples} samples; need at least {minimum}")
