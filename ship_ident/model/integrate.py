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
TERM_FIELDS = ("r_power", "abs_power", "harmonic", "trig")  # integer fields of a forcing term, in kernel order
RK4_NODES = np.array([0.0, 0.5, 0.5, 1.0])  # stage times within a step, in steps
# Up to this many lanes ``simulate_kernel`` steps them in pairs over all their samples, beyond it in vector loops
# (the faster way on either side, measured on a replay's runs)
MOST_LANES_ONE_BY_ONE = 24


@njit(cache=True, inline="always")
def _forcing(psi, r, coef, r_power, abs_power, harmonic, trig):
    """Yaw forcing (rad/s) of one state: sum of coef r^r_power |r|^abs_power trig(harmonic psi).
    Inlined where it is called (a single chain, or a few lanes stepped in pairs); ``_forcing_lanes``
    evaluates the same sum over many lanes at once, in vector loops."""
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
    """Advance the state (psi, r, z) over one sample of length h with RK4, the rudder linear from d0 to d1.

    The second-order Nomoto model T1 T2 r'' + (T1 + T2) r' + r = K (d + T3 d') plus the forcing terms
    (Nomoto, Taguchi, Honda and Hirano 1957), in the state z = T1 T2 r' + (T1 + T2) r - K T3 d
    (``initial_z``), so that the rudder's rate never appears.

    Parameters
    ----------
    order : int
        1 (nomoto1: T r' + r = K d, T = T1) or 2 (nomoto2).
    h : float
        Sample time (s).
    d0, d1 : float
        Effective rudder angle at the sample's start and end (rad).
    K, T1, T2, T3 : float
        Gain (1/s) and time constants (s).
    psi, r, z : float
        Heading (rad), yaw rate (rad/s) and auxiliary state z (rad) at the sample's start.
    coef : numpy.ndarray
        Forcing coefficients (rad/s per term).
    r_power, abs_power, harmonic, trig : numpy.ndarray
        Each forcing term's powers of r and |r|, heading harmonic and trigonometric function
        (``effects.ForcingTerm``).
    substeps : int
        RK4 steps per sample.

    Returns
    -------
    psi, r, z : float
        The state at the sample's end.
    """
    dt = h / substeps
    for s in range(substeps):
        da = d0 + (s / substeps) * (d1 - d0)
        db = d0 + ((s + 0.5) / substeps) * (d1 - d0)
        dc = d0 + ((s + 1.0) / substeps) * (d1 - d0)
        k1p, k1r, k1z = _rhs(order, psi, r, z, da, K, T1, T2, T3, coef, r_power, abs_power, harmonic, trig)
        k2p, k2r, k2z = _rhs(
            order,
            psi + 0.5 * dt * k1p,
            r + 0.5 * dt * k1r,
            z + 0.5 * dt * k1z,
            db,
            K,
            T1,
            T2,
            T3,
            coef,
            r_power,
            abs_power,
            harmonic,
            trig,
        )
        k3p, k3r, k3z = _rhs(
            order,
            psi + 0.5 * dt * k2p,
            r + 0.5 * dt * k2r,
            z + 0.5 * dt * k2z,
            db,
            K,
            T1,
            T2,
            T3,
            coef,
            r_power,
            abs_power,
            harmonic,
            trig,
        )
        k4p, k4r, k4z = _rhs(
            order,
            psi + dt * k3p,
            r + dt * k3r,
            z + dt * k3z,
            dc,
            K,
            T1,
            T2,
            T3,
            coef,
            r_power,
            abs_power,
            harmonic,
            trig,
        )
        psi += dt * (k1p + 2 * k2p + 2 * k3p + k4p) / 6.0
        r += dt * (k1r + 2 * k2r + 2 * k3r + k4r) / 6.0
        z += dt * (k1z + 2 * k2z + 2 * k3z + k4z) / 6.0
    return psi, r, z


@njit(cache=True)
def initial_z(K, T1, T2, T3, r, rdot, rudder):
    """The nomoto2 auxiliary state z = T1 T2 r' + (T1 + T2) r - K T3 d (unused by nomoto1).

    Parameters
    ----------
    K, T1, T2, T3 : float
        Gain (1/s) and time constants (s).
    r, rdot : float
        Yaw rate (rad/s) and yaw acceleration (rad/s^2).
    rudder : float
        Effective rudder angle (rad).

    Returns
    -------
    float
        z (rad).
    """
    return T1 * T2 * rdot + (T1 + T2) * r - K * T3 * rudder


