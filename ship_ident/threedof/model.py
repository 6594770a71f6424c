"""3-DOF manoeuvring model (surge u, sway v, yaw rate r) identified from free-running data (seed 000).

Model (Abkowitz type, the cubic Taylor expansion used for the Mariner class
in Fossen 2011, ch. 7, and in MSS ``mariner.m``). Non-dimensional (prime)
variables with the length between perpendiculars L, the reference
(approach) speed U0 and the instantaneous total speed U = sqrt(u^2 + v^2):

    u' = (u - U0) / U,   v' = v / U,   r' = r L / U,   delta in rad.

Forces: X, Y in 1/2 rho L^2 U^2, N in 1/2 rho L^3 U^2; masses in 1/2 rho L^3,
inertia in 1/2 rho L^5. With the mass matrix (rigid body plus added mass)

    m11 = m' - X_udot,  m22 = m' - Y_vdot,  m23 = m' xG' - Y_rdot,
    m32 = m' xG' - N_vdot,  m33 = Iz' - N_rdot,

the equations of motion m11 u'_t = X', [m22 m23; m32 m33] [v'_t; r'_t] = [Y'; N']
are written with the accelerations on the left, one linear regression per DOF:

    u'_t = u_dot L / U^2    = a . phi_X(u', v', r', delta)
    v'_t = v_dot L / U^2    = b . phi_YN(u', v', r', delta)
    r'_t = r_dot L^2 / U^2  = c . phi_YN(u', v', r', delta)

with a = X-derivatives / m11 and [b; c] = [m22 m23; m32 m33]^-1 [Y-derivatives;
N-derivatives]. The coriolis terms m' v' r' and m' u' r' belong to the X_rv,
Y_r, N_r ... columns. Free-running data identify a, b, c (the added masses
are not separable from the hydrodynamic derivatives); these are the
coefficients reported, with standard errors from the regression covariance.

Regressors (``X_TERMS``, ``YN_TERMS``; ``d`` = delta, ``u`` = u'):

    phi_X  = [u, u^2, u^3, v^2, r^2, r v, d^2, u d^2, v d, u v d]
    phi_YN = [v, r, v^3, v^2 r, v u, r u, d, d^3, u d, u^2 d, v d^2, v^2 d, 1, u, u^2]

Sign convention (NED): u forward, v to starboard, r and heading clockwise
seen from above, positive rudder turns the ship to starboard (r > 0).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit

RHO_FRESH_WATER = 1000.0  # kg/m^3, towing tank
DIVERGED_SPEED_RATIO = 3.0  # a free run faster than 3 U0 has diverged
X_TERMS = ("u", "uu", "uuu", "vv", "rr", "rv", "dd", "udd", "vd", "uvd")
YN_TERMS = ("v", "r", "vvv", "vvr", "vu", "ru", "d", "ddd", "ud", "uud", "vdd", "vvd", "0", "0u", "0uu")
DOFS = ("surge", "sway", "yaw")


@njit(cache=True)
def _regressors(du, v, r, d, phi_x, phi_yn):
    """Fill phi_X and phi_YN (order of X_TERMS, YN_TERMS) from prime u', v', r' and rudder d (rad)."""
    phi_x[0] = du
    phi_x[1] = du * du
    phi_x[2] = du * du * du
    phi_x[3] = v * v
    phi_x[4] = r * r
    phi_x[5] = r * v
    phi_x[6] = d * d
    phi_x[7] = du * d * d
    phi_x[8] = v * d
    phi_x[9] = du * v * d
    phi_yn[0] = v
    phi_yn[1] = r
    phi_yn[2] = v * v * v
    phi_yn[3] = v * v * r
    phi_yn[4] = v * du
    phi_yn[5] = r * du
    phi_yn[6] = d
    phi_yn[7] = d * d * d
    phi_yn[8] = du * d
    phi_yn[9] = du * du * d
    phi_yn[10] = v * d * d
    phi_yn[11] = v * v * d
    phi_yn[12] = 1.0
    phi_yn[13] = du
    phi_yn[14] = du * du


