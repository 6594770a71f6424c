"""The tables and plots of ``bench peers``: each peer against ours, and where a peer is better."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .common import machine_line, table
from .peer_experiments import OURS, RECOVERY_TOLERANCE

TARGET_CRB_RATIO = 1.3
TARGET_CPU_SHARE = 0.10
TARGET_REPLAY_SPEED = 100.0


def plot(result: dict, plot_dir: str) -> list[str]:
    """peers_tracking.png (K against time per method, truth step) and peers_accuracy.png (bars)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    Path(plot_dir).mkdir(parents=True, exist_ok=True)
    scenarios = result["tracking"]
    fig, axes = plt.subplots(len(scenarios), 1, figsize=(9, 4.2 * len(scenarios)), squeeze=False)
    for ax, track in zip(axes[:, 0], scenarios.values()):
        change = track["change_time_s"]
        ax.step(
            [0, change, track["duration_s"]],
            [track["K_before"], track["K_after"], track["K_after"]],
            where="post",
            color="k",
            lw=2,
            label="truth",
        )
        ax.fill_between(
            [change, track["duration_s"]],
            track["K_after"] * (1 - RECOVERY_TOLERANCE),
            track["K_after"] * (1 + RECOVERY_TOLERANCE),
            color="0.85",
            label="new truth +-5 %",
        )
        for name, m in track["methods"].items():
            ax.plot(
                m["times"],
                m["K"],
                lw=2.2 if name.startswith("ship_ident") else 1.0,
                label=f"{name}: {_seconds(m['recovery_s'])}",
            )
        ax.set_ylim(0.5 * track["K_after"], 1.4 * track["K_before"])
        ax.set_xlabel("time (s)")
        ax.set_ylabel("K (1/s)")
        ax.set_title(
            f"{track['maneuver']} manoeuvre: K -30 %, T1 +30 % at {change:.0f} s; ours: window "
            f"{track['window_s']:.0f} s, refit every {track['refit_period_s']:.0f} s "
            "(legend: recovery time)",
            fontsize=9,
        )
        ax.legend(fontsize=7, loc="upper right")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    paths = [str(Path(plot_dir) / "peers_tracking.png")]
    fig.savefig(paths[0], dpi=100)
    plt.close(fig)

    methods = {n: m for n, m in result["accuracy"]["methods"].items()}
    names = list(methods)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    ax1.barh(names, [methods[n]["rmse_heading_deg"] for n in names], color="tab:blue")
    ax1.set_xscale("log")
    ax1.set_xlabel("held-out free-run heading RMSE (deg, log scale)")
    ax1.invert_yaxis()
    shown = [n for n in names if methods[n]["quantities"] and n != "truth"]
    quantities = ("K", "T1", "delta_r", "T1+T2-T3")
    width = 0.8 / len(shown)
    for i, name in enumerate(shown):
        values = [methods[name]["quantities"][q]["rms_percent"] for q in quantities]
        ax2.bar(np.arange(len(quantities)) + i * width, values, width, label=name)
    ax2.set_xticks(np.arange(len(quantities)) + 0.4 - width / 2, quantities)
    ax2.set_yscale("log")
    ax2.set_ylabel("RMS error over seeds (%)")
    ax2.legend(fontsize=7)
    fig.tight_layout()
    paths.append(str(Path(plot_dir) / "peers_accuracy.png"))
    fig.savefig(paths[1], dpi=100)
    plt.close(fig)
    return paths


def _seconds(value: float) -> str:
    return f"{round(value, 1):g} s" if np.isfinite(value) else "never"


def _best(values: dict) -> str:
    """The key of the smallest finite value."""
    finite = {k: v for k, v in values.items() if np.isfinite(v)}
    return min(finite, key=finite.get)


OURS_LABEL = f"ship_ident {OURS[0]}"
ACCURACY_COLUMNS = ("K", "T1", "T2", "T3", "delta_r", "alpha", "T1+T2-T3")
CRB_COLUMNS = ("K", "T1", "delta_r", "T1+T2-T3")


def _better_than_ours(figures: dict, ours: dict) -> str:
    """The names of the figures (smaller is better) where a peer beats ours."""
    return ", ".join(k for k, v in figures.items() if v < ours[k]) or "-"


