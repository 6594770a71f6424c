"""``vessels``: the online identifier on randomised vessels, judged against their truth.

Each case draws a vessel with ``simulator.random_vessel`` (quick USVs to slow
ships), a manoeuvre (random rudder steps of +-25 deg held 4-15 s, 10/10 and
20/20 zigzags, steady turns with the rudder held 30-120 s, long straight
legs under an autopilot, the mixed manoeuvre; holds and legs stretch with
the hull's time constant), a sensor-noise level of 0.5-3x the realistic one
(``simulator.Noise``), and either a steady vessel or one whose K falls 30 %
and T1 grows 30 % halfway through. The record is replayed through the
node's online core exactly as ``ship-ident replay`` does (``OnlineIdentifier``
+ ``run_schedule``, the node's defaults) for USVs; a slow ship gets a
configuration that follows its hull (``config_for``). Case ``i`` of seed
``S`` is drawn from seed ``S + i`` alone, so ``--seed S+i --count 1``
replays it.

Figures, all against the simulated truth:

* coverage: the share of published OK estimates (a new estimate, status OK)
  whose 95 % interval (1.96 std errors) holds the truth, per parameter;
* on steady vessels, the worst K and T1 error of a published OK estimate and
  the share more than 10 % off;
* rejected refits on well-excited windows: a window is well excited when its
  Cramer-Rao bound (``crb.py``, with the record's rudder noise) puts K within
  ``WELL_EXCITED['K']`` and T1 within ``WELL_EXCITED['T1']`` (relative std; half the
  errors the node trusts), whatever its signal-to-noise ratios, and (steady cases) T1 held
  10 % either side of the truth lies outside the 95 % region of the window's cost profile
  (``WELL_EXCITED_PROFILE_RISE``; the share by the bound alone is printed too); any refit
  there that does not give a new OK estimate is rejected, and its conditions are counted, and
  those before a full window (start-up, where the node checks K and T1 along the cubic damping
  from half the errors it trusts);
* after the step change: the time until the K in force is back within 5 %
  of the new truth and stays there (``peers.recovery_time``), median (also apart for
  hulls with T1 up to ``QUICK_HULL_T1``, whose target is 60 s, and for slower ones), worst,
  and the share beyond one window plus one refit period; the K error before
  the change (RMS over the last two thirds of a window); the share beyond also over the
  step cases whose data after the change determine K (``determined_after_change``), the
  others listed by seed; the 95 % coverage of the new truth by the estimates published (WARN)
  while the gain is followed after a change;
* false ``vessel_changed`` per hour of steady data (changes declared, not the records that
  repeat one while the gain follows it).

The JSON carries each case's refits in short (``_brief``): a rejected refit is found there with
its conditions and window bound, and replayed by the case's seed.

``--generator mmg`` replays hulls of the physics-based generator instead (``mmg.py``: the MMG
standard method on hulls varied around KVLCC2's 7 m model), steady, on random rudder steps
(each angle within +-35 deg held 10-40 s) for five windows, with the configuration of a ship
whose T1 is that of an offline fit (the node's model and method) of the hull's own 600 s of
steps. They have no Nomoto truth, so only what needs none is judged (``summarise_mmg``): the
share of refits that publish a new OK estimate and the conditions of the others, false
``vessel_changed`` per hour (the hull never changes), and whether the published estimates (OK or
with a warning) agree with each other within their errors: the share whose 95 % interval holds
the median of the hull's published values, per parameter (an estimator whose windows
scatter more than it says, or a model whose parameters follow the window's turn rates, falls
short of 0.95).
"""

from __future__ import annotations

import math
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from ..estimators import make_estimator
from ..estimators.base import TRUSTED_RELATIVE_ERRORS, Z_95
from ..model.dataset import DataError, Dataset
from ..model.simulator import Noise, random_vessel, simulate
from ..model.structure import StructureError
from ..online.config import OnlineConfig
from ..online.identifier import OnlineIdentifier, run_schedule
from . import progress, register
from .common import table
from .crb import cramer_rao_bound
from .peers import RECOVERY_TOLERANCE, dataset_samples, recovery_time

