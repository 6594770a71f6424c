"""Verdicts of the online identifier's decisions, and the one table that words them.

A decision on a window (too little excitation, a poor fit, an implausible or uncertain estimate, a
gain refit after a change refused) returns a ``Verdict``: the condition it reports (a key of the
record's ``conditions``), a code saying which rule decided, and the figures behind it in SI units.
Programs and tests read the code and the figures; ``sentence`` turns a verdict into the sentence the
record carries (``~/estimate``'s ``conditions``), here and nowhere else.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

# What a refusal leaves in force, worded at the end of its sentence.
LAST_GOOD = "last_good"  # the last good estimate is kept
FOLLOWED = "followed"  # a gain refitted on the data after a change is published instead
KEEPING_SENTENCES = {
    LAST_GOOD: "keeping the last good estimate",
    FOLLOWED: "K refitted on the new data instead (see vessel_changed)",
}


@dataclass(frozen=True)
class Verdict:
    """One decision on a window: a code and the figures behind it.

    Attributes
    ----------
    condition : str
        The record's condition it reports (``identifier.CONDITION_LEVELS``' keys).
    code : str
        Which rule decided (a key of ``SENTENCES``).
    figures : dict
        The numbers and names behind the decision, SI units (rad, s, rad/s, (rad/s)^2); a figure
        may itself be a verdict (the reason of a refused gain refit).
    keeping : str or None
        What stays in force when the verdict refuses the estimate (LAST_GOOD or FOLLOWED); None
        when it refuses nothing by itself.
    """

    condition: str
    code: str
    figures: dict = field(default_factory=dict)
    keeping: str | None = None

    @property
    def sentence(self) -> str:
        """The verdict in words, as the record's ``conditions`` carry it (``sentence``)."""
        return sentence(self)


def _yaw_rate_rms(mean_square: float) -> str:
    """A mean-square yaw-rate error ((rad/s)^2) as its rms in deg/s."""
    return f"{math.degrees(math.sqrt(mean_square)):.3f}"


def _correlation(f: dict) -> str:
    """The free-run fit against what the window's noise allows (a poor fit's figures)."""
    return (
        f"free-run yaw-rate correlation {f['correlation']:.2f} (needs >= {f['needed']:.2f}, "
        f"{f['share']:g} of the {f['best']:.2f} its noise allows)"
    )


def _held_sentence(kept: str):
    """The sentence of a loose full fit held back after a change for ``kept``."""
    return lambda f: (
        f"the window determines {', '.join(f['loose'])} only loosely ({f['errors']}): "
        f"{kept} is kept until a full fit is trusted"
    )


def _refused_gain_refit(f: dict) -> str:
    """A gain refit after a change refused, after the full fit's refusal of the same kind, if any."""
    refit = f"gain refit on the {f['duration']:.0f} s since the change: {body(f['reason'])}"
    return f"{body(f['full_fit'])}; {refit}" if f.get("full_fit") else refit


# code -> the sentence's body from the figures (without what is kept, which ``sentence`` adds).
SENTENCES = {
    # gap_in_window
    "segments_apart": lambda f: (
        f"{f['gaps']} gap(s) in the window, longest {f['longest']:.1f} s; fitting the segments apart"
    ),
    # too_little_excitation: the estimators' own account of the window (excitation_shortfall)
    "below_floors": lambda f: f["shortfall"],
    "parameters_undetermined": lambda f: f["shortfall"],
    "gain_diverged": lambda f: "it diverged",
    "gain_undetermined": lambda f: f["errors"],
    # refit_failed
    "window_unusable": lambda f: f"window unusable: {f['error']}",
    "fit_error": lambda f: f"{f['error_type']}: {f['error']}",
    "gain_refit_error": lambda f: f"gain refit after the change: {f['error_type']}: {f['error']}",
    "estimate_rejected": lambda f: f"estimate rejected ({', '.join(f['flags'])})",
    # poor_fit
    "misses_motion": lambda f: (
        f"{_correlation(f)}{', ' + ', '.join(f['at_bounds']) if f['at_bounds'] else ''}: the model misses the motion"
    ),
    "search_on_bound": lambda f: (
        f"the search ended {', '.join(f['at_bounds'])} ({_correlation(f)}): no estimate to trust"
    ),
    # implausible_estimate
    "on_bound": lambda f: (
        ", ".join(f"{name} = {value:.4g} {unit} on its bound {bound:g}" for name, value, unit, bound in f["bounds"])
        + ": the search ran to a physical limit, not to the vessel"
    ),
    "misses_window": lambda f: (
        "its free run misses the window more than the last good estimate's (yaw-rate rms "
        f"{_yaw_rate_rms(f['new_mean_square'])} vs {_yaw_rate_rms(f['old_mean_square'])} deg/s)"
    ),
    "unconfirmed_jump": lambda f: (
        f"{f['name']} {f['value']:.4g} +- {f['std_error']:.2g} jumps {f['jump']:.0f} standard errors from the "
        f"last good {f['last_value']:.4g} +- {f['last_std_error']:.2g}, and its free run over the newest "
        f"{f['newest']:g} s is not clearly better (yaw-rate rms {_yaw_rate_rms(f['new_mean_square'])} vs "
        f"{_yaw_rate_rms(f['old_mean_square'])} deg/s); held until a refit confirms it"
    ),
    # uncertain_estimate
    "published_uncertain": lambda f: (
        f"the window determines {', '.join(f['loose'])} only loosely ({f['errors']}): "
        "published with its uncertainty, not to be trusted as OK"
    ),
    "followed_gain_kept": _held_sentence("the gain followed on the new data"),
    "better_gain_kept": _held_sentence("K known better by the last good estimate"),
    # too_little_excitation or implausible_estimate, after a change
    "gain_refit_refused": _refused_gain_refit,
}


def body(verdict: Verdict) -> str:
    """The sentence of ``verdict`` without what it keeps in force.

    Parameters
    ----------
    verdict : Verdict
        A decision whose code is a key of ``SENTENCES``.

    Returns
    -------
    str
        Its figures in words (angles in deg, rates in deg/s, times in s).
    """
    return SENTENCES[verdict.code](verdict.figures)


def sentence(verdict: Verdict) -> str:
    """The sentence a record's ``conditions`` carry for ``verdict``: its body, then what stays in force.

    Parameters
    ----------
    verdict : Verdict
        A decision whose code is a key of ``SENTENCES``.

    Returns
    -------
    str
        '<figures in words>; keeping the last good estimate' for a refusal that keeps the last good
        estimate, the body alone for a verdict that refuses nothing by itself.
    """
    text = body(verdict)
    return f"{text}; {KEEPING_SENTENCES[verdict.keeping]}" if verdict.keeping else text
