"""Physical effects as plug-ins.

An effect is one object: a name, a sentence a sailor understands, its
parameters (SI units), and hooks that say how it acts

* in simulation: on the rudder (``effective_rudder``), as a yaw forcing
  (``forcing_terms``), on the gains and time constants through speed
  (``speed_scales``), or on the yaw-rate sensor (``measured_yaw_rate``);
* in the equation-error regression: extra regressor columns and the map
  from their coefficients back to the effect's parameters;
* in diagnosis: ``evidence``, a score of how strongly the free-run residual
  carries the effect's signature, and a sentence saying so.

Every hook has a neutral default, so a new effect writes only what it
changes. Register it with ``register_effect`` (see docs/diagnose.md, "Adding an effect").
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from .integrate import TRIG_COS, TRIG_NONE, TRIG_SIN

BOUND_SHARE = 0.01  # a parameter within 1 % of a physical bound is on it (Parameter.bound_reached)


def on_bound(value: float, bound: float) -> bool:
    """Whether ``value`` sits on the finite ``bound``.

    Within ``BOUND_SHARE`` of the bound (plus 1e-6 in the parameter's SI unit, for a bound at or
    near zero) is on it: a bounded search that runs off along a ridge of the cost (T1 -> infinity
    with K and alpha, for a window no model fits) stops within a fraction of a percent of the bound
    it was running to, not exactly on it.

    Parameters
    ----------
    value, bound : float
        A parameter's value and one of its bounds, in its SI unit.

    Returns
    -------
    bool
        True when the value is on the bound; False for an infinite bound.
    """
    return bool(np.isfinite(bound) and abs(value - bound) <= BOUND_SHARE * abs(bound) + 1e-6 * max(1.0, abs(bound)))


@dataclass(frozen=True)
class Parameter:
    """A physical parameter: SI unit, starting value and physical bounds for fits."""

    name: str
    unit: str
    description: str
    initial: float = 0.0
    lower: float = -np.inf
    upper: float = np.inf
    display_unit: str = ""  # e.g. "deg" for angles shown to people
    display_scale: float = 1.0  # SI value * display_scale = display value

    def bound_reached(self, value: float) -> float | None:
        """The physical bound ``value`` sits on, or None.

        See ``on_bound`` for the tolerance.

        Parameters
        ----------
        value : float
            The parameter's value, in its SI unit.

        Returns
        -------
        float or None
            The lower or upper bound reached, None when the value is inside both.
        """
        return next((float(b) for b in (self.lower, self.upper) if on_bound(value, b)), None)


@dataclass(frozen=True)
class ForcingTerm:
    """One additive yaw forcing term ``coefficient * r**r_power * |r|**abs_power * trig(harmonic*psi)`` (rad/s)."""

    coefficient: float
    r_power: int = 0
    abs_power: int = 0
    harmonic: int = 0
    trig: int = TRIG_NONE


def heading_harmonics(psi: np.ndarray) -> dict:
    """The first two harmonics of the heading: a steady wind or current's yaw forcing along it.

    Parameters
    ----------
    psi : ndarray
        Heading (rad).

    Returns
    -------
    dict
        cos(k psi) and sin(k psi) for k = 1, 2 (dimensionless), by column name ("cos(1psi)", ...),
        the wind_yaw effect's regression columns.
    """
    return {f"{f.__name__}({k}psi)": f(k * psi) for k in (1, 2) for f in (np.cos, np.sin)}


@dataclass
class Evidence:
    """How strongly the residual points to an effect: a score (larger: stronger) and a sentence.

    ``feature`` is what the residual was tested against (for the report's
    residual-versus-feature plot), ``feature_label`` names it with the unit
    shown, ``feature_scale`` turns SI into that unit, and ``residual`` is the
    residual tested when it is not the context's equation residual.
    """

    score: float
    sentence: str
    feature: np.ndarray | None = None
    feature_label: str = ""
    feature_scale: float = 1.0
    residual: np.ndarray | None = None


@dataclass
class StartContext:
    """What an effect's ``starts`` reads.

    The training data (a ``Dataset``), ``nested``, the fitted
    parameters of the model without the effect, and ``refit(dataset)``, that model's cheap
    regression fit (parameters) on other data, e.g. the training data seen through the effect."""

    training: object
    nested: dict
    refit: Callable[[object], dict]


T_UPPER_BOUND = 1e3  # s, the base models' upper bound on T and T1 (structure.BASE_MODELS)


def yaw_time_constant(params: dict) -> float:
    """The hull's yaw time constant (s), the mean delay the diagnosis's time scales are drawn from.

    T, T1 + T2, or the acceleration form's 1 / |a1| (T1 + T2 when it is stable; the time a
    course-unstable turn takes to grow by e when not), at most ``T_UPPER_BOUND``. T1 + T2 rather
    than T1: it is the mean delay (first moment) of the yaw rate's impulse response
    1 / ((1 + T1 s)(1 + T2 s)), how long a yaw rate, and the information in an initial state, lasts;
    it is the coefficient of r' (1 / a1 in the acceleration form, where T1 alone needs the roots),
    and it stays smooth where T1 and T2 meet and trade places.

    Parameters
    ----------
    params : dict
        A parameter set of any model form (s, 1/s).

    Returns
    -------
    float
        The time constant (s); 1 s for a set without any.
    """
    if "T" in params:
        return float(params["T"])
    if "T1" in params:
        return float(params["T1"] + params.get("T2", 0.0))
    if "a1" in params:
        slow = 1.0 / max(abs(params["a1"]), 1e-12)
        return float(min(slow, T_UPPER_BOUND))
    return 1.0


def slow_time_constant(params: dict) -> float:
    """The hull's slow pole's time constant (s): T, T1, or the acceleration form's 1 / |a1|.

    The time a change of rudder takes to settle into a new steady turn, which sets how much new data
    a refit of the gain alone needs (``change``, the gain followed ``online``) and how long a shooting
    interval of the output-error search must be to learn K (``OutputError.shooting_length``); the
    mean delay ``yaw_time_constant`` (T1 + T2) is the longer of the two, and a refit on that much
    new data comes later after a change.

    Parameters
    ----------
    params : dict
        A parameter set of any model form (s, 1/s).

    Returns
    -------
    float
        The time constant (s), at most ``T_UPPER_BOUND``; 0 for a set without any.
    """
    if "T" in params:
        return float(params["T"])
    if "T1" in params:
        return float(params["T1"])
    if "a1" in params:
        return float(min(1.0 / max(abs(params["a1"]), 1e-12), T_UPPER_BOUND))
    return 0.0


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    a = a - a.mean()
    b = b - b.mean()
    den = np.sqrt((a @ a) * (b @ b))
    return float(a @ b / den) if den > 0 else 0.0


def _partial_corr(residual: np.ndarray, feature: np.ndarray, controls: list[np.ndarray]) -> float:
    """Correlation of residual and feature after removing the controls' linear part from the feature."""
    if controls:
        C = np.column_stack([np.ones_like(feature)] + controls)
        feature = feature - C @ np.linalg.lstsq(C, feature, rcond=None)[0]
    return _corr(residual, feature)


