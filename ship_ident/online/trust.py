"""Whether a new online estimate replaces the one in force: plausibility and precision.

A new estimate (with its published standard errors, ``uncertainty``) is implausible when it sits on a
physical bound, when its free run misses the window more than the last good estimate's, or when its
gain or main time constant jumps further than their joint errors allow without the data showing a
changed vessel. A plausible one is trusted (OK) when its relative errors are within
TRUSTED_RELATIVE_ERRORS; a looser one is published as uncertain, or, after a change, held back when
a gain refitted on the new data is known better. Each decision is a ``Verdict``.
"""

from __future__ import annotations

import math

import numpy as np

from ..estimators.base import TRUSTED_RELATIVE_ERRORS, loose_parameters
from ..model.dataset import cut_segments
from ..model.structure import Structure
from .change import block_errors
from .verdicts import LAST_GOOD, Verdict

JUMP_STANDARD_ERRORS = 5.0  # a jump beyond this many joint standard errors needs evidence
CLEAR_IMPROVEMENT = 2.0  # ... its free run over the newest data this many times better
# (mean squares) than the last good one's, or the next refit agreeing
FREE_RUN_TOLERANCE = 1.25  # a new estimate's free run may miss the window at most this much
# more (mean squares) than the last good one's


class TrustPolicy:
    """The rules a new estimate passes before it replaces the last good one.

    It remembers the last estimate held for an unconfirmed jump (``candidate``): the next refit
    agreeing with it confirms the jump.
    """

    def __init__(self):
        self.candidate = None  # Estimate held for jumping, or None

    def plausibility(self, config, structure: Structure, estimate, dataset, last_good) -> Verdict | None:
        """Why a new estimate must not replace the last good one (an implausible_estimate verdict), or None.

        It sits on a physical bound (code ``on_bound``); or its free run misses this window more than
        the last good estimate's (FREE_RUN_TOLERANCE, mean squares over blocks of
        ``change_test_length``, each run free from the measured state one block before it: a run
        started at the block carries the transient of its unknown yaw acceleration, which favours
        whichever time constants shed it fastest; ``misses_window``); or its gain or main time
        constant jumps beyond JUMP_STANDARD_ERRORS joint standard errors from the last good one, and
        neither does its free run over the newest ``change_test_length`` s beat the last good one's
        CLEAR_IMPROVEMENT times (a changed vessel shows there first), nor does the previous refit's
        held estimate agree with it (``unconfirmed_jump``; the estimate is held as the candidate). A
        last good estimate whose free run diverges on this window (a changed vessel can make it
        unstable) is no yardstick: it blocks nothing.

        Parameters
        ----------
        config : OnlineConfig
            The identifier's configuration (``change_test_length``, s).
        structure : Structure
            The model both estimates are of.
        estimate : Estimate
            The new estimate, with its published standard errors (SI units).
        dataset : Dataset
            The window it was fitted on.
        last_good : Estimate or None
            The estimate in force (None: only the bounds are checked).

        Returns
        -------
        Verdict or None
            The implausible_estimate verdict (keeping the last good estimate), or None when the
            estimate may replace the last good one.
        """
        bounds = on_bounds(structure, estimate.parameters)
        if bounds:
            return Verdict("implausible_estimate", "on_bound", {"bounds": bounds}, LAST_GOOD)
        if last_good is None or last_good.structure.label() != structure.label():
            return None
        n = int(round(config.change_test_length / dataset.sample_time))
        blocks = cut_segments(dataset.segments, n, min_samples=2, align="end")
        new_blocks, old_blocks = (
            block_errors(structure, p, dataset, blocks, lead=n) for p in (estimate.parameters, last_good.parameters)
        )
        new_error, old_error = float(np.mean(new_blocks)), float(np.mean(old_blocks))
        if math.isfinite(old_error) and not new_error <= FREE_RUN_TOLERANCE * old_error:
            figures = {"new_mean_square": new_error, "old_mean_square": old_error}
            return Verdict("implausible_estimate", "misses_window", figures, LAST_GOOD)
        jump, name = largest_jump(estimate, last_good)
        if jump <= JUMP_STANDARD_ERRORS:
            return None
        new_newest, old_newest = float(new_blocks[-1]), float(old_blocks[-1])
        if not old_newest < CLEAR_IMPROVEMENT * new_newest:  # NaN: the last good one diverges there
            return None
        candidate, self.candidate = self.candidate, estimate
        if (
            candidate is not None
            and candidate.structure.label() == structure.label()
            and largest_jump(estimate, candidate)[0] <= JUMP_STANDARD_ERRORS
        ):
            return None
        figures = {
            "name": name,
            "value": estimate.parameters[name],
            "std_error": estimate.std_errors[name],
            "jump": jump,
            "last_value": last_good.parameters[name],
            "last_std_error": last_good.std_errors[name],
            "newest": config.change_test_length,
            "new_mean_square": new_newest,
            "old_mean_square": old_newest,
        }
        return Verdict("implausible_estimate", "unconfirmed_jump", figures, LAST_GOOD)

    @staticmethod
    def precision(published, last_good, after_change: bool, followed: bool) -> Verdict | None:
        """Whether a plausible estimate is determined well enough to be trusted, or uncertain.

        An estimate whose gain or main time constant has a relative error beyond
        TRUSTED_RELATIVE_ERRORS is published with its uncertainty (WARN, code
        ``published_uncertain``). After a change it is held back instead (the verdict keeps the last
        good estimate): when the estimate in force is a gain followed on the new data
        (``followed_gain_kept``), or when its K is loose and known better by the last good
        estimate (``better_gain_kept``).

        Parameters
        ----------
        published : Estimate
            The new estimate with its published standard errors (SI units).
        last_good : Estimate or None
            The estimate in force.
        after_change : bool
            Whether a change of the vessel is being followed.
        followed : bool
            Whether the estimate in force was fitted on the data after the last change.

        Returns
        -------
        Verdict or None
            The uncertain_estimate verdict, with ``keeping`` set when it holds the estimate back;
            None when the estimate is trusted.
        """
        loose, errors = loose_parameters(published.parameters, published.std_errors, TRUSTED_RELATIVE_ERRORS)
        if not loose:
            return None
        figures = {"loose": loose, "errors": errors}
        held = (  # after a change, a K refitted on the new data is not replaced by a looser fit
            after_change
            and last_good is not None
            and (followed or ("K" in loose and last_good.std_errors.get("K", math.inf) < published.std_errors["K"]))
        )
        if not held:
            return Verdict("uncertain_estimate", "published_uncertain", figures)
        code = "followed_gain_kept" if followed else "better_gain_kept"
        return Verdict("uncertain_estimate", code, figures, LAST_GOOD)


