"""``python -m billiards.campaign report paper``: the reproduction, table by table, from run
directories.

Two sources. By default (:data:`REGENERATE`) the committed run directories under
``results/training/<campaign>/<key>/`` and ``results/search/<campaign>/<key>/``: each holds
what its figures need (eval.json, summary.json, eval_history.jsonl, config.yaml and the
campaign's start records; a search's results.json and chains), so the report regenerates from
the repository alone, byte for byte (CI diffs it). With ``--root`` a live campaign's state
directory: it reads every finished entry (a training run's ``eval*.json`` and ``summary.json``, a search
run's ``results.json``), copies their small files into ``<out>/training/<campaign>/<key>/`` and
``<out>/search/<campaign>/<key>/`` (never the checkpoints), and writes

* ``<out>/reproduction.json``: ``{"rows": [...]}``, one row per table variant (Tables 1-5) and
  per proposer x method x protocol (Table 6), ours beside the paper's figures, with the seeds
  finished and planned, the steps per seed, the physics, the CPU-hours and the commits; and
  ``"extra"``: the runs beside the tables (:data:`EXTRA_RUNS`) in the same form;
* ``<out>/reproduction.md``: the same as Markdown tables, and the CPU-hours per table.

Rows whose seeds are not all finished are written with ``"complete": false``; the report
can be rebuilt at any time while the campaign runs. Training figures are aggregated by
:func:`billiards.report.aggregate` (the same arithmetic as ``python -m billiards.report``).
"""

from __future__ import annotations

import json
import shutil
from collections import defaultdict
from itertools import groupby
from pathlib import Path

from billiards.files import atomic_write_text
from billiards.report import COLUMN_TITLES, PAPER, SMALL_RUN_FILES, aggregate, plot_seed_bands, read_curve, read_run
from billiards.search.report import PAPER_TABLE6

from .ledger import STARTS, entry_dir, is_done, progress, search_result, search_seconds
from .spec import PROPOSERS, Campaign, Entry
from .status import EntryState, entry_states

# the command that rebuilds results/reproduction.json, .md and the figures from committed files
# (recorded in reproduction.json; ``--out DIR`` writes DIR/reproduction.json instead)
REGENERATE = "python -m billiards.campaign report paper"

# campaign table -> the paper's table number and its variants in the spelling, each
# with the paper's row it is compared with (PAPER's row key).
TRAIN_TABLES: dict[str, tuple[int, dict[str, str]]] = {
    "table1": (1, {"sac": "sac", "td3": "td3", "ppo": "ppo"}),
    "table2": (2, {v: v for v in ("canonical_reset", "canonical_continue", "random_reset", "random_continue")}),
    "table3": (3, {"plain": "plain", "staged": "staged", "rm": "rm", "rm_aim": "rm_aim", "aim": "aim"}),
    "table4": (4, {"plain": "plain", "aim": "aim", "aim_features": "aim_features"}),
    "table5": (5, {"aim_features": "none", "foul_penalty": "foul_penalty", "gentle": "gentle",
                   "near_miss": "near_miss", "both": "both"}),
}
# runs beside the tables (``data["extra"]``, not rows of the paper's tables), the campaign's
# ``extra`` table: variant -> the table and its variant (the spelling) each is compared
# with, ours and the paper's: the authors' SAC settings on Table 1's task
EXTRA_TABLE = "extra"
EXTRA_RUNS: dict[str, tuple[str, str]] = {
    "sac_paper": ("table1", "sac"),
}
OUR_KEYS = ("mean", "std", "max", "foul_inn", "foul_sh", "succ_sh", "canonical", "rand_eval")
SEARCH_FILES = ("results.json", "chains.jsonl", "config.yaml", "search.log")
TRAIN_EXTRA_FILES = (STARTS, "train.log")


def _round(x):
    return None if x is None else round(float(x), 4)


def _copy(src_dir: Path, dest: Path, patterns: tuple[str, ...]) -> None:
    dest.mkdir(parents=True, exist_ok=True)
    for pattern in patterns:
        for f in sorted(src_dir.glob(pattern)):
            if f.is_file():
                shutil.copy2(f, dest / f.name)


def _train_groups(campaign: Campaign, extra: bool = False) -> dict[tuple[str, str], list[Entry]]:
    """The training entries of Tables 1-5 (or, with ``extra``, of :data:`EXTRA_RUNS`) by
    (table, variant), in the campaign's order."""
    groups: dict[tuple[str, str], list[Entry]] = defaultdict(list)
    for e in campaign.entries:
        if e.kind != "train":
            continue
        if (e.table == EXTRA_TABLE and e.variant in EXTRA_RUNS) if extra else \
                (e.table in TRAIN_TABLES and e.variant in TRAIN_TABLES[e.table][1]):
            groups[(e.table, e.variant)].append(e)
    return groups


