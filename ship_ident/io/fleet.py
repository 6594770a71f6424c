"""Fleet re-identification: many bags through the online identifier, in parallel, into one table.

``ship-ident replay BAG... [--jobs N] [--dask ADDRESS|local] [--table OUT.csv] [--plot-dir DIR]``
replays every bag exactly as ``ship-ident replay`` replays one (the node's
``OnlineIdentifier``, the bag's time as its clock: ``io.bag_replay.replay_bag``) in ``identify_bag``, one
bag per task. ``--jobs N`` spreads the bags over N local processes
(``concurrent.futures.ProcessPoolExecutor``); ``--dask ADDRESS`` sends the
same tasks to a running Dask scheduler, ``--dask local`` starts a local Dask
cluster of N worker processes (``dask.distributed``, the ``bench`` extra).

The vessel of a bag (``--vessel-from``): ``parent`` (default) is the name of
the directory that holds the bag (a fleet archive laid out as
``VESSEL/TRIP.mcap`` or ``VESSEL/TRIP/`` for rosbag2 directories); ``prefix``
is the bag's own name up to its first ``_``; any other value is a regular
expression searched in the bag's path whose first group is the vessel
(e.g. ``'hull-(\\w+)'``).

The table has one row per accepted estimate (a refit that produced a new
estimate): vessel, bag, time (s, bag clock at the refit), the estimate's
window start and end (s), every parameter (SI), its standard error
(``<name>_std``) and the free-run fit figures (``fit_<name>``, SI). A drift
plot per vessel (``drift_<vessel>.png``: K and T1 with 1.96-std error bars
against time) goes to ``--plot-dir``, or next to the table. Bag times that
look like Unix time (after 2001) are plotted as dates; simulated bags that
all start near 0 s are laid end to end in the order given.
"""

from __future__ import annotations

import concurrent.futures
import csv
import math
import re
import sys
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from ..estimators.base import Z_95
from ..model.dataset import DataError
from ..online.config import ConfigError, OnlineConfig
from ..online.samples import Topics
from .bag_replay import replay_bag
from .jsonio import dumps_json

UNIX_TIME_AFTER_2001 = 1e9  # s: bag stamps above this are wall-clock dates


class FleetError(ValueError):
    """Unusable fleet options (vessel rule, worker count, missing Dask): one line for the user."""


@dataclass(frozen=True)
class BagJob:
    """One bag to re-identify: where it is, whose it is, how to read and fit it."""

    bag: str
    vessel: str
    topics: Topics
    config: OnlineConfig


@dataclass
class BagResult:
    """The accepted estimates of one bag as table rows, with timing; ``error`` when it failed."""

    job: BagJob
    rows: list = field(default_factory=list)
    refits: int = 0
    bag_seconds: float = 0.0  # s of bag time covered
    read_seconds: float = 0.0  # wall s to read the bag (and set up)
    loop_seconds: float = 0.0  # wall s of the identification loop
    error: str = ""


def identify_bag(job: BagJob) -> BagResult:
    """Replay one bag as ``ship-ident replay`` does (``replay_bag``); the per-bag task of every executor."""
    result = BagResult(job)
    try:
        t0 = time.perf_counter()
        replay = replay_bag(job.bag, job.topics, job.config)
        total = time.perf_counter() - t0
    except (DataError, ConfigError) as exc:
        result.error = str(exc)
        return result
    result.refits = len(replay.records)
    result.bag_seconds = replay.duration
    result.loop_seconds = replay.wall_seconds
    result.read_seconds = total - replay.wall_seconds
    result.rows = [table_row(job, record.to_json()) for record in replay.records if record.new_estimate]
    return result


def table_row(job: BagJob, record: dict) -> dict:
    """One CSV row of an accepted estimate (the ``~/estimate`` record)."""
    row = {
        "vessel": job.vessel,
        "bag": job.bag,
        "time": record["stamp"],
        "window_start": record["estimate_window"]["start"],
        "window_end": record["estimate_window"]["end"],
    }
    row.update(record["parameters"])
    row.update({f"{name}_std": value for name, value in record["std_errors"].items()})
    row.update({f"fit_{name}": value for name, value in record["fit"].items() if isinstance(value, (int, float))})
    return row


