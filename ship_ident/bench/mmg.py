"""Recordings from a physics-based manoeuvring model: the MMG standard method on KVLCC2-like hulls.

The hull, propeller and rudder forces and the surge-sway-yaw equations of motion are those of
the MMG standard method (Yasukawa, H. and Yoshimura, Y., "Introduction of MMG standard method
for ship maneuvering predictions", J. Mar. Sci. Technol. 20:37-52, 2015), integrated by the
``shipmmg`` package (MIT licence; the ``bench`` extra installs it). Nothing of this project's
Nomoto models or effects enters the simulation: course instability, nonlinear sway-yaw damping,
the rudder's lift at the effective inflow angle (which falls with drift and turn rate), the
speed lost in a turn and the sway-yaw coupling all come from the hull's coefficients.

The coefficients are those published for the KVLCC2 tanker's 7 m model (``KVLCC2_*``); a hull
drawn by ``random_hull`` scales a few of them (``VARIATION``): the linear yaw damping N'_r and
the sway-yaw coupling N'_v, which decide course stability, the rudder area, the nonlinear hull
terms, and the approach speed. Manoeuvres (``MANOEUVRES``) are run at model scale from a steady
straight course at the approach speed, the propeller at the revolutions that hold that speed
(``self_propulsion_rps``), the rudder through a rate-limited steering gear; they are recorded
at 10 Hz with the sensor noise of ``simulator.Noise``.

Conventions are this project's (``dataset``): heading and yaw rate positive clockwise seen from
above (NED), a positive rudder angle turns the ship to starboard. The MMG equations of
``shipmmg`` use the same: x forward, y to starboard, and a positive rudder angle gives a
positive rudder yaw moment ``N_R = -(x_R + a_H x_H) F_N cos(delta)`` (x_R, x_H < 0), so no sign
is converted (``test_mmg`` checks it).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np

from ..model.dataset import Dataset, join_recordings
from ..model.simulator import Noise

WATER_DENSITY = 1025.0  # kg/m^3 (shipmmg's default, passed explicitly: every mass below is in kg)

# KVLCC2 7 m model (scale 1:45.7), Yasukawa and Yoshimura (2015), Tables 1-3. Lengths in m, areas
# in m^2, volume in m^3; primed values are non-dimensional (forces by 0.5 rho L d U^2, moments by
# 0.5 rho L^2 d U^2, masses by 0.5 rho L^2 d, inertias by 0.5 rho L^4 d, velocities by U, r by U/L).
KVLCC2_PARTICULARS = {
    "L_pp": 7.00,  # length between perpendiculars
    "B": 1.27,  # breadth
    "d": 0.46,  # draught
    "displacement": 3.27,  # displaced volume
    "x_G": 0.25,  # centre of gravity forward of midship
    "D_p": 0.216,  # propeller diameter
    "H_R": 0.345,  # rudder span
    "A_R": 0.0539,  # rudder area
}
KVLCC2_HULL = {  # hull forces: resistance, added masses and the hull derivatives of Table 3
    "m_x_dash": 0.022,
    "m_y_dash": 0.223,
    "J_z_dash": 0.011,
    "R_0_dash": 0.022,
    "X_vv_dash": -0.040,
    "X_vr_dash": 0.002,
    "X_rr_dash": 0.011,
    "X_vvvv_dash": 0.771,
    "Y_v_dash": -0.315,
    "Y_r_dash": 0.083,
    "Y_vvv_dash": -1.607,
    "Y_vvr_dash": 0.379,
    "Y_vrr_dash": -0.391,
    "Y_rrr_dash": 0.008,
    "N_v_dash": -0.137,
    "N_r_dash": -0.049,
    "N_vvv_dash": -0.030,
    "N_vvr_dash": -0.294,
    "N_vrr_dash": 0.055,
    "N_rrr_dash": -0.013,
}
KVLCC2_PROPELLER = {  # open-water thrust K_T = k_0 + k_1 J + k_2 J^2, thrust deduction, wake
    "k_0": 0.2931,
    "k_1": -0.2753,
    "k_2": -0.1385,
    "t_P": 0.220,
    "w_P0": 0.40,
    # propeller position, in shipmmg's wake in drift w_P0 exp(-4 beta_P^2) only (shipmmg's tests take
    # -0.69: KVLCC2's overshoots move by at most 0.2 deg, its turning circle by 2 %)
    "x_P_dash": -0.48,
}
KVLCC2_RUDDER = {  # rudder force and hull-rudder interaction
    "t_R": 0.387,  # steering resistance deduction
    "a_H": 0.312,  # rudder force increase factor (hull's share of the rudder's side force)
    "x_H_dash": -0.464,  # where that extra side force acts
    "x_R_dash": -0.500,  # rudder position
    "gamma_R_minus": 0.395,  # flow straightening, beta_R < 0
    "gamma_R_plus": 0.640,  # flow straightening, beta_R > 0
    "l_R_dash": -0.710,  # effective rudder position for the inflow angle beta_R
    "epsilon": 1.09,  # wake ratio rudder / propeller
    "kappa": 0.50,  # propeller slipstream constant
    "f_alpha": 2.747,  # rudder lift gradient (1/rad)
}
KVLCC2_SPEED = 1.179  # m/s, the model's approach speed (full scale 15.5 kn, Fn 0.142)
RADIUS_OF_GYRATION = 0.25  # of the ship's yaw inertia I_zG = m (0.25 L)^2 (as shipmmg's KVLCC2 tests)
SCALE = 45.7  # the model's scale: the steering gear's rate is Froude-scaled from full scale
# Steering gear: 2.32 deg/s at full scale (SOLAS: 35 deg one side to 30 deg the other in 28 s),
# sqrt(45.7) = 6.8 times faster at model scale; the rudder stops at 35 deg
RUDDER_RATE = float(np.radians(2.32 * np.sqrt(SCALE)))  # rad/s
RUDDER_LIMIT = float(np.radians(35.0))  # rad

# Factors drawn log-uniformly by ``random_hull`` on the KVLCC2 values: N_r the linear yaw damping
# N'_r, N_v the sway-yaw coupling N'_v (the two that decide course stability: about half the
# hulls stay course-unstable, see ``stability_index``), rudder the rudder area A_R (the rudder's
# moment per degree), nonlinear every nonlinear sway and yaw hull term (Y', N' of vvv, vvr, vrr,
# rrr), speed the approach speed
VARIATION = {
    "N_r": (0.6, 1.8),
    "N_v": (0.7, 1.3),
    "rudder": (0.7, 1.4),
    "nonlinear": (0.5, 2.0),
    "speed": (0.8, 1.2),
}
NONLINEAR_TERMS = tuple(f"{f}_{t}_dash" for f in ("Y", "N") for t in ("vvv", "vvr", "vrr", "rrr"))

SAMPLE_TIME = 0.1  # s: recorded at 10 Hz
EXECUTE_S = 5.0  # s of straight course before the rudder is put over
KNOT_STEP = 0.05  # s between the knots of the rudder's time history handed to shipmmg
MAX_STEP = 0.5  # s: the integrator's largest step (a rudder step never falls between two)
TOLERANCES = {"rtol": 1e-6, "atol": 1e-9}
# Manoeuvres and their durations (s, model scale): random rudder steps (the training record), the
# 10/10 and 20/20 zigzags and a 35 deg turning circle (held out)
MANOEUVRES = {"steps": 600.0, "zigzag10": 150.0, "zigzag20": 150.0, "turning35": 200.0}
TRAINING = "steps"
HELD_OUT = ("zigzag10", "zigzag20", "turning35")
STEP_HOLD_S = (10.0, 40.0)  # random steps: each rudder angle held this long (s) ...
STEP_ANGLE = float(np.radians(35.0))  # ... drawn uniformly within +-35 deg
PUT_OVER = float(np.radians(1.0))  # rad: the rudder is put over (executed) once beyond this


@dataclass(frozen=True)
class MmgHull:
    """An MMG hull: its coefficients as ``shipmmg`` takes them, approach speed (m/s), propeller
    revolutions (1/s), steering gear rate (rad/s) and limit (rad), and the factors drawn on the
    KVLCC2 coefficients (``VARIATION``; all 1 for KVLCC2 itself)."""

    name: str
    basic: object  # shipmmg.mmg_3dof.Mmg3DofBasicParams, SI
    maneuvering: object  # shipmmg.mmg_3dof.Mmg3DofManeuveringParams, non-dimensional
    speed: float
    propeller_rps: float
    rudder_rate: float = RUDDER_RATE
    rudder_limit: float = RUDDER_LIMIT
    variation: dict = field(default_factory=dict)


@dataclass
class MmgRun:
    """One simulated manoeuvre: the recorded ``dataset`` (noisy, 10 Hz) and the noise-free states
    on the same grid: surge u, sway v (m/s), yaw rate r (rad/s), heading psi (rad), north x and
    east y (m) of midship, and the rudder angle (rad)."""

    dataset: Dataset
    u: np.ndarray
    v: np.ndarray
    r: np.ndarray
    psi: np.ndarray
    x: np.ndarray
    y: np.ndarray
    rudder: np.ndarray


def _shipmmg():
    """The ``shipmmg`` module, or a one-line error naming the extra that installs it."""
    try:
        from shipmmg import mmg_3dof
    except ModuleNotFoundError as exc:
        raise ValueError("the MMG generator needs the shipmmg package: pip install 'ship_ident[bench]'") from exc
    return mmg_3dof


def kvlcc2_hull(variation: dict | None = None) -> MmgHull:
    """The KVLCC2 7 m model with the factors ``variation`` (``VARIATION``'s names, default 1) on its
    coefficients, at its approach speed times ``variation['speed']``."""
    mmg_3dof = _shipmmg()
    factors = {name: 1.0 for name in VARIATION}
    factors.update(variation or {})
    unknown = set(factors) - set(VARIATION)
    if unknown:
        raise ValueError(f"unknown hull variation {sorted(unknown)}; choose from {', '.join(VARIATION)}")
    p, rudder, prop = KVLCC2_PARTICULARS, KVLCC2_RUDDER, KVLCC2_PROPELLER
    length, draught = p["L_pp"], p["d"]
    mass = WATER_DENSITY * p["displacement"]
    mass_scale = 0.5 * WATER_DENSITY * length**2 * draught
    basic = mmg_3dof.Mmg3DofBasicParams(
        L_pp=length,
        B=p["B"],
        d=draught,
        x_G=p["x_G"],
        D_p=p["D_p"],
        m=mass,
        I_zG=mass * (RADIUS_OF_GYRATION * length) ** 2,
        A_R=p["A_R"] * factors["rudder"],
        η=p["D_p"] / p["H_R"],
        m_x=KVLCC2_HULL["m_x_dash"] * mass_scale,
        m_y=KVLCC2_HULL["m_y_dash"] * mass_scale,
        J_z=KVLCC2_HULL["J_z_dash"] * mass_scale * length**2,
        f_α=rudder["f_alpha"],
        ϵ=rudder["epsilon"],
        t_R=rudder["t_R"],
        x_R=rudder["x_R_dash"] * length,
        a_H=rudder["a_H"],
        x_H=rudder["x_H_dash"] * length,
        γ_R_minus=rudder["gamma_R_minus"],
        γ_R_plus=rudder["gamma_R_plus"],
        l_R=rudder["l_R_dash"],
        κ=rudder["kappa"],
        t_P=prop["t_P"],
        w_P0=prop["w_P0"],
        x_P=prop["x_P_dash"],
    )
    hull = {k: v for k, v in KVLCC2_HULL.items() if k not in ("m_x_dash", "m_y_dash", "J_z_dash")}
    hull["N_r_dash"] *= factors["N_r"]
    hull["N_v_dash"] *= factors["N_v"]
    for name in NONLINEAR_TERMS:
        hull[name] *= factors["nonlinear"]
    maneuvering = mmg_3dof.Mmg3DofManeuveringParams(k_0=prop["k_0"], k_1=prop["k_1"], k_2=prop["k_2"], **hull)
    speed = KVLCC2_SPEED * factors["speed"]
    varied = {k: v for k, v in factors.items() if v != 1.0}
    name = "kvlcc2" + ("(" + ",".join(f"{k}={v:.3g}" for k, v in varied.items()) + ")" if varied else "")
    return MmgHull(name, basic, maneuvering, speed, self_propulsion_rps(basic, maneuvering, speed), variation=factors)


def random_hull(rng: np.random.Generator) -> MmgHull:
    """A hull drawn around KVLCC2: every factor of ``VARIATION`` log-uniform in its range."""
    return kvlcc2_hull({name: float(np.exp(rng.uniform(*np.log(bounds)))) for name, bounds in VARIATION.items()})


def self_propulsion_rps(basic, maneuvering, speed: float) -> float:
    """Propeller revolutions (1/s) at which thrust balances the straight-course resistance at
    ``speed`` (m/s): ``(1 - t_P) rho K_T(J) n^2 D_p^4 = 0.5 rho L d U^2 R'_0`` with
    ``J = (1 - w_P0) U / (n D_p)``, solved for n (a quadratic in n)."""
    k0, k1, k2 = maneuvering.k_0, maneuvering.k_1, maneuvering.k_2
    advance = (1.0 - basic.w_P0) * speed / basic.D_p  # J n, 1/s
    resistance = 0.5 * basic.L_pp * basic.d * speed**2 * maneuvering.R_0_dash / ((1.0 - basic.t_P) * basic.D_p**4)
    # k0 n^2 + k1 (J n) n + k2 (J n)^2 = resistance
    a, b, c = k0, k1 * advance, k2 * advance**2 - resistance
    return float((-b + np.sqrt(b * b - 4 * a * c)) / (2 * a))


def stability_index(hull: MmgHull) -> float:
    """The linear course-stability criterion of the bare hull (non-dimensional, negative: course-
    unstable): ``C = Y'_v (N'_r - m' x'_G) - N'_v (Y'_r - m' - m'_x)``, the determinant of the
    linear sway-yaw damping about midship with the centripetal terms of the equations of motion
    (m' = m / (0.5 rho L^2 d), x'_G = x_G / L). The rudder adds damping of its own (its inflow
    angle follows v and r), which ``pull_out_turn_rate`` includes."""
    b, m = hull.basic, hull.maneuvering
    mass_scale = 0.5 * WATER_DENSITY * b.L_pp**2 * b.d
    mass, added_x = b.m / mass_scale, b.m_x / mass_scale
    yaw_damping = m.N_r_dash - mass * b.x_G / b.L_pp
    sway_yaw = m.Y_r_dash - mass - added_x
    return float(m.Y_v_dash * yaw_damping - m.N_v_dash * sway_yaw)


def pull_out_turn_rate(hull: MmgHull, hold_s: float = 60.0, settle_s: float = 300.0) -> float:
    """Non-dimensional turn rate r' = r L / U left ``settle_s`` (s) after a pull-out, the larger of
    the two sides: the rudder held at 35 deg to one side for ``hold_s`` (s), then put back to
    midships. A course-stable ship's turn dies out (r' near 0); a course-unstable one keeps
    turning at the edge of its instability loop (as KVLCC2 does in MARIN's free-running model
    tests). The loop of a hull whose flow straightening differs to port and starboard (gamma_R)
    is not symmetric: KVLCC2's is open to port only."""
    total = EXECUTE_S + hold_s + settle_s
    rates = []
    for side in (1.0, -1.0):
        run = _simulate(hull, [(EXECUTE_S, side * hull.rudder_limit), (EXECUTE_S + hold_s, 0.0)], total)
        rates.append(abs(run.r[-1]) * hull.basic.L_pp / np.hypot(run.u[-1], run.v[-1]))
    return float(max(rates))