def training_rows(campaign: Campaign, runs: "Runs", out: Path | None, extra: bool = False) -> list[dict]:
    """One row per (table, variant) of Tables 1-5 present in ``campaign``; with ``extra``, one
    per run of :data:`EXTRA_RUNS`, with ``compared_with`` (the table's variant) and ``paper_row``."""
    rows, states = [], runs.states
    for (table, variant), entries in _train_groups(campaign, extra).items():
        paper_table, compared = EXTRA_RUNS[variant] if extra else (table, variant)
        number, variants = TRAIN_TABLES[paper_table]
        paper_spec = PAPER[paper_table]
        done, cpu_s, commits, shared = [], 0.0, [], set()
        for e in entries:
            src = campaign.source(e)
            if e.same_as:
                shared.add(src.key.rsplit("/seed", 1)[0])
            state = states[src.key]
            cpu_s += state.cpu_seconds
            commits += list(state.commits)
            if state.state != "done":  # the ledger's one definition: eval.json and summary.json written
                continue
            run_dir = runs.dir(src)
            done.append(read_run(run_dir))
            if out is not None and runs.copy:
                _copy(run_dir, out / "training" / campaign.name / src.key, SMALL_RUN_FILES + TRAIN_EXTRA_FILES)
        paper_row = paper_spec["rows"].get(variants[compared], {})
        columns = ["mean", *paper_spec["columns"]]
        row = {
            "table": number, "variant": variant,
            **({"compared_with": compared, "paper_row": variants[compared]} if extra else {}),
            "seeds": sorted(r.config.get("seed") for r in done),
            "seeds_planned": sorted(e.seed for e in entries),
            "steps": max(e.steps if not e.same_as else campaign.source(e).steps for e in entries),
            "physics": sorted({r.physics for r in done}) if done else None,
            "ours": None, "paper": {k: paper_row[k] for k in ("mean", "std", *paper_spec["columns"]) if k in paper_row},
            "cpu_hours": round(cpu_s / 3600, 3), "commits": list(dict.fromkeys(commits)),
            "shared_with": sorted(shared) or None,
        }
        if done:
            agg = aggregate(done)
            row["ours"] = {k: _round(agg[k]) if k != "max" else agg[k] for k in OUR_KEYS
                           if k in ("std", *columns) and agg.get(k) is not None}
            row["steps_reached"] = agg["frames"]
            row["physics"] = row["physics"][0] if len(row["physics"]) == 1 else row["physics"]
        row["complete"] = len(done) == len(entries)
        rows.append(row)
    return rows


def _done_curves(campaign: Campaign, runs: "Runs", entries: list[Entry]) -> list:
    """The learning curves of the finished runs among ``entries`` (a shared entry: its source's)."""
    curves = []
    for e in entries:
        src = campaign.source(e)
        if runs.states[src.key].state == "done":
            curve = read_curve(runs.dir(src))
            if curve is not None:
                curves.append(curve)
    return curves


def curve_figures(campaign: Campaign, runs: "Runs", out: Path) -> dict[str, str]:
    """Per table of Tables 1-5 with a finished run: its learning curves (each variant's mean
    over its finished seeds, ± their std, the paper's figure beside them) drawn to
    ``out/img/reproduction_<table>.png``; and per table with a finished extra run, that run
    beside the table's variant it is compared with (``out/img/reproduction_extra_<table>.png``,
    key ``extra_<table>``). Returns ``{key: path relative to out}``."""
    curves = {k: _done_curves(campaign, runs, entries) for k, entries in _train_groups(campaign).items()}
    by_table: dict[str, list] = defaultdict(list)
    for (table, variant), seeds in curves.items():
        if seeds:
            spec, key = PAPER[table], TRAIN_TABLES[table][1][variant]
            by_table[table].append((spec["labels"].get(key, variant), seeds, spec["rows"].get(key)))
    titles = {table: f"{PAPER[table]['title'].split(' (paper')[0]}: learning curves" for table in PAPER}
    for (_, variant), entries in _train_groups(campaign, extra=True).items():
        seeds = _done_curves(campaign, runs, entries)
        if not seeds:
            continue
        table, compared = EXTRA_RUNS[variant]
        spec, key = PAPER[table], TRAIN_TABLES[table][1][compared]
        series = by_table[f"extra_{table}"]
        series.append((f"{variant} (authors' SAC)", seeds, None))
        series.append((f"{compared} (project CPU settings)",
                       curves.get((table, compared), []), spec["rows"].get(key)))
        titles[f"extra_{table}"] = f"Table {TRAIN_TABLES[table][0]}'s task: the authors' SAC settings and ours"
    figures = {}
    for table, series in by_table.items():
        rel = f"img/reproduction_{table}.png"
        plot_seed_bands(series, out / rel, titles[table])
        figures[table] = rel
    return figures