def vessel_of(bag: str, rule: str = "parent") -> str:
    """The vessel a bag belongs to, by ``rule`` (see the module docstring)."""
    path = Path(bag).resolve()
    if path.name == "metadata.yaml":
        path = path.parent
    if rule == "parent":
        return path.parent.name
    if rule == "prefix":
        return path.stem.split("_", 1)[0]
    match = re.search(rule, str(path))
    if not match or not match.groups():
        raise FleetError(
            f"--vessel-from {rule!r} has no match with a group in {path}; "
            "use parent, prefix or a regular expression with one (group)"
        )
    return match.group(1)


def add_fleet_arguments(parser) -> None:
    """The many-bag options of ``ship-ident replay``."""
    group = parser.add_argument_group("many bags (fleet)")
    group.add_argument(
        "--jobs",
        type=int,
        default=1,
        metavar="N",
        help="bags replayed in parallel by N local processes (or N local Dask workers)",
    )
    group.add_argument(
        "--dask",
        metavar="ADDRESS",
        help="run the bags on a Dask scheduler (tcp://host:8786), or 'local' for a local "
        "Dask cluster of --jobs workers (needs dask[distributed])",
    )
    group.add_argument(
        "--table",
        metavar="OUT.csv",
        help="write one row per accepted estimate: vessel, bag, time, parameters, "
        "std errors, fit figures (SI); drift plots go next to it",
    )
    group.add_argument("--plot-dir", metavar="DIR", help="write a drift plot per vessel (drift_VESSEL.png) here")
    group.add_argument(
        "--vessel-from",
        default="parent",
        metavar="RULE",
        help="vessel of a bag: 'parent' (its directory's name, default), 'prefix' (its "
        "name up to the first '_'), or a regular expression whose first group is it",
    )


def run_fleet(args, bags: list[str], topics: Topics, config: OnlineConfig) -> int:
    """Replay many bags read by ``topics`` and fitted by ``config`` (the fleet options in ``args``, see
    ``add_fleet_arguments``); table, plots, bags per minute. Exit code; FleetError on bad options."""
    if args.jobs < 1:
        raise FleetError(f"--jobs must be >= 1, got {args.jobs}")
    jobs = [BagJob(str(bag), vessel_of(str(bag), args.vessel_from), topics, config) for bag in bags]
    wall0 = time.perf_counter()
    results = identify_bags(jobs, args.jobs, args.dask)
    wall = time.perf_counter() - wall0
    rows = [row for result in results for row in result.rows]
    failed = [r for r in results if r.error]
    if args.table:
        write_table(args.table, rows)
    plot_dir = args.plot_dir or (str(Path(args.table).parent) if args.table else None)
    plots = plot_drift(rows, plot_dir) if plot_dir and rows else []
    rate = 60.0 * len(results) / max(wall, 1e-9)
    summary = {
        "bags": len(results),
        "failed": len(failed),
        "rows": len(rows),
        "wall_seconds": wall,
        "bags_per_minute": rate,
        "bag_hours": sum(r.bag_seconds for r in results) / 3600.0,
        "table": args.table,
        "plots": plots,
        "vessels": vessel_summary(rows),
    }
    if args.json:
        print(dumps_json(summary))
    else:
        print_summary(summary)
    return 1 if failed else 0


def identify_bags(jobs: list[BagJob], workers: int = 1, dask: str | None = None) -> list[BagResult]:
    """Run ``identify_bag`` on every job (in order of ``jobs``), with progress on stderr."""
    if dask:
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError:
            raise FleetError(
                "--dask needs dask.distributed: pip install 'dask[distributed]' (or the ship_ident[bench] extra)"
            ) from None
        if dask == "local":
            with (
                LocalCluster(
                    n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
                ) as cluster,
                Client(cluster) as client,
            ):
                return _run(jobs, client.get_executor())
        with Client(dask) as client:
            return _run(jobs, client.get_executor())
    if workers == 1:
        return _run(jobs, None)
    with concurrent.futures.ProcessPoolExecutor(max_workers=workers) as pool:
        return _run(jobs, pool)


def _run(jobs: list[BagJob], executor) -> list[BagResult]:
    """Submit every job to ``executor`` (None: in this process), report each bag as it finishes."""
    start = time.perf_counter()
    results = {}

    def report(result: BagResult) -> None:
        results[id(result.job)] = result
        done = len(results)
        name = f"{result.job.vessel}/{Path(result.job.bag).name}"
        if result.error:
            status = f"FAILED: {result.error}"
        else:
            status = (
                f"{len(result.rows)} estimates from {result.refits} refits over "
                f"{result.bag_seconds:.0f} s ({result.bag_seconds / max(result.loop_seconds, 1e-9):.0f}x "
                "real time)"
            )
        elapsed = time.perf_counter() - start
        print(
            f"[{done}/{len(jobs)} bags, {60.0 * done / max(elapsed, 1e-9):.1f} bags/min] {name}: {status}",
            file=sys.stderr,
            flush=True,
        )

    if executor is None:
        for job in jobs:
            report(identify_bag(job))
    else:
        futures = {executor.submit(identify_bag, job): job for job in jobs}
        for future in concurrent.futures.as_completed(futures):
            result = future.result()
            result.job = futures[future]  # the caller's job object (a remote result holds a copy)
            report(result)
    return [results[id(job)] for job in jobs]


