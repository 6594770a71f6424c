"""``onboard-diagnosis``: does the diagnosis on board name a hidden effect once, early, and see it fixed? (randomised)

Each trip hides one of ten kinds (every catalogued effect, or none), in turn: a vessel, its
manoeuvre and the effect's strength are drawn as ``hidden-effects`` draws them
(``hidden_effects.draw_case``: quick USVs to slow ships, a strength that matters on that vessel in
that manoeuvre); the trips without a hidden effect also sail steady legs and steady turns. The
trip lasts ``TRIP_S`` (15 min) and is written to an MCAP and replayed as ``ship-ident replay BAG
--model nomoto2 --diagnosis-period 60 --auto-add-effects`` replays it (``io.bag_replay.replay_bag``:
the node's core, the diagnoses inline), the window ``WINDOW_S`` long for the vessel's kind (a
slow ship's crew gives it ten minutes).

A trip hiding an effect is **fair** when an output-error fit of the true structure removes at
least ``hidden_effects.FAIR_SHARE`` of the held-out error of a one-shot ``diagnose`` of the
trip's first ``NAMED_BY_S`` s (the fairness of ``hidden-effects``). Per trip:

* **named**: the first diagnosis whose verdict is ``missing_effect`` with the hidden effect named,
  or in the group named with it (near-equivalent on the pooled data); **named first**: named alone
  or leading its group;
* **changes**: how often the named effect changes between diagnoses of one model;
* **at the floor after the add**: once auto-add has added an effect, one of the next two
  diagnoses shows the held-out yaw-rate error pooled since the add within ``NOISE_MARGIN`` of the
  pooled noise floor (the share on a window's own error is printed too: with the right model it
  scatters about the floor by the fit's own scatter);
* on trips with nothing hidden, the share of diagnoses saying ``missing_effect``;
* the diagnoses' CPU time over the trip's duration (the share of one core the node's child
  process spends at this period).
"""

from __future__ import annotations

import tempfile
from collections import Counter
from pathlib import Path

import numpy as np

from ..diagnosis.diagnose import NOISE_MARGIN, diagnose
from ..io.bag_replay import replay_bag
from ..io.files import DEFAULT_TOPICS, write_simulation
from ..model.effects import EFFECTS
from ..online.config import OnlineConfig
from . import progress, register
from .common import table
from .hidden_effects import FAIR_SHARE, MANOEUVRES, SAMPLE_TIME_S, draw_case, true_improvement

KINDS = (*EFFECTS, "none")  # hidden in turn
TRIP_S = 900.0  # s, one trip
NAMED_BY_S = 600.0  # s: the hidden effect must be named by then
PERIOD_S = 60.0  # diagnosis_period
WINDOW_S = {"usv": 180.0, "ship": 600.0}  # window_length by vessel kind
STEADY_MANOEUVRES = ("legs", "steady_turns")  # also sailed by the trips with nothing hidden
AFTER_ADD = 2  # diagnoses after an add within which the error must reach the floor
QUICK = {"kinds": ("rudder_offset", "none"), "trip_s": 420.0, "named_by_s": 360.0}


def trip_config(vessel_kind: str) -> OnlineConfig:
    """The node's configuration for a trip: the default one with nomoto2 and no effects (every
    catalogued effect is a candidate), the speed log read, the window for the vessel's kind, the
    diagnosis every ``PERIOD_S``, auto-add on."""
    return OnlineConfig(
        model="nomoto2",
        effects=(),
        speed_topic=DEFAULT_TOPICS.speed,
        window_length=WINDOW_S[vessel_kind],
        sample_time=SAMPLE_TIME_S[vessel_kind],
        diagnosis_period=PERIOD_S,
        auto_add_effects=True,
    )


def named_effects(diagnosis: dict) -> list[str]:
    """The effect a ``missing_effect`` diagnosis names, then the group named with it ([] otherwise)."""
    if diagnosis.get("verdict") != "missing_effect":
        return []
    return [diagnosis["candidates"][0]["effect"], *diagnosis.get("near_equivalent", [])]


def name_changes(done: list[dict]) -> int:
    """How often the effect named missing changes between diagnoses of one model."""
    changes, last = 0, {}
    for d in done:
        names = named_effects(d)
        if not names:
            continue
        structure = tuple(d["structure"]["effects"])
        if structure in last and last[structure] != names[0]:
            changes += 1
        last[structure] = names[0]
    return changes


def after_add(done: list[dict]) -> tuple[str | None, list[dict]]:
    """The effect auto-add added first (None: none) and the held-out error over the noise floor of
    the next ``AFTER_ADD`` diagnoses of the new model: the window's own and the pooled one."""
    added = next((k for k, d in enumerate(done) if d.get("auto_add", {}).get("action") == "added"), None)
    if added is None:
        return None, []
    effects = done[added]["auto_add"]["effects"]
    after = [d for d in done[added + 1 :] if d["structure"]["effects"] == effects][:AFTER_ADD]
    ratios = [
        {
            "window": d["held_out_error"] / d["noise_floor"],
            "pooled": d["pooled"]["held_out_error"] / d["pooled"]["noise_floor"] if "pooled" in d else float("nan"),
        }
        for d in after
    ]
    return done[added]["auto_add"]["effect"], ratios