def search_rows(campaign: Campaign, runs: "Runs", out: Path | None) -> list[dict]:
    """One row per Table 6 search entry (proposer x method x protocol); a P3 row carries the 95 %
    bootstrap interval of its mean chain (:func:`chain_interval`)."""
    rows, states = [], runs.states
    for e in campaign.entries:
        if e.kind != "search":
            continue
        proposer, cell = e.variant.split("/", 1)
        method, protocol = cell.rsplit("_", 1)
        run_dir = runs.dir(e)
        path = run_dir / "results.json"
        state = states[e.key]
        res = json.loads(path.read_text()) if state.state == "done" else None
        row = {"table": 6, "proposer": proposer, "method": method, "protocol": protocol,
               "complete": res is not None, "cpu_hours": round(state.cpu_seconds / 3600, 3),
               "commits": list(state.commits), "proposer_steps": _proposer_steps(campaign, proposer)}
        paper = PAPER_TABLE6.get(proposer, {}).get(f"{protocol}_{method}")
        if protocol == "p1":
            row["paper"] = None if paper is None else {"mean": paper}
        else:
            row["paper"] = None if paper is None else {"mean": paper[0], "max": paper[1]}
        if res is not None:
            extra = res.get("extra", {})
            if protocol == "p1":
                row.update(innings=extra.get("n_innings"), shots=extra.get("shots_per_inning"))
            else:
                row.update(cap=extra.get("cap"), seeds=extra.get("seeds"), reached_cap=extra.get("reached_cap"),
                           ci95=chain_interval(res["values"]))
            row.update(mean=_round(res["mean"]), max=res["max"], physics=res.get("physics"),
                       sims_per_decision=res.get("sims_per_decision"))
            if out is not None and runs.copy:
                _copy(run_dir, out / "search" / campaign.name / e.key, SEARCH_FILES)
        rows.append(row)
    return rows


def _proposer_steps(campaign: Campaign, proposer: str) -> int:
    """Training steps per seed behind a proposer: 0 for the training-free geometric one, else
    the budget of the Table 5 runs its shipped ensemble was exported from."""
    variant = PROPOSERS.get(proposer)
    if variant is None:
        return 0
    by_key = campaign.by_key()
    return max((campaign.source(e).steps for k, e in by_key.items() if k.startswith(f"table5/{variant}/seed")), default=0)


def chain_interval(values, level: float = 0.95, draws: int = 10_000, seed: int = 0) -> list[float]:
    """The percentile-bootstrap ``level`` interval of the mean of P3 chain lengths ``values``
    (a heavy-tailed, capped distribution: no normal approximation). Integers sum exactly, so the
    same bits on every machine."""
    import numpy as np

    x = np.asarray(values, dtype=np.float64)
    if x.size == 0:
        return [float("nan"), float("nan")]
    idx = np.random.default_rng(seed).integers(0, x.size, size=(draws, x.size))
    means = np.sort(x[idx].sum(axis=1)) / x.size
    lo, hi = means[int((1 - level) / 2 * draws)], means[int((1 + level) / 2 * draws) - 1]
    return [round(float(lo), 1), round(float(hi), 1)]