def write_table(path: str, rows: list[dict]) -> None:
    """CSV of the accepted estimates; columns are the union of the rows' keys, first-seen order."""
    columns = list(dict.fromkeys(key for row in rows for key in row))
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns or ["vessel", "bag", "time"])
        writer.writeheader()
        writer.writerows(rows)


def vessel_summary(rows: list[dict]) -> dict:
    """Per vessel: number of estimates and the median of K and T1 over them."""
    out = {}
    for vessel in dict.fromkeys(row["vessel"] for row in rows):
        mine = [row for row in rows if row["vessel"] == vessel]
        out[vessel] = {"estimates": len(mine), "bags": len({row["bag"] for row in mine})}
        for name in ("K", "T1", "T"):
            values = sorted(row[name] for row in mine if name in row)
            if values:
                out[vessel][f"median_{name}"] = values[len(values) // 2]
    return out


def plot_drift(rows: list[dict], plot_dir: str) -> list[str]:
    """A PNG per vessel: K and T1 (or T) with 1.96-std error bars against time. Returns the paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    Path(plot_dir).mkdir(parents=True, exist_ok=True)
    dated = all(row["time"] > UNIX_TIME_AFTER_2001 for row in rows)
    offsets, end = {}, 0.0  # undated bags: laid end to end in the order given
    for row in rows:
        if row["bag"] not in offsets:
            offsets[row["bag"]] = end
        end = max(end, offsets[row["bag"]] + row["time"])
    paths = []
    for vessel in dict.fromkeys(row["vessel"] for row in rows):
        mine = [row for row in rows if row["vessel"] == vessel]
        names = [n for n in ("K", "T1", "T") if n in mine[0]][:2]
        if dated:
            x = [datetime.fromtimestamp(row["time"], timezone.utc) for row in mine]
        else:
            x = [(offsets[row["bag"]] + row["time"]) / 3600.0 for row in mine]
        fig, axes = plt.subplots(len(names), 1, sharex=True, figsize=(8, 2.6 * len(names)), squeeze=False)
        for ax, name in zip(axes[:, 0], names):
            y = [row[name] for row in mine]
            err = [Z_95 * row.get(f"{name}_std", math.nan) for row in mine]
            ax.errorbar(x, y, yerr=err, fmt=".", ms=3, elinewidth=0.6, capsize=0)
            unit = "1/s" if name == "K" else "s"
            ax.set_ylabel(f"{name} ({unit})")
            ax.grid(alpha=0.3)
        axes[0, 0].set_title(
            f"{vessel}: {len(mine)} estimates from {len({r['bag'] for r in mine})} bags (error bars {Z_95:g} std)"
        )
        axes[-1, 0].set_xlabel("time (UTC)" if dated else "hours of bag time, bags end to end")
        fig.tight_layout()
        path = str(Path(plot_dir) / f"drift_{re.sub(r'[^A-Za-z0-9_.-]', '_', vessel)}.png")
        fig.savefig(path, dpi=100)
        plt.close(fig)
        paths.append(path)
    return paths


def print_summary(summary: dict) -> None:
    """Per-vessel medians and the throughput, for people."""
    print(
        f"{summary['bags']} bags ({summary['bag_hours']:.2f} h of data) in {summary['wall_seconds']:.1f} s: "
        f"{summary['bags_per_minute']:.1f} bags/min; {summary['rows']} accepted estimates"
        + (f"; {summary['failed']} bags failed (see above)" if summary["failed"] else "")
    )
    for vessel, s in summary["vessels"].items():
        medians = ", ".join(f"{k[7:]} {v:.4g}" for k, v in s.items() if k.startswith("median_"))
        print(f"  {vessel}: {s['estimates']} estimates from {s['bags']} bags; median {medians}")
    if summary["table"]:
        print(f"table: {summary['table']}")
    for path in summary["plots"]:
        print(f"drift plot: {path}")
