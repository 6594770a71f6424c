"""Seed 000's 3-DOF manoeuvring model (surge u, sway v, yaw rate r), its own namespace beside the
Nomoto simulator (both have vessels, records and noise): ``model`` (equations, vessel presets,
simulation), ``fit`` (identification by equation error, free-run prediction), ``marin`` (KVLCC2
free-running records), ``data`` (CSV files and bags in and out)."""

from .fit import METHODS, Identification, default_window_time, identify, predict, prediction_metrics, regression, smooth
from .marin import approach_speed, load_marin_raw
from .model import DOFS, VESSELS, X_TERMS, YN_TERMS, Coefficients, Noise, Record, Vessel, run_model, simulate_manoeuvre

__all__ = [
    "DOFS",
    "METHODS",
    "VESSELS",
    "X_TERMS",
    "YN_TERMS",
    "Coefficients",
    "Identification",
    "Noise",
    "Record",
    "Vessel",
    "approach_speed",
    "default_window_time",
    "identify",
    "load_marin_raw",
    "predict",
    "prediction_metrics",
    "regression",
    "run_model",
    "simulate_manoeuvre",
    "smooth",
]
