"""USV steering simulator with known truth: manoeuvres, actuator, sensors.

A manoeuvre is planned closed loop (zigzags switch on heading deviation)
on a fine internal step; the rudder then passes a rate-limited, saturated
actuator, and the vessel's true response is integrated by the same RK4
kernel the estimators use, on the fine step (0.01 s, rudder piecewise
linear between fine steps), before sampling at ``sample_time`` and adding
sensor noise. Heading is output wrapped to (-pi, pi] as a compass gives it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .dataset import Dataset
from .structure import Structure

MANEUVERS = ("zigzag10", "zigzag20", "turning", "random", "mixed", "steps", "steady_turns", "legs")


@dataclass(frozen=True)
class Vessel:
    """A vessel preset: true parameters (SI) of nomoto2 and of every effect, speed and actuator."""

    name: str
    description: str
    parameters: dict
    seed_effects: tuple = ()  # effects the preset carries by default
    speed: float = 2.0  # m/s, nominal
    rudder_rate: float = np.radians(20.0)  # rad/s
    rudder_limit: float = np.radians(35.0)  # rad


_EFFECT_TRUTH = {
    "delta_r": 0.0093,
    "alpha": -0.1239,
    "tau": 0.5,
    "wind_c1": 0.012,
    "wind_s1": -0.008,
    "wind_c2": 0.004,
    "wind_s2": 0.0,
    "r_bias": np.radians(0.5),
    "n_K": 1.0,
    "n_T": 1.0,
}

VESSELS = {
    "seed001": Vessel(
        "seed001",
        "seed 001 Table 1 simulation vessel (fast small USV)",
        dict(_EFFECT_TRUTH, K=0.5883, T1=1.4397, T2=0.1202, T3=0.0440, T=1.4397 + 0.1202 - 0.0440),
        seed_effects=("rudder_offset", "cubic_yaw"),
        speed=2.0,
    ),
    "usv75": Vessel(
        "usv75",
        "typical 7.5 m USV (seed 001 Tables 5-6: Lpp 7.5 m, 2.97 t)",
        dict(_EFFECT_TRUTH, K=0.35, T1=4.30, T2=0.40, T3=0.20, T=4.30 + 0.40 - 0.20, alpha=2.0, delta_r=0.012),
        seed_effects=("rudder_offset", "cubic_yaw"),
        speed=3.0,
        rudder_rate=np.radians(15.0),
    ),
}


# Ranges of the randomised vessels (log-uniform unless said): quick USVs to slow ships.
VESSEL_KINDS = {
    # K (1/s), T1 (s), T2 / T1, T3 (s), rudder rate (deg/s), rudder limit (deg), speed (m/s)
    "usv": dict(
        K=(0.15, 0.8),
        T1=(1.0, 12.0),
        T2_share=(0.03, 0.3),
        T3=(0.0, 2.5),
        rudder_rate=(10.0, 30.0),
        rudder_limit=(30.0, 35.0),
        speed=(1.5, 6.0),
    ),
    "ship": dict(
        K=(0.03, 0.15),
        T1=(15.0, 80.0),
        T2_share=(0.03, 0.2),
        T3=(0.0, 10.0),
        rudder_rate=(2.3, 5.0),
        rudder_limit=(35.0, 35.0),
        speed=(4.0, 8.0),
    ),
}


def random_vessel(rng: np.random.Generator, kind: str = "any") -> Vessel:
    """A vessel drawn at random over wide ranges (``VESSEL_KINDS``).

    ``any``: a USV two times in three, else a slow ship. T2 is a share of T1 and capped at 1.5 s for
    USVs; the cubic damping alpha is drawn so that alpha r^2 lies in [-0.1, 0.5] at the turn rate of
    the rudder at its limit (K * limit): with alpha < 0 the steady turn r + alpha r^3 = K delta exists
    only while -alpha (K delta)^2 < 4/27, so every rudder the gear can give still ends in a steady
    turn (a draw at -0.2 for 20 deg of rudder spun up without bound at 25 deg); the rudder offset in
    +-1.5 deg; all other effect parameters take the presets' values. The name carries the drawn
    values, so a failing case can be read off.

    Parameters
    ----------
    rng : numpy.random.Generator
        The random source.
    kind : str
        'usv', 'ship' or 'any'.

    Returns
    -------
    Vessel
        Its name, description, true parameters (SI units) and effects.
    """
    if kind == "any":
        kind = "usv" if rng.uniform() < 2 / 3 else "ship"
    if kind not in VESSEL_KINDS:
        raise ValueError(f"unknown vessel kind {kind!r}; choose from any, {', '.join(VESSEL_KINDS)}")
    ranges = VESSEL_KINDS[kind]

    def log_uniform(lo, hi):
        return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))

    k_gain, t1 = log_uniform(*ranges["K"]), log_uniform(*ranges["T1"])
    t2 = t1 * rng.uniform(*ranges["T2_share"])
    t2 = min(t2, 1.5) if kind == "usv" else t2
    t3 = float(rng.uniform(*ranges["T3"]))
    damping_at_limit = float(rng.uniform(-0.1, 0.5))  # alpha r^2 at the turn rate of full rudder
    delta_r = float(np.radians(rng.uniform(-1.5, 1.5)))
    speed = float(rng.uniform(*ranges["speed"]))
    rudder_rate = float(np.radians(rng.uniform(*ranges["rudder_rate"])))
    rudder_limit = float(np.radians(rng.uniform(*ranges["rudder_limit"])))
    parameters = dict(
        _EFFECT_TRUTH,
        K=k_gain,
        T1=t1,
        T2=t2,
        T3=t3,
        T=t1 + t2 - t3,
        alpha=damping_at_limit / (k_gain * rudder_limit) ** 2,
        delta_r=delta_r,
    )
    name = f"{kind}(K={k_gain:.3g},T1={t1:.3g},T2={t2:.3g},T3={t3:.3g})"
    return Vessel(
        name,
        f"random {kind}: " + ", ".join(f"{k}={parameters[k]:.4g}" for k in ("K", "T1", "T2", "T3", "alpha", "delta_r")),
        parameters,
        seed_effects=("rudder_offset", "cubic_yaw"),
        speed=speed,
        rudder_rate=rudder_rate,
        rudder_limit=rudder_limit,
    )


@dataclass(frozen=True)
class Noise:
    """Sensor noise standard deviations (SI): the realistic levels of the identification benchmarks."""

    rudder: float = np.radians(0.1)
    heading: float = np.radians(0.1)
    yaw_rate: float = np.radians(0.2)
    speed: float = 0.02

    def scaled(self, factor: float) -> Noise:
        """Every sensor's noise multiplied by ``factor``.

        Parameters
        ----------
        factor : float
            The multiple of these levels.

        Returns
        -------
        Noise
            The scaled levels (SI units).
        """
        return Noise(self.rudder * factor, self.heading * factor, self.yaw_rate * factor, self.speed * factor)


@dataclass
class Simulation:
    """Simulated measurements, the noise-free truth and the parameters behind them."""

    dataset: Dataset
    truth: dict
    structure: Structure
    true_heading: np.ndarray
    true_yaw_rate: np.ndarray
    true_rudder: np.ndarray
    info: dict = field(default_factory=dict)

    def truth_json(self) -> dict:
        return {
            "structure": self.structure.to_json(),
            "parameters": {k: self.truth[k] for k in self.structure.parameter_names},
            **self.info,
        }


def _plan_commands(
    maneuver: str, vessel: Vessel, duration: float, dt: float, rng: np.random.Generator, amplitude: float | None
) -> np.ndarray:
    """Rudder command (rad) on the fine grid, planned on a first-order model of the vessel."""
    p = vessel.parameters
    k_gain, t_eff = p["K"], max(p["T1"] + p["T2"] - p["T3"], 0.1)
    n = int(round(duration / dt)) + 1
    if maneuver == "mixed":
        parts = [("zigzag10", 0.25), ("zigzag20", 0.25), ("turning", 0.25), ("random", 0.25)]
        out = [_plan_commands(m, vessel, duration * f, dt, rng, None) for m, f in parts]
        cmd = np.concatenate(out)
        return np.resize(cmd, n) if len(cmd) != n else cmd
    cmd = np.zeros(n)
    if maneuver.startswith("zigzag"):
        amp = np.radians(float(maneuver[6:])) if amplitude is None else amplitude
        psi = r = 0.0
        side = 1.0
        for i in range(n):
            if side > 0 and psi >= amp:
                side = -1.0
            elif side < 0 and psi <= -amp:
                side = 1.0
            cmd[i] = side * amp
            r += dt * (k_gain * cmd[i] - r) / t_eff
            psi += dt * r
    elif maneuver == "turning":
        amp = np.radians(20.0) if amplitude is None else amplitude
        t = np.arange(n) * dt
        period = duration / 2
        phase = np.mod(t, period) / period
        sign = np.where(t < period, 1.0, -1.0)
        cmd = np.where((phase > 0.05) & (phase < 0.8), sign * amp, 0.0)
    elif maneuver == "random":
        amp = np.radians(25.0) if amplitude is None else amplitude
        i = 0
        while i < n:
            hold = int(rng.uniform(2.0, 12.0) / dt)
            cmd[i : i + hold] = rng.uniform(-amp, amp)
            i += hold
    elif maneuver == "steps":
        amp = np.radians(25.0) if amplitude is None else amplitude
        cmd = _held_angles(n, dt, rng, (4.0 * _time_scale(t_eff), 15.0 * _time_scale(t_eff)), (-amp, amp))
    elif maneuver == "steady_turns":
        amp = np.radians(25.0) if amplitude is None else amplitude
        scale = _time_scale(t_eff)
        cmd = _held_angles(n, dt, rng, (30.0 * scale, 120.0 * scale), (0.2 * amp, amp), alternate=True)
    elif maneuver == "legs":
        cmd = _straight_legs(n, dt, rng, k_gain, t_eff, np.radians(10.0) if amplitude is None else amplitude)
    else:
        raise ValueError(f"unknown maneuver {maneuver!r}; choose from {', '.join(MANEUVERS)}")
    return cmd


def _time_scale(t_eff: float) -> float:
    """How much slower than a 10 s hull the vessel answers (1 for USVs): holds and legs stretch by it."""
    return max(1.0, t_eff / 10.0)


def _held_angles(
    n: int, dt: float, rng: np.random.Generator, hold_s: tuple, angle: tuple, alternate: bool = False
) -> np.ndarray:
    """Rudder angles (rad) drawn uniformly in ``angle``, each held for a time drawn in ``hold_s``
    (s); ``alternate``: every other hold to the other side (turns to port and starboard)."""
    cmd = np.zeros(n)
    i, side = 0, 1.0
    while i < n:
        hold = max(1, int(rng.uniform(*hold_s) / dt))
        cmd[i : i + hold] = side * rng.uniform(*angle)
        side = -side if alternate else side
        i += hold
    return cmd


def _straight_legs(
    n: int, dt: float, rng: np.random.Generator, k_gain: float, t_eff: float, limit: float
) -> np.ndarray:
    """Long straight legs held by a course-keeping autopilot (PD on heading, rudder within
    ``limit``) against a slowly wandering yaw disturbance (sea and wind, a random walk of
    0.5 deg of equivalent rudder per sqrt(s)), with course changes of 30-90 deg between legs
    of 100-300 s (stretched for slow hulls); planned on the first-order model."""
    scale = _time_scale(t_eff)
    gain_p = 1.0 / (k_gain * 4.0 * t_eff * scale)  # rad of rudder per rad of heading error
    gain_d = t_eff * gain_p
    cmd = np.zeros(n)
    psi = r = course = disturbance = 0.0
    next_turn = rng.uniform(100.0, 300.0) * scale
    disturbance_steps = np.radians(0.5) * np.sqrt(dt) * rng.standard_normal(n)
    for i in range(n):
        if i * dt >= next_turn:
            course += np.radians(rng.uniform(30.0, 90.0)) * rng.choice((-1.0, 1.0))
            next_turn += rng.uniform(100.0, 300.0) * scale
        disturbance += disturbance_steps[i]
        cmd[i] = np.clip(-gain_p * (psi - course) - gain_d * r, -limit, limit)
        r += dt * (k_gain * (cmd[i] + disturbance) - r) / t_eff
        psi += dt * r
    return cmd


def _actuator(cmd: np.ndarray, dt: float, rate: float, limit: float) -> np.ndarray:
    """Rate-limited, saturated steering gear: the rudder follows the command."""
    out = np.empty_like(cmd)
    x = 0.0
    step = rate * dt
    for i, c in enumerate(np.clip(cmd, -limit, limit)):
        x += min(max(c - x, -step), step)
        out[i] = x
    return out


def speed_profile(time: np.ndarray, nominal: float, varying: bool) -> np.ndarray:
    """Forward speed (m/s): constant, or stepping between 60 % and 120 % of nominal when varying."""
    if not varying:
        return np.full(len(time), nominal)
    levels = nominal * np.array([1.0, 0.6, 1.2, 0.8])
    index = (time // 150.0).astype(int) % len(levels)
    return levels[index]


def simulate(
    maneuver: str = "mixed",
    vessel: str | Vessel = "seed001",
    effects=None,
    duration: float = 600.0,
    sample_time: float = 0.1,
    noise: float | Noise = 1.0,
    seed: int = 0,
    parameters: dict | None = None,
    amplitude: float | None = None,
    fine_step: float = 0.01,
    model: str = "nomoto2",
    change: tuple[float, dict] | None = None,
) -> Simulation:
    """Simulate a manoeuvre and return noisy measurements with their truth.

    ``effects`` defaults to the vessel's own (``seed001``: rudder offset and
    cubic yaw damping); ``parameters`` overrides true values; ``noise`` is a
    multiple of the realistic sensor noise or a ``Noise``. ``change =
    (time_s, values)`` changes true parameters at that time (a vessel loaded
    mid-trip); the motion stays continuous and ``info['truth_after']`` holds
    the new values.

    Parameters
    ----------
    maneuver : str
        One of MANEUVERS (zigzag10, zigzag20, turning, random, mixed, steps, steady_turns, legs).
    vessel : str or Vessel
        A preset of VESSELS by name, or a vessel.
    effects : sequence of str or None
        The effects simulated; None: the vessel's own.
    duration : float
        Length of the record (s).
    sample_time : float
        Sample time of the measurements (s).
    noise : float or Noise
        Sensor noise, as a multiple of the realistic levels or as levels (SI units).
    seed : int
        Seed of the manoeuvre's and the noise's random draws.
    parameters : dict or None
        True values that override the vessel's (SI units).
    amplitude : float or None
        Rudder amplitude (rad) of the manoeuvre; None: its own.
    fine_step : float
        Integration step of the truth (s).
    model : str
        The base model simulated ('nomoto2', 'nomoto1', ...).
    change : tuple of (float, dict) or None
        (time s, new true values) of a change mid-record.

    Returns
    -------
    Simulation
        The noisy measurements (a Dataset), the truth (parameters, noise-free heading, yaw rate and
        rudder) and facts of the run in ``info``.
    """
    vessel = VESSELS[vessel] if isinstance(vessel, str) else vessel
    effects = vessel.seed_effects if effects is None else tuple(effects)
    structure = Structure(model, effects)
    truth = dict(vessel.parameters)
    truth.update(parameters or {})
    if "speed_dependence" in effects:
        truth["U_ref"] = vessel.speed
    if structure.form == "acceleration":  # the vessel's Nomoto constants and forcing, per unit yaw inertia
        truth = {k: v for k, v in structure.in_form(truth).items() if k in structure.parameter_names}
    rng = np.random.default_rng(seed)
    cmd = _plan_commands(maneuver, vessel, duration, fine_step, rng, amplitude)
    stride = int(round(sample_time / fine_step))
    t_fine = np.arange(len(cmd)) * fine_step
    commanded = _actuator(cmd[::stride], sample_time, vessel.rudder_rate, vessel.rudder_limit)
    rudder_fine = np.interp(t_fine, t_fine[::stride], commanded)
    speed_fine = speed_profile(t_fine, vessel.speed, "speed_dependence" in effects)
    zeros = np.zeros(len(t_fine))
    fine = Dataset(
        time=t_fine,
        rudder=rudder_fine,
        heading=zeros,
        yaw_rate=zeros,
        speed=speed_fine,
        meta={"sample_time": fine_step},
    )
    psi_fine, r_meas_fine = structure.simulate(truth, fine, initial=[(0.0, 0.0, 0.0)], substeps=2)
    r_fine = r_meas_fine - structure.yaw_rate_bias(truth)
    truth_after = None
    if change is not None:
        i = int(round(change[0] / fine_step))
        truth_after = dict(truth, **change[1])
        state = (psi_fine[i], r_fine[i], (r_fine[i] - r_fine[i - 1]) / fine_step)
        psi_fine[i:], r_meas_fine[i:] = structure.simulate(
            truth_after, fine.slice(i, len(t_fine)), initial=[state], substeps=2
        )
        r_fine[i:] = r_meas_fine[i:] - structure.yaw_rate_bias(truth_after)
    idx = np.arange(0, len(t_fine), stride)
    noise = Noise().scaled(noise) if not isinstance(noise, Noise) else noise
    n = len(idx)
    rudder = rudder_fine[idx] + noise.rudder * rng.standard_normal(n)
    heading = psi_fine[idx] + noise.heading * rng.standard_normal(n)
    heading = np.mod(heading + np.pi, 2 * np.pi) - np.pi
    heading[heading == -np.pi] = np.pi
    yaw_rate = r_meas_fine[idx] + noise.yaw_rate * rng.standard_normal(n)
    speed = speed_fine[idx] + noise.speed * rng.standard_normal(n)
    dataset = Dataset(
        time=t_fine[idx],
        rudder=rudder,
        heading=np.unwrap(heading),
        yaw_rate=yaw_rate,
        speed=speed,
        meta={"sample_time": sample_time, "source": f"simulate:{maneuver}", "wrapped_heading": heading},
    )
    info = {
        "maneuver": maneuver,
        "vessel": vessel.name,
        "sample_time": sample_time,
        "duration": float(t_fine[idx][-1]),
        "seed": seed,
        "noise": {"rudder": noise.rudder, "heading": noise.heading, "yaw_rate": noise.yaw_rate, "speed": noise.speed},
    }
    if truth_after is not None:
        info["change_time"] = float(change[0])
        info["truth_after"] = {k: truth_after[k] for k in structure.parameter_names}
    return Simulation(
        dataset=dataset,
        truth={k: truth[k] for k in structure.parameter_names},
        structure=structure,
        true_heading=psi_fine[idx],
        true_yaw_rate=r_fine[idx],
        true_rudder=rudder_fine[idx],
        info=info,
    )
