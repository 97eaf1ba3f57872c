"""The paper's reproduction, table by table, from run directories: ``results/reproduction.json``
and ``.md`` and the learning-curve figures (``python -m billiards.campaign report``).

The tables, their rows, seeds, budgets and the paper's figures are :mod:`billiards.tables`'.
A training row's runs are ``<train>/<table>/<row>/seed<k>/`` (a ``same_as`` row: its source's),
a Table 6 cell's ``<search>/table6/<proposer>/<method>_<protocol>/``: the layout of a
campaign's stages (``outputs/campaign/<name>/``) and of the committed copies
(``results/training/<name>/``, ``results/search/<name>/``), so the report regenerates from the
repository alone, byte for byte (CI diffs it). A run is finished when it wrote ``eval.json`` and
``summary.json`` (training) or a ``results.json`` not marked partial (search); rows whose runs
are not all finished are written with ``"complete": false``.

* ``reproduction.json``: ``{"rows": [...]}``, one row per training table row (Tables 1-5) and
  per proposer x method x protocol (Table 6), ours beside the paper's figures, with the seeds
  finished and planned, steps per seed, physics, CPU-hours and commits; ``"extra"``: the rows
  beside the tables (``compared_with``) in the same form;
* per training row, ``"aggregate"``: the interquartile mean (IQM) of every evaluation inning of
  every finished seed with its 95 % stratified bootstrap interval (:func:`billiards.stats.aggregate`,
  the methodology of Agarwal et al. 2021, ``rliable``); ``"improvement"``: for the comparisons
  a table's take-away rests on (:data:`COMPARISONS`), the probability of improvement P(X > Y)
  with its interval (:func:`billiards.stats.probability_of_improvement`). Both draw from
  a fixed generator, so the report still regenerates byte for byte;
* ``reproduction.md``: the same as Markdown tables (``tabulate``), and the CPU-hours per table.
"""

from __future__ import annotations

import json
import shutil
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

from billiards import files, stats
from billiards.files import SUMMARY_FILE, atomic_write_text
from billiards.protocol import Protocol
from billiards.provenance import STARTS_FILE
from billiards.tables import Table, paper_tables

from .markdown import COLUMN_TITLES, figure, md_table
from .runs import SMALL_RUN_FILES, aggregate, read_curve, read_run

# the command that rebuilds results/reproduction.json, .md and the figures from committed files
REGENERATE = "python -m billiards.campaign report paper"
EXTRA = "extra"  # the rows beside the tables
STARTS = STARTS_FILE  # a training run's start records (billiards.provenance.record_start)
OUR_KEYS = ("mean", "std", "max", "foul_inn", "foul_sh", "succ_sh", "canonical", "rand_eval")
SEARCH_FILES = ("results.json", "chains.jsonl", "config.yaml")
# the row comparisons each training table's take-away rests on, (X, Y): P(X > Y) is reported
COMPARISONS = {
    "table1": (("sac", "ppo"),),
    "table2": (("random_continue", "canonical_continue"),),
    "table3": (("rm", "plain"), ("rm_aim", "aim")),
    "table4": (("aim_features", "aim"), ("aim", "plain")),
    "table5": (("near_miss", "aim_features"), ("foul_penalty", "aim_features")),
}


def _round(x):
    return None if x is None else round(float(x), 4)


def read_json(path: Path) -> dict | None:
    try:
        data = files.read_run_json(path)  # the one reader of run-folder files (no link, no FIFO, bounded)
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


@dataclass
class Sources:
    """Where the runs are: ``train`` and ``search`` roots; ``copy_to``: copy each finished
    run's small files to ``<copy_to>/training/<name>/...`` and ``.../search/<name>/...``."""

    name: str
    train: Path
    search: Path
    copy_to: Path | None = None

    def train_dir(self, key: str, seed: int) -> Path:
        return self.train / key / f"seed{seed}"

    def search_dir(self, proposer: str, method: str, protocol: str) -> Path:
        return self.search / "table6" / proposer / f"{method}_{protocol}"

    def copy(self, run_dir: Path, kind: str, patterns: tuple[str, ...]) -> None:
        if self.copy_to is None:
            return
        root = self.train if kind == "training" else self.search
        dest = self.copy_to / kind / self.name / run_dir.relative_to(root)
        dest.mkdir(parents=True, exist_ok=True)
        for pattern in patterns:
            for f in sorted(run_dir.glob(pattern)):
                if f.is_file():
                    shutil.copy2(f, dest / f.name)