class Effect:
    """Base class: a physical effect that can be added to a Nomoto model."""

    name: str = ""
    explanation: str = ""
    parameters: tuple[Parameter, ...] = ()
    needs_speed: bool = False
    # the yaw damping this effect adds can hold a linear damping of either sign: the structure is
    # fitted in the acceleration form (structure.py), where a weak or negative damping is determined
    frees_linear_damping: bool = False
    # parameters that scale a yaw forcing term (per unit of the yaw equation's leading coefficient)
    forcing_parameters: tuple[str, ...] = ()
    # effects whose term this one includes, each with {their parameter: this effect's parameter}
    replaces: dict = {}

    # --- simulation hooks -------------------------------------------------
    def effective_rudder(self, time: np.ndarray, rudder: np.ndarray, p: dict) -> np.ndarray:
        """Rudder angle that acts on the hull, given the measured one (a dead band, an offset, a delay).

        Parameters
        ----------
        time : numpy.ndarray
            Sample times (s).
        rudder : numpy.ndarray
            The measured rudder angle (rad).
        p : dict
            The model's parameters (SI units), this effect's among them.

        Returns
        -------
        numpy.ndarray
            The effective rudder angle (rad), per sample.
        """
        return rudder

    def forcing_terms(self, p: dict) -> list[ForcingTerm]:
        """State-dependent yaw forcing terms added to the right-hand side of the yaw equation.

        Parameters
        ----------
        p : dict
            The model's parameters (SI units), this effect's among them.

        Returns
        -------
        list of ForcingTerm
            Additive terms of the yaw-rate equation (rad/s per time constant); none by default.
        """
        return []

    def speed_scales(self, speed: np.ndarray, p: dict) -> tuple[np.ndarray, np.ndarray] | None:
        """Per-sample multipliers of the gain K and of the time constants, for an effect of the speed.

        The non-dimensional Nomoto model keeps K L / U and T U / L (L the hull's length) whatever the
        speed U: the gain grows as U and the time constants shrink as 1 / U.

        Parameters
        ----------
        speed : numpy.ndarray
            Measured speed through the water (m/s), per sample.
        p : dict
            The model's parameters (SI units), this effect's among them.

        Returns
        -------
        tuple of numpy.ndarray or None
            (gain multiplier, time-constant multiplier) per sample (dimensionless); None for an effect
            that does not scale with speed.
        """
        return None

    def measured_yaw_rate(self, yaw_rate: np.ndarray, p: dict) -> np.ndarray:
        """What the yaw-rate sensor reads when the hull turns at ``yaw_rate`` (a bias, a scale error).

        Parameters
        ----------
        yaw_rate : numpy.ndarray
            The hull's true yaw rate (rad/s).
        p : dict
            The model's parameters (SI units), this effect's among them.

        Returns
        -------
        numpy.ndarray
            The sensor's reading (rad/s).
        """
        return yaw_rate

    # --- regression hooks -------------------------------------------------
    def prepare(self, signals) -> dict:
        """Parameters fixed before the regression (e.g. a reference speed); may adjust ``signals``.

        Parameters
        ----------
        signals : Signals
            The regression's signals (rudder rad, heading rad, yaw rate rad/s and its derivatives).

        Returns
        -------
        dict
            Fixed parameter values (SI units); none by default.
        """
        return {}

    def regressors(self, signals) -> dict[str, np.ndarray]:
        """Extra regressor columns of the equation-error regression ``r = X w``.

        Parameters
        ----------
        signals : Signals
            The regression's signals.

        Returns
        -------
        dict
            Column name -> values, one per sample.
        """
        return {}

    def from_coefficients(self, coefficients: dict, base: dict) -> dict:
        """This effect's parameters from its regression coefficients and the base model's (closed form).

        Parameters
        ----------
        coefficients : dict
            Regression coefficients by column name.
        base : dict
            The base model's parameters mapped back (K 1/s, time constants s).

        Returns
        -------
        dict
            This effect's parameters (SI units); their initial values by default.
        """
        return {p.name: p.initial for p in self.parameters}

    def neutral(self) -> dict:
        """Values of the free parameters at which the effect does nothing.

        The model without it, where a fit with the effect can start (every effect here vanishes at zero).

        Returns
        -------
        dict
            Parameter -> neutral value (SI units).
        """
        return {p.name: 0.0 for p in self.parameters if p.name not in getattr(self, "fixed", ())}

    def starts(self, context: StartContext) -> list[dict]:
        """Extra starting points for a fit with this effect, for parameters with several minima.

        For parameters that enter non-smoothly or have several minima: a local search from the model
        without the effect would stay in the nearest minimum.

        Parameters
        ----------
        context : StartContext
            The training data, the nested model's parameters and its cheap refit.

        Returns
        -------
        list of dict
            Full parameter sets (SI units); none by default.
        """
        return []

    # --- diagnosis --------------------------------------------------------
    def evidence(self, context) -> Evidence:
        """Signature of this effect in the free-run residual (see ``diagnose.ResidualContext``).

        Parameters
        ----------
        context : ResidualContext
            The base model's free-run residual and the signals it is tested against.

        Returns
        -------
        Evidence
            A score (larger: stronger) and a sentence; no evidence test by default.
        """
        return Evidence(0.0, f"no evidence test for {self.name}")


