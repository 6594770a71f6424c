"""Model structure: a Nomoto base model plus effects.

The structure knows the parameters (names, units, physical bounds), how to
simulate the model free from measured rudder (``simulate``) and how to
write the ODE as an equation-error regression ``r = X w`` and map ``w``
back to physical parameters in closed form.

Regression (continuous time, on smoothed derivatives, see signals.py):

    nomoto1:  r = -T r' + K d + (effect columns)
    nomoto2:  r = -T1 T2 r'' - (T1 + T2) r' + K d + K T3 d' + (effect columns)

so w = [-T1 T2, -(T1 + T2), K, K T3, ...] and T1, T2 are the roots of
x^2 - (T1 + T2) x + T1 T2 = 0 (T1 >= T2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .dataset import DataError, Dataset
from .effects import EFFECTS, Effect, Parameter
from .integrate import TERM_FIELDS, simulate_kernel, substeps_for

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
    """A base model (``nomoto1``/``nomoto2``) and a list of effects."""

    def __init__(self, model: str = "nomoto2", effects=()):
        if model not in BASE_MODELS:
            raise StructureError(f"unknown model {model!r}; choose from {', '.join(BASE_MODELS)}")
        effects = parse_effects(effects)
        self.model = model
        self.effect_names = tuple(effects)
        self.effects: tuple[Effect, ...] = tuple(EFFECTS[e] for e in effects)
        self.parameters: tuple[Parameter, ...] = BASE_MODELS[model] + tuple(
            p for e in self.effects for p in e.parameters
        )
        self.parameter_names = [p.name for p in self.parameters]
        self.fixed_names = [n for e in self.effects for n in getattr(e, "fixed", ())]
        self.free_names = [n for n in self.parameter_names if n not in self.fixed_names]

    @property
    def order(self) -> int:
        return 1 if self.model == "nomoto1" else 2

    @property
    def needs_speed(self) -> bool:
        return any(e.needs_speed for e in self.effects)

    def with_effects(self, effects) -> Structure:
        return Structure(self.model, list(effects))

    def neutral_effect_start(self, base: dict) -> dict:
        """A start for this structure from ``base``, the parameters of the model without some of
        its effects: the missing effects' parameters at their neutral values, where they do
        nothing, so the start simulates exactly as the model it came from."""
        start = dict(base)
        for effect in self.effects:
            start.update({k: v for k, v in effect.neutral().items() if k not in base})
        return start

    def label(self) -> str:
        return "+".join((self.model,) + self.effect_names)

    def to_json(self) -> dict:
        return {"model": self.model, "effects": list(self.effect_names)}

    def parameter(self, name: str) -> Parameter:
        return next(p for p in self.parameters if p.name == name)

    def initial_parameters(self) -> dict:
        return {p.name: p.initial for p in self.parameters}

    def bounds(self, names=None, dataset: Dataset | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of the parameters ``names``: the physical ones, narrowed with
        ``dataset`` by every effect's ``data_bounds`` (e.g. cubic_yaw: stable over the turn
        rates the data reach)."""
        names = self.free_names if names is None else names
        limits = {n: (self.parameter(n).lower, self.parameter(n).upper) for n in names}
        if dataset is not None:
            for effect in self.effects:
                data_bounds = getattr(effect, "data_bounds", None)
                for n, (lo, hi) in (data_bounds(dataset) if data_bounds else {}).items():
                    if n in limits:
                        limits[n] = (max(lo, limits[n][0]), min(hi, limits[n][1]))
        return np.array([limits[n][0] for n in names]), np.array([limits[n][1] for n in names])

    def check_data(self, dataset: Dataset) -> None:
        if self.needs_speed and dataset.speed is None:
            raise StructureError("speed_dependence needs a speed signal; record /usv/speed or add a speed column")

    # --- simulation -------------------------------------------------------
    def simulate(
        self, params: dict, dataset: Dataset, initial: list | None = None, substeps: int | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Free-run heading (rad) and measured yaw rate (rad/s) from the measured rudder.

        Each segment starts from ``initial[i] = (psi0, r0, rdot0)`` (true
        hull states) or, by default, from the measured heading and yaw rate at
        its first sample with r' = 0.
        """
        psi, r = self.simulate_runs([params], dataset, None if initial is None else [initial], substeps)
        return psi[0], r[0]

    def simulate_runs(
        self, param_sets: list, dataset: Dataset, initials: list | None = None, substeps: int | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``simulate`` for several parameter sets (and initial states) at once, one compiled call
        (the runs advance side by side: far cheaper than one call each, e.g. for a Jacobian).
        Returns heading and measured yaw rate, one row per run; ``substeps`` is shared (by
        default that of the fastest time constant of all runs)."""
        self.check_data(dataset)
        h = dataset.sample_time
        names = ("T",) if self.order == 1 else ("T1", "T2")
        substeps = substeps or substeps_for(h, min(p[n] for p in param_sets for n in names))
        inputs = [self.effective_inputs(p, dataset.time, dataset.rudder, dataset.speed) for p in param_sets]
        rudder, gain, tscale = (np.array([x[i] for x in inputs], dtype=float) for i in range(3))
        terms = [[t for e in self.effects for t in e.forcing_terms(p)] for p in param_sets]
        coef = np.array([[t.coefficient for t in ts] for ts in terms], dtype=float).reshape(len(terms), -1)
        ints = [np.array([getattr(t, f) for t in terms[0]], dtype=np.int64) for f in TERM_FIELDS]
        constants = np.array(
            [
                [p["K"], p["T"], 0.0, 0.0] if self.order == 1 else [p["K"], p["T1"], p["T2"], p["T3"]]
                for p in param_sets
            ],
            dtype=float,
        )
        bounds = np.array(dataset.segments, dtype=np.int64).reshape(-1, 2)
        if initials is None:
            initials = [
                [(dataset.heading[a], dataset.yaw_rate[a] - self.yaw_rate_bias(p), 0.0) for a, _ in dataset.segments]
                for p in param_sets
            ]
        initial = np.array(initials, dtype=float).reshape(len(param_sets), len(bounds), 3)
        psi_out, r_out = simulate_kernel(
            self.order, h, rudder, gain, tscale, constants, bounds, initial, coef, *ints, substeps
        )
        return psi_out, np.array([self.measured_yaw_rate(r, p) for r, p in zip(r_out, param_sets)])

    def effective_inputs(
        self, params: dict, time: np.ndarray, rudder: np.ndarray, speed: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The rudder angle acting on the hull (rad) and the per-sample multipliers of K and of
        the time constants, after every effect's rudder and speed hooks."""
        for effect in self.effects:
            rudder = effect.effective_rudder(time, rudder, params)
        gain = np.ones(len(time))
        time_scale = np.ones(len(time))
        for effect in self.effects:
            scales = effect.speed_scales(speed, params) if speed is not None else None
            if scales is not None:
                gain, time_scale = gain * scales[0], time_scale * scales[1]
        return rudder, gain, time_scale

    def yaw_rate_bias(self, params: dict) -> float:
        """What the yaw-rate sensor reads (rad/s) when the hull does not turn (gyro bias)."""
        return float(self.measured_yaw_rate(np.zeros(1), params)[0])

    def measured_yaw_rate(self, r: np.ndarray, params: dict) -> np.ndarray:
        for effect in self.effects:
            r = effect.measured_yaw_rate(r, params)
        return r

    # --- regression -------------------------------------------------------
    def regression(self, signals) -> Regression:
        """Build ``r = X w`` on the usable rows; effects may fix parameters first."""
        fixed = {}
        for effect in self.effects:
            fixed.update(effect.prepare(signals))
        s = signals
        scale_k = s.base_column_scales.get("K", 1.0)
        scale_t = s.base_column_scales.get("T", 1.0)
        if self.order == 1:
            cols = {"r'": s.r_dot * scale_t, "delta": s.delta * scale_k}
        else:
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
        return Regression(X=X, y=s.r[rows], columns=list(cols), fixed=fixed, signals=s)

    def parameters_from_coefficients(self, w: np.ndarray, regression: Regression) -> tuple[dict, list[str]]:
        """Closed-form map from regression coefficients to physical parameters, with flags."""
        c = dict(zip(regression.columns, w))
        flags = []
        base = {"K": c["delta"]}
        if self.order == 1:
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
        params = dict(base)
        for effect in self.effects:
            params.update(effect.from_coefficients(c, base))
        params.update(regression.fixed)
        for p in self.parameters:
            if not p.lower <= params[p.name] <= p.upper:
                flags.append(f"{p.name}_out_of_bounds")
        return params, flags

    def clip_to_bounds(self, params: dict) -> dict:
        """Parameters moved just inside their physical bounds (K > 0, T > 0, T3 >= 0, ...)."""
        out = dict(params)
        for p in self.parameters:
            v = out[p.name]
            if not np.isfinite(v):
                v = p.initial
            span = 1e-6 * max(1.0, abs(v))
            lo = p.lower + (span if np.isfinite(p.lower) and p.lower > 0 else 0.0)
            out[p.name] = float(np.clip(v, lo, p.upper))
        return out


def parse_effects(effects) -> tuple[str, ...]:
    """Effect names from a comma-separated string or a sequence of names ("", None or (): no
    effects); StructureError for a name not in ``effects.EFFECTS`` (naming those) or one listed twice."""
    items = (effects or "").split(",") if isinstance(effects, str) or effects is None else effects
    names = tuple(str(e).strip() for e in items if str(e).strip())
    unknown = [e for e in names if e not in EFFECTS]
    if unknown:
        raise StructureError(f"unknown effect {unknown[0]!r}; choose from {', '.join(EFFECTS)}")
    if len(set(names)) != len(names):
        raise StructureError(f"effect listed twice: {', '.join(names)}")
    return names


def require_samples(dataset: Dataset, minimum: int = 20) -> None:
    if dataset.n_samples < minimum:
        raise DataError(f"only {dataset.n_samples} samples; need at least {minimum}")
