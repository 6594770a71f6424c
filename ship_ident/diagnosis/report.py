"""HTML report of a diagnosis: index.html with matplotlib PNGs (angles in degrees)."""

from __future__ import annotations

import html
from dataclasses import replace
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..estimators.base import Z_95  # noqa: E402
from .diagnose import Diagnosis, covered, signal_table  # noqa: E402

DEG = np.degrees(1.0)
DPI = 80


def _save(fig, directory: Path, name: str) -> str:
    fig.tight_layout()
    fig.savefig(directory / name, dpi=DPI)
    plt.close(fig)
    return name


def _segments_plot(ax, dataset, values, label, **style):
    """One line per segment (no line drawn across the gaps between a split's windows)."""
    for k, (a, b) in enumerate(dataset.segments):
        ax.plot(dataset.time[a:b], values[a:b], label=label if k == 0 else None, **style)


def plot_measured_vs_model(d: Diagnosis, directory: Path) -> str:
    """Measured and free-run heading and yaw rate, held-out windows and worst segments shaded;
    held-out recordings (cross-manoeuvre) are drawn after the fitted one, 60 s apart."""
    fig, axes = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True)
    train_psi, train_r = d.structure.simulate(d.estimate.parameters, d.training)
    shift = d.dataset.time[-1] + 60.0 - d.held_out.time[0] if d.cross_manoeuvre else 0.0
    held_out = replace(d.held_out, time=d.held_out.time + shift)
    for ax, scale, label, measured, train, held in (
        (axes[0], DEG, "heading (deg)", "heading", train_psi, d.run.heading),
        (axes[1], DEG, "yaw rate (deg/s)", "yaw_rate", train_r, d.run.yaw_rate),
    ):
        for k, (a, b) in enumerate(held_out.segments):
            ax.axvspan(
                held_out.time[a],
                held_out.time[b - 1],
                color="tab:blue",
                alpha=0.08,
                lw=0,
                label="held-out window" if k == 0 else None,
            )
        for k, seg in enumerate(d.worst_segments):
            moved = shift if seg.get("held_out") else 0.0
            ax.axvspan(
                seg["start"] + moved,
                seg["end"] + moved,
                ymin=0.0,
                ymax=0.04,
                color="tab:orange",
                alpha=0.9,
                lw=0,
                label=f"worst {len(d.worst_segments)} segments" if k == 0 else None,
            )
        ax.plot(d.dataset.time, getattr(d.dataset, measured) * scale, color="black", lw=0.8, label="measured")
        if d.cross_manoeuvre:
            _segments_plot(ax, held_out, getattr(held_out, measured) * scale, None, color="black", lw=0.8)
        _segments_plot(ax, d.training, train * scale, "model, fitting part (in-sample)", color="tab:gray", lw=0.9)
        _segments_plot(ax, held_out, held * scale, "model, held-out free run", color="tab:blue", lw=1.2)
        if d.before_run is not None:
            _segments_plot(
                ax,
                held_out,
                getattr(d.before_run, measured) * scale,
                f"before: {d.before.structure.label()}",
                color="tab:red",
                lw=0.8,
                ls="--",
            )
        ax.set_ylabel(label)
    axes[0].legend(fontsize=7, loc="best", ncol=2)
    axes[0].set_title(
        f"{d.structure.label()}: free runs, each window from the measured state (orange ticks: worst segments)",
        fontsize=9,
    )
    axes[1].set_xlabel(
        "time (s)" + (f"; held-out recordings from {shift + d.held_out.time[0]:.0f} s" if d.cross_manoeuvre else "")
    )
    return _save(fig, directory, "measured_vs_model.png")