@njit(cache=True, error_model="numpy")
def _forcing_lanes(out, work, psi, r, coef, r_power, abs_power, harmonic, trig):
    """``_forcing`` of every lane at once: ``coef[term, lane]``, states ``psi[lane]``, ``r[lane]``.
    Each loop runs over the lanes, so that it compiles to vector instructions."""
    lanes = out.shape[0]
    for lane in range(lanes):
        out[lane] = 0.0
    for j in range(coef.shape[0]):
        for lane in range(lanes):
            work[lane] = coef[j, lane]
        for _ in range(r_power[j]):
            for lane in range(lanes):
                work[lane] *= r[lane]
        for _ in range(abs_power[j]):
            for lane in range(lanes):
                work[lane] *= abs(r[lane])
        if trig[j] == 1:
            for lane in range(lanes):
                work[lane] *= np.cos(harmonic[j] * psi[lane])
        elif trig[j] == 2:
            for lane in range(lanes):
                work[lane] *= np.sin(harmonic[j] * psi[lane])
        for lane in range(lanes):
            out[lane] += work[lane]


@njit(cache=True)
def _advance_lane(
    order,
    h,
    rudder,
    gain_scale,
    time_scale,
    constants,
    first,
    last,
    psi,
    r,
    z,
    coef,
    r_power,
    abs_power,
    harmonic,
    trig,
    substeps,
    psi_out,
    r_out,
):
    """One lane of ``simulate_kernel`` on its own, with ``advance``: samples first..last+1."""
    for k in range(first, last + 1):
        s = time_scale[k]
        psi, r, z = advance(
            order,
            h,
            rudder[k],
            rudder[k + 1],
            constants[0] * gain_scale[k],
            constants[1] * s,
            constants[2] * s,
            constants[3] * s,
            psi,
            r,
            z,
            coef,
            r_power,
            abs_power,
            harmonic,
            trig,
            substeps,
        )
        if not (np.isfinite(psi) and np.isfinite(r)) or abs(r) > 1e3:
            return
        psi_out[k + 1], r_out[k + 1] = psi, r


@njit(cache=True, error_model="numpy", inline="always")
def _lane_slopes(order, tp, tr, tz, d, lane_constants, coef, r_power, abs_power, harmonic, trig):
    """One lane's RK4 stage slopes of (psi, r, z) at the state (tp, tr, tz) and rudder d (rad), its
    per-sample ``lane_constants`` those of ``simulate_kernel``'s lanes (K, T1 + T2, 1 / (T1 T2),
    K T3, 1 / T) and the forcing terms as ``_forcing``'s: the same operations as the vector loops,
    so the same numbers."""
    K, S, inv_P, KT3, inv_T = lane_constants
    force = _forcing(tp, tr, coef, r_power, abs_power, harmonic, trig)
    if order == 1:
        return tr, (K * d + force - tr) * inv_T, 0.0
    return tr, (tz - S * tr + KT3 * d) * inv_P, K * d + force - tr


@njit(cache=True, error_model="numpy", inline="always")
def _sample_constants(constants, gain_scale, time_scale, k):
    """One lane's constants over sample ``k`` as ``simulate_kernel``'s vector loops form them: K,
    T1 + T2, 1 / (T1 T2) (inf for nomoto1: unused), K T3 and 1 / T, with the run's ``constants``
    (K, T1, T2, T3) scaled by its ``gain_scale`` and ``time_scale`` there."""
    s = time_scale[k]
    K = constants[0] * gain_scale[k]
    return (
        K,
        (constants[1] + constants[2]) * s,
        1.0 / (constants[1] * constants[2] * s * s),
        K * constants[3] * s,
        1.0 / (constants[1] * s),
    )