class RudderOffset(Effect):
    name = "rudder_offset"
    explanation = (
        "the boat holds a turn with the rudder at zero: a constant yaw moment "
        "(rudder misalignment, propeller asymmetry) worth a fixed rudder angle"
    )
    parameters = (Parameter("delta_r", "rad", "equivalent rudder offset", 0.0, -0.35, 0.35, "deg", np.degrees(1.0)),)

    def effective_rudder(self, time, rudder, p):
        return rudder + p["delta_r"]

    def regressors(self, signals):
        return {"1": np.ones_like(signals.r)}

    def from_coefficients(self, coefficients, base):
        return {"delta_r": coefficients["1"] / base["K"]}

    def evidence(self, context):
        e = context.equation_residual
        t = float(np.mean(e) / (np.std(e) / np.sqrt(max(context.effective_samples, 1)) + 1e-12))
        side = "starboard" if np.mean(e) > 0 else "port"
        return Evidence(
            abs(t),
            f"the model's yaw-rate error has a steady bias to {side} "
            f"(t = {t:.1f}): a constant turning moment the rudder does not explain",
            context.signals.delta,
            "rudder (deg)",
            np.degrees(1.0),
        )


class CubicYaw(Effect):
    name = "cubic_yaw"
    explanation = (
        "the boat's resistance to turning changes in tight turns: yaw damping grows "
        "(or shrinks) with the cube of the turn rate"
    )
    parameters = (Parameter("alpha", "s^2/rad^2", "cubic yaw damping coefficient", 0.0, -1e7, 1e7),)
    forcing_parameters = ("alpha",)

    def forcing_terms(self, p):
        return [ForcingTerm(-p["alpha"], r_power=3)]

    def regressors(self, signals):
        return {"r^3": signals.r**3}

    def from_coefficients(self, coefficients, base):
        return {"alpha": -coefficients["r^3"]}

    def data_bounds(self, dataset) -> dict:
        """Bounds of alpha (s^2/rad^2) that keep the model stable over the turn rates the data
        reach: about a steady turn r0 the linearised model damps with 1 + 3 alpha r0^2, so
        alpha >= -1 / (3 r_max^2), r_max the largest measured |yaw rate| (rad/s). A negative
        alpha beyond it makes a turn the boat was seen to make run away (the free run
        diverges); the limit is the data's, not the sign's (seed 001's own alpha is negative)."""
        r_max = float(np.max(np.abs(dataset.yaw_rate))) if dataset.n_samples else 0.0
        alpha = self.parameters[0]
        lower = max(alpha.lower, -1.0 / (3.0 * r_max**2)) if r_max > 0 else alpha.lower
        return {"alpha": (lower, alpha.upper)}

    def evidence(self, context):
        c = _partial_corr(context.equation_residual, context.signals.r**3, [context.signals.r])
        return Evidence(
            abs(c) * np.sqrt(context.effective_samples),
            f"the error grows with the turn rate cubed (correlation {c:+.2f}): damping is not linear in tight turns",
            context.signals.r,
            "yaw rate (deg/s)",
            np.degrees(1.0),
        )