@njit(cache=True)
def _prime(u, v, r, length, speed0):
    """Prime state (u', v', r') and the total speed U (m/s) from SI u, v (m/s), r (rad/s)."""
    speed = np.sqrt(u * u + v * v)
    return (u - speed0) / speed, v / speed, r * length / speed, speed


@njit(cache=True)
def _accelerations(u, v, r, d, a, b, c, length, speed0, phi_x, phi_yn):
    """Body-fixed accelerations u_dot, v_dot (m/s^2) and r_dot (rad/s^2)."""
    du, vp, rp, speed = _prime(u, v, r, length, speed0)
    _regressors(du, vp, rp, d, phi_x, phi_yn)
    q = speed * speed / length
    return q * np.dot(a, phi_x), q * np.dot(b, phi_yn), q / length * np.dot(c, phi_yn)


@njit(cache=True)
def _integrate(
    a,
    b,
    c,
    length,
    speed0,
    sample_time,
    command,
    u0,
    v0,
    r0,
    psi0,
    substeps,
    zigzag_amplitude,
    rudder_rate,
    rudder_limit,
):
    """RK4 over samples of the state (u, v, r, psi); the rudder is linear within each sample.

    Rudder: the command (rad) passes a steering gear of rate ``rudder_rate`` (rad/s)
    and limit ``rudder_limit`` (rad). With ``zigzag_amplitude`` > 0 the command is
    the closed-loop zigzag rule (+-amplitude, switched when the heading crosses
    -+amplitude) and ``command[0]`` only gives the first side's sign.
    A run whose speed leaves (0, DIVERGED_SPEED_RATIO * U0) has diverged: the
    rest of its states are NaN. Returns states (n, 4) and the rudder (n,).
    """
    n = command.shape[0]
    states = np.empty((n, 4))
    rudder = np.empty(n)
    phi_x = np.empty(10)
    phi_yn = np.empty(15)
    u, v, r, psi = u0, v0, r0, psi0
    side = 1.0 if command[0] >= 0 else -1.0
    d1 = 0.0
    step = rudder_rate * sample_time
    h = sample_time / substeps
    for i in range(n):
        states[i, 0], states[i, 1], states[i, 2], states[i, 3] = u, v, r, psi
        if zigzag_amplitude > 0:
            if (side > 0 and psi - psi0 >= zigzag_amplitude) or (side < 0 and psi - psi0 <= -zigzag_amplitude):
                side = -side
            target = side * zigzag_amplitude
        else:
            target = command[i]
        target = min(max(target, -rudder_limit), rudder_limit)
        if i == 0:  # open loop starts at the first command, the zigzag from a centred rudder
            d0 = target if zigzag_amplitude <= 0 else 0.0
        else:
            d0 = d1
        rudder[i] = d0
        if i == n - 1:
            break
        nxt = command[i + 1] if zigzag_amplitude <= 0 else target
        nxt = min(max(nxt, -rudder_limit), rudder_limit)
        d1 = d0 + min(max(nxt - d0, -step), step)
        for s in range(substeps):
            da = d0 + (s / substeps) * (d1 - d0)
            db = d0 + ((s + 0.5) / substeps) * (d1 - d0)
            dc = d0 + ((s + 1.0) / substeps) * (d1 - d0)
            k1u, k1v, k1r = _accelerations(u, v, r, da, a, b, c, length, speed0, phi_x, phi_yn)
            k1p = r
            k2u, k2v, k2r = _accelerations(
                u + 0.5 * h * k1u, v + 0.5 * h * k1v, r + 0.5 * h * k1r, db, a, b, c, length, speed0, phi_x, phi_yn
            )
            k2p = r + 0.5 * h * k1r
            k3u, k3v, k3r = _accelerations(
                u + 0.5 * h * k2u, v + 0.5 * h * k2v, r + 0.5 * h * k2r, db, a, b, c, length, speed0, phi_x, phi_yn
            )
            k3p = r + 0.5 * h * k2r
            k4u, k4v, k4r = _accelerations(
                u + h * k3u, v + h * k3v, r + h * k3r, dc, a, b, c, length, speed0, phi_x, phi_yn
            )
            k4p = r + h * k3r
            u += h * (k1u + 2 * k2u + 2 * k3u + k4u) / 6.0
            v += h * (k1v + 2 * k2v + 2 * k3v + k4v) / 6.0
            r += h * (k1r + 2 * k2r + 2 * k3r + k4r) / 6.0
            psi += h * (k1p + 2 * k2p + 2 * k3p + k4p) / 6.0
        if not (np.isfinite(u) and np.isfinite(v) and np.isfinite(r)) or not (
            1e-6 < u * u + v * v < DIVERGED_SPEED_RATIO**2 * speed0 * speed0
        ):
            states[i + 1 :] = np.nan
            rudder[i + 1 :] = command[i + 1 :]
            break
    return states, rudder


