"""Training runs as Markdown: the paper's tables with its figures beside ours, and learning
curves. Tables are laid out by ``tabulate`` (GitHub's pipe format); the paper's titles, columns,
row labels and figures come from :mod:`billiards.tables`."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np
from tabulate import tabulate

from billiards.tables import Table, paper_tables

from .runs import Curve, Run, aggregate, base_variant, find_runs, group_curves, split_rows

COLUMN_TITLES = {
    "mean": "mean ± std",
    "max": "max",
    "foul_inn": "foul/inn (%)",
    "foul_sh": "foul/sh (%)",
    "succ_sh": "succ/sh (%)",
    "canonical": "canonical mean",
    # the paper's "rand. eval" (Table 3): random-start innings that end at the first miss, read as
    # the points before the first miss of the random-start evaluation (billiards/evaluation.py)
    "rand_eval": "rand. eval",
}
GENERIC_COLUMNS = ["mean", "max", "foul_inn", "foul_sh", "succ_sh"]
DASH = "–"


def md_table(header: list[str], rows: list[list]) -> str:
    """A GitHub Markdown table; every cell is shown as given (no number re-formatting)."""
    return tabulate(rows, headers=header, tablefmt="github", disable_numparse=True)


def figure(col: str, row: dict | None) -> str:
    """One figure of a row (ours or the paper's) as the tables print it; mean with its std."""
    if row is None or row.get(col) is None:
        return DASH
    if col == "mean":
        return f"{row['mean']:.3f} ± {row['std']:.3f}" if row.get("std") is not None else f"{row['mean']:.3f}"
    if col == "max":
        return f"{row['max']:.0f}"
    if col == "canonical":
        return f"{row['canonical']:.2f}"
    if col == "rand_eval":
        return f"{row['rand_eval']:.3f}"
    return f"{row[col]:.1f}"


def steps_label(frames: list[int]) -> str:
    """Steps of a row's runs, 3 significant digits: "100k", "100k/200k", or "1.23M–1.29M" for
    more than two different counts (runs stopped by a CPU budget)."""
    def k(n: int) -> str:
        return f"{n / 1e6:.3g}M" if n >= 1_000_000 else f"{n / 1e3:.3g}k" if n >= 1000 else str(n)

    labels = list(dict.fromkeys(k(f) for f in frames))
    return f"{labels[0]}–{labels[-1]}" if len(labels) > 2 else "/".join(labels)


def label(table: str | None, variant: str) -> str:
    """A row's label in its paper table (a suffix that tells apart settings kept)."""
    spec = paper_tables().get(table or "")
    base = base_variant(variant)
    if spec is None or base not in spec.rows:
        return variant
    return spec.rows[base].label + variant[len(base):]


def row_summary(table: str | None, variant: str, runs: list[Run]) -> dict:
    """What a report row shows: its label, :func:`~.runs.aggregate` of its runs, the tables they
    played (``physics``) and the paper's figures for it (None outside a paper table)."""
    spec = paper_tables().get(table or "")
    paper = spec.rows.get(base_variant(variant)) if spec is not None else None
    return {"label": label(table, variant), **aggregate(runs), "physics": sorted({r.physics for r in runs}),
            "paper": paper.figures if paper is not None else None}


def render_table(table: str | None, groups: dict[str, list[Run]]) -> str:
    spec: Table | None = paper_tables().get(table or "")
    if spec is not None and spec.app == "train":
        columns = list(spec.columns)
        rank = {v: i for i, v in enumerate(spec.rows)}
        order = sorted(groups, key=lambda v: (rank.get(base_variant(v), len(rank)), v))
        title, header = spec.title, ["variant", "seeds", "steps", "wall min", "CPU min"]
        for c in columns:
            header += [f"{COLUMN_TITLES[c]} (ours)", "(paper)"]
    else:
        spec, columns, order = None, GENERIC_COLUMNS, sorted(groups)
        title = table or "Runs without a paper table"
        header = ["variant", "seeds", "steps", "wall min", "CPU min"] + [COLUMN_TITLES[c] for c in columns]
    rows = []
    for variant in order:
        row = row_summary(table, variant, groups[variant])
        minutes = [f"{row[k]:.1f}" if row[k] is not None else DASH for k in ("minutes", "cpu_minutes")]
        cells = [row["label"], str(row["n"]), steps_label(row["frames"]), *minutes]
        for c in columns:
            cells += [figure(c, row), figure(c, row["paper"])] if spec is not None else [figure(c, row)]
        rows.append(cells + [", ".join(row["physics"])])
    lines = [f"### {title}", "", md_table(header + ["physics"], rows)]
    present = {base_variant(v) for v in groups}
    if spec is not None and (missing := [r.label for name, r in spec.rows.items() if name not in present]):
        lines += ["", f"No runs yet for: {', '.join(missing)}."]
    return "\n".join(lines) + "\n"


def share_rows(by_table: dict) -> None:
    """Rows that are another table's runs (``same_as`` in :mod:`billiards.tables`: Table 3's plain
    and aim rows are Table 4's, ...) show those runs, where the table has runs of its own."""
    for name, spec in paper_tables().items():
        for row_name, row in spec.rows.items():
            source_table, _, source_row = (row.same_as or "").partition("/")
            if name in by_table and row_name not in by_table[name] and source_row in by_table.get(source_table, {}):
                by_table[name][row_name] = by_table[source_table][source_row]


def table_groups(runs: list[Run]) -> dict[str | None, dict[str, list[Run]]]:
    """The report's rows: per table (None: runs of no table), per row the runs it aggregates; a
    row whose runs differ in a setting is split into one per configuration and per repeat of a
    seed (``"<row> (algo.lr=0.001)"``, ``"<row> (repeat 2)"``)."""
    by_table: dict[str | None, dict[str, list[Run]]] = defaultdict(lambda: defaultdict(list))
    for run in runs:
        by_table[run.table][run.variant()].append(run)
    share_rows(by_table)
    return {table: {variant + suffix: part for variant, group in groups.items()
                    for suffix, part in split_rows(group, lambda r: r.config).items()}
            for table, groups in by_table.items()}


def report(dirs: list[Path]) -> str:
    from billiards.search.report import find_results, table6_markdown

    runs, unfinished, broken = find_runs(dirs)
    searches = find_results(dirs)
    if not runs and not searches:
        raise SystemExit(
            f"Error: no finished training runs (config.yaml + eval.json) or search results under {', '.join(map(str, dirs))}"
        )
    if not runs:
        return "## Search results\n\n" + table6_markdown(searches)
    by_table = table_groups(runs)
    parts = [
        "## Training results",
        "",
        "mean ± std: points per inning, mean and population std over seeds of each seed's "
        "evaluation mean (unified protocol: continue-on-miss, max_shots 10, deterministic policy); "
        "max: best inning over all seeds; foul/inn: innings with a foul; foul/sh, succ/sh: per shot. "
        "wall min, CPU min: training wall-clock and process CPU minutes per seed (evaluations included).",
        "",
    ]
    for table in sorted(by_table, key=lambda t: (t is None, t or "")):
        parts.append(render_table(table, by_table[table]))
    if unfinished:
        parts += [f"Unfinished runs (no eval.json), skipped: {', '.join(str(p) for p in unfinished)}", ""]
    if broken:
        parts += [f"Broken run directories, skipped: {'; '.join(broken)}", ""]
    if searches:
        parts += ["## Search results", "", table6_markdown(searches)]
    return "\n".join(parts)


def curves_markdown(curves: list[Curve], cpu_budget_min: float | None = None) -> str:
    """Learning curves as markdown: per variant, the mean ± std over seeds of the evaluation
    mean at each evaluated step (only steps every seed has reached), with mean CPU minutes."""
    lines = ["## Learning curves", "",
             "Periodic evaluations (unified protocol, the run's own eval innings) from each run's "
             "eval_history.jsonl; mean ± std over the seeds that reached the step; CPU min: mean "
             "process CPU minutes at that evaluation.", ""]
    for (table, variant), group in group_curves(curves).items():
        seeds = sorted(c.config.get("seed") for c in group)
        lines += [f"### {table + ': ' if table else ''}{label(table, variant)} (seeds {', '.join(map(str, seeds))})", ""]
        # runs with an averaged actor (algo.actor_ema) evaluate it, and the live actor beside it
        live = any("live_eval_mean" in p for c in group for p in c.points)
        rows = []
        for step in sorted({p["step"] for c in group for p in c.points}):
            pts = [p for c in group for p in c.points if p["step"] == step]
            means = np.array([p["eval_mean"] for p in pts])
            row = [f"{step:,}", len(pts), f"{int(np.mean([p.get('updates', 0) for p in pts])):,}",
                   f"{np.mean([p['cpu_time'] for p in pts]) / 60:.1f}", f"{means.mean():.3f} ± {means.std():.3f}",
                   max(int(p["eval_best"]) for p in pts)]
            if live:
                lives = np.array([p["live_eval_mean"] for p in pts if "live_eval_mean" in p])
                row.append(f"{lives.mean():.3f} ± {lives.std():.3f}" if len(lives) else DASH)
            rows.append([str(c) for c in row])
        header = ["steps", "seeds", "updates", "CPU min", "mean ± std", "best"] + (["live actor"] if live else [])
        lines.append(md_table(header, rows))
        if cpu_budget_min is not None:
            lines += ["", f"Within {cpu_budget_min:g} CPU minutes of training, per seed:", ""]
            picks, rows = [], []
            for c in sorted(group, key=lambda c: c.config.get("seed")):
                p = c.within_cpu(cpu_budget_min * 60)
                if p is None:
                    rows.append([str(c.config.get("seed")), DASH, DASH, DASH, "no evaluation yet", DASH])
                    continue
                picks.append(p["eval_mean"])
                rows.append([str(c.config.get("seed")), f"{p['step']:,}", f"{p['cpu_time'] / 60:.1f}",
                             f"{p['wall_time'] / 60:.1f}", f"{p['eval_mean']:.3f}", "yes" if p.get("final") else "no"])
            lines.append(md_table(["seed", "steps", "CPU min", "wall min", "mean", "final evaluation?"], rows))
            if picks:
                lines += ["", f"Mean over seeds: {np.mean(picks):.3f} ± {np.std(picks):.3f}"]
        lines.append("")
    return "\n".join(lines)