def _rudder_history(times: np.ndarray, start_angle: float, commands: list[tuple[float, float]], hull) -> np.ndarray:
    """The steering gear's angle (rad) at ``times`` (s): from ``start_angle`` it moves to each
    command ``(time s, angle rad)`` at the gear's rate from that time on, clipped to its limit."""
    angle = np.full(len(times), start_angle)
    current = start_angle
    bounds = [c[0] for c in commands[1:]] + [np.inf]
    for (t0, target), t1 in zip(commands, bounds):
        target = float(np.clip(target, -hull.rudder_limit, hull.rudder_limit))
        inside = (times >= t0) & (times < t1)
        travel = hull.rudder_rate * (times[inside] - t0)
        angle[inside] = current + np.clip(target - current, -travel, travel)
        reach = hull.rudder_rate * (t1 - t0)
        current = float(current + np.clip(target - current, -reach, reach))
    return angle


def _solve(hull: MmgHull, t0: float, t1: float, state: np.ndarray, rudder_at, event=None):
    """shipmmg's solution from ``state`` (u, v, r, x, y, psi) over [t0, t1] s, the rudder given as
    a function of time (``rudder_at``) on knots KNOT_STEP apart; ``event(t, X)`` stops it."""
    mmg_3dof = _shipmmg()
    knots = np.append(np.arange(t0, t1, KNOT_STEP), t1)
    u, v, r, x, y, psi = state
    return mmg_3dof.simulate_mmg_3dof(
        hull.basic,
        hull.maneuvering,
        knots,
        rudder_at(knots),
        np.full(len(knots), hull.propeller_rps),
        u0=u,
        v0=v,
        r0=r,
        x0=x,
        y0=y,
        ψ0=psi,
        ρ=WATER_DENSITY,
        events=event,
        max_step=MAX_STEP,
        **TOLERANCES,
    )