@njit(cache=True)
def _regression_matrices(u, v, r, d, length, speed0):
    """Rows phi_X (n, 10) and phi_YN (n, 15) and the factor U^2 / L (m/s^2) per sample."""
    n = u.shape[0]
    phi_x = np.empty((n, 10))
    phi_yn = np.empty((n, 15))
    q = np.empty(n)
    for i in range(n):
        du, vp, rp, speed = _prime(u[i], v[i], r[i], length, speed0)
        _regressors(du, vp, rp, d[i], phi_x[i], phi_yn[i])
        q[i] = speed * speed / length
    return phi_x, phi_yn, q


# --------------------------------------------------------------------------- vessels


def _flip_odd_in_rudder(derivatives: dict) -> dict:
    """Mariner data use positive rudder to port; ours turns to starboard: odd-in-delta terms change sign."""
    odd = ("d", "ddd", "ud", "uud", "vvd", "vd", "uvd")
    return {k: (-val if k[1:] in odd else val) for k, val in derivatives.items()}


# Mariner class hydrodynamic derivatives (prime, 1e-5 units dropped), Fossen 2011 / MSS mariner.m,
# after Chislett & Strom-Tejsen (1965); rudder sign converted to ours.
MARINER_DERIVATIVES = _flip_odd_in_rudder(
    {
        "Xudot": -42e-5,
        "Yvdot": -748e-5,
        "Yrdot": -9.354e-5,
        "Nvdot": 4.646e-5,
        "Nrdot": -43.8e-5,
        "Xu": -184e-5,
        "Xuu": -110e-5,
        "Xuuu": -215e-5,
        "Xvv": -899e-5,
        "Xrr": 18e-5,
        "Xdd": -95e-5,
        "Xudd": -190e-5,
        "Xvd": 93e-5,
        "Xuvd": 93e-5,
        "Yv": -1160e-5,
        "Yr": -499e-5,
        "Yvvv": -8078e-5,
        "Yvvr": 15356e-5,
        "Yvu": -1160e-5,
        "Yru": -499e-5,
        "Yd": 278e-5,
        "Yddd": -90e-5,
        "Yud": 556e-5,
        "Yuud": 278e-5,
        "Yvdd": -4e-5,
        "Yvvd": 1190e-5,
        "Y0": -4e-5,
        "Y0u": -8e-5,
        "Y0uu": -4e-5,
        "Nv": -264e-5,
        "Nr": -166e-5,
        "Nvvv": 1636e-5,
        "Nvvr": -5483e-5,
        "Nvu": -264e-5,
        "Nru": -166e-5,
        "Nd": -139e-5,
        "Nddd": 45e-5,
        "Nud": -278e-5,
        "Nuud": -139e-5,
        "Nvdd": 13e-5,
        "Nvvd": -489e-5,
        "N0": 3e-5,
        "N0u": 6e-5,
        "N0uu": 3e-5,
    }
)