DEFAULTS = OnlineConfig()
PARAMETERS = DEFAULTS.structure().parameter_names
MANEUVER_CHOICES = ("steps", "steps", "zigzag10", "zigzag20", "steady_turns", "legs", "mixed")
NOISE_RANGE = (0.5, 3.0)  # multiples of the realistic sensor noise
STEP_SHARE = 0.5  # share of cases with a change mid-run
CHANGE = {"K": 0.7, "T1": 1.3}  # factors on the truth at the change
WINDOWS_PER_RUN = 5.0  # run length in windows (quick: 3); a change at half of it
# A window is well excited when its Cramer-Rao bound puts K and T1 within half the relative errors
# the node trusts (estimators.base.TRUSTED_RELATIVE_ERRORS): no fit's published error can be smaller than the
# bound, and model error and each fit's own scatter come on top (at the trust limit itself half of
# the windows of a perfect estimator would be refused)
WELL_EXCITED = {q: 0.5 * TRUSTED_RELATIVE_ERRORS[q] for q in ("K", "T1")}
OFF_TOLERANCE = 0.10  # a published OK estimate this far off the truth is wrong
# The bound is local: a hull whose fast pole and rudder lead nearly cancel (T2 close to T3) answers
# like a first-order one, and the lead can cancel the slow pole instead (T3 close to T1) at the same
# cost, so T1 is not determined however small its bound. A steady case's window is well excited only
# when, besides its bound, T1 held OFF_TOLERANCE either side of the truth lies outside the 95 % region
# of the cost's profile (a rise of chi2 3.84): a window that cannot tell T1 from a value that far off
# does not determine it. (A rise of 25, what a quadratic profile with T1's error at
# WELL_EXCITED['T1'] gives, would judge the estimator's own cost, not the data.)
WELL_EXCITED_PROFILE_RISE = 3.84
QUICK_HULL_T1 = 12.0  # s: the recovery target (60 s median) is set for hulls up to this T1
MAX_SCALE = 10.0  # a ship's window is at most 10 node windows (1800 s)
DEFAULT_COUNT, QUICK_COUNT = 60, 6
MMG_COUNT, MMG_QUICK_COUNT = 10, 2
WORKERS = 2
GENERATORS = ("ours", "mmg")


def config_for(vessel) -> OnlineConfig:
    """The online configuration of a case: the node's defaults for a USV; for a slow ship, the
    defaults stretched by f = 30 T1 / 180 s within [1, 10] (window about 30 T1, at most 1800 s;
    sample time, refit period and first-fit length by the same factor, the sample time at most
    1 s; gap threshold five sample times)."""
    if not vessel.name.startswith("ship"):
        return DEFAULTS
    return config_for_time_constant(vessel.parameters["T1"])


def config_for_time_constant(t1: float) -> OnlineConfig:
    """A ship's configuration (``config_for``) for a hull with the time constant ``t1`` (s)."""
    scale = float(np.clip(30.0 * t1 / DEFAULTS.window_length, 1.0, MAX_SCALE))
    sample_time = min(1.0, round(DEFAULTS.sample_time * scale, 2))
    return DEFAULTS.changed(
        window_length=DEFAULTS.window_length * scale,
        refit_period=DEFAULTS.refit_period * scale,
        min_window_length=DEFAULTS.min_window_length * scale,
        sample_time=sample_time,
        gap_threshold=5 * sample_time,
    )


def draw_case(seed: int, quick: bool = False) -> dict:
    """Vessel, manoeuvre, noise and change of the case with this seed (nothing simulated yet)."""
    rng = np.random.default_rng(seed)
    vessel = random_vessel(rng)
    maneuver = str(rng.choice(MANEUVER_CHOICES))
    noise = float(rng.uniform(*NOISE_RANGE))
    step = bool(rng.uniform() < STEP_SHARE)
    config = config_for(vessel)
    duration = config.window_length * (3.0 if quick else WINDOWS_PER_RUN)
    return {
        "seed": seed,
        "vessel": vessel,
        "maneuver": maneuver,
        "noise": noise,
        "step": step,
        "config": config,
        "duration": duration,
        "change_time": duration / 2 if step else None,
    }


