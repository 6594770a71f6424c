"""``training-size``: 3-DOF prediction quality against training-set size (seed 000, Table 3).

The DTC preset (``threedof.VESSELS["dtc"]``) runs a series of free-running
manoeuvres (zigzags and turning circles, each from a straight approach,
realistic sensor noise); a training set of N samples is the first N samples
of that series, as a test programme grows run by run. Each set is
identified (truncated LS-SVM, GCV truncation, and OLS for reference) and
the model runs free on a held-out 15/15 zigzag from its measured initial
state with its measured rudder. Per DOF (surge u, sway v, yaw rate r) the
table gives correlation R, normalised centred RMS difference E' and
normalised STD (model STD / measured STD), the Taylor-diagram measures.
``plateau_size`` is the smallest set from which the mean E' stays within
``PLATEAU_TOLERANCE`` of the best: beyond it, more data stops helping.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import threedof
from . import progress, register

SIZES = (1200, 1300, 1500, 1700, 2000, 2300, 2900, 4000, 5000, 6000, 7000, 8000, 9000, 10000)
QUICK_SIZES = (1200, 2900, 10000)
METHODS = ("tlssvm-gcv", "ols")
QUICK_METHODS = ("tlssvm-gcv",)
SAMPLE_TIME = 0.1  # s
# (manoeuvre, amplitude deg (< 0: to port first), duration s): 10,109 samples in all
TRAINING_PROGRAMME = (
    ("zigzag", 10, 100),
    ("zigzag", 20, 100),
    ("turning", 35, 120),
    ("zigzag", -15, 100),
    ("turning", -25, 120),
    ("zigzag", -25, 100),
    ("turning", 15, 120),
    ("zigzag", 30, 100),
    ("turning", -35, 150),
)
HELD_OUT = ("zigzag", 15, 100)
PLATEAU_TOLERANCE = 0.05


def training_records(size: int, records: list) -> list:
    """The first ``size`` samples of the programme, as whole runs plus the start of the last one."""
    out, left = [], size
    for record in records:
        if left <= 0:
            break
        out.append(record.head(min(left, len(record))))
        left -= len(out[-1])
    return out


def mean_e_centred(row: dict) -> float:
    """Mean E' over the DOFs; a diverged free run counts as infinite."""
    if any(row[d]["diverged"] for d in threedof.DOFS):
        return float("inf")
    return float(np.mean([row[d]["e_centred"] for d in threedof.DOFS]))


def plateau_size(rows: list) -> int:
    """Smallest size from which every larger set's mean E' is within the tolerance of the best."""
    scores = np.array([mean_e_centred(r) for r in rows])
    good = scores <= (1 + PLATEAU_TOLERANCE) * scores.min()
    last_bad = np.flatnonzero(~good)
    start = last_bad[-1] + 1 if len(last_bad) else 0
    return int(rows[min(start, len(rows) - 1)]["size"])


def run(quick: bool = False, progress=progress, figure: str | None = None, plot_dir: str | None = None) -> dict:
    """Identify on every training-set size, predict the held-out zigzag; optionally draw the Taylor
    diagram to ``figure`` or to ``plot_dir``/taylor_training_size.png."""
    if plot_dir is not None:
        Path(plot_dir).mkdir(parents=True, exist_ok=True)
        figure = str(Path(plot_dir) / "taylor_training_size.png")
    vessel = threedof.VESSELS["dtc"]
    records = [
        threedof.simulate_manoeuvre(vessel, m, a, duration=d, sample_time=SAMPLE_TIME, seed=i)[0]
        for i, (m, a, d) in enumerate(TRAINING_PROGRAMME)
    ]
    held_out, _ = threedof.simulate_manoeuvre(
        vessel, *HELD_OUT[:2], duration=HELD_OUT[2], sample_time=SAMPLE_TIME, seed=len(TRAINING_PROGRAMME)
    )
    result = {
        "vessel": vessel.name,
        "sample_time": SAMPLE_TIME,
        "held_out": list(HELD_OUT),
        "reference_std": {d: float(np.std(held_out.dof(d))) for d in threedof.DOFS},
        "methods": {},
    }
    for method in QUICK_METHODS if quick else METHODS:
        rows = []
        for size in QUICK_SIZES if quick else SIZES:
            progress(f"training-size: {method} on {size} samples")
            identification = threedof.identify(
                training_records(size, records), vessel.length, vessel.speed, method=method
            )
            metrics = threedof.prediction_metrics(held_out, threedof.predict(identification.coefficients, held_out))
            rows.append(
                {
                    "size": size,
                    **{
                        d: {k: metrics[d][k] for k in ("r", "e_centred", "std_ratio", "diverged")}
                        for d in threedof.DOFS
                    },
                    "truncation": {d: identification.info[d].get("truncation") for d in threedof.DOFS},
                }
            )
        result["methods"][method] = {"rows": rows, "plateau_size": plateau_size(rows)}
    if figure:
        taylor_diagram(result, METHODS[0], figure)
        result["figure"] = figure
    return result


