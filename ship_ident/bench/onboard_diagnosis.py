"""``onboard-diagnosis``: does the diagnosis on board name a missing effect once, early, see it fixed,
and stay quiet when nothing is missing? (randomised)

Every trip lasts ``TRIP_S`` (15 min), is written to an MCAP and replayed as ``ship-ident replay BAG
--model nomoto2 --diagnosis-period 60 --auto-add-effects`` replays it (``io.bag_replay.replay_bag``:
the node's core, the diagnoses inline), the speed log read, the window ``WINDOW_S`` long for the
vessel's kind (a slow ship's crew gives it ten minutes). Three kinds of trip:

* **hidden-effect trips** (``--count``, default ``COUNT``): each hides one catalogued effect, in
  turn, on a vessel, manoeuvre and strength drawn as ``hidden-effects`` draws them
  (``hidden_effects.draw_case``: quick USVs to slow ships, a strength that matters on that vessel
  in that manoeuvre). One is **fair** when the true structure at its known parameters removes at
  least ``hidden_effects.FAIR_SHARE`` of the held-out error of a one-shot ``diagnose`` of the trip's
  first ``NAMED_BY_S`` s, and more of it than any other effect's candidate there
  (``hidden_effects.fairness``);
* **none trips** (``--none-trips``, default ``NONE_COUNT``): nothing hidden, USVs and ships in turn,
  each manoeuvre of ``NONE_MANOEUVRES`` in turn (steady legs and turns as well as zigzags and steps);
* **MMG trips** (``--mmg-trips``, default ``MMG_COUNT``): 15 minutes of random rudder steps on a
  hull of the MMG generator (``mmg.py``: KVLCC2-like, nothing hidden by name; the truth is an
  outcome). A trip **has a halving effect** when some catalogued effect, added to the model fitted
  on the trip's first ``NAMED_BY_S`` s, halves the held-out heading error on the hull's standard
  manoeuvres (10/10 and 20/20 zigzags, 35 deg turning circle; ``hidden_effects.HALVING``); there,
  the effect the diagnosis on board names first must be one that halves it (what the effect named
  removes there is printed beside: damping laws a few per cent apart around a half are common).
  The share is the median of three fits, on the first ``NAMED_BY_S`` s and one diagnosis period
  less and more (``JUDGE_SPANS_S``, each printed): a Nomoto model fitted to an MMG hull's random
  steps and run free over a 200 s turning circle integrates a small error of its steady turn rate,
  so one fit's share moves by up to a quarter of the error with a minute more or less of training
  data, and a fit that fails scores 0 (``median_shares``). ``--count 0 --none-trips 0`` draws MMG
  trips alone.

Per trip:

* **named**: the first diagnosis whose verdict is ``missing_effect`` with the hidden effect named,
  or in the group named with it (near-equivalent on the pooled data); **named first**: named alone
  or leading its group;
* **changes**: how often the named effect changes between diagnoses of one model;
* **at the floor after the add**: once auto-add has added an effect, one of the next two
  diagnoses shows the held-out yaw-rate error pooled since the add within ``NOISE_MARGIN`` of the
  pooled noise floor (the share on a window's own error is printed too: with the right model it
  scatters about the floor by the fit's own scatter);
* the share of diagnoses saying ``missing_effect`` (on none trips: false alarms);
* the diagnoses' CPU time over the trip's duration (the share of one core the node's child
  process spends at this period).

``--dds-trips N`` (default 0: it takes minutes of wall time per trip) also plays the first N
hidden-effect trips to the real node (``identifier_node`` with the same parameters, ``use_sim_time``,
over DDS on a private domain restricted to this machine, ``ship-ident play`` at ``DDS_PACE`` times
real time; the node shut down after each) and compares what it publishes on ``~/diagnosis`` with
the replay: the same effect named first, the same effect auto-added, and the share of diagnoses
(matched by their time) with the same verdict.
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
from . import Option, progress, register
from .common import table
from .hidden_effects import HALVING, MANOEUVRES, SAMPLE_TIME_S, draw_case, fairness

KINDS = tuple(EFFECTS)  # hidden in turn
TRIP_S = 900.0  # s, one trip
NAMED_BY_S = 600.0  # s: the hidden effect must be named by then
PERIOD_S = 60.0  # diagnosis_period
WINDOW_S = {"usv": 180.0, "ship": 600.0}  # window_length by vessel kind
NONE_MANOEUVRES = ("steady_turns", *MANOEUVRES, "legs")  # sailed in turn by the trips with nothing hidden
NONE_VESSELS = ("usv", "ship")  # in turn
STEADY_MANOEUVRES = ("legs", "steady_turns")
MMG_KIND = "ship"  # an MMG hull's trip is configured as a ship's (KVLCC2-like)
AFTER_ADD = 2  # diagnoses after an add within which the error must reach the floor
COUNT, NONE_COUNT, MMG_COUNT = 30, 30, 10  # trips of each kind by default
DDS_PACE = 1.0  # x real time: the diagnosis child keeps the pace a boat gives it (faster, a loaded machine starves it)
DDS_DOMAIN_IDS = range(200, 205)  # apart from the tests' (1..100, 150..199) and the other benches' (101..149)
JUDGE_SPANS_S = (-PERIOD_S, 0.0, PERIOD_S)  # s about named_by_s: the MMG judge's training spans
QUICK = {"count": 1, "none_trips": 1, "trip_s": 420.0, "named_by_s": 360.0}
TARGETS = {"named_in_time": 0.9, "at_floor_after_add": 0.9, "none_missing_effect": 0.05, "mmg_named_halves": 0.9}


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


def node_parameters(config: OnlineConfig) -> list[str]:
    """``name:=value`` overrides that give the node ``trip_config``'s settings (no effects: one empty name)."""
    return [
        f"model:={config.model}",
        "effects:=['']",
        f"speed_topic:={config.speed_topic}",
        f"window_length:={config.window_length}",
        f"sample_time:={config.sample_time}",
        f"diagnosis_period:={config.diagnosis_period}",
        "auto_add_effects:=true",
    ]


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