def simulate_case(case: dict):
    """The record of a drawn case (``draw_case``): its manoeuvre at its noise over its whole
    duration, with its change if it has one (a replay of part of a case must simulate all of it:
    the noise is drawn over the whole record)."""
    vessel = case["vessel"]
    change = None
    if case["step"]:
        change = (case["change_time"], {k: f * vessel.parameters[k] for k, f in CHANGE.items()})
    return simulate(
        case["maneuver"],
        vessel,
        duration=case["duration"],
        sample_time=case["config"].sample_time,
        noise=Noise().scaled(case["noise"]),
        seed=case["seed"],
        change=change,
    )


def run_case(seed: int, quick: bool = False) -> dict:
    """Simulate the case, replay it through the online core and judge every refit (plain data)."""
    case = draw_case(seed, quick)
    vessel, config = case["vessel"], case["config"]
    noise = Noise().scaled(case["noise"])
    sim = simulate_case(case)
    truth_after = sim.info.get("truth_after", sim.truth)
    refits = []
    identifier = OnlineIdentifier(config)
    for record in run_schedule(identifier, dataset_samples(sim.dataset)):
        if "window_filling" in record.conditions or "no_data" in record.conditions:
            continue
        data = record.to_json()
        start = max(record.time - config.window_length, 0.0)
        regime = _regime(start, record.time, case["change_time"])
        estimate_window = data["estimate_window"] or {}
        truth = truth_after if regime == "after" else sim.truth
        crb = _window_bound(sim, noise, start, record.time, truth) if regime != "across" else None
        rise = _t1_profile_rise(identifier, record.time, truth) if not case["step"] and _bound_excited(crb) else None
        refits.append(
            {
                "time": record.time,
                "status": data["status"],
                "new": data["new_estimate"],
                "conditions": sorted(data["conditions"]),
                "parameters": data["parameters"],
                "std_errors": data["std_errors"],
                "estimate_regime": _regime(
                    estimate_window.get("start", math.nan), estimate_window.get("end", math.nan), case["change_time"]
                ),
                "crb": crb,
                "t1_profile_rise": rise,
            }
        )
    return {
        "seed": seed,
        "vessel": vessel.name,
        "description": vessel.description,
        "maneuver": case["maneuver"],
        "noise": case["noise"],
        "step": case["step"],
        "change_time": case["change_time"],
        "duration": case["duration"],
        "window_s": config.window_length,
        "refit_period_s": config.refit_period,
        "sample_time_s": config.sample_time,
        "truth": sim.truth,
        "truth_after": truth_after,
        "refits": refits,
    }


def _regime(start: float, end: float, change_time: float | None) -> str:
    """Which truth a window of data [start, end] (s) belongs to: before or after the change, or across it."""
    if change_time is None or end <= change_time:
        return "before"
    return "after" if start >= change_time else "across"


def _window_bound(sim, noise: Noise, start: float, end: float, truth: dict) -> dict:
    """Cramer-Rao bound (relative std) of K and T1 on the noise-free record within [start, end] s."""
    time = sim.dataset.time
    a, b = int(np.searchsorted(time, start)), int(np.searchsorted(time, end))
    if b - a < 20:
        return {"K": math.inf, "T1": math.inf}
    exact = Dataset(
        time=time[a:b],
        rudder=sim.true_rudder[a:b],
        heading=sim.true_heading[a:b],
        yaw_rate=sim.true_yaw_rate[a:b],
        meta=sim.dataset.meta,
    )
    h = sim.dataset.sample_time
    r = sim.true_yaw_rate
    initial = [(sim.true_heading[a], r[a], (r[min(a + 1, len(r) - 1)] - r[max(a - 1, 0)]) / (2 * h))]
    try:
        bound = cramer_rao_bound(sim.structure, truth, exact, initial, noise.heading, noise.yaw_rate, noise.rudder)
    except np.linalg.LinAlgError:
        return {"K": math.inf, "T1": math.inf}
    return {q: float(bound[q] / truth[q]) if np.isfinite(bound[q]) else math.inf for q in ("K", "T1")}


def _bound_excited(crb: dict | None) -> bool:
    """Whether a window's Cramer-Rao bound puts K and T1 within WELL_EXCITED."""
    return crb is not None and all(crb[q] <= WELL_EXCITED[q] for q in WELL_EXCITED)


def well_excited(refit: dict) -> bool:
    """Whether a refit's window determines K and T1: its bound (``_bound_excited``) and, where it was
    taken (steady cases), T1's profile (``WELL_EXCITED_PROFILE_RISE``)."""
    rise = refit.get("t1_profile_rise")
    return _bound_excited(refit["crb"]) and (rise is None or rise >= WELL_EXCITED_PROFILE_RISE)