class TrainState(NamedTuple):
    done: bool  # eval.json and summary.json written
    cpu_seconds: float  # summary.json's (0 before the run finished)
    frames: int  # summary.json's (0 before the run finished)
    commits: list[str]  # of every start (starts.jsonl)


def train_state(run_dir: Path) -> TrainState:
    """What a training run directory's summary and start records say (a missing one: not started)."""
    summary = read_json(run_dir / SUMMARY_FILE) or {}
    commits: list[str] = []
    if (starts := run_dir / STARTS).is_file():
        records = [json.loads(line) for line in files.read_run_text(starts, "ledger").splitlines() if line.strip()]
        commits = list(dict.fromkeys(r["commit"] for r in records if r.get("commit")))
    return TrainState(bool(summary) and (run_dir / "eval.json").is_file(), float(summary.get("cpu_seconds", 0.0)),
                      int(summary.get("frames", 0)), commits)


def inning_points(runs: list) -> list[list[float]] | None:
    """Each run's per-inning points of its final evaluation (``eval.json``'s ``points``), one
    list per seed; None unless every run recorded them."""
    points = [r.eval.get("points") for r in runs]
    return points if runs and all(isinstance(p, list) and p for p in points) else None


def seed_aggregate(points: list[list[float]] | None) -> dict | None:
    """The IQM of every (seed, inning) score with its 95 % stratified bootstrap interval, the
    plain mean and the per-seed means (:func:`billiards.stats.aggregate`)."""
    if points is None:
        return None
    from billiards.stats import aggregate as stratified

    agg = stratified(points)
    return {"iqm": _round(agg["iqm"]), "ci95": [_round(x) for x in agg["ci95"]], "mean": _round(agg["mean"]),
            "seeds": agg["seeds"], "per_seed": [_round(x) for x in agg["per_seed"]]}


def improvements(tables: list[Table], scores: dict[tuple[str, str], list]) -> list[dict]:
    """P(X > Y) with its 95 % stratified bootstrap interval for each pair of :data:`COMPARISONS`
    whose rows both have every finished seed's inning points (``scores``, by table and row)."""
    from billiards.stats import probability_of_improvement

    out = []
    for table in tables:
        for x, y in COMPARISONS.get(table.name, ()):
            if (xs := scores.get((table.name, x))) and (ys := scores.get((table.name, y))):
                p = probability_of_improvement(xs, ys)
                out.append({"table": int(table.name[5:]), "x": x, "y": y, "p": _round(p["p"]),
                            "ci95": [_round(v) for v in p["ci95"]], "seeds": [len(xs), len(ys)]})
    return out


def training_rows(src: Sources, tables: list[Table], spent: dict[str, float],
                  scores: dict[tuple[str, str], list] | None = None) -> list[dict]:
    """One row per row of ``tables``; a ``compared_with`` row carries ``compared_with`` and
    ``paper_row`` (the row it is shown against). Adds each table's CPU seconds to ``spent``
    (a shared row's are its source's) and, with ``scores``, each row's per-seed inning points
    under ``(table, row)``."""
    rows = []
    for table in tables:
        for name, spec in table.rows.items():
            source = spec.same_as or f"{table.name}/{name}"
            source_table = paper_tables()[source.partition("/")[0]]
            done, cpu_s, commits = [], 0.0, []
            for seed in table.seeds:
                run_dir = src.train_dir(source, seed)
                state = train_state(run_dir)
                cpu_s, commits = cpu_s + state.cpu_seconds, commits + state.commits
                if state.done:
                    done.append(read_run(run_dir))
                    src.copy(run_dir, "training", SMALL_RUN_FILES + (STARTS, "train.log"))
            compared = spec.compared_with.partition("/")[2] if spec.compared_with else None
            columns = paper_tables()[spec.compared_with.partition("/")[0]].columns if compared else table.columns
            row = {
                "table": int(table.name[5:]) if not compared else int(spec.compared_with[5:].partition("/")[0]),
                "variant": name,
                **({"compared_with": compared, "paper_row": compared} if compared else {}),
                "seeds": sorted(r.config.get("seed") for r in done), "seeds_planned": list(table.seeds),
                "steps": source_table.steps, "physics": None, "ours": None,
                "paper": {k: spec.figures[k] for k in ("mean", "std", *columns) if k in spec.figures},
                "cpu_hours": round(cpu_s / 3600, 3), "commits": list(dict.fromkeys(commits)),
                "shared_with": [source] if spec.same_as else None, "aggregate": None,
            }
            if done:
                agg = aggregate(done)
                row["ours"] = {k: _round(agg[k]) if k != "max" else agg[k] for k in OUR_KEYS
                               if k in ("std", "mean", *columns) and agg.get(k) is not None}
                row["steps_reached"] = agg["frames"]
                physics = sorted({r.physics for r in done})
                row["physics"] = physics[0] if len(physics) == 1 else physics
                points = inning_points(done)
                row["aggregate"] = seed_aggregate(points)
                if scores is not None and points is not None:
                    scores[(table.name, name)] = points
            row["complete"] = len(done) == len(table.seeds)
            spent[table.name] += 0.0 if spec.same_as else cpu_s
            rows.append(row)
    return rows