@dataclass(frozen=True)
class Vessel:
    """Main particulars (SI) and, for simulation presets, prime hydrodynamic derivatives.

    ``derivatives`` holds added masses (Xudot ...) and the force derivatives
    named X<term>, Y<term>, N<term> after X_TERMS / YN_TERMS; ``Xrv`` is set to
    m' (the coriolis term m v r) when absent.
    """

    name: str
    description: str
    length: float  # m, Lpp
    beam: float  # m
    draught: float  # m
    block_coefficient: float
    mass: float  # kg
    x_g: float  # m, centre of gravity forward of midship
    inertia_z: float  # kg m^2
    speed: float  # m/s, approach speed U0
    rudder_rate: float = np.radians(20.0)  # rad/s
    rudder_limit: float = np.radians(35.0)  # rad
    water_density: float = RHO_FRESH_WATER  # kg/m^3
    derivatives: dict = field(default_factory=dict)

    def coefficients(self) -> Coefficients:
        """The true regression coefficients a, b, c of the acceleration form (needs derivatives)."""
        if not self.derivatives:
            raise ValueError(f"vessel {self.name!r} has no hydrodynamic derivatives to simulate with")
        half_rho = 0.5 * self.water_density
        m = self.mass / (half_rho * self.length**3)
        iz = self.inertia_z / (half_rho * self.length**5)
        xg = self.x_g / self.length
        der = dict({"Xrv": m}, **self.derivatives)
        m11 = m - der["Xudot"]
        mass_yn = np.array([[m - der["Yvdot"], m * xg - der["Yrdot"]], [m * xg - der["Nvdot"], iz - der["Nrdot"]]])
        x = np.array([der["X" + t] for t in X_TERMS])
        yn = np.array([[der["Y" + t] for t in YN_TERMS], [der["N" + t] for t in YN_TERMS]])
        b, c = np.linalg.solve(mass_yn, yn)
        return Coefficients(surge=x / m11, sway=b, yaw=c, length=self.length, speed=self.speed)


DTC_SCALE = 89.11  # DTC model scale (Lpp 355 m / 3.984 m)
KVLCC2_SCALE = 45.714
KVLCC2_MASS = 3.27 * KVLCC2_SCALE**3 * 1025.0  # kg: model displacement 3.27 m^3 scaled, sea water
VESSELS = {
    "dtc": Vessel(
        "dtc",
        "Duisburg Test Case container ship model (seed 000 Table 2) with Mariner-class "
        "derivatives as stand-in hydrodynamics",
        length=3.984,
        beam=0.572,
        draught=0.163,
        block_coefficient=0.661,
        mass=242.8,
        x_g=-0.052,
        inertia_z=219.0,
        speed=1.2,
        rudder_rate=np.radians(2.32) * np.sqrt(DTC_SCALE),
        derivatives=MARINER_DERIVATIVES,
    ),
    "kvlcc2": Vessel(
        "kvlcc2",
        "KVLCC2 tanker, full scale (MARIN free-running tests, SIMMAN 2008; model 1:45.714)",
        length=320.0,
        beam=58.0,
        draught=20.8,
        block_coefficient=0.81,
        mass=KVLCC2_MASS,
        x_g=11.1,
        inertia_z=KVLCC2_MASS * (0.25 * 320.0) ** 2,
        speed=7.97,  # radius of gyration 0.25 Lpp
        water_density=1025.0,
    ),
}


@dataclass
class Coefficients:
    """Acceleration-form coefficient vectors a (surge), b (sway), c (yaw), with U0 (m/s) and L (m)."""

    surge: np.ndarray
    sway: np.ndarray
    yaw: np.ndarray
    length: float
    speed: float
    std_errors: dict | None = None  # DOF -> array like the coefficients

    def vector(self, dof: str) -> np.ndarray:
        return getattr(self, dof)

    def to_json(self) -> dict:
        out = {"length": self.length, "speed": self.speed}
        for dof in DOFS:
            terms = X_TERMS if dof == "surge" else YN_TERMS
            std = self.std_errors[dof] if self.std_errors else np.full(len(terms), np.nan)
            out[dof] = {t: {"value": float(w), "std_error": float(s)} for t, w, s in zip(terms, self.vector(dof), std)}
        return out


# --------------------------------------------------------------------------- records


@dataclass(frozen=True)
class Record:
    """A free-running manoeuvre on a uniform grid, body-fixed, SI units.

    time (s), surge u and sway v (m/s, body-fixed), yaw rate r (rad/s),
    heading (rad, unwrapped, NED), rudder (rad, positive to starboard),
    propeller rate (rev/s) when measured.
    """

    time: np.ndarray
    surge: np.ndarray
    sway: np.ndarray
    yaw_rate: np.ndarray
    heading: np.ndarray
    rudder: np.ndarray
    propeller_rate: np.ndarray | None = None
    meta: dict = field(default_factory=dict)

    @property
    def sample_time(self) -> float:
        return float(np.median(np.diff(self.time)))

    def __len__(self) -> int:
        return len(self.time)

    def head(self, n: int) -> Record:
        """The first n samples."""
        cut = {k: getattr(self, k)[:n] for k in ("time", "surge", "sway", "yaw_rate", "heading", "rudder")}
        rate = None if self.propeller_rate is None else self.propeller_rate[:n]
        return replace(self, propeller_rate=rate, **cut)

    def dof(self, name: str) -> np.ndarray:
        return {"surge": self.surge, "sway": self.sway, "yaw": self.yaw_rate}[name]