class Runs:
    """Where the report finds each entry's run directory and state: a live campaign's root
    (:meth:`campaign_root`: the ledger's states, its files copied into the report's ``out``) or
    the committed run directories (:meth:`committed`: states read from the directories alone)."""

    def __init__(self, states: dict[str, EntryState], locate, copy: bool):
        self.states, self.dir, self.copy = states, locate, copy

    @classmethod
    def campaign_root(cls, campaign: Campaign, root: Path) -> "Runs":
        return cls({s.entry.key: s for s in entry_states(campaign, root)}, lambda e: entry_dir(root, campaign, e), True)

    @classmethod
    def committed(cls, campaign: Campaign, results: Path) -> "Runs":
        """``results/training/<campaign>/<key>`` and ``results/search/<campaign>/<key>``: done when
        its results are there; CPU seconds from the run's own summary.json / results.json; commits
        from the campaign's start records (training) or results.json (search)."""
        def locate(e: Entry) -> Path:
            src = campaign.source(e)
            return results / ("search" if src.kind == "search" else "training") / campaign.name / src.key

        states = {}
        for e in campaign.entries:
            src, run_dir = campaign.source(e), locate(e)
            done = src.kind in ("train", "search") and is_done(src, run_dir, results)
            frames, cpu, commits = 0, 0.0, ()
            if src.kind == "train":
                p = progress(run_dir)
                frames, cpu = p.frames, p.cpu_seconds
                starts = run_dir / STARTS
                if starts.is_file():
                    recs = [json.loads(line) for line in starts.read_text().splitlines() if line.strip()]
                    commits = tuple(dict.fromkeys(r["commit"] for r in recs if r.get("commit")))
            elif src.kind == "search" and (secs := search_seconds(run_dir)):
                frames, cpu = secs
                commits = tuple(c for c in [(search_result(run_dir) or {}).get("commit")] if c)
            if e.same_as:
                state, frames, cpu = ("shared" if done else "left (shared)"), 0, 0.0
            else:
                state = "done" if done else "new"
            states[e.key] = EntryState(e, state, frames, cpu, 0.0, commits)
        return cls(states, locate, False)


def reproduction(campaign: Campaign, root: Path | None = None, out: Path | None = None, results: Path | None = None) -> dict:
    """The rows of ``reproduction.json`` from a campaign's ``root`` or, without one, from the
    committed run directories under ``results``; with ``out``, also draws each table's learning
    curves (``figures``) and, from a campaign root, copies the run files there."""
    runs = Runs.campaign_root(campaign, root) if root is not None else Runs.committed(campaign, results)
    data = {"campaign": campaign.name, "regenerate": REGENERATE,
            "rows": training_rows(campaign, runs, out) + search_rows(campaign, runs, out),
            "extra": training_rows(campaign, runs, out, extra=True),
            "cpu_hours_by_table": _cpu_by_table(runs.states)}
    if out is not None:
        data["figures"] = curve_figures(campaign, runs, out)
    return data


def _cpu_by_table(states: dict) -> dict[str, float]:
    by: dict[str, float] = defaultdict(float)
    for s in states.values():
        by[s.entry.table] += s.cpu_seconds / 3600
    return {t: round(h, 3) for t, h in by.items()}


# ----------------------------------------------------------------------------- Markdown

def _fig(v, key: str) -> str:
    if v is None:
        return "–"
    if key == "max":
        return f"{v:.0f}"
    if key in ("mean", "std", "rand_eval"):
        return f"{v:.3f}"
    if key == "canonical":
        return f"{v:.2f}"
    return f"{v:.1f}"


def _mean_std(fig: dict) -> str:
    return f"{_fig(fig.get('mean'), 'mean')} ± {_fig(fig.get('std'), 'std')}" if fig.get("mean") is not None else "–"


def _extra_line(label: str, r: dict | None, cols: list[str], figs: dict | None = None) -> str:
    """A line of the extra section: seeds, steps, the compared table's ``cols``, CPU-h and
    commits of run row ``r``; or, with ``r`` None, the figures ``figs`` alone (the paper's)."""
    figs = (r["ours"] if r is not None else figs) or {}
    cells = " | ".join(_mean_std(figs) if c == "mean" else _fig(figs.get(c), c) for c in cols)
    if r is None:
        return f"| {label} | | | {cells} | | |"
    return (f"| {label} | {len(r['seeds'])}/{len(r['seeds_planned'])} | {r['steps']:,} | {cells} | "
            f"{r['cpu_hours']:.2f} | {', '.join(r['commits']) or '–'} |")