def _t1_profile_rise(identifier: OnlineIdentifier, time: float, truth: dict) -> float:
    """The smaller rise of the cost (chi2) of the window the refit at ``time`` (s) saw, with T1 held
    OFF_TOLERANCE either side of the truth, over the best fit near the truth; every point weighed
    alike (``fit_held``'s ``weighted_at``). Infinite when it cannot be taken (no held fits, a fit
    that fails): the bound alone judges then."""
    config = identifier.config
    estimator, structure = make_estimator(config.method), config.structure()
    if not hasattr(estimator, "fit_held"):
        return math.inf
    try:
        window = identifier.window_dataset(time)
        best = estimator.fit(structure, window, starts=(truth,))

        def cost(t1: float) -> float:
            return estimator.held_point(structure, window, best, {"T1": t1}, ("T1",), best.parameters)[1]

        base = cost(best.parameters["T1"])
        return float(min(cost(f * truth["T1"]) - base for f in (1 - OFF_TOLERANCE, 1 + OFF_TOLERANCE)))
    except (DataError, StructureError, ValueError, np.linalg.LinAlgError):
        return math.inf


def determined_after_change(case: dict) -> bool:
    """A step case whose data after the change determine K: in some refit at least one window
    after the change, K's Cramer-Rao bound is within WELL_EXCITED['K'] (half the error the node
    trusts, as for a well-excited window). Without one no estimate of the new gain can be trusted,
    and the K in force is followed only by luck (a USV whose rudder lead outruns its pole,
    zigzagging at 2.5x the noise: K's bound 8-9 %, T1's 33-42 %, never an estimate to trust)."""
    after = case["change_time"] + case["window_s"]
    return any(
        r["crb"] is not None and r["crb"]["K"] <= WELL_EXCITED["K"] for r in case["refits"] if r["time"] >= after
    )