def search_rows(src: Sources, table: Table, spent: dict[str, float]) -> list[dict]:
    """One row per Table 6 cell (proposer x method x protocol); a P3 row carries the 95 %
    bootstrap interval of its mean chain (:func:`billiards.stats.chain_interval`)."""
    rows = []
    for proposer, method, protocol in table.search_cells():
        spec = table.rows.get(proposer)
        trained = spec.trained_from if spec else None
        steps = paper_tables()[trained.partition("/")[0]].steps if trained else 0
        run_dir = src.search_dir(proposer, method, protocol)
        res = read_json(run_dir / "results.json")
        cpu = float(res.get("seconds", 0.0)) if res else 0.0
        spent[table.name] += cpu
        if res is not None and res.get("extra", {}).get("partial"):
            res = None
        row = {"table": 6, "proposer": proposer, "method": method, "protocol": protocol,
               "complete": res is not None, "cpu_hours": round(cpu / 3600, 3),
               "commits": [c for c in [(res or {}).get("commit")] if c], "proposer_steps": steps}
        paper = (spec.figures if spec else {}).get(f"{protocol}_{method}")
        if Protocol(protocol) is Protocol.P1:
            row["paper"] = None if paper is None else {"mean": paper}
        else:
            row["paper"] = None if paper is None else {"mean": paper[0], "max": paper[1]}
        if res is not None:
            extra = res.get("extra", {})
            if Protocol(protocol) is Protocol.P1:
                row.update(innings=extra.get("n_innings"), shots=extra.get("shots_per_inning"))
            else:
                row.update(cap=extra.get("cap"), seeds=extra.get("seeds"), reached_cap=extra.get("reached_cap"),
                           ci95=stats.chain_interval(res["values"]))
            row.update(mean=_round(res["mean"]), max=res["max"], physics=res.get("physics"),
                       sims_per_decision=res.get("sims_per_decision"))
            src.copy(run_dir, "search", SEARCH_FILES)
        rows.append(row)
    return rows


def curve_figures(src: Sources, tables: list[Table], extra: list[Table], out: Path) -> dict[str, str]:
    """Per table with a finished run: each row's mean learning curve over its finished seeds,
    ± their std, the paper's figure beside it (``out/img/reproduction_<table>.png``); per
    extra row, it beside the row it is compared with (``img/reproduction_extra_<table>.png``).
    Returns ``{key: path relative to out}``."""
    from .plots import plot_seed_bands

    def curves(key: str, seeds: list[int]) -> list:
        found = [read_curve(src.train_dir(key, s)) for s in seeds if train_state(src.train_dir(key, s)).done]
        return [c for c in found if c is not None]

    series, titles = defaultdict(list), {}
    for table in tables:
        titles[table.name] = f"{table.title.split(' (paper')[0]}: learning curves"
        for name, spec in table.rows.items():
            if seeds := curves(spec.same_as or f"{table.name}/{name}", table.seeds):
                series[table.name].append((spec.label, seeds, spec.figures))
    for table in extra:
        for name, spec in table.rows.items():
            if not (seeds := curves(f"{table.name}/{name}", table.seeds)):
                continue
            target, _, compared = spec.compared_with.partition("/")
            base = paper_tables()[target]
            key = f"extra_{target}"
            series[key] += [(spec.label, seeds, None),
                            (f"{compared} (project CPU settings)", curves(spec.compared_with, base.seeds), spec.figures)]
            titles[key] = f"Table {target[5:]}'s task: the authors' SAC settings and ours"
    figures = {}
    for key, lines in series.items():
        figures[key] = f"img/reproduction_{key}.png"
        plot_seed_bands(lines, out / figures[key], titles[key])
    return figures