DELAY_GRID_POINTS = 10  # rudder delays profiled before the local refinement
BEYOND_GRID_POINTS = 3  # ... and from the yaw time constant up to the bound


def lead_compensated(nested: dict, tau: float) -> dict | None:
    """The parameters of a model fitted without a rudder dead time ``tau`` (s) with the delay added
    and the lead it hid in given back: T3 + tau on nomoto2, T - tau on nomoto1 (at least a tenth of
    T); None for a form without either (the acceleration form)."""
    if "T3" in nested:
        return dict(nested, T3=nested["T3"] + tau, tau=tau)
    if "T" in nested:
        return dict(nested, T=max(nested["T"] - tau, 0.1 * nested["T"]), tau=tau)
    return None


class RudderDelay(Effect):
    name = "rudder_delay"
    explanation = (
        "the hull answers the rudder later than the rudder sensor says: a dead time "
        "in the steering gear, the sensor or the data link"
    )
    parameters = (Parameter("tau", "s", "rudder dead time", 0.05, 0.0, 5.0),)

    def effective_rudder(self, time, rudder, p):
        return np.interp(time - p["tau"], time, rudder)

    def starts(self, context):
        """Profile the dead time over a grid relative to the vessel and the log: ``DELAY_GRID_POINTS``
        delays spaced geometrically from two sample times (or 5 % of the yaw time constant T1 + T2,
        whichever is longer) up to that time constant (at most the 5 s bound); at each delay the
        model without it is refitted by regression on the delayed rudder. A delay of a few seconds
        otherwise hides in T2 and T3 (a lag looks like a slow second pole), and the search from
        tau = 0 stays there.

        Each delay also starts from the model without it with its lead given back
        (``lead_compensated``): at low frequencies a dead time and a rudder lead cancel,
        exp(-tau s) (1 + T3 s) ~ 1 + (T3 - tau) s, so a model fitted without the delay shows the
        lead T3 - tau (or, on nomoto1, the time constant T + tau); a search started at the delay
        with the lead it had stays in that valley, at a fraction of the true delay."""
        data, nested = context.training, context.nested
        upper = self.parameters[0].upper
        time_constant = yaw_time_constant(nested)
        shortest = min(max(2.0 * data.sample_time, 0.05 * time_constant), upper)
        longest = float(np.clip(time_constant, shortest, upper))
        grid = np.geomspace(shortest, longest, DELAY_GRID_POINTS)
        if longest < upper:  # a base fit without the delay can miss the hull: its time constant bounds nothing
            grid = np.concatenate([grid, np.geomspace(longest, upper, BEYOND_GRID_POINTS + 1)[1:]])
        out = []
        for tau in grid:
            delayed = replace(data, rudder=self.effective_rudder(data.time, data.rudder, {"tau": tau}))
            out.append(dict(context.refit(delayed), tau=float(tau)))
            compensated = lead_compensated(nested, float(tau))
            if compensated is not None:
                out.append(compensated)
        return out

    def evidence(self, context):
        c = _partial_corr(context.equation_residual, -context.signals.delta_dot, [context.signals.delta])
        note = ""
        if context.parameters.get("T3", 1.0) <= 1e-6 or context.parameters.get("T3", 1.0) < 0:
            note = "; T3 is pinned at its bound 0, which is what a delay looks like"
        return Evidence(
            max(c, 0.0) * np.sqrt(context.effective_samples),
            f"the error follows the rudder rate with the sign of a lag "
            f"(correlation {c:+.2f}){note}: the hull answers later than the sensor says",
            context.signals.delta_dot,
            "rudder rate (deg/s)",
            np.degrees(1.0),
        )