def _render_accuracy(acc: dict) -> list[str]:
    d, methods = acc["data"], acc["methods"]

    def figures(v):
        out = {"heading RMSE": v["rmse_heading_deg"]}
        out.update({q: v["quantities"][q]["rms_percent"] for q in ACCURACY_COLUMNS} if v["quantities"] else {})
        return out

    ours = figures(methods[OURS_LABEL])
    best = _best({n: v["rmse_heading_deg"] for n, v in methods.items() if n != "truth"})
    rows = []
    for name, v in methods.items():
        q = v["quantities"]
        peer = name not in ("truth", OURS_LABEL)
        rows.append(
            [name + (" (best)" if name == best else ""), v["rmse_heading_deg"], v["rmse_yaw_rate_deg_s"]]
            + [q[p]["rms_percent"] if q else "-" for p in ACCURACY_COLUMNS]
            + [v["fit_seconds"]]
            + [_better_than_ours(figures(v), ours) if peer else ""]
        )
    noise = d["noise"]
    title = (
        f"accuracy: seed001 vessel + {', '.join(d['effects'])}, {d['train']} {d['train_duration_s']:.0f} s "
        f"training, {d['held_out']} {d['held_out_duration_s']:.0f} s held out, {d['seeds']} noise seeds, noise "
        f"std rudder {noise['rudder_deg']:.2g} deg, heading {noise['heading_deg']:.2g} deg, yaw rate "
        f"{noise['yaw_rate_deg_s']:.2g} deg/s; parameter columns: RMS error over seeds; RMSE: mean over "
        "seeds, free run from the measured initial state"
    )
    out = [
        table(
            ["method", "held-out heading RMSE deg", "yaw rate RMSE deg/s"]
            + [f"{p} %" for p in ACCURACY_COLUMNS]
            + ["fit s", f"better than {OURS_LABEL} on"],
            rows,
            title,
        )
    ]
    rows = []
    for name, v in methods.items():
        if v["quantities"] and name != "truth":
            ratios = {p: v["quantities"][p]["rms_over_crb"] for p in CRB_COLUMNS}
            beyond = [p for p in ("K", "T1", "delta_r") if ratios[p] > TARGET_CRB_RATIO]
            rows.append([name] + list(ratios.values()) + [", ".join(beyond) or "all within"])
    crb = methods["truth"]["quantities"]
    title = (
        "ratio to the Cramer-Rao bound (CRB % of truth: "
        + ", ".join(f"{p} {crb[p]['crb_percent']:.3g}" for p in CRB_COLUMNS)
        + ")"
    )
    out.append(
        table(["method"] + [f"{p} RMS/CRB" for p in CRB_COLUMNS] + [f"beyond {TARGET_CRB_RATIO}x CRB"], rows, title)
    )
    return out


def _render_tracking(track: dict) -> str:
    ours = track["methods"][OURS_LABEL]
    ours = {"recovery": ours["recovery_s"], "error before": ours["error_before_percent"]}
    rows = [
        [
            name,
            _seconds(v["recovery_s"]),
            v["error_before_percent"],
            _better_than_ours({"recovery": v["recovery_s"], "error before": v["error_before_percent"]}, ours)
            if not name.startswith("ship_ident")
            else "",
        ]
        for name, v in track["methods"].items()
    ]
    title = (
        f"tracking, {track['maneuver']} manoeuvre: K {track['K_before']:.4g} -> {track['K_after']:.4g} 1/s, "
        f"T1 {track['T1_before']:.4g} -> {track['T1_after']:.4g} s at {track['change_time_s']:.0f} s of "
        f"{track['duration_s']:.0f} s; target for ours: < window + refit period = "
        f"{track['window_s'] + track['refit_period_s']:.0f} s; error before: the last 120 s"
    )
    return table(
        ["method", "K back within 5 %", "K RMS error before change %", f"better than {OURS_LABEL} on"], rows, title
    )


def _render_speed(speed: dict) -> list[str]:
    ours = speed["cost"][OURS_LABEL]["cpu_share"]
    rows = [
        [
            name,
            1e3 * v["seconds"],
            v["per"],
            100 * v["cpu_share"],
            ("yes" if v["cpu_share"] < ours else "-") if not name.startswith("ship_ident") else "",
        ]
        for name, v in speed["cost"].items()
    ]
    out = [
        table(
            ["method", "ms", "per", "CPU % of one core at 10 Hz", f"cheaper than {OURS_LABEL}"],
            rows,
            f"speed: window {speed['window_samples']} samples, refit every {speed['refit_period_s']:.0f} s, "
            f"inputs at {speed['input_rate_hz']:.0f} Hz (target for ours: < {100 * TARGET_CPU_SHARE:.0f} %)",
        )
    ]
    sizes = list(next(iter(speed["refit_seconds"].values())))
    steps = list(zip(sizes, sizes[1:]))
    rows = [
        [method] + [1e3 * t[n] for n in sizes] + [1e3 * (t[b] - t[a]) / ((int(b) - int(a)) / 1000) for a, b in steps]
        for method, t in speed["refit_seconds"].items()
    ]
    out.append(
        table(
            ["method"] + [f"{n} samples ms" for n in sizes] + [f"ms per extra 1k, {a}->{b}" for a, b in steps],
            rows,
            "scaling: one cold refit (Estimator.fit) against window length; linear growth = the same "
            "ms per extra 1k samples at every step (the 1k figure also holds the fixed cost)",
        )
    )
    r = speed["replay"]
    out.append(
        f"replay of a {r['bag_seconds'] / 60:.0f} min simulated bag (node defaults): "
        f"{r['speed_loop']:.0f}x real time for the loop ({r['loop_seconds']:.1f} s), "
        f"{r['speed_total']:.0f}x with reading the bag ({r['read_seconds']:.1f} s); "
        f"{r['estimates']} accepted estimates from {r['refits']} refits "
        f"(target >= {TARGET_REPLAY_SPEED:.0f}x)"
    )
    return out


def render(result: dict) -> str:
    m, online = result["machine"], result["online_config"]
    out = [
        f"peers: {machine_line(m)}, OPENBLAS_NUM_THREADS={m['OPENBLAS_NUM_THREADS']}; "
        f"ours online: {online['method']}, window {online['window_s']:.0f} s, "
        f"refit every {online['refit_period_s']:.0f} s"
    ]
    out += _render_accuracy(result["accuracy"])
    out += [_render_tracking(track) for track in result["tracking"].values()]
    out += _render_speed(result["speed"])
    return "\n\n".join(out)