def reproduction(src: Sources, out: Path | None = None) -> dict:
    """The contents of ``reproduction.json``; with ``out``, also the figures drawn there."""
    tables = [t for name, t in sorted(paper_tables().items()) if t.app == "train" and name[5:].isdigit()]
    extra = [paper_tables()[EXTRA]]
    spent: dict[str, float] = defaultdict(float)
    scores: dict[tuple[str, str], list] = {}
    rows = training_rows(src, tables, spent, scores) + search_rows(src, paper_tables()["table6"], spent)
    data = {"campaign": src.name, "regenerate": REGENERATE, "rows": rows, "extra": training_rows(src, extra, spent),
            "improvement": improvements(tables, scores)}
    data["cpu_hours_by_table"] = {t: round(s / 3600, 3) for t, s in spent.items()}
    if out is not None:
        data["figures"] = curve_figures(src, tables, extra, out)
    return data


# ----------------------------------------------------------------------------- Markdown

IQM_TITLE = "IQM [95 % CI]"


def iqm_cell(r: dict | None) -> str:
    """A row's IQM with its 95 % stratified bootstrap interval (``aggregate``), or a dash."""
    agg = (r or {}).get("aggregate")
    if not agg:
        return "–"
    return f"{agg['iqm']:.3f} [{agg['ci95'][0]:.3f}, {agg['ci95'][1]:.3f}]"


def _with_iqm(cols: list[str], r: dict | None, cells: list[str]) -> list[str]:
    """``cells`` (one per column of ``cols``) with the IQM cell after the mean's (the header's
    title where ``r`` is None)."""
    at = cols.index("mean") + 1 if "mean" in cols else 0
    return [*cells[:at], IQM_TITLE if r is None else iqm_cell(r), *cells[at:]]


def _run_cells(r: dict, cols: list[str]) -> list[str]:
    return [f"{len(r['seeds'])}/{len(r['seeds_planned'])}", f"{r['steps']:,}",
            *_with_iqm(cols, r, [figure(c, r["ours"]) for c in cols]), f"{r['cpu_hours']:.2f}", ", ".join(r["commits"]) or "–"]