def summarise(cases: list[dict]) -> dict:
    """The suite's figures over all cases (see the module docstring)."""
    covered = {p: [] for p in PARAMETERS}
    off = {"K": [], "T1": []}
    worst = {"K": (0.0, None), "T1": (0.0, None)}
    excited = rejected = rejected_start_up = excited_by_bound = rejected_by_bound = 0
    reasons: dict[str, int] = {}
    recoveries, errors_before, beyond, quick_hull, undetermined, beyond_determined = [], [], [], [], [], []
    changed, steady_hours = 0, 0.0
    followed = {"K": [], "T1": []}  # new estimates after a step while its vessel_changed note stands
    for case in cases:
        for refit in case["refits"]:
            published = refit["new"] and refit["status"] == "OK"
            if published and refit["estimate_regime"] != "across":
                truth = case["truth_after"] if refit["estimate_regime"] == "after" else case["truth"]
                for p in PARAMETERS:
                    error = abs(refit["parameters"][p] - truth[p])
                    covered[p].append(error <= Z_95 * refit["std_errors"].get(p, math.nan))
                if not case["step"]:
                    for q in off:
                        error = abs(refit["parameters"][q] / truth[q] - 1.0)
                        off[q].append(error > OFF_TOLERANCE)
                        if error > worst[q][0]:
                            worst[q] = (error, case["seed"])
            if case["step"] and refit["new"] and "vessel_changed" in refit["conditions"]:
                if refit["time"] > case["change_time"]:
                    for q in followed:
                        error = abs(refit["parameters"][q] - case["truth_after"][q])
                        followed[q].append(error <= Z_95 * refit["std_errors"].get(q, math.nan))
            if not case["step"] and _bound_excited(refit["crb"]):  # the bound alone, as before the profile
                excited_by_bound += 1
                rejected_by_bound += not published
            if not case["step"] and well_excited(refit):
                excited += 1
                if not published:
                    rejected += 1
                    rejected_start_up += refit["time"] < case["window_s"]  # no full window yet
                    for c in refit["conditions"] or ["new estimate not OK"]:
                        reasons[c] = reasons.get(c, 0) + 1
        if case["step"]:
            recovery, error_before = _recovery(case)
            recoveries.append(recovery)
            quick_hull.append(case["truth"]["T1"] <= QUICK_HULL_T1)
            errors_before.append(error_before)
            late = recovery > case["window_s"] + case["refit_period_s"]
            beyond.append(late)
            if determined_after_change(case):
                beyond_determined.append(late)
            else:
                undetermined.append(case["seed"])
        elif case["refits"]:
            steady_hours += (case["refits"][-1]["time"] - case["refits"][0]["time"]) / 3600.0
            changed += _changes_declared(case["refits"])
    recoveries, quick_hull = np.array(recoveries, dtype=float), np.array(quick_hull, dtype=bool)
    return {
        "cases": len(cases),
        "steady_cases": sum(not c["step"] for c in cases),
        "step_cases": sum(c["step"] for c in cases),
        "coverage": {p: _share(v) for p, v in covered.items()},
        "published_ok": len(covered["K"]),
        "steady": {
            "published_ok": len(off["K"]),
            **{
                q: {"worst_percent": 100 * worst[q][0], "worst_seed": worst[q][1], "share_off": _share(off[q])}
                for q in off
            },
        },
        "well_excited": {
            "refits": excited,
            "rejected": rejected,
            "rejected_start_up": rejected_start_up,
            "share_rejected": rejected / excited if excited else math.nan,
            "refits_by_bound": excited_by_bound,
            "rejected_by_bound": rejected_by_bound,
            "reasons": dict(sorted(reasons.items(), key=lambda kv: -kv[1])),
        },
        "recovery": {
            "median_s": _median(recoveries),
            "quick_hull_cases": int(quick_hull.sum()),
            "quick_hull_median_s": _median(recoveries[quick_hull]),
            "slow_hull_median_s": _median(recoveries[~quick_hull]),
            "worst_s": float(np.max(recoveries)) if len(recoveries) else math.nan,
            "share_beyond_window": _share(beyond),
            "share_beyond_window_determined": _share(beyond_determined),
            "error_before_percent_median": float(np.nanmedian(errors_before)) if errors_before else math.nan,
            "error_before_percent_worst": float(np.nanmax(errors_before)) if errors_before else math.nan,
            "undetermined_seeds": undetermined,
            "followed_refits": len(followed["K"]),
            "followed_coverage": {q: _share(v) for q, v in followed.items()},
        },
        "false_changes_per_hour": changed / steady_hours if steady_hours else math.nan,
        "steady_hours": steady_hours,
    }


def _median(values: np.ndarray) -> float:
    return float(np.median(values)) if len(values) else math.nan


def _share(flags: list) -> float:
    return float(np.mean(flags)) if len(flags) else math.nan


def _k_trace(case: dict) -> tuple[np.ndarray, np.ndarray]:
    """Times (s) of the refits and the K (1/s) in force after each."""
    kept = [(r["time"], r["parameters"]["K"]) for r in case["refits"] if "K" in r["parameters"]]
    return np.array([t for t, _ in kept]), np.array([k for _, k in kept])


def _changes_declared(refits: list) -> int:
    """How many times a change was declared: records that report vessel_changed after one that
    did not (every record while the gain follows the change repeats it, several per refit period)."""
    flagged = ["vessel_changed" in r["conditions"] for r in refits]
    return sum(now and not before for before, now in zip([False] + flagged, flagged))


def _recovery(case: dict) -> tuple[float, float]:
    """Seconds until K stays within 5 % of the new truth, and the K error (RMS %) before the change."""
    times, ks = _k_trace(case)
    change, k0 = case["change_time"], case["truth"]["K"]
    before = (times > change - 2 * case["window_s"] / 3) & (times <= change)
    error = float(100 * np.sqrt(np.mean((ks[before] / k0 - 1) ** 2))) if before.any() else math.nan
    return recovery_time(times, ks, change, case["truth_after"]["K"]), error


def case_line(case: dict) -> str:
    """One line per case: seed, vessel, manoeuvre, noise and its figures (for replay by seed)."""
    refits = case["refits"]
    ok = sum(r["new"] and r["status"] == "OK" for r in refits)
    excited = [r for r in refits if well_excited(r)]
    rejected = sum(not (r["new"] and r["status"] == "OK") for r in excited)
    text = (
        f"seed {case['seed']} {case['vessel']} {case['maneuver']} noise {case['noise']:.2f}x "
        f"window {case['window_s']:.0f} s: {ok}/{len(refits)} refits OK, rejected {rejected}/"
        f"{len(excited)} well-excited"
    )
    if case["step"]:
        recovery, error = _recovery(case)
        text += f"; step at {case['change_time']:.0f} s: K back within 5 % after {recovery:.0f} s"
        text += f" (error before {error:.2f} %)"
        if not determined_after_change(case):
            text += "; its data after the change never determine K"
    return text