@njit(cache=True, error_model="numpy", inline="always")
def _rk4_substep(
    order, dt, sub, substeps, p, q, w, d0, slope, lane_constants, coef, r_power, abs_power, harmonic, trig
):
    """One lane's RK4 step ``sub`` of ``substeps`` over a sample from the state (p, q, w) = (psi, r,
    z), the rudder d0 + t slope at the sample's fraction t: the vector loops' operations in their
    order, so the same numbers."""
    half, whole = 0.5 * dt, 1.0 * dt
    d_start = d0 + ((sub + 0.0) / substeps) * slope
    d_mid = d0 + ((sub + 0.5) / substeps) * slope
    d_end = d0 + ((sub + 1.0) / substeps) * slope
    s1p, s1r, s1z = _lane_slopes(order, p, q, w, d_start, lane_constants, coef, r_power, abs_power, harmonic, trig)
    s2p, s2r, s2z = _lane_slopes(
        order,
        p + half * s1p,
        q + half * s1r,
        w + half * s1z,
        d_mid,
        lane_constants,
        coef,
        r_power,
        abs_power,
        harmonic,
        trig,
    )
    s3p, s3r, s3z = _lane_slopes(
        order,
        p + half * s2p,
        q + half * s2r,
        w + half * s2z,
        d_mid,
        lane_constants,
        coef,
        r_power,
        abs_power,
        harmonic,
        trig,
    )
    s4p, s4r, s4z = _lane_slopes(
        order,
        p + whole * s3p,
        q + whole * s3r,
        w + whole * s3z,
        d_end,
        lane_constants,
        coef,
        r_power,
        abs_power,
        harmonic,
        trig,
    )
    p += dt * (s1p + 2 * s2p + 2 * s3p + s4p) / 6
    q += dt * (s1r + 2 * s2r + 2 * s3r + s4r) / 6
    w += dt * (s1z + 2 * s2z + 2 * s3z + s4z) / 6
    return p, q, w


@njit(cache=True, error_model="numpy")
def _advance_lane_pair(
    order,
    dt,
    substeps,
    lane_a,
    lane_b,
    run,
    first,
    last,
    alive,
    rudder,
    gain_scale,
    time_scale,
    constants,
    psi,
    r,
    z,
    coef,
    r_power,
    abs_power,
    harmonic,
    trig,
    psi_out,
    r_out,
):
    """Two lanes of ``simulate_kernel`` over all their samples, side by side in registers: for a few
    lanes the vector loops are mostly overhead, and two independent chains interleaved fill the
    processor's pipelines where one alone waits on each result. ``lane_b`` may be ``lane_a`` (a lane
    alone). Each lane's steps are the vector loops' operations in their order, so the same numbers."""
    n = rudder.shape[1]
    ja, jb = run[lane_a], run[lane_b]
    coef_a, coef_b = coef[ja], coef[jb]
    pa, qa, wa = psi[lane_a], r[lane_a], z[lane_a]
    pb, qb, wb = psi[lane_b], r[lane_b], z[lane_b]
    live_a, live_b = alive[lane_a], alive[lane_b]
    for step in range(max(last[lane_a] - first[lane_a], last[lane_b] - first[lane_b]) + 1):
        if not (live_a or live_b):
            return
        ka, kb = min(first[lane_a] + step, last[lane_a]), min(first[lane_b] + step, last[lane_b])
        constants_a = _sample_constants(constants[ja], gain_scale[ja], time_scale[ja], ka)
        constants_b = _sample_constants(constants[jb], gain_scale[jb], time_scale[jb], kb)
        da, db = rudder[ja, ka], rudder[jb, kb]
        slope_a, slope_b = rudder[ja, min(ka + 1, n - 1)] - da, rudder[jb, min(kb + 1, n - 1)] - db
        for sub in range(substeps):
            pa, qa, wa = _rk4_substep(
                order,
                dt,
                sub,
                substeps,
                pa,
                qa,
                wa,
                da,
                slope_a,
                constants_a,
                coef_a,
                r_power,
                abs_power,
                harmonic,
                trig,
            )
            pb, qb, wb = _rk4_substep(
                order,
                dt,
                sub,
                substeps,
                pb,
                qb,
                wb,
                db,
                slope_b,
                constants_b,
                coef_b,
                r_power,
                abs_power,
                harmonic,
                trig,
            )
        if live_a:
            if np.isfinite(pa) and np.isfinite(qa) and abs(qa) <= 1e3:
                psi_out[ja, ka + 1], r_out[ja, ka + 1] = pa, qa
                live_a = first[lane_a] + step < last[lane_a]
            else:
                live_a = False
        if live_b:
            if np.isfinite(pb) and np.isfinite(qb) and abs(qb) <= 1e3:
                psi_out[jb, kb + 1], r_out[jb, kb + 1] = pb, qb
                live_b = first[lane_b] + step < last[lane_b]
            else:
                live_b = False