def plot_residual_features(d: Diagnosis, directory: Path) -> str:
    """Equation residual against the feature each candidate effect tests, binned means."""
    items = [(name, ev) for name, ev in d.evidences.items() if ev.feature is not None]
    cols = 3
    rows = max(1, int(np.ceil(len(items) / cols)))
    fig, axes = plt.subplots(rows, cols, figsize=(10, 2.8 * rows), squeeze=False)
    for ax in axes.ravel()[len(items) :]:
        ax.axis("off")
    for ax, (name, ev) in zip(axes.ravel(), items):
        residual = (ev.residual if ev.residual is not None else d.context.equation_residual) * DEG
        x = np.asarray(ev.feature) * ev.feature_scale
        ax.plot(x, residual, ".", ms=1, alpha=0.15, color="tab:gray")
        edges = np.unique(np.quantile(x, np.linspace(0, 1, 16)))
        if len(edges) > 2:
            which = np.clip(np.digitize(x, edges) - 1, 0, len(edges) - 2)
            centres = [x[which == k].mean() for k in range(len(edges) - 1) if np.any(which == k)]
            means = [residual[which == k].mean() for k in range(len(edges) - 1) if np.any(which == k)]
            ax.plot(centres, means, "o-", color="tab:red", ms=3)
        ax.axhline(0, color="black", lw=0.5)
        ax.set_xlabel(ev.feature_label, fontsize=8)
        ax.set_ylabel("residual (deg/s)", fontsize=8)
        ax.set_title(f"{name} (score {ev.score:.1f})", fontsize=9)
        lim = np.nanpercentile(np.abs(residual), 99) * 1.2 or 1.0
        ax.set_ylim(-lim, lim)
    return _save(fig, directory, "residual_features.png")


def plot_correlations(d: Diagnosis, directory: Path) -> str:
    """Autocorrelation of the yaw-rate residual and its cross-correlation with the rudder, 95 % bounds."""
    t = d.residual_tests
    lags = np.array(t["lags"]) * t["lag_step"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3))
    for ax, values, title in (
        (axes[0], t["autocorrelation"], "autocorrelation of the yaw-rate residual"),
        (axes[1], t["cross_correlation_rudder"], "cross-correlation rudder -> residual"),
    ):
        ax.vlines(lags, 0, values, color="tab:blue", lw=1)
        ax.axhspan(-t["bound"], t["bound"], color="tab:green", alpha=0.2, label="95 % bounds")
        ax.axhline(0, color="black", lw=0.5)
        ax.set_xlabel("lag (s)")
        ax.set_ylabel("normalised correlation (-)", fontsize=8)
        ax.set_title(title, fontsize=9)
    if not np.any(t["cross_correlation_rudder"]):
        axes[1].text(
            0.5,
            0.5,
            "rudder constant in the held-out windows:\nno cross-correlation to show",
            transform=axes[1].transAxes,
            ha="center",
            fontsize=8,
        )
    axes[0].legend(fontsize=7)
    return _save(fig, directory, "correlations.png")


def plot_taylor(d: Diagnosis, directory: Path) -> str:
    """Taylor diagram (seed 000): normalised STD as radius, correlation R as angle, for every model."""
    models = [(d.structure.label(), d.run)] + ([(d.before.structure.label(), d.before_run)] if d.before else [])
    models += [(f"+{c.effect}", c) for c in d.candidates if c.fit is not None]
    fig, axes = plt.subplots(1, 2, subplot_kw={"projection": "polar"}, figsize=(10, 4.5))
    for ax, signal in zip(axes, ("heading", "yaw_rate")):
        ax.set_thetamin(0)
        ax.set_thetamax(90)
        ax.plot([0], [1], "k*", ms=12, label="measured")
        radius = [1.5]
        for k, (label, run) in enumerate(models):
            fit = run.fit
            r, s = np.clip(fit[f"r_{signal}"], -1, 1), fit[f"std_ratio_{signal}"]
            if not np.isfinite(s):
                continue
            radius.append(s)
            ax.plot([np.arccos(max(r, 0.0))], [s], "o", color=f"C{k % 10}", label=label)
        ax.set_rmax(min(max(radius) * 1.1, 3.0))
        grid = np.linspace(0, np.pi / 2, 100)
        for e in (0.25, 0.5, 1.0):
            x = 1 + e * np.cos(np.linspace(0, np.pi, 100))
            y = e * np.sin(np.linspace(0, np.pi, 100))
            ax.plot(np.arctan2(y, x), np.hypot(x, y), color="tab:gray", lw=0.5, ls=":")
        ax.plot(grid, np.ones_like(grid), color="black", lw=0.5)
        ticks = np.array([0.0, 0.2, 0.4, 0.6, 0.8, 0.9, 0.95, 0.99])
        ax.set_thetagrids(np.degrees(np.arccos(ticks)), [f"{t:g}" for t in ticks], fontsize=7)
        ax.text(
            np.radians(52), ax.get_rmax() * 1.12, "correlation R", fontsize=8, rotation=-38, ha="center", va="center"
        )
        ax.set_xlabel("STD ratio (model / measured)", fontsize=8, labelpad=14)
        ax.set_title(f"{signal.replace('_', ' ')} (held-out free runs); dotted arcs: E' = 0.25, 0.5, 1", fontsize=8)
    axes[1].legend(fontsize=6, loc="upper right", bbox_to_anchor=(1.35, 1.0))
    return _save(fig, directory, "taylor.png")