def first_named(done: list[dict], by: float = np.inf) -> tuple[float, str] | None:
    """(time s, effect) of the first diagnosis up to ``by`` (s) naming an effect missing (the leader
    of its group), or None."""
    return next(((d["stamp"], named_effects(d)[0]) for d in done if named_effects(d) and d["stamp"] <= by), None)


def first_added(done: list[dict]) -> str | None:
    """The effect auto-add added first, or None."""
    return after_add(done)[0]


def replayed(sim, config: OnlineConfig, dds: dict | None = None) -> tuple[list[dict], float, float, dict | None]:
    """``sim`` (its ``dataset``) written to an MCAP and replayed with ``config``: (the diagnoses,
    the trip's duration s, the replay's wall time s, and with ``dds`` (``pace``, ``domain_id``) the
    node's diagnoses of the same bag over DDS, else None)."""
    with tempfile.TemporaryDirectory() as folder:
        bag = Path(folder) / "trip.mcap"
        write_simulation(sim, bag, "mcap")
        replay = replay_bag(bag, DEFAULT_TOPICS, config)
        node = None
        if dds is not None:
            node = node_diagnoses(bag, config, replay.duration, dds["pace"], dds["domain_id"], folder)
    diagnoses = [r.diagnosis for r in replay.records if r.diagnosis is not None]
    return diagnoses, replay.duration, replay.wall_seconds, node


def node_diagnoses(bag: Path, config: OnlineConfig, duration: float, pace: float, domain_id: int, log_dir) -> dict:
    """``bag`` (``duration`` s) played at ``pace`` to the real node configured as ``config``, over DDS
    on ``domain_id``; the node is shut down after. Returns its diagnoses (``~/diagnosis``), exit code
    and, when that is not 0, the end of its output."""
    from ..ros.demo import node_log_tail, quiet_trip, shut_down

    node, listener, play = quiet_trip(domain_id, log_dir, bag, pace, *node_parameters(config))
    try:
        listener.spin(duration / pace + 60.0, lambda: play.poll() is not None)
        listener.spin(10.0)  # the last diagnosis, finished in the child after the bag's end
    finally:
        code, _ = shut_down(node, listener, play)
    return {
        "diagnoses": list(listener.diagnoses),
        "estimates": len(listener.estimates),
        "exit_code": code,
        "log": node_log_tail(log_dir) if code else "",
    }