def run_mmg_case(seed: int, quick: bool = False) -> dict:
    """An MMG hull drawn from ``seed`` on random rudder steps, replayed through the online core with
    a ship's configuration for the T1 of an offline fit of its first 600 s (plain data)."""
    from . import mmg

    hull = mmg.random_hull(np.random.default_rng(seed))
    first = mmg.simulate(hull, "steps", seed).dataset
    offline = make_estimator(DEFAULTS.method).fit(DEFAULTS.structure(), first)
    config = config_for_time_constant(offline.parameters["T1"])
    duration = config.window_length * (3.0 if quick else WINDOWS_PER_RUN)
    dataset = mmg.simulate(hull, "steps", seed, duration=duration).dataset
    refits = []
    for record in run_schedule(OnlineIdentifier(config), dataset_samples(dataset)):
        if "window_filling" in record.conditions or "no_data" in record.conditions:
            continue
        data = record.to_json()
        refits.append(
            {
                "time": record.time,
                "status": data["status"],
                "new": data["new_estimate"],
                "conditions": sorted(data["conditions"]),
                "parameters": data["parameters"],
                "std_errors": data["std_errors"],
            }
        )
    return {
        "seed": seed,
        "vessel": hull.name,
        "offline_T1": float(offline.parameters["T1"]),
        "duration": duration,
        "window_s": config.window_length,
        "refits": refits,
    }


def summarise_mmg(cases: list[dict]) -> dict:
    """The figures of MMG hulls, which need no truth (see the module docstring): published means a
    new estimate, OK or with a warning (an uncertain one is published with its errors)."""
    refits = published_ok = published_any = changed = 0
    hours = 0.0
    reasons: dict[str, int] = {}
    covered = {p: [] for p in PARAMETERS}
    for case in cases:
        published = [r for r in case["refits"] if r["new"] and r["parameters"]]
        refits += len(case["refits"])
        published_any += len(published)
        published_ok += sum(r["status"] == "OK" for r in published)
        for r in case["refits"]:
            if not (r["new"] and r["status"] == "OK"):
                for c in r["conditions"] or ["new estimate not OK"]:
                    reasons[c] = reasons.get(c, 0) + 1
        if case["refits"]:
            hours += (case["refits"][-1]["time"] - case["refits"][0]["time"]) / 3600.0
            changed += _changes_declared(case["refits"])
        for p in PARAMETERS:
            median = float(np.median([r["parameters"][p] for r in published])) if published else math.nan
            covered[p] += [
                abs(r["parameters"][p] - median) <= Z_95 * r["std_errors"].get(p, math.nan) for r in published
            ]
    return {
        "cases": len(cases),
        "refits": refits,
        "published_ok": published_ok,
        "published": published_any,
        "share_published_ok": published_ok / refits if refits else math.nan,
        "reasons": dict(sorted(reasons.items(), key=lambda kv: -kv[1])),
        "false_changes_per_hour": changed / hours if hours else math.nan,
        "hours": hours,
        "median_coverage": {p: _share(v) for p, v in covered.items()},
    }


def mmg_case_line(case: dict) -> str:
    """One line per MMG hull: seed, hull, offline T1, window, refits OK, changes declared."""
    ok = sum(r["new"] and r["status"] == "OK" for r in case["refits"])
    return (
        f"seed {case['seed']} {case['vessel']} offline T1 {case['offline_T1']:.1f} s window "
        f"{case['window_s']:.0f} s: {ok}/{len(case['refits'])} refits OK, "
        f"{_changes_declared(case['refits'])} vessel_changed declared"
    )