def markdown(data: dict) -> str:
    rows = data["rows"]
    parts = [f"# Reproduction of the paper's tables (campaign `{data['campaign']}`)", "",
             "Ours | paper. mean ± std: points per inning over seeds (each seed's evaluation mean: 100 innings, "
             "max_shots 10, deterministic policy); max: best inning over seeds; foul/inn: innings with a foul (%); "
             "foul/sh, succ/sh: per shot (%); canonical: the same evaluation from the opening rack. "
             "seeds: finished / planned.", ""]
    for number in range(1, 6):
        table = [r for r in rows if r["table"] == number]
        if not table:
            continue
        spec = PAPER[f"table{number}"]
        cols = spec["columns"]
        parts += [f"## {spec['title']}", "",
                  "| variant | seeds | steps | " + " | ".join(COLUMN_TITLES.get(c, c) for c in cols) + " | CPU-h | commits |",
                  "|---|---|---|" + "---|" * len(cols) + "---|---|"]
        for r in table:
            ours, paper = r["ours"] or {}, r["paper"] or {}
            cells = []
            for c in cols:
                if c == "mean":
                    o = f"{_fig(ours.get('mean'), 'mean')} ± {_fig(ours.get('std'), 'std')}" if ours else "–"
                    p = f"{_fig(paper.get('mean'), 'mean')} ± {_fig(paper.get('std'), 'std')}" if paper.get("std") is not None \
                        else _fig(paper.get("mean"), "mean")
                else:
                    o, p = _fig(ours.get(c), c), _fig(paper.get(c), c)
                cells.append(f"{o} \\| {p}")
            shared = f" (= {', '.join(r['shared_with'])})" if r.get("shared_with") else ""
            parts.append(f"| {r['variant']}{shared} | {len(r['seeds'])}/{len(r['seeds_planned'])} | {r['steps']:,} | "
                         + " | ".join(cells) + f" | {r['cpu_hours']:.2f} | {', '.join(r['commits']) or '–'} |")
        parts.append("")
        figure = data.get("figures", {}).get(f"table{number}")
        if figure:
            parts += [f"![Table {number}: learning curves of the finished seeds, the paper's figure beside them]({figure})", ""]
    t6 = [r for r in rows if r["table"] == 6]
    if t6:
        parts += ["## Table 6: proposers at 400 simulations per shot", "",
                  "P1: points per 100-shot random-start inning; P3: canonical-start chain length before the first "
                  "miss or foul, mean (longest) [95 % bootstrap interval of the mean] over its chains (the paper's "
                  "caption gives no count).", "",
                  "| proposer | method | protocol | ours | paper | proposer steps | CPU-h |", "|---|---|---|---|---|---|---|"]
        for r in t6:
            paper = r["paper"]
            if r["protocol"] == "p1":
                ours = f"{r['mean']:.2f}" if r["complete"] else "–"
                ptxt = f"{paper['mean']:.2f}" if paper else "–"
            else:
                ours = (f"{r['mean']:.1f} ({r['max']:.0f}) [{r['ci95'][0]:.0f}, {r['ci95'][1]:.0f}], "
                        f"{len(r['seeds'])} chains" if r["complete"] else "–")
                ptxt = f"{paper['mean']:g} ({paper['max']})" if paper else "–"
            parts.append(f"| {r['proposer']} | {r['method']} | {r['protocol']} | {ours} | {ptxt} | "
                         f"{r['proposer_steps']:,} | {r['cpu_hours']:.2f} |")
        parts.append("")
    for number, group in groupby(data.get("extra", []), key=lambda r: r["table"]):
        cols = PAPER[f"table{number}"]["columns"]
        parts += [f"## Extra: the authors' SAC settings (`algo=sac_paper`) on Table {number}'s task", "",
                  "| run | seeds | steps | " + " | ".join(COLUMN_TITLES.get(c, c) for c in cols) + " | CPU-h | commits |",
                  "|---|---|---|" + "---|" * len(cols) + "---|---|"]
        for r in group:
            base = next((x for x in rows if x["table"] == number and x["variant"] == r["compared_with"]), None)
            parts.append(_extra_line(r["variant"], r, cols))
            if base is not None:
                parts.append(_extra_line(f"Table {number} `{base['variant']}` (project CPU settings)", base, cols))
            parts.append(_extra_line(f"the paper's `{r['compared_with']}`", None, cols, r["paper"]))
        parts.append("")
        figure = data.get("figures", {}).get(f"extra_table{number}")
        if figure:
            parts += [f"![Table {number}'s task: learning curves of the authors' SAC settings and ours, "
                      f"the paper's figure beside them]({figure})", ""]
    parts += ["## CPU-hours per table", "", "| table | CPU-h |", "|---|---|"]
    parts += [f"| {t} | {h:.2f} |" for t, h in data["cpu_hours_by_table"].items()]
    parts.append(f"| total | {sum(data['cpu_hours_by_table'].values()):.2f} |")
    return "\n".join(parts) + "\n"


def write_report(campaign: Campaign, root: Path | None, out: Path, results: Path | None = None) -> tuple[Path, Path]:
    """Write reproduction.json / .md (and the figures) under ``out``: from a campaign ``root``
    (copying the finished runs' small files there too) or, with ``root`` None, from the committed
    run directories under ``results``."""
    data = reproduction(campaign, root, out, results)
    out.mkdir(parents=True, exist_ok=True)
    json_path, md_path = out / "reproduction.json", out / "reproduction.md"
    atomic_write_text(json_path, json.dumps(data, indent=2) + "\n")
    atomic_write_text(md_path, markdown(data))
    return json_path, md_path