@njit(cache=True, error_model="numpy")
def simulate_kernel(
    order,
    h,
    rudder,
    gain_scale,
    time_scale,
    constants,
    bounds,
    initial,
    coef,
    r_power,
    abs_power,
    harmonic,
    trig,
    substeps,
):
    """Integrate ``m`` runs of the model over every segment with RK4, ``substeps`` steps per sample.

    Run ``j`` has its own inputs ``rudder[j]``, ``gain_scale[j]``, ``time_scale[j]`` (m x n),
    constants (K, T1, T2, T3) = ``constants[j]``, forcing coefficients ``coef[j]`` and initial states
    ``initial[j, i] = (psi0, r0, rdot0)`` for segment ``bounds[i] = (start, stop)``.

    Every (run, segment) pair is a lane, and the lanes are independent. Up to
    MOST_LANES_ONE_BY_ONE lanes (the runs of a finite-difference Jacobian on a few shooting
    intervals) go two at a time over all their samples, their two chains of dependent operations
    interleaved (``_advance_lane_pair``); more lanes advance one sample together, in loops over the
    lanes that run as vector instructions (several times faster for a window of many shooting
    intervals). Same steps as ``advance``.

    Parameters
    ----------
    order : int
        1 or 2 (nomoto1, nomoto2).
    h : float
        Sample time (s).
    rudder : numpy.ndarray
        (m, n) effective rudder angle (rad).
    gain_scale, time_scale : numpy.ndarray
        (m, n) multipliers of K and of the time constants (speed dependence; 1 without it).
    constants : numpy.ndarray
        (m, 4) K (1/s), T1, T2, T3 (s).
    bounds : numpy.ndarray
        (segments, 2) half-open sample ranges.
    initial : numpy.ndarray
        (m, segments, 3) initial heading (rad), yaw rate (rad/s), yaw acceleration (rad/s^2).
    coef : numpy.ndarray
        Forcing coefficients (rad/s per term).
    r_power, abs_power, harmonic, trig : numpy.ndarray
        Each forcing term's powers of r and |r|, heading harmonic and trigonometric function
        (``effects.ForcingTerm``).
    substeps : int
        RK4 steps per sample.

    Returns
    -------
    heading, yaw_rate : numpy.ndarray
        (m, n) heading (rad) and yaw rate (rad/s) of every run, NaN outside the segments. A blow-up
        (non-finite state, |r| > 1e3 rad/s) fills the rest of its segment with NaN.
    """
    n = rudder.shape[1]
    psi_out, r_out, run, first, last, alive, psi, r, z, longest = lane_starts(
        rudder, gain_scale, time_scale, constants, bounds, initial
    )
    lanes = run.shape[0]
    lane_coef = np.empty((coef.shape[1], lanes))
    for lane in range(lanes):
        lane_coef[:, lane] = coef[run[lane]]
    if lanes == 1:  # a single chain: scalar registers beat vector loops of length one
        if alive[0]:
            _advance_lane(
                order,
                h,
                rudder[0],
                gain_scale[0],
                time_scale[0],
                constants[0],
                first[0],
                last[0],
                psi[0],
                r[0],
                z[0],
                coef[0],
                r_power,
                abs_power,
                harmonic,
                trig,
                substeps,
                psi_out[0],
                r_out[0],
            )
        return psi_out, r_out
    if lanes <= MOST_LANES_ONE_BY_ONE:
        for lane in range(0, lanes, 2):
            _advance_lane_pair(
                order,
                h / substeps,
                substeps,
                lane,
                min(lane + 1, lanes - 1),
                run,
                first,
                last,
                alive,
                rudder,
                gain_scale,
                time_scale,
                constants,
                psi,
                r,
                z,
                coef,
                r_power,
                abs_power,
                harmonic,
                trig,
                psi_out,
                r_out,
            )
        return psi_out, r_out
    # per-sample constants of each lane: K, T1 + T2, 1 / (T1 T2), K T3, 1 / T
    K, S, inv_P, KT3, inv_T = (np.empty(lanes), np.empty(lanes), np.empty(lanes), np.empty(lanes), np.empty(lanes))
    d0, slope, d = np.empty(lanes), np.empty(lanes), np.empty(lanes)
    stage = np.empty((4, 3, lanes))  # RK4 slopes k1..k4 of (psi, r, z)
    tp, tr, tz = np.empty(lanes), np.empty(lanes), np.empty(lanes)
    force, work = np.empty(lanes), np.empty(lanes)
    dt = h / substeps
    for step in range(longest - 1):
        for lane in range(lanes):
            j, k = run[lane], min(first[lane] + step, last[lane])
            s = time_scale[j, k]
            K[lane] = constants[j, 0] * gain_scale[j, k]
            S[lane] = (constants[j, 1] + constants[j, 2]) * s
            inv_P[lane] = 1.0 / (constants[j, 1] * constants[j, 2] * s * s)  # inf for nomoto1: unused
            KT3[lane] = K[lane] * constants[j, 3] * s
            inv_T[lane] = 1.0 / (constants[j, 1] * s)
            d0[lane] = rudder[j, k]
            slope[lane] = rudder[j, min(k + 1, n - 1)] - d0[lane]
        for sub in range(substeps):
            for q in range(4):  # stage q from the state advanced by the previous stage's slope
                fraction = (sub + RK4_NODES[q]) / substeps
                weight = RK4_NODES[q] * dt
                for lane in range(lanes):
                    d[lane] = d0[lane] + fraction * slope[lane]
                    if q == 0:
                        tp[lane], tr[lane], tz[lane] = psi[lane], r[lane], z[lane]
                    else:
                        tp[lane] = psi[lane] + weight * stage[q - 1, 0, lane]
                        tr[lane] = r[lane] + weight * stage[q - 1, 1, lane]
                        tz[lane] = z[lane] + weight * stage[q - 1, 2, lane]
                _forcing_lanes(force, work, tp, tr, lane_coef, r_power, abs_power, harmonic, trig)
                for lane in range(lanes):
                    stage[q, 0, lane] = tr[lane]
                    if order == 1:
                        stage[q, 1, lane] = (K[lane] * d[lane] + force[lane] - tr[lane]) * inv_T[lane]
                        stage[q, 2, lane] = 0.0
                    else:
                        stage[q, 1, lane] = (tz[lane] - S[lane] * tr[lane] + KT3[lane] * d[lane]) * inv_P[lane]
                        stage[q, 2, lane] = K[lane] * d[lane] + force[lane] - tr[lane]
            for lane in range(lanes):
                psi[lane] += (
                    dt * (stage[0, 0, lane] + 2 * stage[1, 0, lane] + 2 * stage[2, 0, lane] + stage[3, 0, lane]) / 6
                )
                r[lane] += (
                    dt * (stage[0, 1, lane] + 2 * stage[1, 1, lane] + 2 * stage[2, 1, lane] + stage[3, 1, lane]) / 6
                )
                z[lane] += (
                    dt * (stage[0, 2, lane] + 2 * stage[1, 2, lane] + 2 * stage[2, 2, lane] + stage[3, 2, lane]) / 6
                )
        store_lanes(step, run, first, last, alive, psi, r, psi_out, r_out)
    return psi_out, r_out