def run_mmg(quick: bool, seed: int, count: int | None, workers: int) -> dict:
    """Hulls of the MMG generator (``run_mmg_case``): hull i of seed S from seed S + i alone."""
    count = count or (MMG_QUICK_COUNT if quick else MMG_COUNT)
    seeds = [seed + i for i in range(count)]
    cases = []
    with ProcessPoolExecutor(max_workers=max(1, min(workers, count))) as pool:
        for i, case in enumerate(pool.map(run_mmg_case, seeds, [quick] * count)):
            progress(f"vessels mmg {i + 1}/{count}: {mmg_case_line(case)}")
            cases.append(case)
    return {"summary": summarise_mmg(cases), "cases": [dict(c, line=mmg_case_line(c)) for c in cases]}


def render_mmg(result: dict) -> str:
    s = result["summary"]
    lines = [
        f"vessels, MMG generator: {s['cases']} steady hulls, seed {result.get('seed')}; hull i replays "
        "with --seed (seed + i) --count 1"
    ]
    lines += [c["line"] for c in result["cases"]]
    lines.append(
        table(
            ["parameter", "95 % interval holds the hull's median"],
            [[p, v] for p, v in s["median_coverage"].items()],
            f"published OK estimates: {s['published_ok']} of {s['refits']} refits "
            f"({100 * s['share_published_ok']:.0f} %); the others: "
            + (", ".join(f"{c} {n}" for c, n in s["reasons"].items()) or "-")
            + f"; over the {s['published']} estimates published (OK or with a warning):",
        )
    )
    lines.append(f"false vessel_changed: {s['false_changes_per_hour']:.2f} per hour over {s['hours']:.1f} h (target 0)")
    return "\n\n".join(lines)


def run(
    quick: bool = False,
    seed: int = 0,
    count: int | None = None,
    plot_dir: str | None = None,
    workers: int = WORKERS,
    generator: str = "ours",
) -> dict:
    if generator not in GENERATORS:
        raise ValueError(f"unknown generator {generator!r}; choose from {', '.join(GENERATORS)}")
    if generator == "mmg":
        return dict(run_mmg(quick, seed, count, workers), generator=generator)
    count = count or (QUICK_COUNT if quick else DEFAULT_COUNT)
    seeds = [seed + i for i in range(count)]
    cases = []
    if workers > 1 and count > 1:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            for i, case in enumerate(pool.map(run_case, seeds, [quick] * count)):
                progress(f"vessels {i + 1}/{count}: {case_line(case)}")
                cases.append(case)
    else:
        for i, s in enumerate(seeds):
            cases.append(run_case(s, quick))
            progress(f"vessels {i + 1}/{count}: {case_line(cases[-1])}")
    result = {"summary": summarise(cases), "cases": [_brief(c) for c in cases], "well_excited_crb": WELL_EXCITED}
    if plot_dir:
        result["plots"] = plot(cases, plot_dir)
    return result


def _brief(case: dict) -> dict:
    """The case with its line of figures and one short record per refit: time (s), status, whether
    it published a new estimate, its condition names, the parameters in force with their
    published standard errors (SI), the window's Cramer-Rao bound of K and T1 (relative std) and
    whether that makes it well excited: enough to find a refit to replay."""
    out = {k: v for k, v in case.items() if k != "refits"}
    out["line"] = case_line(case)
    out["refits"] = [
        {
            "time": r["time"],
            "status": r["status"],
            "new": r["new"],
            "conditions": r["conditions"],
            "parameters": r["parameters"],
            "std_errors": r["std_errors"],
            "crb": r["crb"],
            "t1_profile_rise": r.get("t1_profile_rise"),
            "well_excited": well_excited(r),
        }
        for r in case["refits"]
    ]
    return out