def plot_before_after(d: Diagnosis, directory: Path) -> str:
    """Held-out free-run RMSE of the model, its predecessor and every candidate refit."""
    rows = [(d.structure.label(), d.run.fit)]
    if d.before is not None:
        rows.insert(0, (f"before: {d.before.structure.label()}", d.before_run.fit))
    rows += [(f"+{c.effect}" + (" *" if c.significant else ""), c.fit) for c in d.candidates if c.fit]
    fig, axes = plt.subplots(1, 2, figsize=(10, 0.4 * len(rows) + 1.5))
    y = np.arange(len(rows))
    for ax, key, unit in ((axes[0], "rmse_heading", "deg"), (axes[1], "rmse_yaw_rate", "deg/s")):
        values = [fit[key] * DEG for _, fit in rows]
        ax.barh(
            y, values, color=["tab:gray"] * (2 if d.before else 1) + ["tab:blue"] * (len(rows) - (2 if d.before else 1))
        )
        ax.set_yticks(y, [label for label, _ in rows], fontsize=8)
        ax.invert_yaxis()
        ax.set_xlabel(f"held-out free-run RMSE ({unit})")
        if key == "rmse_yaw_rate":
            ax.axvline(d.noise["yaw_rate"] * DEG, color="tab:red", ls="--", label="noise floor")
            ax.legend(fontsize=7)
    axes[0].set_title("before / after (* significant)", fontsize=9)
    return _save(fig, directory, "before_after.png")


def plot_parameters(d: Diagnosis, directory: Path) -> str:
    """Every free parameter with its 95 % interval and physical bounds (display units)."""
    names = d.structure.free_names
    fig, axes = plt.subplots(len(names), 1, figsize=(8, 0.7 * len(names) + 0.6), squeeze=False)
    for ax, name in zip(axes[:, 0], names):
        p = d.structure.parameter(name)
        scale = p.display_scale if p.display_unit else 1.0
        value, std = d.estimate.parameters[name] * scale, d.estimate.std_errors.get(name, np.nan) * scale
        half = Z_95 * std if np.isfinite(std) else 0.0
        ax.errorbar([value], [0], xerr=[[half], [half]], fmt="o", color="tab:blue", capsize=4)
        for bound in (p.lower, p.upper):
            if np.isfinite(bound) and abs(bound * scale - value) <= 3 * max(half, abs(value), 1e-9):
                ax.axvline(bound * scale, color="tab:red", ls="--")
        ax.set_yticks([])
        ax.set_ylabel(f"{name}\n({p.display_unit or p.unit})", rotation=0, ha="right", va="center", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0, 0].set_title("parameters with 95 % intervals (red dashed: physical bound)", fontsize=9)
    return _save(fig, directory, "parameters.png")