@njit(cache=True)
def lane_starts(rudder, gain_scale, time_scale, constants, bounds, initial):
    """The lanes of a free-run kernel, every (run, segment) pair, and their starts.

    Parameters
    ----------
    rudder, gain_scale, time_scale, constants, bounds, initial : numpy.ndarray
        As ``simulate_kernel``'s.

    Returns
    -------
    psi_out, r_out : numpy.ndarray
        (m, n) heading (rad) and yaw rate (rad/s) to be filled, NaN but for each lane's initial
        state at its segment's first sample.
    run, first, last : numpy.ndarray
        Each lane's run, first sample and last sample it steps from (int64).
    alive : numpy.ndarray
        Whether the lane steps at all (its segment holds two samples or more).
    psi, r, z : numpy.ndarray
        Each lane's initial state: heading (rad), yaw rate (rad/s) and z (``initial_z``).
    longest : int
        Samples of the longest segment.
    """
    (runs, n), segments = rudder.shape, bounds.shape[0]
    lanes = runs * segments
    psi_out = np.full((runs, n), np.nan)
    r_out = np.full((runs, n), np.nan)
    run = np.empty(lanes, dtype=np.int64)
    first = np.empty(lanes, dtype=np.int64)
    last = np.empty(lanes, dtype=np.int64)  # last sample a lane steps from
    alive = np.empty(lanes, dtype=np.bool_)
    psi, r, z = np.empty(lanes), np.empty(lanes), np.empty(lanes)
    longest = 0
    for lane in range(lanes):
        j, i = lane // segments, lane % segments
        a, b = bounds[i, 0], bounds[i, 1]
        run[lane], first[lane], last[lane], alive[lane] = j, a, max(b - 2, a), b - a >= 2
        longest = max(longest, b - a)
        psi[lane], r[lane] = initial[j, i, 0], initial[j, i, 1]
        s = time_scale[j, a]
        z[lane] = initial_z(
            constants[j, 0] * gain_scale[j, a],
            constants[j, 1] * s,
            constants[j, 2] * s,
            constants[j, 3] * s,
            r[lane],
            initial[j, i, 2],
            rudder[j, a],
        )
        if b > a:
            psi_out[j, a], r_out[j, a] = psi[lane], r[lane]
    return psi_out, r_out, run, first, last, alive, psi, r, z, longest