def markdown(data: dict) -> str:
    rows, tables = data["rows"], paper_tables()
    parts = [f"# Reproduction of the paper's tables (campaign `{data['campaign']}`)", "",
             "Ours | paper. mean ± std: points per inning over seeds (each seed's evaluation mean: 100 innings, "
             "max_shots 10, deterministic policy); max: best inning over seeds; foul/inn: innings with a foul (%); "
             "foul/sh, succ/sh: per shot (%); canonical: the same evaluation from the opening rack. "
             "seeds: finished / planned.", "",
             "IQM [95 % CI] (ours only): the interquartile mean, the mean of the middle 50 %, of every evaluation "
             "inning of every seed, with a 95 % stratified bootstrap interval that resamples the seeds and the "
             "innings within each seed (Agarwal et al. 2021, \"Deep RL at the Edge of the Statistical Precipice\"). "
             "P(X > Y): the probability that an inning of row X scores above one of row Y (ties count half), "
             "averaged over their seed pairs, with its interval from the same resampling.", ""]
    for number in range(1, 6):
        if not (table := [r for r in rows if r["table"] == number]):
            continue
        spec = tables[f"table{number}"]
        cols = list(spec.columns)
        body = [[r["variant"] + (f" (= {', '.join(r['shared_with'])})" if r.get("shared_with") else ""),
                 f"{len(r['seeds'])}/{len(r['seeds_planned'])}", f"{r['steps']:,}",
                 *_with_iqm(cols, r, [f"{figure(c, r['ours'])} \\| {figure(c, r['paper'])}" for c in cols]),
                 f"{r['cpu_hours']:.2f}", ", ".join(r["commits"]) or "–"] for r in table]
        parts += [f"## {spec.title}", "",
                  md_table(["variant", "seeds", "steps", *_with_iqm(cols, None, [COLUMN_TITLES[c] for c in cols]),
                            "CPU-h", "commits"], body), ""]
        if pairs := [p for p in data.get("improvement", []) if p["table"] == number]:
            parts += [md_table(["probability of improvement", "P(X > Y) [95 % CI]", "seeds X, Y"],
                               [[f"`{p['x']}` > `{p['y']}`", f"{p['p']:.3f} [{p['ci95'][0]:.3f}, {p['ci95'][1]:.3f}]",
                                 f"{p['seeds'][0]}, {p['seeds'][1]}"] for p in pairs]), ""]
        if picture := data.get("figures", {}).get(f"table{number}"):
            parts += [f"![Table {number}: learning curves of the finished seeds, the paper's figure beside them]({picture})", ""]
    if t6 := [r for r in rows if r["table"] == 6]:
        body = []
        for r in t6:
            paper = r["paper"]
            if Protocol(r["protocol"]) is Protocol.P1:
                ours = f"{r['mean']:.2f}" if r["complete"] else "–"
                ptxt = f"{paper['mean']:.2f}" if paper else "–"
            else:
                ours = (f"{r['mean']:.1f} ({r['max']:.0f}) [{r['ci95'][0]:.0f}, {r['ci95'][1]:.0f}], "
                        f"{len(r['seeds'])} chains" if r["complete"] else "–")
                ptxt = f"{paper['mean']:g} ({paper['max']})" if paper else "–"
            body.append([r["proposer"], r["method"], r["protocol"], ours, ptxt, f"{r['proposer_steps']:,}", f"{r['cpu_hours']:.2f}"])
        parts += [f"## {tables['table6'].title}", "",
                  "P1: points per 100-shot random-start inning; P3: canonical-start chain length before the first "
                  "miss or foul, mean (longest) [95 % bootstrap interval of the mean] over its chains (the paper's "
                  "caption gives no count).", "",
                  md_table(["proposer", "method", "protocol", "ours", "paper", "proposer steps", "CPU-h"], body), ""]
    for r in data.get("extra", []):
        cols = list(tables[f"table{r['table']}"].columns)
        base = next((x for x in rows if x["table"] == r["table"] and x["variant"] == r["compared_with"]), None)
        body = [[r["variant"], *_run_cells(r, cols)]]
        if base is not None:
            body.append([f"Table {r['table']} `{base['variant']}` (project CPU settings)", *_run_cells(base, cols)])
        body.append([f"the paper's `{r['compared_with']}`", "", "",
                     *_with_iqm(cols, {}, [figure(c, r["paper"]) for c in cols]), "", ""])
        parts += [f"## {tables[EXTRA].title}", "",
                  md_table(["run", "seeds", "steps", *_with_iqm(cols, None, [COLUMN_TITLES[c] for c in cols]),
                            "CPU-h", "commits"], body), ""]
        if picture := data.get("figures", {}).get(f"extra_table{r['table']}"):
            parts += [f"![Table {r['table']}'s task: learning curves of the authors' SAC settings and ours, "
                      f"the paper's figure beside them]({picture})", ""]
    hours = data["cpu_hours_by_table"]
    parts += ["## CPU-hours per table", "",
              md_table(["table", "CPU-h"], [[t, f"{h:.2f}"] for t, h in hours.items()] + [["total", f"{sum(hours.values()):.2f}"]])]
    return "\n".join(parts) + "\n"


def write_report(src: Sources, out: Path) -> tuple[Path, Path]:
    """Write reproduction.json / .md (and the figures) under ``out``."""
    data = reproduction(src, out)
    out.mkdir(parents=True, exist_ok=True)
    json_path, md_path = out / "reproduction.json", out / "reproduction.md"
    atomic_write_text(json_path, json.dumps(data, indent=2) + "\n")
    atomic_write_text(md_path, markdown(data))
    return json_path, md_path