class WindYaw(Effect):
    name = "wind_yaw"
    explanation = (
        "a steady wind or current turns the bow depending on the heading: the boat "
        "needs different rudder on different courses"
    )
    parameters = tuple(
        Parameter(
            f"wind_{kind}{k}",
            "rad/s",
            f"{kind} harmonic {k} of heading of the wind/current yaw forcing",
            0.0,
            -1.0,
            1.0,
        )
        for k in (1, 2)
        for kind in ("c", "s")
    )
    forcing_parameters = tuple(p.name for p in parameters)

    def forcing_terms(self, p):
        return [ForcingTerm(p[f"wind_c{k}"], harmonic=k, trig=TRIG_COS) for k in (1, 2)] + [
            ForcingTerm(p[f"wind_s{k}"], harmonic=k, trig=TRIG_SIN) for k in (1, 2)
        ]

    def regressors(self, signals):
        return heading_harmonics(signals.psi)

    def from_coefficients(self, coefficients, base):
        return {
            f"wind_{'c' if f == 'cos' else 's'}{k}": coefficients[f"{f}({k}psi)"]
            for k in (1, 2)
            for f in ("cos", "sin")
        }

    def evidence(self, context):
        e = context.equation_residual
        psi = context.signals.psi
        C = np.column_stack(list(heading_harmonics(psi).values()))
        C = C - C.mean(axis=0)
        e0 = e - e.mean()
        coef = np.linalg.lstsq(C, e0, rcond=None)[0]
        r2 = 1 - np.sum((e0 - C @ coef) ** 2) / max(np.sum(e0**2), 1e-30)
        spread = np.ptp(np.mod(psi, 2 * np.pi)) if len(psi) else 0.0
        return Evidence(
            r2 * np.sqrt(context.effective_samples) * min(1.0, spread / np.pi),
            f"the error depends on the heading ({100 * r2:.0f} % of it explained by "
            "heading harmonics): a steady wind or current pushes the bow",
            np.mod(psi, 2 * np.pi),
            "heading (deg)",
            np.degrees(1.0),
        )


