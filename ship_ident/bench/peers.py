"""``peers``: ship_ident against the online identifiers a user would otherwise pick, on the same data.

Peers (real libraries where one exists, not re-implementations):

* ``rls``: recursive least squares with exponential forgetting on the very
  same equation-error regression as ours (unit-scaled columns, P0 = 1e4 I);
  forgetting factor 1 - h/M for a memory of M seconds.
* ``ukf``: filterpy's ``UnscentedKalmanFilter`` on (psi, r, z, K, T1, T2,
  T3, delta_r, alpha) with random-walk parameters (per-sample std = drift x
  |parameter|), heading and yaw rate measured with their estimated noise,
  started from an OLS fit of the first 60 s.
* ``frols``: SysIdentPy's FROLS polynomial NARX model (yaw rate from rudder,
  lags 2, degree 3, information-criterion order), run free on held-out data
  (heading integrated); a black box without physical parameters.
* ``lssvm-dual``: the seed's plain LS-SVM solved in the N x N dual with
  bias (rows thinned to 3000: the dual is O(N^3)).
* ours: ``rwlssvm+pem`` (the node's default), ``rwlssvm+oe`` and ``rwlssvm``.

Accuracy: seed 001's vessel (nomoto2 + rudder offset + cubic yaw), mixed
manoeuvre, realistic sensor noise (``simulator.Noise()``), several noise
seeds; per parameter the RMS error over the seeds and its ratio to the
Cramer-Rao bound of the record (``crb.py``); free-run heading and yaw-rate
RMSE on a held-out random manoeuvre (``truth`` row: the true parameters, the
floor set by the noise). Every method sees the whole training record (RLS
with a memory of the record length, the UKF with drift 1e-4).

Tracking: K drops 30 % and T1 rises 30 % at a known time, in two scenarios
(``TRACKING_MANEUVERS``: random rudder steps throughout, and the mixed
manoeuvre, whose second half opens with a weakly exciting turning circle);
ours run through
``OnlineIdentifier`` with the node's default configuration (window W =
180 s, refit every 5 s); RLS and the UKF run sample by sample with a small
grid of memories and drifts, every setting reported. Recovery: seconds from
the change until K stays within 5 % of the new truth to the end of the run,
read at each K published (ours: the K in force from one record to the next,
every refit period, and every tenth of one while the gain follows a change;
RLS and the UKF: every sample).

Speed: time per refit (ours: the online refit, warm-started, as on board;
FROLS and the dual: a fit of one window) or per sample (RLS, UKF), and the
CPU share of one core each needs at 10 Hz with the 5 s refit period (ours:
the whole online core over the tracking run: inputs, refits, change watches
and the gain refits after the change).
Scaling: refit time of ours for 1k, 10k and 100k samples; replay throughput
of a 1-hour simulated bag (``fleet.identify_bag``, the replay loop).
"""

from __future__ import annotations

from . import register
from .common import machine
from .peer_experiments import (
    ONLINE,
    RECOVERY_TOLERANCE,
    TRACKING_MANEUVERS,
    accuracy,
    dataset_samples,
    online_trace,
    recovery_time,
    speed_and_scaling,
    tracking,
)
from .peer_rendering import plot, render

# The peers live in peer_models, the experiments in peer_experiments, the tables and plots in peer_rendering;
# what other benchmarks and tests import from here stays importable.
__all__ = ["RECOVERY_TOLERANCE", "dataset_samples", "online_trace", "recovery_time", "render", "run"]


def run(quick: bool = False, plot_dir: str | None = None) -> dict:
    scenarios = {maneuver: tracking(quick, maneuver) for maneuver in TRACKING_MANEUVERS}
    result = {
        "machine": machine(),
        "online_config": {
            "method": ONLINE.method,
            "window_s": ONLINE.window_length,
            "refit_period_s": ONLINE.refit_period,
        },
        "accuracy": accuracy(quick),
        "tracking": scenarios,
        "speed": speed_and_scaling(scenarios[TRACKING_MANEUVERS[0]]["compute_seconds"], quick),
    }
    for scenario in scenarios.values():
        del scenario["compute_seconds"]
    if plot_dir:
        result["plots"] = plot(result, plot_dir)
    return result


register(
    "peers",
    "ship_ident against RLS, filterpy UKF, SysIdentPy FROLS and the dual LS-SVM: accuracy, tracking, speed, scaling",
    run,
    render,
    plots=True,
)