def plot(cases: list[dict], plot_dir: str) -> list[str]:
    """vessels_recovery.png: the K error (%) in force against the time since the step, per step case."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    Path(plot_dir).mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for case in (c for c in cases if c["step"]):
        times, ks = _k_trace(case)
        truth = np.where(times > case["change_time"], case["truth_after"]["K"], case["truth"]["K"])
        ax.plot(
            (times - case["change_time"]) / case["window_s"],
            100 * np.abs(ks / truth - 1),
            lw=0.8,
            label=f"seed {case['seed']}",
        )
    ax.axhline(100 * RECOVERY_TOLERANCE, color="k", ls="--", lw=1)
    ax.axvline(0, color="k", lw=1)
    ax.set_yscale("log")
    ax.set_xlabel("time since the step (windows)")
    ax.set_ylabel("|K error| in force (%)")
    ax.set_title("K -30 %, T1 +30 % mid-run: the published K against the truth (dashed: 5 %)", fontsize=9)
    if sum(c["step"] for c in cases) <= 12:
        ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path = str(Path(plot_dir) / "vessels_recovery.png")
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return [path]


def render(result: dict) -> str:
    if result.get("generator") == "mmg":
        return render_mmg(result)
    s = result["summary"]
    lines = [
        f"vessels: {s['cases']} cases ({s['steady_cases']} steady, {s['step_cases']} with K -30 %, "
        f"T1 +30 % mid-run), seed {result.get('seed')}; case i replays with --seed (seed + i) --count 1"
    ]
    lines += [c["line"] for c in result["cases"]]
    lines.append(
        table(
            ["parameter", "95 % coverage"],
            [[p, v] for p, v in s["coverage"].items()],
            f"coverage of the truth by the 95 % interval, over {s['published_ok']} published OK "
            "estimates (target about 0.95)",
        )
    )
    st = s["steady"]
    lines.append(
        table(
            ["parameter", "worst error %", "worst case seed", "share > 10 % off"],
            [[q, st[q]["worst_percent"], st[q]["worst_seed"], st[q]["share_off"]] for q in ("K", "T1")],
            f"steady vessels: {st['published_ok']} published OK estimates (target: none > 10 % off)",
        )
    )
    we = s["well_excited"]
    crb = result["well_excited_crb"]
    lines.append(
        f"well-excited windows (CRB relative std K <= {100 * crb['K']:g} %, T1 <= "
        f"{100 * crb['T1']:g} %, and T1 held {100 * OFF_TOLERANCE:.0f} % either side of the truth raises "
        f"the cost by chi2 >= {WELL_EXCITED_PROFILE_RISE:g}) on steady vessels: {we['rejected']} of "
        f"{we['refits']} refits rejected ({100 * we['share_rejected']:.1f} %, target <= 5 %), "
        f"{we['rejected_start_up']} of them before a full window (start-up); conditions: "
        + (", ".join(f"{c} {n}" for c, n in we["reasons"].items()) or "-")
        + f"; by the bound alone {we['rejected_by_bound']} of {we['refits_by_bound']} "
        f"({100 * we['rejected_by_bound'] / max(we['refits_by_bound'], 1):.1f} %)"
    )
    rc = s["recovery"]
    lines.append(
        f"step cases: K back within 5 % after {rc['median_s']:.0f} s median; on the "
        f"{rc['quick_hull_cases']} hulls with T1 <= {QUICK_HULL_T1:.0f} s {rc['quick_hull_median_s']:.0f} s "
        f"median (target <= 60 s), on slower ones {rc['slow_hull_median_s']:.0f} s; "
        f"worst {rc['worst_s']:.0f} s; beyond one window + one refit period: "
        f"{100 * rc['share_beyond_window']:.0f} % (target 0); K error before the change "
        f"{rc['error_before_percent_median']:.2f} % median, {rc['error_before_percent_worst']:.2f} % worst; "
        f"beyond one window + one refit period on the cases whose data after the change determine K: "
        f"{100 * rc['share_beyond_window_determined']:.0f} %; the data of {len(rc['undetermined_seeds'])} "
        f"never do (K's bound above {100 * WELL_EXCITED['K']:g} % in every window after it)"
        + (f": seeds {', '.join(map(str, rc['undetermined_seeds']))}" if rc["undetermined_seeds"] else "")
        + f"; the estimates published (WARN) while a change's gain is followed: 95 % coverage of the new "
        f"truth K {rc['followed_coverage']['K']:.3f}, T1 {rc['followed_coverage']['T1']:.3f} over "
        f"{rc['followed_refits']} refits"
    )
    lines.append(
        f"false vessel_changed: {s['false_changes_per_hour']:.2f} per hour over "
        f"{s['steady_hours']:.1f} h of steady data (target 0)"
    )
    return "\n\n".join(lines)


register(
    "vessels",
    "the online core on randomised vessels (USVs to ships, steady and stepped): coverage, "
    "errors, rejected refits, recovery, false changes",
    run,
    render,
    plots=True,
    randomised=True,
    generators=GENERATORS,
)