def _table(headers: list[str], rows: list[list]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in headers)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def write_report(d: Diagnosis, directory, source: str = "") -> Path:
    """Write the diagnosis as an HTML report: ``directory/index.html`` and its PNG figures.

    Parameters
    ----------
    d : Diagnosis
        The diagnosis.
    directory : str or Path
        Where to write (created if missing).
    source : str
        What was diagnosed (file names), shown in the report.

    Returns
    -------
    Path
        The HTML file's path.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    images = [
        (plot_measured_vs_model(d, directory), "Measured vs model (free run)"),
        (plot_before_after(d, directory), "Before / after: held-out free-run error"),
        (plot_residual_features(d, directory), "Residual against each candidate effect's feature"),
        (plot_correlations(d, directory), "Residual tests"),
        (plot_taylor(d, directory), "Taylor diagram"),
        (plot_parameters(d, directory), "Parameters"),
    ]
    measures = _table(
        ["model", "signal", "RMSE", "R", "E'", "STD ratio", "fit %"],
        [
            [
                row["model"],
                row["signal"],
                f"{row['rmse'] * DEG:.3g} {'deg' if row['signal'] == 'heading' else 'deg/s'}",
                f"{row['r']:.3f}",
                f"{row['e_centred']:.3f}",
                f"{row['std_ratio']:.3f}",
                f"{row['fit_percent']:.1f}",
            ]
            for row in signal_table(d)
        ],
    )
    candidates = _table(
        ["effect", "improvement", "heading", "yaw rate", "t", "significant", "evidence"],
        [
            [
                c.effect,
                f"{100 * c.improvement:.1f} %",
                f"{c.rmse_heading_after * DEG:.3g} deg",
                f"{c.rmse_yaw_rate_after * DEG:.3g} deg/s",
                f"{c.t_statistic:.1f}",
                "yes" if c.significant else "no",
                c.evidence.sentence
                + (f" ({c.note})" if c.note else "")
                + (f"; much worse held out: {c.extrapolation}" if c.extrapolation else ""),
            ]
            for c in d.candidates
        ],
    )
    worst = _table(
        [
            "recording",
            "time (s)",
            "heading RMSE (deg)",
            "yaw-rate RMSE (deg/s)",
            "turning",
            "|r| (deg/s)",
            "heading",
            "rudder std (deg)",
            "speed (m/s)",
        ],
        [
            [
                s.get("recording", "")
                + (" (held out)" if s.get("held_out") and "held out" not in s.get("recording", "") else ""),
                f"{s['start']:.0f}-{s['end']:.0f}",
                f"{s['rmse_heading'] * DEG:.3g}"
                + (f" (was {s['rmse_heading_before'] * DEG:.3g})" if "rmse_heading_before" in s else ""),
                f"{s['rmse_yaw_rate'] * DEG:.3g}"
                + (f" (was {s['rmse_yaw_rate_before'] * DEG:.3g})" if "rmse_yaw_rate_before" in s else ""),
                s["conditions"]["turning"],
                f"{s['conditions']['mean_abs_yaw_rate_deg_s']:.2f}",
                f"{s['conditions']['heading_deg']:.0f} ({s['conditions']['heading_sector']})",
                f"{s['conditions']['rudder_std_deg']:.1f}",
                f"{s['conditions']['speed']:.2f}" if "speed" in s["conditions"] else "-",
            ]
            for s in d.worst_segments
        ],
    )
    warnings = "".join(f"<li>{html.escape(w['message'])}</li>" for w in d.parameter_warnings) or "<li>none</li>"
    figures = "".join(
        f'<h2>{html.escape(title)}</h2><img src="{name}" alt="{html.escape(title)}">' for name, title in images
    )
    page = f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>ship_ident diagnosis: {html.escape(d.structure.label())}</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:auto}} table{{border-collapse:collapse;font-size:13px}}
td,th{{border:1px solid #ccc;padding:2px 6px}} img{{max-width:100%}}</style></head><body>
<h1>Diagnosis of {html.escape(d.structure.label())}</h1>
<p>Data: {html.escape(source)}. Fitted on {covered(d.training):.0f} s, run free on {covered(d.held_out):.0f} s
held out ({len(d.held_out.segments)} free runs, each from the measured heading and yaw rate).
All figures are free-run figures. Yaw-rate noise floor {d.noise["yaw_rate"] * DEG:.3g} deg/s.</p>
<p><b>Verdict: {d.verdict}</b>: {html.escape(d.verdict_sentence)}</p>
<h2>Held-out free-run measures</h2>{measures}
<h2>Candidate effects (best first)</h2>{candidates}
<h2>Worst segments</h2>{worst}
<h2>Parameter warnings</h2><ul>{warnings}</ul>
{figures}
</body></html>
"""
    path = directory / "index.html"
    path.write_text(page)
    return path
