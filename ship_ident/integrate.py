"""Compiled free-run integrator of the Nomoto models (numba, RK4).

The ODE (SI units, NED sign convention):

    nomoto1:  T r' + r = K d(t) + F
    nomoto2:  T1 T2 r'' + (T1 + T2) r' + r = K (d(t) + T3 d'(t)) + F
    psi' = r

with d the effective rudder angle (rad) and F the sum of state-dependent
forcing terms (rad/s), each ``c * r**p * |r|**q * trig(k psi)``. The rudder
derivative is never formed: nomoto2 is integrated in the state
(psi, r, z) with z = T1 T2 r' + (T1 + T2) r - K T3 d, so z' = K d + F - r.

Inputs are samples: the rudder is interpolated linearly between samples
(first-order hold), speed scales are held per sample. Gains scale with
``gain_scale`` (K -> K g) and time constants with ``time_scale``
(T -> T s), quasi-steadily.
"""
from __future__ import annotations

import numpy as np
from numba import njit

TRIG_NONE, TRIG_COS, TRIG_SIN = 0, 1, 2


@njit(cache=True)
def _forcing(psi, r, coef, r_power, abs_power, harmonic, trig):
    total = 0.0
    for j in range(coef.shape[0]):
        v = coef[j]
        for _ in range(r_power[j]):  # repeated products: far cheaper than pow in the inner loop
            v *= r
        for _ in range(abs_power[j]):
            v *= abs(r)
        if trig[j] == 1:
            v *= np.cos(harmonic[j] * psi)
        elif trig[j] == 2:
            v *= np.sin(harmonic[j] * psi)
        total += v
    return total


@njit(cache=True)
def _rhs(order, psi, r, z, d, K, T1, T2, T3, coef, r_power, abs_power, harmonic, trig):
    f = _forcing(psi, r, coef, r_power, abs_power, harmonic, trig)
    if order == 1:
        return r, (K * d + f - r) / T1, 0.0
    rdot = (z - (T1 + T2) * r + K * T3 * d) / (T1 * T2)
    return r, rdot, K * d + f - r


@njit(cache=True)
def advance(order, h, d0, d1, K, T1, T2, T3, psi, r, z, coef, r_power, abs_power, harmonic, trig, substeps):
    """Advance the state (psi, r, z) over one sample of length h, rudder linear from d0 to d1."""
    dt = h / substeps
    for s in range(substeps):
        da = d0 + (s / substeps) * (d1 - d0)
        db = d0 + ((s + 0.5) / substeps) * (d1 - d0)
        dc = d0 + ((s + 1.0) / substeps) * (d1 - d0)
        k1p, k1r, k1z = _rhs(order, psi, r, z, da, K, T1, T2, T3, coef, r_power, abs_power, harmonic, trig)
        k2p, k2r, k2z = _rhs(order, psi + 0.5 * dt * k1p, r + 0.5 * dt * k1r, z + 0.5 * dt * k1z, db,
                             K, T1, T2, T3, coef, r_power, abs_power, harmonic, trig)
        k3p, k3r, k3z = _rhs(order, psi + 0.5 * dt * k2p, r + 0.5 * dt * k2r, z + 0.5 * dt * k2z, db,
                             K, T1, T2, T3, coef, r_power, abs_power, harmonic, trig)
        k4p, k4r, k4z = _rhs(order, psi + dt * k3p, r + dt * k3r, z + dt * k3z, dc,
                             K, T1, T2, T3, coef, r_power, abs_power, harmonic, trig)
        psi += dt * (k1p + 2 * k2p + 2 * k3p + k4p) / 6.0
        r += dt * (k1r + 2 * k2r + 2 * k3r + k4r) / 6.0
        z += dt * (k1z + 2 * k2z + 2 * k3z + k4z) / 6.0
    return psi, r, z


@njit(cache=True)
def initial_z(K, T1, T2, T3, r, rdot, rudder):
    """The nomoto2 auxiliary state z = T1 T2 r' + (T1 + T2) r - K T3 d (unused by nomoto1)."""
    return T1 * T2 * rdot + (T1 + T2) * r - K * T3 * rudder


@njit(cache=True)
def simulate_kernel(order, h, rudder, gain_scale, time_scale, K0, T10, T20, T30,
                    bounds, initial, coef, r_power, abs_power, harmonic, trig, substeps):
    """Integrate every segment ``bounds[i] = (start, stop)`` from ``initial[i] = (psi0, r0,
    rdot0)`` with RK4, ``substeps`` steps per sample.

    Returns heading (rad) and yaw rate (rad/s) at every sample (NaN outside the
    segments). A blow-up (non-finite state) fills the rest of its segment with NaN.
    """
    n = rudder.shape[0]
    psi_out = np.full(n, np.nan)
    r_out = np.full(n, np.nan)
    for i in range(bounds.shape[0]):
        a, b = bounds[i, 0], bounds[i, 1]
        psi, r = initial[i, 0], initial[i, 1]
        K, T1, T2, T3 = K0 * gain_scale[a], T10 * time_scale[a], T20 * time_scale[a], T30 * time_scale[a]
        z = initial_z(K, T1, T2, T3, r, initial[i, 2], rudder[a])
        psi_out[a], r_out[a] = psi, r
        for k in range(a, b - 1):
            K = K0 * gain_scale[k]
            T1, T2, T3 = T10 * time_scale[k], T20 * time_scale[k], T30 * time_scale[k]
            psi, r, z = advance(order, h, rudder[k], rudder[k + 1], K, T1, T2, T3, psi, r, z,
                                coef, r_power, abs_power, harmonic, trig, substeps)
            if not (np.isfinite(psi) and np.isfinite(r)) or abs(r) > 1e3:
                break
            psi_out[k + 1], r_out[k + 1] = psi, r
    return psi_out, r_out


def substeps_for(h: float, fastest_time_constant: float, steps_per_time_constant: float = 2.0) -> int:
    """RK4 substeps per sample: ``steps_per_time_constant`` steps or more per fastest time
    constant (by default a step of at most half of it: RK4 is stable to 2.8 and its error on that
    mode is below 1e-3 there), at most 200."""
    return int(min(200, max(1, np.ceil(steps_per_time_constant * h / max(fastest_time_constant, 1e-3)))))
