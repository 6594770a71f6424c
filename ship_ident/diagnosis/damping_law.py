"""Which yaw damping law the data show, when one manoeuvre cannot tell the laws apart by their free runs.

A quadratic damping (``quadratic_yaw``: -d_q r|r|), a cubic one on a course-stable hull (``cubic_yaw``)
and a cubic one holding a course-unstable hull (``course_instability``: -a1 r - a3 r^3 with a1 < 0)
all bend the turn rate down in tight turns: on one zigzag each, refitted alone, often predicts the
held-out part within a few per cent of the others, and that order is the scatter of three searches.
What separates them is the shape of the damping against the turn rate and the sign of the linear
damping. ``damping_law`` fits one model that holds both laws and a linear damping of either sign,
``-a1 r - d_q r|r| - a3 r^3`` beside the base model, and reads them there: the law whose term carries
more of the damping over the turn rates of the fitted data (signed: a term that lowers the damping is not a
damping law), and, for the cubic law, the sign of a1 where the fit determines it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..estimators import Estimate, make_estimator
from ..model.dataset import Dataset

QUADRATIC, CUBIC, UNSTABLE = "quadratic_yaw", "cubic_yaw", "course_instability"
DAMPING_LAWS = (QUADRATIC, CUBIC, UNSTABLE)
SIGN_SIGMAS = 2.0  # a1 further than this many standard errors from zero has a sign the data determine


@dataclass(frozen=True)
class DampingLaw:
    """The damping law a fit holding both laws shows.

    Attributes
    ----------
    laws : tuple of str
        The effects consistent with it: ``("quadratic_yaw",)``, ``("cubic_yaw",)``,
        ``("course_instability",)``, or both cubic ones when the sign of a1 is not determined.
    quadratic, cubic : float
        The RMS yaw acceleration (rad/s^2) of the quadratic and cubic damping terms over the fitted
        turn rates, signed: positive damps.
    linear_damping, linear_damping_std : float
        a1 (1/s) and its standard error; negative is course-unstable.
    """

    laws: tuple[str, ...]
    quadratic: float
    cubic: float
    linear_damping: float
    linear_damping_std: float

    @property
    def stability(self) -> str:
        """The sign of the linear damping: course-stable, course-unstable or undetermined.

        ``undetermined`` unless a1 lies beyond ``SIGN_SIGMAS`` standard errors of zero.
        """
        if self.linear_damping > SIGN_SIGMAS * self.linear_damping_std:
            return "course-stable"
        if self.linear_damping < -SIGN_SIGMAS * self.linear_damping_std:
            return "course-unstable"
        return "undetermined"

    def sentence(self) -> str:
        """What a naval architect reads: the two terms and the sign of the linear damping.

        Returns
        -------
        str
            A clause, without a leading separator.
        """
        shape = "quadratic" if self.laws == (QUADRATIC,) else "cubic"
        stability = "stability undetermined" if self.stability == "undetermined" else self.stability
        return (
            f"a fit holding both laws puts the growth of the damping in the {shape} term "
            f"({np.degrees(self.quadratic):.2g} deg/s^2 quadratic, {np.degrees(self.cubic):.2g} deg/s^2 cubic, "
            f"RMS over the turn rates seen), with a linear damping a1 {self.linear_damping:.3g} +- "
            f"{self.linear_damping_std:.2g} 1/s ({stability})"
        )


def damping_law(
    estimate: Estimate, recorded: Dataset, starts: list[dict], method: str, shooting_s: float | None = None
) -> DampingLaw | None:
    """Fit the model that holds both damping laws and read which one the data show.

    Parameters
    ----------
    estimate : Estimate
        The model the damping laws would extend (its base model and effects).
    recorded : Dataset
        The data to fit (s, rad, rad/s).
    starts : list of dict
        Fitted parameters of the model with one law each (either form, SI units); the search also
        starts from ``estimate`` with no nonlinear damping.
    method : str
        The estimation method (``make_estimator``).
    shooting_s : float or None
        The search's shooting intervals (s), when not the estimator's own (a slow hull's, as long
        as the free runs the laws are judged by).

    Returns
    -------
    DampingLaw or None
        None when the fit fails.
    """
    joint = estimate.structure
    for law in (QUADRATIC, UNSTABLE):  # a law already in the model stays, once
        joint = joint if law in joint.effect_names else joint.adding(law)
    points = [
        {name: value for name, value in joint.neutral_effect_start(p).items() if name in joint.parameter_names}
        for p in (*starts, estimate.parameters)
    ]
    search = make_estimator(method, explore=False)
    if shooting_s is not None:
        search.shooting_s = shooting_s
    fit = search.fit(joint, recorded, starts=tuple(points))
    if not fit.ok:
        return None
    if shooting_s is not None and search.uses_starts:
        # on a slow hull's long intervals the start the search picks by its first cost can be the
        # regression's, with the fast pole lost: each start is searched, the least cost is the law
        weighted_at = fit.parameters  # one weighting, so that the costs compare
        searched = [search.fit_held(joint, recorded, fit, dict(p), (), weighted_at) for p in (fit.parameters, *points)]
        fit = min((f for f in searched if f.ok), key=lambda f: f.info["cost"], default=fit)
    p, std = fit.parameters, fit.std_errors
    r = recorded.yaw_rate
    quadratic = p["d_q"] * float(np.sqrt(np.mean((r * np.abs(r)) ** 2)))
    cubic = p["a3"] * float(np.sqrt(np.mean(r**6)))
    a1, a1_std = float(p["a1"]), float(std.get("a1", np.inf))
    law = DampingLaw((), float(quadratic), float(cubic), a1, a1_std)
    if quadratic > cubic:
        laws = (QUADRATIC,)
    else:
        laws = {"course-stable": (CUBIC,), "course-unstable": (UNSTABLE,)}.get(law.stability, (CUBIC, UNSTABLE))
    return replace(law, laws=laws)