def _simulate(
    hull: MmgHull, commands: list[tuple[float, float]], duration: float, zigzag: float | None = None
) -> MmgRun:
    """The noise-free run on the SAMPLE_TIME grid over ``duration`` (s) from a straight course at
    the approach speed: the rudder follows ``commands`` (``(time s, angle rad)``, ``_rudder_history``),
    or, with ``zigzag`` (rad), a zigzag from EXECUTE_S on: the rudder to +zigzag, then to the
    other side each time the heading passes +-zigzag (the check angle equals the rudder angle)."""
    grid = np.arange(0.0, duration + 0.5 * SAMPLE_TIME, SAMPLE_TIME)
    states = np.zeros((7, len(grid)))
    state = np.array([hull.speed, 0.0, 0.0, 0.0, 0.0, 0.0])
    if zigzag is None:
        sol = _solve(hull, 0.0, grid[-1], state, lambda t: _rudder_history(t, 0.0, commands, hull))
        states[:] = sol.sol(grid)[:7]
    else:
        t0, angle, side, done = 0.0, 0.0, 1.0, 0
        commands = [(0.0, 0.0), (EXECUTE_S, zigzag)]
        while done < len(grid):
            target = side * zigzag

            def check(t, X, target=target):
                return X[5] - target

            check.terminal, check.direction = True, side
            rudder_at = partial(_rudder_history, start_angle=angle, commands=commands, hull=hull)
            sol = _solve(hull, t0, grid[-1], state, rudder_at, check)
            t_end = sol.t_events[0][0] if len(sol.t_events[0]) else np.inf
            upto = int(np.searchsorted(grid, t_end)) if np.isfinite(t_end) else len(grid)
            states[:, done:upto] = sol.sol(grid[done:upto])[:7]
            done = upto
            if not np.isfinite(t_end):
                break
            end = sol.sol(t_end)
            state, angle, t0 = end[:6], float(end[6]), float(t_end)
            side = -side
            commands = [(t0, side * zigzag)]
    u, v, r, x, y, psi, rudder = states
    dataset = Dataset(time=grid, rudder=rudder, heading=psi, yaw_rate=r, speed=np.hypot(u, v))
    return MmgRun(dataset, u, v, r, psi, x, y, rudder)


