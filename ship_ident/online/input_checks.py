"""Checks of the online identifier's inputs, as pure functions of the window (times in s, SI).

Each returns ``{condition: sentence}`` (empty when all is well) or, for one sample, why it is
rejected: values that no sensor reports, stamps out of order, heading in degrees or of the other
sign convention, the rudder held at the steering gear's limit, a window cut short by the sample
bound, inputs missing, stale or still filling the window, clock jumps.
"""

from __future__ import annotations

import math

import numpy as np

from .config import OnlineConfig
from .samples import ROLES, Sample

REQUIRED_ROLES = ("rudder", "heading", "yaw_rate")
REJECTIONS = ("non_finite", "absurd", "out_of_order", "duplicate")

# Largest magnitude a sensor can plausibly report (SI); beyond it a sample is a fault.
ABSURD_LIMITS = {
    "rudder": math.radians(90.0),  # rad: no rudder turns beyond 90 deg
    "heading": 1000.0,  # rad: wrapped or unwrapped compass heading
    "yaw_rate": 3.0,  # rad/s (172 deg/s): no USV turns faster
    "speed": 50.0,  # m/s
}

# Plausibility of heading against yaw rate: the heading change over intervals of HEADING_BASELINE
# is regressed on the integrated yaw rate; the slope is 1 when both are rad and NED.
HEADING_BASELINE = 1.0  # s
MIN_TURN_RATE_STD = math.radians(0.5)  # rad/s: with less turning the slope says nothing
DEGREES_SLOPE = 10.0  # slope beyond this: heading in degrees (57.3)
DEGREE_WRAP = (300.0, 420.0)  # a heading step this large is a wrap at 360 (degrees)
# Rudder saturation: a single extreme value, within SATURATION_TOLERANCE of the steering gear's
# limit, held (within SATURATION_TOLERANCE) for this share of the window.
SATURATION_SHARE = 0.5
SATURATION_TOLERANCE = math.radians(1.0)  # rad


def value_rejection(sample: Sample) -> str:
    """Why a sample's value cannot be used: 'non_finite' or 'absurd', or '' for a usable one.

    A value (or stamp) no sensor reports: NaN or inf, or beyond ABSURD_LIMITS (|rudder| > 90 deg,
    |heading| > 1000 rad,
    |yaw rate| > 172 deg/s, |speed| > 50 m/s).

    Parameters
    ----------
    sample : Sample
        The sample (time s, SI value).

    Returns
    -------
    str
        'non_finite', 'absurd' or ''.

    Raises
    ------
    ValueError
        For a role that is not one of ROLES.
    """
    if sample.role not in ROLES:
        raise ValueError(f"unknown role {sample.role!r}; use one of {', '.join(ROLES)}")
    if not (math.isfinite(sample.time) and math.isfinite(sample.value)):
        return "non_finite"
    if abs(sample.value) > ABSURD_LIMITS[sample.role]:
        return "absurd"
    return ""


def order_rejection(time: float, newest: float) -> str:
    """'duplicate' or 'out_of_order' for a stamp at or before the input's newest, else ''.

    Parameters
    ----------
    time : float
        The sample's stamp (s).
    newest : float
        The input's newest accepted stamp (s).

    Returns
    -------
    str
        'duplicate', 'out_of_order' or ''.
    """
    if time == newest:
        return "duplicate"
    if time < newest:
        return "out_of_order"
    return ""


def input_conditions(
    config: OnlineConfig, series: dict, newest: dict, now: float, fresh: dict, last_jump: float
) -> dict:
    """What the window's inputs say before any fit.

    No data, still filling (less than ``min_window_length``), stale inputs (no sample for
    ``stale_timeout``), samples rejected since the last refit, a clock jump.

    Parameters
    ----------
    config : OnlineConfig
        The identifier's configuration.
    series : dict
        Role -> (n, 2) array of the window's accepted (time s, value) samples (rad, rad/s, m/s).
    newest : dict
        Role -> newest accepted stamp (s).
    now : float
        Clock time of the refit (s).
    fresh : dict
        Input counts by outcome since the last refit.
    last_jump : float
        The clock's last jump (s; negative backwards).

    Returns
    -------
    dict
        Condition name -> sentence.
    """
    conditions = {}
    roles = list(REQUIRED_ROLES) + (["speed"] if config.speed_topic else [])
    empty = [r for r in roles if len(series[r]) < 2]
    if empty:
        conditions["no_data"] = f"no {', '.join(empty)} data in the last {config.window_length:g} s"
    else:
        span = min(series[r][-1, 0] for r in roles) - max(series[r][0, 0] for r in roles)
        if span < config.min_window_length - 0.5 * config.sample_time:
            conditions["window_filling"] = (
                f"window holds {max(span, 0):.0f} s of {config.min_window_length:g} s needed for a first fit"
            )
    stale = [
        f"{r} ({now - newest[r]:.1f} s)"
        for r in roles
        if math.isfinite(newest[r]) and now - newest[r] > config.stale_timeout
    ]
    if stale:
        conditions["stale_input"] = "no new samples on " + ", ".join(stale)
    rejected = {k: fresh[k] for k in REJECTIONS if fresh[k]}
    if rejected:
        conditions["rejected_samples"] = "rejected since last refit: " + ", ".join(
            f"{n} {k.replace('_', '-')}" for k, n in rejected.items()
        )
    if fresh["clock_jumps"] and last_jump < 0:
        conditions["clock_jump"] = f"clock jumped back {-last_jump:.1f} s; window and schedule were reset"
    elif fresh["clock_jumps"]:
        conditions["clock_jump"] = (
            f"clock jumped forward {last_jump:.1f} s (or every input "
            "fell silent); schedule restarted, the window keeps only "
            f"the last {config.window_length:g} s"
        )
    return conditions