def at_floor(row: dict, which: str) -> bool | None:
    """Whether one of the diagnoses after the add has its ``which`` (``window`` or ``pooled``)
    held-out error within ``NOISE_MARGIN`` of the noise floor (None: no diagnosis after an add)."""
    ratios = row["after_add"]
    return None if not ratios else any(r[which] <= NOISE_MARGIN for r in ratios)


def run_trip(seed: int, kind: str, trip_s: float = TRIP_S, named_by_s: float = NAMED_BY_S) -> dict:
    """One trip hiding ``kind`` (an effect, or ``none``) on a vessel drawn from ``seed``: replayed
    with the diagnosis on board, and (hiding an effect) judged fair or not."""
    hidden = () if kind == "none" else (kind,)
    manoeuvres = MANOEUVRES + STEADY_MANOEUVRES if kind == "none" else MANOEUVRES
    vessel, manoeuvre, sim = draw_case(seed, hidden, trip_s, manoeuvres)
    vessel_kind = vessel.name.split("(")[0]
    with tempfile.TemporaryDirectory() as folder:
        bag = Path(folder) / "trip.mcap"
        write_simulation(sim, bag, "mcap")
        replay = replay_bag(bag, DEFAULT_TOPICS, trip_config(vessel_kind))
    diagnoses = [r.diagnosis for r in replay.records if r.diagnosis is not None]
    done = [d for d in diagnoses if d["status"] == "done"]
    added, ratios = after_add(done)
    row = {
        "seed": seed,
        "hidden": kind,
        "vessel": vessel.name,
        "manoeuvre": manoeuvre,
        "diagnoses": len(diagnoses),
        "done": len(done),
        "skipped": [d["reason"] for d in diagnoses if d["status"] == "skipped"],
        "missing_effect": sum(d["verdict"] == "missing_effect" for d in done),
        "changes": name_changes(done),
        "added": added,
        "after_add": ratios,
        "first_named": next(
            (f"{d['stamp']:.0f} s: {'/'.join(named_effects(d))}" for d in done if named_effects(d)), None
        ),
        "diagnosis_cpu_percent": 100.0 * sum(d["compute_seconds"] for d in diagnoses) / replay.duration,
        "replay_wall_seconds": replay.wall_seconds,
    }
    if hidden:
        named = [d for d in done if kind in named_effects(d)]
        row["named_at"] = named[0]["stamp"] if named else None
        first = [d for d in done if named_effects(d)[:1] == [kind]]
        row["named_first_at"] = first[0]["stamp"] if first else None
        early = sim.dataset.slice(0, int(round(named_by_s / sim.dataset.sample_time)))
        row["true_improvement"] = true_improvement(diagnose(early, "nomoto2", (), workers=1), hidden, sim.truth)
        row["fair"] = bool(row["true_improvement"] >= FAIR_SHARE)
        row["named_in_time"] = row["named_at"] is not None and row["named_at"] <= named_by_s
        row["named_first_in_time"] = row["named_first_at"] is not None and row["named_first_at"] <= named_by_s
    return row


def share(rows: list[dict], key: str) -> float:
    """Share of ``rows`` whose ``key`` is true (nan for no rows)."""
    return float(np.mean([bool(r[key]) for r in rows])) if rows else float("nan")


def run(quick: bool = False, seed: int = 0, count: int | None = None) -> dict:
    rng = np.random.default_rng(seed)
    kinds = QUICK["kinds"] if quick else KINDS
    trip_s = QUICK["trip_s"] if quick else TRIP_S
    named_by_s = QUICK["named_by_s"] if quick else NAMED_BY_S
    count = count or (len(kinds) if quick else 3 * len(kinds))
    rows = []
    for k in range(count):
        kind = kinds[k % len(kinds)]
        trip_seed = int(rng.integers(2**31))
        row = run_trip(trip_seed, kind, trip_s, named_by_s)
        progress(
            f"onboard-diagnosis {k + 1}/{count}: {kind} on {row['vessel']} ({row['manoeuvre']}, seed {trip_seed}): "
            f"first named {row['first_named']}, {row['missing_effect']} of {row['done']} missing_effect, "
            f"{row['changes']} changes, added {row['added']}, after it "
            + ", ".join(f"{r['window']:.2f} ({r['pooled']:.2f} pooled)" for r in row["after_add"])
            + " noise floors"
            + (f", fair {row['fair']} ({100 * row['true_improvement']:.0f} %)" if "fair" in row else "")
        )
        rows.append(row)
    return dict(summary(rows, kinds), seed=seed, trip_seconds=trip_s, named_by_seconds=named_by_s)