class GyroBias(Effect):
    name = "gyro_bias"
    explanation = (
        "the rate gyro reads a small turn when the boat goes straight: its yaw rate "
        "disagrees with how fast the compass heading actually changes"
    )
    parameters = (Parameter("r_bias", "rad/s", "yaw-rate sensor bias", 0.0, -0.2, 0.2, "deg/s", np.degrees(1.0)),)

    def measured_yaw_rate(self, yaw_rate, p):
        return yaw_rate + p["r_bias"]

    def prepare(self, signals):
        bias = float(np.mean(signals.r_measured - signals.heading_rate))
        signals.r = signals.r - bias
        return {"r_bias": bias}

    def from_coefficients(self, coefficients, base):
        return {}

    def evidence(self, context):
        d = context.signals.r_measured - context.signals.heading_rate
        t = float(np.mean(d) / (np.std(d) / np.sqrt(max(context.effective_samples, 1)) + 1e-12))
        return Evidence(
            abs(t),
            f"the gyro's yaw rate and the heading's rate of change differ "
            f"by {np.degrees(np.mean(d)):+.3f} deg/s on average (t = {t:.1f})",
            context.signals.r,
            "yaw rate (deg/s)",
            np.degrees(1.0),
            residual=d,
        )


class SpeedDependence(Effect):
    name = "speed_dependence"
    explanation = (
        "the boat steers differently at different speeds: the rudder is stronger and "
        "the hull answers faster when it goes faster"
    )
    needs_speed = True
    parameters = (
        Parameter("U_ref", "m/s", "reference speed at which K and T hold (fixed: median speed)", 1.0, 0.0, np.inf),
        Parameter("n_K", "-", "exponent of K in U/U_ref (1: K ~ U, the non-dimensional Nomoto form)", 1.0, 0.0, 2.0),
        Parameter("n_T", "-", "exponent of the time constants in U_ref/U (1: T ~ 1/U)", 1.0, 0.0, 2.0),
    )
    fixed = ("U_ref",)

    def speed_scales(self, speed, p):
        ratio = np.maximum(speed, 0.05 * p["U_ref"]) / p["U_ref"]
        return ratio ** p["n_K"], ratio ** (-p["n_T"])

    def prepare(self, signals):
        if signals.speed is None:
            raise ValueError("speed_dependence needs a speed signal (a /usv/speed topic or a speed column)")
        u_ref = float(np.median(signals.speed))
        ratio = np.maximum(signals.speed, 0.05 * u_ref) / u_ref
        signals.base_column_scales = {"K": ratio, "T": 1.0 / ratio}
        return {"U_ref": u_ref}

    def from_coefficients(self, coefficients, base):
        return {"n_K": 1.0, "n_T": 1.0}

    def starts(self, context):
        """The non-dimensional Nomoto form, K ~ U and T ~ 1/U, from the model without the effect."""
        return [dict(context.nested, n_K=1.0, n_T=1.0)]

    def evidence(self, context):
        if context.signals.speed is None or np.std(context.signals.speed) < 1e-6:
            return Evidence(0.0, "no speed variation in the data: speed dependence cannot be seen")
        s = context.signals
        feature = (s.speed - np.median(s.speed)) * s.delta
        c = _partial_corr(context.equation_residual, feature, [s.delta])
        return Evidence(
            abs(c) * np.sqrt(context.effective_samples),
            f"the error follows rudder times speed change (correlation {c:+.2f}): "
            "the rudder's effect changes with speed",
            feature,
            "rudder x speed change (deg m/s)",
            np.degrees(1.0),
        )


class CourseInstability(Effect):
    name = "course_instability"
    explanation = (
        "the ship does not hold a straight course by itself: left alone it turns one way "
        "or the other (negative linear yaw damping), and only the growing damping of a "
        "faster turn keeps the turn bounded"
    )
    parameters = (
        Parameter(
            "a3",
            "s/rad^2",
            "cubic yaw damping per unit yaw inertia that bounds the unstable turn",
            0.0,
            0.0,
            1e7,
        ),
    )
    frees_linear_damping = True  # the linear damping a1 of the acceleration form, of either sign
    forcing_parameters = ("a3",)
    replaces = {"cubic_yaw": {"alpha": "a3"}}

    def forcing_terms(self, p):
        return [ForcingTerm(-p["a3"], r_power=3)]

    def regressors(self, signals):
        return {"r^3": signals.r**3}

    def from_coefficients(self, coefficients, base):
        return {"a3": -coefficients["r^3"]}

    def starts(self, context):
        """The sign of the linear damping: a search from the stable model never crosses the region
        where the simulation diverges, so it also starts from a1 at 0.5, 0, -0.25 and -0.5 times
        the stable start's, with the cubic damping that holds the unstable turn at about half the
        largest measured rate (a1 r + a3 r^3 = 0 there)."""
        r_max = float(np.max(np.abs(context.training.yaw_rate))) or 1e-3
        a1 = abs(context.nested["a1"])
        return [
            dict(context.nested, a1=share * a1, a3=max(-share, 0.05) * a1 / (0.5 * r_max) ** 2)
            for share in (0.5, 0.0, -0.25, -0.5)
        ]

    def evidence(self, context):
        s = context.signals
        c = _partial_corr(context.equation_residual, s.r, [s.delta])
        pinned = any(on_bound(context.parameters.get(name, 0.0), T_UPPER_BOUND) for name in ("T", "T1"))
        note = (
            "; the time constant sits on its upper bound, which is what course instability looks like" if pinned else ""
        )
        return Evidence(
            (abs(c) + (1.0 if pinned else 0.0)) * np.sqrt(context.effective_samples),
            f"the error follows the turn rate itself (correlation {c:+.2f}){note}: "
            "the linear yaw damping is not what the model assumes",
            s.r,
            "yaw rate (deg/s)",
            np.degrees(1.0),
        )