@njit(cache=True)
def store_lanes(step, run, first, last, alive, psi, r, psi_out, r_out):
    """Write each lane's state after its sample first + ``step`` at the next sample, while its segment lasts.

    A lane whose state blew up (non-finite, |r| > 1e3 rad/s) stops there, the rest of its segment
    left NaN.

    Parameters
    ----------
    step : int
        Samples stepped since each lane's first.
    run, first, last, alive : numpy.ndarray
        ``lane_starts``' lanes (``alive`` turns False where a lane blows up).
    psi, r : numpy.ndarray
        Each lane's heading (rad) and yaw rate (rad/s) after the step.
    psi_out, r_out : numpy.ndarray
        (m, n) heading and yaw rate of every run, written in place.
    """
    for lane in range(run.shape[0]):
        k = first[lane] + step
        if alive[lane] and k <= last[lane]:
            if np.isfinite(psi[lane]) and np.isfinite(r[lane]) and abs(r[lane]) <= 1e3:
                psi_out[run[lane], k + 1], r_out[run[lane], k + 1] = psi[lane], r[lane]
            else:
                alive[lane] = False


def forcing(psi: np.ndarray, r: np.ndarray, terms) -> np.ndarray:
    """Yaw forcing of ``terms`` on every sample of heading and yaw rate, by the integrator's own evaluator.

    Parameters
    ----------
    psi : numpy.ndarray
        Heading (rad).
    r : numpy.ndarray
        Yaw rate (rad/s).
    terms : sequence of ForcingTerm
        Each with coefficient, r_power, abs_power, harmonic and trig (``effects.ForcingTerm``).

    Returns
    -------
    numpy.ndarray
        The forcing (rad/s) per sample (each sample a lane).
    """
    n = len(psi)
    out = np.zeros(n)
    if terms:
        coef = np.repeat(np.array([[t.coefficient] for t in terms], dtype=float), n, axis=1)
        ints = [np.array([getattr(t, f) for t in terms], dtype=np.int64) for f in TERM_FIELDS]
        psi, r = np.ascontiguousarray(psi, dtype=float), np.ascontiguousarray(r, dtype=float)
        _forcing_lanes(out, np.empty(n), psi, r, coef, *ints)
    return out


def substeps_for(h: float, fastest_time_constant: float, steps_per_time_constant: float = 2.0) -> int:
    """RK4 substeps per sample: ``steps_per_time_constant`` steps or more per fastest time constant.

    By default a step of at most half of it: RK4 is stable to h / T = 2.8 and its error on that mode
    is below 1e-3 there; at most 200.

    Parameters
    ----------
    h : float
        Sample time (s).
    fastest_time_constant : float
        The model's fastest time constant (s).
    steps_per_time_constant : float
        Steps per fastest time constant.

    Returns
    -------
    int
        Substeps per sample, 1 to 200.
    """
    return int(min(200, max(1, np.ceil(steps_per_time_constant * h / max(fastest_time_constant, 1e-3)))))