def simulate(
    hull: MmgHull, manoeuvre: str, seed: int, noise: Noise | None = None, duration: float | None = None
) -> MmgRun:
    """``manoeuvre`` (one of ``MANOEUVRES``) on ``hull`` for ``duration`` (s, default the
    manoeuvre's), recorded at SAMPLE_TIME with sensor ``noise`` (default ``simulator.Noise()``)
    drawn from ``seed``; the random steps too are drawn from ``seed``. The run's noise-free states
    stay beside the recorded ``dataset``; the heading is recorded unwrapped and, as a compass gives
    it, wrapped to (-pi, pi] (``meta["wrapped_heading"]``)."""
    if manoeuvre not in MANOEUVRES:
        raise ValueError(f"unknown MMG manoeuvre {manoeuvre!r}; choose from {', '.join(MANOEUVRES)}")
    rng = np.random.default_rng(seed)
    duration = MANOEUVRES[manoeuvre] if duration is None else float(duration)
    if manoeuvre == "steps":
        commands, t = [(0.0, 0.0)], EXECUTE_S
        while t < duration:
            commands.append((t, float(rng.uniform(-STEP_ANGLE, STEP_ANGLE))))
            t += float(rng.uniform(*STEP_HOLD_S))
        run = _simulate(hull, commands, duration)
    elif manoeuvre.startswith("zigzag"):
        run = _simulate(hull, [], duration, zigzag=float(np.radians(float(manoeuvre[len("zigzag") :]))))
    else:  # turning35: the rudder to 35 deg and held
        run = _simulate(hull, [(0.0, 0.0), (EXECUTE_S, np.radians(float(manoeuvre[len("turning") :])))], duration)
    noise = noise or Noise()
    n = run.dataset.n_samples
    heading = run.psi + noise.heading * rng.standard_normal(n)
    dataset = replace(
        run.dataset,
        rudder=run.rudder + noise.rudder * rng.standard_normal(n),
        heading=heading,
        yaw_rate=run.r + noise.yaw_rate * rng.standard_normal(n),
        speed=run.dataset.speed + noise.speed * rng.standard_normal(n),
        meta={
            "sample_time": SAMPLE_TIME,
            "source": f"mmg:{manoeuvre}",
            "hull": hull.name,
            "wrapped_heading": np.mod(heading + np.pi, 2 * np.pi) - np.pi,
        },
    )
    return replace(run, dataset=dataset)