def summary(rows: list[dict], kinds=KINDS) -> dict:
    """The figures over the trips ``rows`` (``run_trip``'s), overall and per hidden kind."""
    fair = [r for r in rows if r.get("fair")]
    none = [r for r in rows if r["hidden"] == "none"]
    added_hidden = [r for r in rows if r["added"] is not None and r["added"] == r["hidden"]]
    judged_adds = [r for r in rows if r["after_add"]]
    per_kind = {}
    for kind in kinds:
        of_kind = [r for r in rows if r["hidden"] == kind]
        per_kind[kind] = {
            "trips": len(of_kind),
            "fair": sum(bool(r.get("fair")) for r in of_kind),
            "named_in_time": sum(bool(r.get("fair") and r["named_in_time"]) for r in of_kind),
            "max_changes": max((r["changes"] for r in of_kind), default=0),
            "added": sum(r["added"] is not None for r in of_kind),
            "at_floor_after_add": sum(bool(at_floor(r, "pooled")) for r in of_kind),
            "missing_effect": sum(r["missing_effect"] for r in of_kind),
            "done": sum(r["done"] for r in of_kind),
        }
    return {
        "trips": len(rows),
        "fair": len(fair),
        "named_in_time": share(fair, "named_in_time"),
        "named_first_in_time": share(fair, "named_first_in_time"),
        "max_changes": max((r["changes"] for r in rows), default=0),
        "trips_with_more_than_one_change": sum(r["changes"] > 1 for r in rows),
        "added_hidden": len(added_hidden),
        "adds_judged": len(judged_adds),
        "at_floor_after_add": float(np.mean([at_floor(r, "pooled") for r in judged_adds]))
        if judged_adds
        else float("nan"),
        "at_floor_after_add_window": (
            float(np.mean([at_floor(r, "window") for r in judged_adds])) if judged_adds else float("nan")
        ),
        "none_trips": len(none),
        "none_missing_effect_per_diagnosis": (
            sum(r["missing_effect"] for r in none) / max(sum(r["done"] for r in none), 1) if none else float("nan")
        ),
        "skipped": dict(Counter(reason.split(":")[0].split(";")[0] for r in rows for reason in r["skipped"])),
        "diagnosis_cpu_percent": float(np.mean([r["diagnosis_cpu_percent"] for r in rows])),
        "per_kind": per_kind,
        "rows": rows,
    }


def render(result: dict) -> str:
    rows = [
        [
            kind,
            e["trips"],
            e["fair"],
            f"{e['named_in_time']} of {e['fair']}",
            e["max_changes"],
            e["added"],
            f"{e['at_floor_after_add']} of {e['added']}",
            f"{e['missing_effect']} of {e['done']}",
        ]
        for kind, e in result["per_kind"].items()
    ]
    minutes = result["named_by_seconds"] / 60.0
    text = table(
        [
            "hidden",
            "trips",
            "fair",
            f"named within {minutes:g} min",
            "changes of the name (max)",
            "added",
            f"at the floor within {AFTER_ADD} diagnoses (pooled)",
            "missing_effect diagnoses",
        ],
        rows,
        f"onboard-diagnosis, seed {result['seed']}: {result['trips']} trips of {result['trip_seconds'] / 60:g} min "
        f"replayed with a diagnosis every {PERIOD_S:g} s and auto-add",
    )
    return text + (
        f"\n\nhidden effect named missing_effect within {minutes:g} min: {100 * result['named_in_time']:.0f} % of "
        f"{result['fair']} fair trips (named first: {100 * result['named_first_in_time']:.0f} %)\n"
        f"changes of the named effect per trip: at most {result['max_changes']} "
        f"({result['trips_with_more_than_one_change']} trips with more than one)\n"
        f"after an add (auto-add, {result['adds_judged']} trips judged; the hidden effect added in "
        f"{result['added_hidden']}): held-out error within {NOISE_MARGIN:g} times the noise floor within "
        f"{AFTER_ADD} diagnoses in {100 * result['at_floor_after_add']:.0f} % pooled since the add "
        f"({100 * result['at_floor_after_add_window']:.0f} % on a window's own)\n"
        f"trips with nothing hidden: {result['none_trips']}, missing_effect in "
        f"{100 * result['none_missing_effect_per_diagnosis']:.1f} % of their diagnoses\n"
        f"diagnoses skipped, by reason: {result['skipped'] or 'none'}\n"
        f"the diagnoses' CPU: {result['diagnosis_cpu_percent']:.1f} % of "
        "one core on average (inline, this machine)"
    )


register(
    "onboard-diagnosis",
    "does the diagnosis on board name a hidden effect once, within 10 min, and see it fixed? (randomised, replay)",
    run,
    render,
    randomised=True,
)
