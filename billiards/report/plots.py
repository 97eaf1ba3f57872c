"""Pictures of training runs (matplotlib, drawn off-screen): learning curves per run, and
per table its rows' means over seeds with their spread and the paper's figure beside them."""

from __future__ import annotations

from pathlib import Path

from .markdown import label as row_label
from .runs import Curve, group_curves, mean_curve

def plot_curves(curves: list[Curve], path: Path) -> Path:
    """Evaluation mean against env steps and against CPU minutes, one colour per variant,
    one line per seed."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4.2), dpi=110)
    axes = fig.subplots(1, 2, sharey=True)
    for i, ((table, variant), group) in enumerate(group_curves(curves).items()):
        colour = f"C{i % 10}"
        for j, c in enumerate(sorted(group, key=lambda c: c.config.get("seed"))):
            steps = [p["step"] for p in c.points]
            cpu = [p["cpu_time"] / 60 for p in c.points]
            means = [p["eval_mean"] for p in c.points]
            label = f"{table + ': ' if table else ''}{row_label(table, variant)}" if j == 0 else None
            axes[0].plot(steps, means, "-o", ms=3, color=colour, alpha=0.8, label=label)
            axes[1].plot(cpu, means, "-o", ms=3, color=colour, alpha=0.8)
    axes[0].set_xlabel("env steps (shots)")
    axes[1].set_xlabel("CPU minutes (training process)")
    axes[0].set_ylabel("points per inning (eval)")
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def plot_seed_bands(series: list[tuple[str, list[Curve], dict | None]], path: Path, title: str) -> Path:
    """One line per ``(label, runs, paper)``: the mean over its runs (seeds) of the evaluation
    mean against env steps, shaded ± the std over seeds, each seed faint behind it; ``paper``
    (``{"mean", "std"}`` or None) is drawn as a hollow marker with its error bar just right of
    the series' last step, in the series' colour."""
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.ticker import FuncFormatter

    fig = Figure(figsize=(7.5, 4.4), dpi=110)
    ax = fig.subplots()
    last = max((p["step"] for _, runs, _ in series for c in runs for p in c.points), default=1)
    any_paper = False
    for i, (label, runs, paper) in enumerate(series):
        colour = f"C{i % 10}"
        for c in runs:
            ax.plot([p["step"] for p in c.points], [p["eval_mean"] for p in c.points], "-", lw=0.7,
                    color=colour, alpha=0.25)
        steps, mean, std = mean_curve(runs)
        if len(steps):
            n = f"{len(runs)} seed" + ("s" if len(runs) > 1 else "")
            ax.plot(steps, mean, "-o", ms=3, lw=1.8, color=colour, label=f"{label} ({n})")
            ax.fill_between(steps, mean - std, mean + std, color=colour, alpha=0.15, lw=0)
        if paper and paper.get("mean") is not None:
            any_paper = True
            x = (steps[-1] if len(steps) else last) * (1.02 + 0.012 * i)
            ax.errorbar([x], [paper["mean"]], yerr=[[paper.get("std") or 0.0]] * 2, fmt="o", mfc="none",
                        ms=6, color=colour, capsize=3, lw=1.2)
    handles, labels = ax.get_legend_handles_labels()
    if any_paper:
        handles.append(Line2D([], [], marker="o", mfc="none", color="0.3", ls="none"))
        labels.append("paper (mean ± std at its budget)")
    ax.legend(handles, labels, fontsize=8, loc="best")
    ax.set_xlabel("env steps (shots)")
    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1e6:g}M" if x >= 1e6 else f"{x / 1e3:g}k"))
    ax.set_ylabel("points per inning (eval, random racks)")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path