class QuadraticYaw(Effect):
    name = "quadratic_yaw"
    explanation = (
        "the hull's resistance to turning grows with the square of the turn rate "
        "(cross-flow drag, as on small fast boats)"
    )
    parameters = (
        Parameter(
            "d_q",
            "1/rad",
            "quadratic yaw damping per unit yaw inertia: forcing -d_q r|r|",
            0.0,
            -1e4,
            1e4,
        ),
    )
    frees_linear_damping = True  # cross-flow drag holds a hull whose linear yaw damping is weak or negative
    forcing_parameters = ("d_q",)

    def forcing_terms(self, p):
        return [ForcingTerm(-p["d_q"], r_power=1, abs_power=1)]

    def regressors(self, signals):
        return {"r|r|": signals.r * np.abs(signals.r)}

    def from_coefficients(self, coefficients, base):
        return {"d_q": -coefficients["r|r|"]}

    def evidence(self, context):
        s = context.signals
        c = _partial_corr(context.equation_residual, s.r * np.abs(s.r), [s.r])
        return Evidence(
            abs(c) * np.sqrt(context.effective_samples),
            f"the error grows with the turn rate squared, with its sign (correlation {c:+.2f}): "
            "the hull's turning resistance is quadratic",
            s.r,
            "yaw rate (deg/s)",
            np.degrees(1.0),
        )


class RudderStall(Effect):
    name = "rudder_stall"
    explanation = (
        "the rudder turns the boat less than proportionally at large angles: the flow "
        "over it separates (stall) or its lift saturates"
    )
    parameters = (
        Parameter("c_stall", "1/rad^2", "rudder moment loss: acting rudder d (1 - c_stall d^2)", 0.0, -1.0, 0.9),
    )

    def effective_rudder(self, time, rudder, p):
        """Lift that grows less than linearly; c_stall < 0.9 keeps it increasing up to 35 deg."""
        return rudder * (1.0 - p["c_stall"] * rudder**2)

    def regressors(self, signals):
        return {"delta^3": signals.delta**3}

    def from_coefficients(self, coefficients, base):
        return {"c_stall": -coefficients["delta^3"] / base["K"] if base["K"] else 0.0}

    def evidence(self, context):
        s = context.signals
        c = _partial_corr(context.equation_residual, s.delta**3, [s.delta])
        return Evidence(
            abs(c) * np.sqrt(context.effective_samples),
            f"the error follows the rudder angle cubed (correlation {c:+.2f}): the rudder's "
            "moment does not grow in proportion at large angles",
            s.delta,
            "rudder (deg)",
            np.degrees(1.0),
        )


EFFECTS: dict[str, Effect] = {}


def register_effect(effect: Effect) -> Effect:
    """Make an effect available by name to every front door (CLI, node, diagnosis)."""
    if not effect.name:
        raise ValueError("an effect needs a name")
    EFFECTS[effect.name] = effect
    return effect


for _effect in (
    RudderOffset(),
    CubicYaw(),
    RudderDelay(),
    WindYaw(),
    GyroBias(),
    SpeedDependence(),
    CourseInstability(),
    QuadraticYaw(),
    RudderStall(),
):
    register_effect(_effect)