@dataclass(frozen=True)
class Noise:
    """Sensor noise standard deviations (SI): the realistic levels of a free-running model test."""

    surge: float = 0.005  # m/s
    sway: float = 0.005  # m/s
    yaw_rate: float = np.radians(0.2)  # rad/s
    heading: float = np.radians(0.1)  # rad
    rudder: float = np.radians(0.1)  # rad

    def scaled(self, factor: float) -> Noise:
        return Noise(*(factor * getattr(self, k) for k in ("surge", "sway", "yaw_rate", "heading", "rudder")))


def run_model(
    coefficients: Coefficients, time: np.ndarray, rudder: np.ndarray, initial: tuple, substeps: int = 4
) -> Record:
    """Integrate the model from ``initial`` = (u, v, r, psi) driven by ``rudder`` (rad, linear between samples)."""
    h = float(np.median(np.diff(time)))
    states, _ = _integrate(
        coefficients.surge,
        coefficients.sway,
        coefficients.yaw,
        coefficients.length,
        coefficients.speed,
        h,
        np.asarray(rudder, float),
        *map(float, initial),
        substeps,
        0.0,
        np.inf,
        np.inf,
    )
    return Record(
        time=time,
        surge=states[:, 0],
        sway=states[:, 1],
        yaw_rate=states[:, 2],
        heading=states[:, 3],
        rudder=np.asarray(rudder, float),
    )


def simulate_manoeuvre(
    vessel: str | Vessel = "dtc",
    manoeuvre: str = "zigzag",
    amplitude_deg: float = 20.0,
    duration: float = 100.0,
    sample_time: float = 0.1,
    noise: float | Noise = 1.0,
    seed: int = 0,
    substeps: int = 4,
) -> tuple[Record, Record]:
    """Simulate a zigzag (closed loop on heading) or turning circle from a straight run at U0.

    ``amplitude_deg`` < 0 starts to port. Returns (noisy measurements, noise-free truth).
    """
    vessel = VESSELS[vessel] if isinstance(vessel, str) else vessel
    coefficients = vessel.coefficients()
    n = int(round(duration / sample_time)) + 1
    time = np.arange(n) * sample_time
    amplitude = np.radians(amplitude_deg)
    if manoeuvre == "zigzag":
        command, zigzag = np.full(n, np.sign(amplitude)), abs(amplitude)
    elif manoeuvre == "turning":
        command, zigzag = np.full(n, amplitude), 0.0
        command[0] = 0.0
    else:
        raise ValueError(f"unknown manoeuvre {manoeuvre!r}; choose zigzag or turning")
    states, rudder = _integrate(
        coefficients.surge,
        coefficients.sway,
        coefficients.yaw,
        vessel.length,
        vessel.speed,
        sample_time,
        command,
        vessel.speed,
        0.0,
        0.0,
        0.0,
        substeps,
        zigzag,
        vessel.rudder_rate,
        vessel.rudder_limit,
    )
    truth = Record(
        time=time,
        surge=states[:, 0],
        sway=states[:, 1],
        yaw_rate=states[:, 2],
        heading=states[:, 3],
        rudder=rudder,
        meta={"vessel": vessel.name, "manoeuvre": manoeuvre, "amplitude_deg": amplitude_deg},
    )
    noise = Noise().scaled(noise) if not isinstance(noise, Noise) else noise
    rng = np.random.default_rng(seed)
    noisy = {
        k: getattr(truth, k) + getattr(noise, k) * rng.standard_normal(n)
        for k in ("surge", "sway", "yaw_rate", "heading", "rudder")
    }
    return replace(truth, **noisy), truth
