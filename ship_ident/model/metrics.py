"""Free-run fit measures: RMSE, NRMSE fit %, and seed 000's Taylor-diagram measures.

All figures here compare a *free-run simulation* (the model driven only by
the measured rudder from a measured initial state) with measurements; they
are never one-step predictions.
"""

from __future__ import annotations

import numpy as np


def signal_metrics(measured: np.ndarray, model: np.ndarray) -> dict:
    """How closely a model's signal follows the measured one, as the truncated LS-SVM paper measures it.

    RMSE, correlation R, centred RMS difference E' and STD ratio (the Taylor diagram's statistics, as
    Xu and Guedes Soares 2023 report them), and the NRMSE fit in per cent; samples where either is not
    finite are left out.

    Parameters
    ----------
    measured, model : numpy.ndarray
        The two signals, same unit (rad or rad/s).

    Returns
    -------
    dict
        'rmse' (the signal's unit), 'r', 'e_centred' (over the measured std), 'std_ratio',
        'fit_percent', and 'diverged' (some model sample not finite).
    """
    ok = np.isfinite(measured) & np.isfinite(model)
    if ok.sum() < 2:
        return {
            "rmse": float("inf"),
            "r": 0.0,
            "e_centred": float("inf"),
            "std_ratio": 0.0,
            "fit_percent": -float("inf"),
            "diverged": True,
        }
    m, s = measured[ok], model[ok]
    err = s - m
    dm, ds = m - m.mean(), s - s.mean()
    sd_m, sd_s = dm.std(), ds.std()
    r = float(dm @ ds / (len(m) * sd_m * sd_s)) if sd_m > 0 and sd_s > 0 else 0.0
    return {
        "rmse": float(np.sqrt(np.mean(err**2))),
        "r": r,
        "e_centred": float(np.sqrt(np.mean((ds - dm) ** 2)) / sd_m) if sd_m > 0 else float("inf"),
        "std_ratio": float(sd_s / sd_m) if sd_m > 0 else 0.0,
        "fit_percent": float(100 * (1 - np.linalg.norm(err) / np.linalg.norm(dm))) if sd_m > 0 else 0.0,
        "diverged": bool(ok.sum() < len(measured)),
    }


def noise_limited_correlation(measured: np.ndarray, noise: float) -> float:
    """The correlation a perfect model's free run reaches with a signal carrying white noise.

    sqrt(1 - noise^2 / var(measured)): a slow ship whose yaw rate spreads twice its noise allows
    0.87 at most.

    Parameters
    ----------
    measured : numpy.ndarray
        The measured signal.
    noise : float
        Its white noise's std (same unit).

    Returns
    -------
    float
        The best correlation, 0 to 1.
    """
    variance = float(np.var(measured))
    return float(np.sqrt(max(0.0, 1.0 - noise**2 / variance))) if variance > 0 else 0.0


def free_run_fit(heading: np.ndarray, yaw_rate: np.ndarray, sim_heading: np.ndarray, sim_yaw_rate: np.ndarray) -> dict:
    """The ``fit`` record of an estimate, from the free-run heading and yaw rate against the measured.

    Parameters
    ----------
    heading, yaw_rate : numpy.ndarray
        Measured heading (rad) and yaw rate (rad/s).
    sim_heading, sim_yaw_rate : numpy.ndarray
        The model's free run (rad, rad/s).

    Returns
    -------
    dict
        ``signal_metrics`` of both, keyed 'rmse_heading', 'r_yaw_rate', ..., with 'horizon'
        ('free-run') and 'diverged'.
    """
    h = signal_metrics(heading, sim_heading)
    r = signal_metrics(yaw_rate, sim_yaw_rate)
    return {
        "horizon": "free-run",
        "rmse_heading": h["rmse"],
        "rmse_yaw_rate": r["rmse"],
        "r_heading": h["r"],
        "r_yaw_rate": r["r"],
        "e_centred_heading": h["e_centred"],
        "e_centred_yaw_rate": r["e_centred"],
        "std_ratio_heading": h["std_ratio"],
        "std_ratio_yaw_rate": r["std_ratio"],
        "fit_percent_heading": h["fit_percent"],
        "fit_percent_yaw_rate": r["fit_percent"],
        "diverged": h["diverged"] or r["diverged"],
    }


def effective_sample_fraction(residual: np.ndarray, max_lag: int = 50) -> float:
    """The share of samples that are independent, 1 / (1 + 2 sum rho_k), from the residual's autocorrelation.

    The sum runs from lag 1 while the autocorrelation rho_k stays above 0.05 (up to ``max_lag``, at
    most a quarter of the samples); a residual variance divided by the fraction is the long-run
    variance of its mean's samples, as independent samples would give it.

    Parameters
    ----------
    residual : numpy.ndarray
        The residual series.
    max_lag : int
        The longest lag counted (samples).

    Returns
    -------
    float
        The fraction, at most 1.
    """
    e = residual - residual.mean()
    var = e @ e
    if var <= 0 or len(e) < 4:
        return 1.0
    total = 0.0
    for k in range(1, min(max_lag, len(e) // 4)):
        rho = (e[:-k] @ e[k:]) / var
        if rho <= 0.05:
            break
        total += rho
    return 1.0 / (1.0 + 2.0 * total)