def agreement(replay: list[dict], node: list[dict], named_by_s: float) -> dict:
    """How the node's diagnoses ``node`` agree with the replay's ``replay``: the effect each names
    first by ``named_by_s`` (s) and adds first, and the share of the replay's finished diagnoses
    whose verdict the node's nearest in time (within half a period) shares. A node that published
    no diagnosis at all (``received``: 0) neither agrees nor disagrees: nothing reached the listener."""
    done_replay = [d for d in replay if d["status"] == "done"]
    done_node = [d for d in node if d["status"] == "done"]
    same = 0
    for d in done_replay:
        nearest = min(done_node, key=lambda n: abs(n["stamp"] - d["stamp"]), default=None)
        same += (
            nearest is not None
            and abs(nearest["stamp"] - d["stamp"]) <= PERIOD_S / 2
            and nearest["verdict"] == d["verdict"]
        )
    named = [first_named(done, named_by_s) for done in (done_replay, done_node)]
    added = [first_added(done) for done in (done_replay, done_node)]
    return {
        "named_replay": named[0][1] if named[0] else None,
        "named_node": named[1][1] if named[1] else None,
        "added_replay": added[0],
        "added_node": added[1],
        "diagnoses_replay": len(done_replay),
        "diagnoses_node": len(done_node),
        "skipped_node": [d["reason"] for d in node if d["status"] == "skipped"],
        "received": len(node),
        "same_verdict": same / len(done_replay) if done_replay and node else float("nan"),
        "agrees": bool(node) and (named[0] or (0, None))[1] == (named[1] or (0, None))[1] and added[0] == added[1],
    }


def trip_row(seed: int, kind: str, vessel_name: str, manoeuvre: str, diagnoses: list[dict], duration: float) -> dict:
    """What every trip reports, from its diagnoses."""
    done = [d for d in diagnoses if d["status"] == "done"]
    added, ratios = after_add(done)
    named = first_named(done)
    return {
        "seed": seed,
        "hidden": kind,
        "vessel": vessel_name,
        "vessel_kind": vessel_name.split("(")[0],
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
        "first_named_effect": named[1] if named else None,
        "diagnosis_cpu_percent": 100.0 * sum(d["compute_seconds"] for d in diagnoses) / duration,
        "timeline": [timeline_entry(d) for d in diagnoses],
    }


def timeline_entry(diagnosis: dict) -> str:
    """A diagnosis in a few words: its time (s), effects in force, verdict, the effect it names (or
    its best candidate) and the pooled held-out error over the noise floor."""
    effects = "+".join(diagnosis["structure"]["effects"]) or "-"
    if diagnosis["status"] != "done":
        return f"{diagnosis['stamp']:.0f} s {effects}: skipped"
    figures = diagnosis.get("pooled", diagnosis)
    best = "/".join(named_effects(diagnosis)) or (diagnosis["candidates"] or [{"effect": ""}])[0]["effect"]
    add = f", {diagnosis['auto_add']['action']} {diagnosis['auto_add']['effect']}" if "auto_add" in diagnosis else ""
    return (
        f"{diagnosis['stamp']:.0f} s {effects}: {diagnosis['verdict']} {best} "
        f"({figures['held_out_error'] / figures['noise_floor']:.2f} floors{add})"
    )