def render(result: dict) -> str:
    """Seed 000 Table 3 layout: R, E', STD (normalised) per DOF for each training-set size."""
    ref = result["reference_std"]
    lines = [
        f"held-out {result['held_out'][0]} {result['held_out'][1]}/{result['held_out'][1]}; reference STD: "
        f"u {ref['surge']:.4f} m/s, v {ref['sway']:.4f} m/s, r {np.degrees(ref['yaw']):.3f} deg/s"
    ]
    for method, block in result["methods"].items():
        lines += [
            "",
            method,
            f"{'size':>6} | {'SURGE R':>8} {'E´':>6} {'STD':>6} | {'SWAY R':>8} {'E´':>6} {'STD':>6} | "
            f"{'YAW R':>8} {'E´':>6} {'STD':>6} | k (u,v,r)",
            f"{'REF.':>6} | " + " | ".join(f"{1:8.3f} {0:6.3f} {1:6.3f}" for _ in threedof.DOFS) + " |",
        ]
        for row in block["rows"]:
            cells = [
                f"{row[d]['r']:8.3f} {row[d]['e_centred']:6.3g} {row[d]['std_ratio']:6.3g}"
                f"{'*' if row[d]['diverged'] else ' '}"
                for d in threedof.DOFS
            ]
            k = ",".join("-" if row["truncation"][d] is None else str(row["truncation"][d]) for d in threedof.DOFS)
            lines.append(f"{row['size']:>6} | " + " |".join(cells) + f"| {k}")
        lines.append(
            f"adding data stops helping at {block['plateau_size']} samples (mean E' within "
            f"{PLATEAU_TOLERANCE:.0%} of the best from there on); * = free run diverged; "
            "k = singular values kept of p"
        )
    return "\n".join(lines)


def taylor_diagram(result: dict, method: str, path: str) -> None:
    """Polar Taylor diagram: angle arccos(R), radius normalised STD, reference at (0, 1); PNG at ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result["methods"][method]["rows"]
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="polar")
    ax.set_thetamin(0)
    ax.set_thetamax(90)
    radius_max = 1.6
    ax.set_rlim(0, radius_max)
    for e in (0.25, 0.5, 0.75, 1.0):  # E' contours: circles of radius e around the reference (1, 0)
        t = np.linspace(0, np.pi, 200)
        x, y = 1 + e * np.cos(t), e * np.sin(t)
        ok = x >= 0
        ax.plot(np.arctan2(y[ok], x[ok]), np.hypot(x[ok], y[ok]), color="0.75", lw=0.8, ls="--")
    correlations = np.array([0.2, 0.4, 0.6, 0.8, 0.9, 0.95, 0.99])
    ax.set_thetagrids(np.degrees(np.arccos(correlations)), [f"{c:g}" for c in correlations])
    ax.plot(0.0, 1.0, "k*", ms=14, label="reference (measured)")
    sizes = np.array([r["size"] for r in rows])
    norm = matplotlib.colors.LogNorm(sizes.min(), sizes.max())
    markers = {"surge": "o", "sway": "s", "yaw": "^"}
    for d in threedof.DOFS:
        kept = [r for r in rows if not r[d]["diverged"] and r[d]["r"] > 0 and r[d]["std_ratio"] < radius_max]
        ax.scatter(
            [np.arccos(min(r[d]["r"], 1.0)) for r in kept],
            [r[d]["std_ratio"] for r in kept],
            c=[r["size"] for r in kept],
            cmap="viridis",
            norm=norm,
            marker=markers[d],
            s=45,
            edgecolors="k",
            linewidths=0.4,
            label=d,
        )
    fig.colorbar(
        matplotlib.cm.ScalarMappable(norm=norm, cmap="viridis"), ax=ax, pad=0.1, label="training-set size (samples)"
    )
    ax.set_title(
        f"Held-out {result['held_out'][0]} {result['held_out'][1]}/{result['held_out'][1]}, "
        f"{method}\nangle = arccos R, radius = STD / STD_ref, dashed: E' = 0.25 ... 1\n"
        f"(points with R <= 0, STD > {radius_max} or a diverged free run are not drawn)",
        fontsize=9,
    )
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


register(
    "training-size",
    "3-DOF prediction quality vs training-set size (seed 000 Table 3, Taylor diagram)",
    run,
    render,
    plots=True,
)