def on_bounds(structure: Structure, params: dict) -> list:
    """The parameters at a physical bound, as (name, value, unit, bound) (SI units); a zero lower
    bound (no lead, no dead time) is physical, not a limit.

    Parameters
    ----------
    structure : Structure
        The model, whose parameters carry their bounds.
    params : dict
        The estimate's parameters (SI units).

    Returns
    -------
    list of tuple
        (name, value, unit, bound) of each free parameter on a non-zero bound; empty when none is.
    """
    found = []
    for name in structure.free_names:
        parameter, value = structure.parameter(name), params[name]
        bound = parameter.bound_reached(value)
        if bound is not None and bound != 0:
            found.append((name, value, parameter.unit, bound))
    return found


def largest_jump(estimate, reference) -> tuple[float, str]:
    """The largest jump of the gain or main time constant between two estimates.

    Parameters
    ----------
    estimate, reference : Estimate
        The two estimates, with their standard errors (SI units).

    Returns
    -------
    jump : float
        The step in joint standard errors, |a - b| / sqrt(s_a^2 + s_b^2) (infinite for a step with
        no error to measure it).
    name : str
        The parameter that jumps most.
    """
    jumps = []
    for name in TRUSTED_RELATIVE_ERRORS:
        if name in estimate.parameters and name in reference.parameters:
            joint = math.hypot(estimate.std_errors.get(name, 0.0), reference.std_errors.get(name, 0.0))
            step = abs(estimate.parameters[name] - reference.parameters[name])
            jumps.append((step / joint if joint > 0 else (math.inf if step else 0.0), name))
    return max(jumps)