def run_trip(
    seed: int,
    kind: str,
    trip_s: float = TRIP_S,
    named_by_s: float = NAMED_BY_S,
    none_index: int = 0,
    dds: dict | None = None,
) -> dict:
    """One trip hiding ``kind`` (an effect, or ``none``) on a vessel drawn from ``seed``: replayed
    with the diagnosis on board (and with ``dds`` played to the real node too), and (hiding an
    effect) judged fair or not. A none trip sails the ``none_index``-th vessel kind and manoeuvre
    (``NONE_VESSELS``, ``NONE_MANOEUVRES``, in turn)."""
    if kind == "none":
        vessel_kind = NONE_VESSELS[none_index % len(NONE_VESSELS)]
        manoeuvres = (NONE_MANOEUVRES[(none_index // len(NONE_VESSELS)) % len(NONE_MANOEUVRES)],)
        vessel, manoeuvre, sim = draw_case(seed, (), trip_s, manoeuvres, vessel_kind)
    else:
        vessel, manoeuvre, sim = draw_case(seed, (kind,), trip_s)
    config = trip_config(vessel.name.split("(")[0])
    diagnoses, duration, wall, node = replayed(sim, config, dds)
    row = trip_row(seed, kind, vessel.name, manoeuvre, diagnoses, duration)
    row["replay_wall_seconds"] = wall
    done = [d for d in diagnoses if d["status"] == "done"]
    if node is not None:
        row["dds"] = dict(
            agreement(diagnoses, node["diagnoses"], named_by_s),
            node_exit=node["exit_code"],
            node_log=node["log"],
            estimates_node=node["estimates"],
        )
    if kind != "none":
        named = [d for d in done if kind in named_effects(d)]
        row["named_at"] = named[0]["stamp"] if named else None
        first = [d for d in done if named_effects(d)[:1] == [kind]]
        row["named_first_at"] = first[0]["stamp"] if first else None
        early = sim.dataset.slice(0, int(round(named_by_s / sim.dataset.sample_time)))
        judged = diagnose(early, "nomoto2", (), workers=1)
        row.update(fairness(judged, (kind,), sim.truth, vessel))
        row["named_in_time"] = row["named_at"] is not None and row["named_at"] <= named_by_s
        row["named_first_in_time"] = row["named_first_at"] is not None and row["named_first_at"] <= named_by_s
    return row


def run_mmg_trip(seed: int, trip_s: float = TRIP_S, named_by_s: float = NAMED_BY_S) -> dict:
    """One trip of random rudder steps on an MMG hull drawn from ``seed``, replayed with the
    diagnosis on board; whether some catalogued effect halves the held-out heading error of the
    model fitted on the trip's first ``named_by_s`` s on the hull's standard manoeuvres (the median
    of the fits on ``JUDGE_SPANS_S`` about it), and whether the effect named first on board does."""
    from . import mmg

    hull = mmg.random_hull(np.random.default_rng(seed))
    run = mmg.simulate(hull, mmg.TRAINING, seed, duration=trip_s)
    diagnoses, duration, wall, _ = replayed(run, trip_config(MMG_KIND))
    row = trip_row(seed, "mmg", hull.name, "steps", diagnoses, duration)
    row["replay_wall_seconds"] = wall
    validation = mmg.held_out_recordings(hull, seed)
    by_span = []
    for offset in JUDGE_SPANS_S:
        early = run.dataset.slice(0, int(round((named_by_s + offset) / run.dataset.sample_time)))
        judged = diagnose(early, "nomoto2", (), workers=1, validation=validation)
        by_span.append({c.effect: c.improvement_heading for c in judged.candidates})
    shares = median_shares(by_span)
    row["judge_spans_seconds"] = [named_by_s + offset for offset in JUDGE_SPANS_S]
    row["judge_shares"] = {effect: [s.get(effect, 0.0) for s in by_span] for effect in shares}
    row["halving"] = {effect: share for effect, share in shares.items() if share >= HALVING}
    done = [d for d in diagnoses if d["status"] == "done"]
    named = first_named(done, named_by_s)
    row["named_by_deadline"] = named[1] if named else None
    row["named_share"] = shares.get(named[1], float("nan")) if named else float("nan")
    row["named_halves"] = bool(named and named[1] in row["halving"])
    # the near-equivalent group named with it, with what would separate them: a halving effect among them
    group = next((named_effects(d) for d in done if named_effects(d) and d["stamp"] <= named_by_s), [])
    row["group_halves"] = any(effect in row["halving"] for effect in group)
    return row


def median_shares(by_span: list[dict]) -> dict:
    """Each effect's share of the held-out heading error removed, the median over the judge's fits
    on its training spans (``by_span``: one ``{effect: share}`` per span; an effect a fit lacks
    scores 0 there), best first."""
    effects = {effect for shares in by_span for effect in shares}
    medians = {effect: float(np.median([shares.get(effect, 0.0) for shares in by_span])) for effect in effects}
    return dict(sorted(medians.items(), key=lambda item: -item[1]))


def share(rows: list[dict], key: str) -> float:
    """Share of ``rows`` whose ``key`` is true (nan for no rows)."""
    return float(np.mean([bool(r[key]) for r in rows])) if rows else float("nan")


def run(
    quick: bool = False,
    seed: int = 0,
    count: int | None = None,
    none_trips: int | None = None,
    mmg_trips: int | None = None,
    dds_trips: int = 0,
) -> dict:
    """``count`` hidden-effect trips, ``none_trips`` trips with nothing hidden and ``mmg_trips`` MMG
    trips, their seeds drawn from ``seed``; the first ``dds_trips`` hidden-effect trips also played
    to the real node."""
    rng = np.random.default_rng(seed)
    trip_s = QUICK["trip_s"] if quick else TRIP_S
    named_by_s = QUICK["named_by_s"] if quick else NAMED_BY_S
    count = (QUICK["count"] if quick else COUNT) if count is None else count
    none_trips = (QUICK["none_trips"] if quick else NONE_COUNT) if none_trips is None else none_trips
    mmg_trips = (0 if quick else MMG_COUNT) if mmg_trips is None else mmg_trips
    plan = [(KINDS[k % len(KINDS)], k) for k in range(count)] + [("none", k) for k in range(none_trips)]
    plan += [("mmg", k) for k in range(mmg_trips)]
    if not plan:
        raise ValueError("no trips to draw: --count, --none-trips and --mmg-trips are all 0")
    rows = []
    for n, (kind, k) in enumerate(plan):
        trip_seed = int(rng.integers(2**31))
        if kind == "mmg":
            row = run_mmg_trip(trip_seed, trip_s, named_by_s)
        else:
            dds = None
            if kind != "none" and k < dds_trips:
                dds = {"pace": DDS_PACE, "domain_id": DDS_DOMAIN_IDS[(seed + k) % len(DDS_DOMAIN_IDS)]}
            row = run_trip(trip_seed, kind, trip_s, named_by_s, none_index=k, dds=dds)
        progress(f"onboard-diagnosis {n + 1}/{len(plan)}: " + trip_line(row))
        rows.append(row)
    return dict(summary(rows), seed=seed, trip_seconds=trip_s, named_by_seconds=named_by_s)


def trip_line(row: dict) -> str:
    """One trip's outcome in a line (the progress printed as the bench runs)."""
    text = (
        f"{row['hidden']} on {row['vessel']} ({row['manoeuvre']}, seed {row['seed']}): "
        f"first named {row['first_named']}, {row['missing_effect']} of {row['done']} missing_effect, "
        f"{row['changes']} changes, added {row['added']}, after it "
        + ", ".join(f"{r['window']:.2f} ({r['pooled']:.2f} pooled)" for r in row["after_add"])
        + " noise floors"
    )
    if "fair" in row:
        text += f", fair {row['fair']} ({100 * row['true_improvement']:.0f} %)"
    if "halving" in row:
        text += f", halving: {', '.join(f'{n} {100 * v:.0f} %' for n, v in row['halving'].items()) or 'none'}"
        if row["named_by_deadline"]:
            spans = ", ".join(f"{100 * v:.0f}" for v in row["judge_shares"].get(row["named_by_deadline"], []))
            seconds = ", ".join(f"{s:.0f}" for s in row["judge_spans_seconds"])
            text += (
                f"; named by the deadline: {row['named_by_deadline']} ({100 * row['named_share']:.0f} %: "
                f"{spans} % fitted on {seconds} s)"
            )
    if "dds" in row:
        dds = row["dds"]
        if dds["received"]:
            text += (
                f"; over DDS named {dds['named_node']} (replay {dds['named_replay']}), added {dds['added_node']} "
                f"(replay {dds['added_replay']}), {100 * dds['same_verdict']:.0f} % same verdicts"
            )
        else:
            text += (
                f"; over DDS no diagnosis reached the listener ({dds['estimates_node']} estimate records did: "
                + ("the node's diagnoses never came" if dds["estimates_node"] else "nothing of the node came")
                + ")"
            )
        if dds["node_exit"]:
            text += f"; the node exited with {dds['node_exit']}, its output ending:\n{dds['node_log']}"
    return text


def summary(rows: list[dict]) -> dict:
    """The figures over the trips ``rows`` (``run_trip``'s and ``run_mmg_trip``'s), overall and per kind."""
    hidden = [r for r in rows if r["hidden"] not in ("none", "mmg")]
    fair = [r for r in hidden if r["fair"]]
    none = [r for r in rows if r["hidden"] == "none"]
    mmg = [r for r in rows if r["hidden"] == "mmg"]
    halving = [r for r in mmg if r["halving"]]
    judged_adds = [r for r in hidden + none if r["after_add"]]
    dds = [r["dds"] for r in rows if "dds" in r]
    heard = [d for d in dds if d["received"] and np.isfinite(d["same_verdict"])]
    per_kind = {}
    for kind in (*KINDS, "none", "mmg"):
        of_kind = [r for r in rows if r["hidden"] == kind]
        if not of_kind:
            continue
        per_kind[kind] = {
            "trips": len(of_kind),
            "fair": sum(bool(r.get("fair") or r.get("halving")) for r in of_kind),
            "named_in_time": sum(
                bool((r.get("fair") and r["named_in_time"]) or (r.get("halving") and r["named_halves"]))
                for r in of_kind
            ),
            "max_changes": max(r["changes"] for r in of_kind),
            "added": sum(r["added"] is not None for r in of_kind),
            "at_floor_after_add": sum(bool(at_floor(r, "pooled")) for r in of_kind),
            "missing_effect": sum(r["missing_effect"] for r in of_kind),
            "done": sum(r["done"] for r in of_kind),
        }
    return {
        "trips": len(rows),
        "hidden_trips": len(hidden),
        "fair": len(fair),
        "named_in_time": share(fair, "named_in_time"),
        "named_first_in_time": share(fair, "named_first_in_time"),
        "missed": [
            f"{r['hidden']} on {r['vessel']} ({r['manoeuvre']}, trip seed {r['seed']})"
            for r in fair
            if not r["named_in_time"]
        ],
        "max_changes": max((r["changes"] for r in rows), default=0),
        "trips_with_more_than_one_change": sum(r["changes"] > 1 for r in rows),
        "added_hidden": sum(r["added"] is not None and r["added"] == r["hidden"] for r in hidden),
        "adds_judged": len(judged_adds),
        "at_floor_after_add": share([{"k": at_floor(r, "pooled")} for r in judged_adds], "k"),
        "at_floor_after_add_window": share([{"k": at_floor(r, "window")} for r in judged_adds], "k"),
        "none_trips": len(none),
        "none_by_vessel": dict(Counter(r["vessel_kind"] for r in none)),
        "none_steady": sum(r["manoeuvre"] in STEADY_MANOEUVRES for r in none),
        "none_missing_effect": sum(r["missing_effect"] for r in none),
        "none_done": sum(r["done"] for r in none),
        "none_missing_effect_per_diagnosis": (
            sum(r["missing_effect"] for r in none) / max(sum(r["done"] for r in none), 1) if none else float("nan")
        ),
        "mmg_trips": len(mmg),
        "mmg_with_halving_effect": len(halving),
        "mmg_named_halves": share(halving, "named_halves"),
        "mmg_group_halves": share(halving, "group_halves"),
        "mmg_missed": [
            f"{r['named_by_deadline'] or 'nothing'} named"
            + (f" (it removes {100 * r['named_share']:.0f} %)" if r["named_by_deadline"] else "")
            + f" on {r['vessel']} (trip seed {r['seed']})"
            for r in halving
            if not r["named_halves"]
        ],
        "mmg_missing_effect_without_halving": sum(r["missing_effect"] for r in mmg if not r["halving"]),
        "mmg_done_without_halving": sum(r["done"] for r in mmg if not r["halving"]),
        "dds_trips": len(dds),
        "dds_silent": sum(not d["received"] for d in dds),
        "dds_agree": sum(d["agrees"] for d in dds),
        "dds_same_verdict": float(np.mean([d["same_verdict"] for d in heard])) if heard else float("nan"),
        "skipped": dict(Counter(reason.split(":")[0].split(";")[0] for r in rows for reason in r["skipped"])),
        "diagnosis_cpu_percent": float(np.mean([r["diagnosis_cpu_percent"] for r in rows])),
        "per_kind": per_kind,
        "rows": rows,
    }


def percent(value: float) -> str:
    return "-" if np.isnan(value) else f"{100 * value:.0f} %"


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
            "fair (mmg: a halving effect)",
            f"named within {minutes:g} min (mmg: one that halves)",
            "changes of the name (max)",
            "added",
            f"at the floor within {AFTER_ADD} diagnoses (pooled)",
            "missing_effect diagnoses",
        ],
        rows,
        f"onboard-diagnosis, seed {result['seed']}: {result['trips']} trips of {result['trip_seconds'] / 60:g} min "
        f"replayed with a diagnosis every {PERIOD_S:g} s and auto-add",
    )
    changes = (
        f"changes of the named effect per trip: at most {result['max_changes']} "
        f"({result['trips_with_more_than_one_change']} trips with more than one; target: at most one)"
    )
    lines = [changes]
    if result["hidden_trips"]:
        lines[:0] = [
            f"hidden effect named missing_effect within {minutes:g} min: {percent(result['named_in_time'])} of "
            f"{result['fair']} fair trips of {result['hidden_trips']} (named first: "
            f"{percent(result['named_first_in_time'])}; target >= {100 * TARGETS['named_in_time']:.0f} %)"
            + (f"; missed: {'; '.join(result['missed'])}" if result["missed"] else "")
        ]
        lines.append(
            f"after an add (auto-add, {result['adds_judged']} trips judged; the hidden effect added in "
            f"{result['added_hidden']}): held-out error within {NOISE_MARGIN:g} times the noise floor within "
            f"{AFTER_ADD} diagnoses in {percent(result['at_floor_after_add'])} pooled since the add "
            f"({percent(result['at_floor_after_add_window'])} on a window's own; target >= "
            f"{100 * TARGETS['at_floor_after_add']:.0f} %)"
        )
    if result["none_trips"]:
        lines.append(
            f"trips with nothing hidden: {result['none_trips']} "
            f"({', '.join(f'{k} {n}' for k, n in sorted(result['none_by_vessel'].items()))}; "
            f"{result['none_steady']} on steady legs or turns), missing_effect in {result['none_missing_effect']} of "
            f"{result['none_done']} diagnoses ({100 * result['none_missing_effect_per_diagnosis']:.1f} %; target <= "
            f"{100 * TARGETS['none_missing_effect']:.0f} %)"
        )
    if result["mmg_trips"]:
        lines.append(
            f"MMG trips: {result['mmg_trips']}, {result['mmg_with_halving_effect']} with an effect that halves the "
            f"held-out heading error; the effect named first within {minutes:g} min halves it in "
            f"{percent(result['mmg_named_halves'])} of them (target >= {100 * TARGETS['mmg_named_halves']:.0f} %; "
            f"one in the near-equivalent group named with it: {percent(result['mmg_group_halves'])}); "
            f"without one, missing_effect in {result['mmg_missing_effect_without_halving']} of "
            f"{result['mmg_done_without_halving']} diagnoses"
            + (f"; missed: {'; '.join(result['mmg_missed'])}" if result["mmg_missed"] else "")
        )
    if result["dds_trips"]:
        lines.append(
            f"over DDS to the real node (at {DDS_PACE:g}x): {result['dds_agree']} of {result['dds_trips']} trips name "
            f"and add the same effect as the replay; {percent(result['dds_same_verdict'])} of the diagnoses "
            "give the same verdict"
            + (
                f"; from {result['dds_silent']} trips no diagnosis reached the listener (not counted as agreeing)"
                if result["dds_silent"]
                else ""
            )
        )
    lines += [
        f"diagnoses skipped, by reason: {result['skipped'] or 'none'}",
        f"the diagnoses' CPU: {result['diagnosis_cpu_percent']:.1f} % of one core on average (inline, this machine)",
    ]
    return text + "\n\n" + "\n".join(lines)


register(
    "onboard-diagnosis",
    "does the diagnosis on board name a hidden effect once, within 10 min, see it fixed, and stay quiet "
    "with nothing hidden? (randomised, replay; MMG trips; --dds-trips to the real node)",
    run,
    render,
    randomised=True,
    options=(
        Option("none-trips", f"trips with nothing hidden (default {NONE_COUNT})"),
        Option("mmg-trips", f"trips on MMG hulls (default {MMG_COUNT})"),
        Option("dds-trips", "hidden-effect trips also played to the real node over DDS (default 0)"),
    ),
)