def window_truncation(config: OnlineConfig, series: dict, full: list, now: float) -> dict:
    """The sample bound ``max_window_samples`` cut an input's window short of ``window_length``.

    Parameters
    ----------
    config : OnlineConfig
        The identifier's configuration.
    series : dict
        Role -> (n, 2) array of the window's accepted (time s, value) samples (rad, rad/s, m/s).
    full : list of str
        The roles whose window holds ``max_window_samples``.
    now : float
        Clock time of the refit (s).

    Returns
    -------
    dict
        {'window_truncated': sentence} naming the inputs and how much they hold, or {}.
    """
    short = [
        f"{role} ({now - series[role][0, 0]:.0f} s)"
        for role in full
        if len(series[role]) and series[role][0, 0] > now - config.window_length + config.sample_time
    ]
    if not short:
        return {}
    return {
        "window_truncated": (
            f"max_window_samples ({config.max_window_samples}) holds less than "
            f"the {config.window_length:g} s window of {', '.join(short)}: the "
            "input is faster than planned; raise max_window_samples or shorten "
            "window_length"
        )
    }


def heading_plausibility(series: dict) -> dict:
    """Heading in degrees, or heading and yaw rate of opposite sign conventions.

    The heading's change over ``HEADING_BASELINE`` intervals is regressed on
    the yaw rate integrated over the same intervals: the slope is 1 for rad
    and NED on both, 57.3 for a heading in degrees, -1 for a yaw rate of the
    other sign (ENU, counter-clockwise positive). Heading steps of about 360
    (wraps in degrees) also give degrees away when the boat hardly turns.

    Parameters
    ----------
    series : dict
        Role -> (n, 2) array of the window's accepted (time s, value) samples (rad, rad/s, m/s).

    Returns
    -------
    dict
        {'heading_in_degrees': sentence} or {'yaw_rate_sign': sentence}, or {}.
    """
    heading, yaw_rate = series["heading"], series["yaw_rate"]
    if len(heading) < 10 or len(yaw_rate) < 10:
        return {}
    steps = np.abs(np.diff(heading[:, 1]))
    degree_wraps = int(np.count_nonzero((steps > DEGREE_WRAP[0]) & (steps < DEGREE_WRAP[1])))
    t = heading[:, 0]
    stride = max(1, int(round(HEADING_BASELINE / max(float(np.median(np.diff(t))), 1e-6))))
    t, psi = t[::stride], np.unwrap(heading[:, 1])[::stride]
    inside = (t >= yaw_rate[0, 0]) & (t <= yaw_rate[-1, 0])
    t, psi = t[inside], psi[inside]
    slope = correlation = math.nan
    if len(t) >= 10:
        turned = np.diff(integral_at(yaw_rate[:, 0], yaw_rate[:, 1], t))
        changed = np.diff(psi)
        if np.std(turned / np.diff(t)) >= MIN_TURN_RATE_STD:
            slope = float(np.dot(changed, turned) / np.dot(turned, turned))
            correlation = float(np.corrcoef(changed, turned)[0, 1])
    if abs(slope) > DEGREES_SLOPE or degree_wraps:
        evidence = (
            f"it changes {abs(slope):.0f}x as fast as the yaw rate turns the boat"
            if abs(slope) > DEGREES_SLOPE
            else f"it steps by about 360 {degree_wraps} time(s)"
        )
        return {
            "heading_in_degrees": (
                f"the heading looks like degrees, not rad ({evidence}); "
                "publish it in rad: heading-based fit figures are wrong "
                "until then"
            )
        }
    if slope < -0.5 and correlation < -0.5:
        return {
            "yaw_rate_sign": (
                f"heading and yaw rate turn opposite ways (correlation "
                f"{correlation:.2f}): one of them is counter-clockwise positive "
                "(ENU); negate the yaw rate (or heading) to NED, or use imu_topic "
                "for an Imu"
            )
        }
    return {}


def integral_at(time: np.ndarray, values: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Trapezoidal integral of ``values`` over ``time`` from its start, at the times ``at``."""
    cumulative = np.concatenate([[0.0], np.cumsum(np.diff(time) * (values[1:] + values[:-1]) / 2)])
    return np.interp(at, time, cumulative)


def rudder_saturation(rudder: np.ndarray, limit: float) -> dict:
    """The rudder held at the steering gear's limit for most of the window: saturated, or stuck there.

    A zigzag or a turn holding a smaller angle is not saturation.

    Parameters
    ----------
    rudder : numpy.ndarray
        The window's rudder angles (rad).
    limit : float
        The steering gear's limit (rad), ``rudder_limit``.

    Returns
    -------
    dict
        {'rudder_saturated': sentence with the angle and its share of the window}, or {}.
    """
    for extreme in (np.percentile(rudder, 99.5), np.percentile(rudder, 0.5)):
        share = float(np.mean(np.abs(rudder - extreme) <= SATURATION_TOLERANCE))
        if abs(extreme) >= limit - SATURATION_TOLERANCE and share >= SATURATION_SHARE:
            return {
                "rudder_saturated": (
                    f"rudder held at {math.degrees(extreme):+.1f} deg for "
                    f"{100 * share:.0f} % of the window (saturated or stuck): "
                    "the fit rests on the remaining samples"
                )
            }
    return {}
