"""The gain followed after a change of the vessel: K refitted on the new data, the hull held.

After a change (loading, fouling, damage; ``change.ChangeDetector``), the new data are too short for
a full fit, or the full fits of them are refused, long before they determine the gain: a free run is
almost linear in K, and a held rudder determines it (r = K delta in a steady turn). The first set of
GAIN_FITS the new data determine is refitted on them, the other parameters held from the hull before
the change, not from estimates of windows straddling it (a USV's cubic damping bent from 0.4 to 147
by them held K 20 % high).
"""

from __future__ import annotations

import numpy as np

from ..estimators.base import MAX_RELATIVE_ERRORS, Estimate, loose_parameters
from ..model.dataset import DataError, cut_segments
from ..model.effects import slow_time_constant
from ..model.metrics import free_run_fit
from ..model.structure import StructureError
from .change import CHANGED_PARAMETERS, GAIN_FIT_SPAN, fit_gain, with_held_errors
from .verdicts import Verdict

# Refitted on the new data after a change, the first set the data determine: the gain with the main
# time constant, or alone, once the new data span GAIN_FIT_SPAN main time constants of the last good
# estimate (each block's initial yaw rate and acceleration are fitted with them). The rudder offset is
# held: loading does not move it, and a held rudder cannot tell it from the gain.
GAIN_FITS = (CHANGED_PARAMETERS, ("K",))
MIN_GAIN_SAMPLES = 20  # new samples needed for the gain refit after a change
# The gain refit's free runs restart from the measured state every change_test_length s, or every
# GAIN_BLOCK_SPAN held main time constants when that is longer: a block shorter than the response
# leaves the gain to the fitted initial states (a ship with T1 35 s restarted every 30 s).
GAIN_BLOCK_SPAN = 2.0


def refit_gain(config, structure, dataset, held: dict, held_errors: dict, method: str, window: tuple):
    """The gain (with the main time constant T1 or T, or alone) refitted on the data after a change.

    Fitted on free runs in blocks of ``change_test_length`` (at least GAIN_BLOCK_SPAN held slow time
    constants), counted back from the newest, the other parameters held. The most the data determine
    is judged by their own standard errors (within MAX_RELATIVE_ERRORS, however little the rudder
    moves); a refit that may be published has its errors widened by the held hull's
    (``with_held_errors``: the data's own alone covered the new K in half the follow refits of a
    ``bench vessels`` draw).

    Parameters
    ----------
    config : OnlineConfig
        The identifier's configuration (``change_test_length``, s).
    structure : Structure
        The model.
    dataset : Dataset
        The data since the change (SI units).
    held, held_errors : dict
        The hull before the change: its parameters and standard errors (SI units).
    method : str
        The estimator's name the estimate is labelled with.
    window : tuple of float
        Start and end of the data (s).

    Returns
    -------
    estimate : Estimate or None
        The refitted estimate; None while the data are too few (MIN_GAIN_SAMPLES) or span less than
        GAIN_FIT_SPAN slow time constants, or when the refit failed.
    verdict : Verdict or None
        Why the estimate cannot be published: too_little_excitation (codes ``gain_diverged``,
        ``gain_undetermined``), or refit_failed (``gain_refit_error``, with no estimate); None for
        an estimate that the data determine.
    """
    if dataset.n_samples < MIN_GAIN_SAMPLES:
        return None, None
    time_constant = slow_time_constant(held)
    if dataset.duration < GAIN_FIT_SPAN * time_constant:
        return None, None
    block = max(config.change_test_length, GAIN_BLOCK_SPAN * time_constant)
    # blocks counted back from the end: the newest, where a changed hull shows first, is a whole one
    blocks = cut_segments(dataset.segments, int(round(block / dataset.sample_time)), min_samples=2, align="end")
    try:
        for names in GAIN_FITS:  # the most the new data determine (judged by the standard errors alone:
            # a rudder held in a turn determines K, r = K delta, however little it moves)
            params, errors = fit_gain(structure, held, dataset, blocks, names)
            loose, figures = loose_parameters({n: params[n] for n in errors}, errors, MAX_RELATIVE_ERRORS)
            if not figures:
                break
        if not figures:  # what the new data determine is judged by their own errors; the held hull's
            # add to those of a refit that may be published (a refused one is not)
            errors = with_held_errors(structure, params, errors, held_errors, dataset, blocks)
        psi, r = structure.simulate(params, dataset)
    except (DataError, StructureError, ValueError, np.linalg.LinAlgError) as exc:
        failure = {"error_type": type(exc).__name__, "error": str(exc)}
        return None, Verdict("refit_failed", "gain_refit_error", failure)
    fit = free_run_fit(dataset.heading, dataset.yaw_rate, psi, r)
    estimate = Estimate(
        structure,
        method,
        params,
        dict(held_errors, **errors),
        fit,
        dataset.n_samples,
        flags=["diverged"] if fit["diverged"] else [],
        window=window,
    )
    if fit["diverged"]:
        return estimate, Verdict("too_little_excitation", "gain_diverged")
    if figures:
        return estimate, Verdict("too_little_excitation", "gain_undetermined", {"loose": loose, "errors": figures})
    return estimate, None