def _streams(seed: int) -> dict[str, int]:
    """Each manoeuvre's own noise (and steps) seed, drawn from ``seed``."""
    return dict(zip(MANOEUVRES, map(int, np.random.SeedSequence(seed).generate_state(len(MANOEUVRES)))))


def held_out_recordings(hull: MmgHull, seed: int) -> Dataset:
    """The held-out manoeuvres of ``hull`` (``HELD_OUT``: the 10/10 and 20/20 zigzags and the 35 deg
    turning circle, one recording each, joined by ``join_recordings``), each manoeuvre's noise drawn
    from its own stream of ``seed``."""
    streams = _streams(seed)
    return join_recordings([simulate(hull, m, streams[m]).dataset for m in HELD_OUT], names=list(HELD_OUT))


def hull_recordings(hull: MmgHull, seed: int) -> tuple[Dataset, Dataset]:
    """The training record (random rudder steps) and the held-out manoeuvres (``held_out_recordings``)
    of ``hull``, each manoeuvre's noise drawn from its own stream of ``seed``."""
    return simulate(hull, TRAINING, _streams(seed)[TRAINING]).dataset, held_out_recordings(hull, seed)


def overshoots(run: MmgRun, angle: float) -> list[float]:
    """A zigzag's overshoot angles (rad), first one first: after each switch of the rudder, how far
    the heading swings beyond the check angle ``angle`` (rad) before it turns back."""
    over = np.flatnonzero(np.abs(run.rudder) > PUT_OVER)
    switches = [int(i) for i in over[1:][np.diff(np.sign(run.rudder[over])) != 0]]
    ends = switches[1:] + [len(run.psi)]
    return [float(np.max(np.abs(run.psi[a:b])) - angle) for a, b in zip(switches, ends)]


def advance_and_tactical_diameter(run: MmgRun) -> tuple[float, float]:
    """A turning circle's advance (m: distance run along the approach course from the rudder's
    execute to 90 deg of heading change) and tactical diameter (m: distance off the approach
    course at 180 deg)."""
    executed = int(np.flatnonzero(np.abs(run.rudder) > PUT_OVER)[0])
    change = np.abs(run.psi - run.psi[executed])
    quarter, half = int(np.argmax(change >= np.pi / 2)), int(np.argmax(change >= np.pi))
    return float(run.x[quarter] - run.x[executed]), float(abs(run.y[half] - run.y[executed]))
