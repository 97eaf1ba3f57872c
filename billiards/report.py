"""Aggregate training runs into the paper's tables: ``python -m billiards.report DIR...``.

Every directory under the given ones that holds a finished run (``config.yaml`` and
``eval.json`` written by ``train.py``) is read; a run directory that cannot be read (no
``config.yaml``, unparsable YAML or JSON, a config lacking what its row needs) is skipped with
a warning naming it and listed at the end of the report. Runs are grouped by the paper table their
experiment preset names (``table`` in the config), then by the table's variant (algorithm
for Table 1, training paradigm for Table 2, aid for Table 3, domain knowledge for Table 4,
reward shaping for Table 5), and aggregated over seeds:

* mean ± std: the mean over seeds of each run's mean points per inning, and the std over
  seeds (population std, ddof = 0);
* max: the best single inning over all seeds' evaluation innings;
* foul and success percentages: means over seeds.

Search runs (``results.json`` written by ``search.py``) found under the same directories are
laid out as the paper's Table 6 (:mod:`billiards.search.report`).

The paper's figures are printed beside ours for runs whose preset names a table. Runs without
a table are grouped by the settings that differ between them. The markdown goes to stdout and
to ``--out`` (default: ``DIR/report.md`` for one DIR, else ``./report.md``).

Learning curves (``--curves``): every periodic evaluation in each run's
``eval_history.jsonl``, unfinished runs included, as one markdown table per variant (steps,
CPU minutes, mean ± std over seeds); ``--cpu-budget MIN`` adds, per run, the last evaluation
made within MIN CPU minutes of training; ``--plot FILE.png`` draws the curves against env
steps and CPU minutes.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from billiards.files import CHECKPOINT_FILE, CONFIG_FILE, EVAL_FILE, EVAL_HISTORY_FILE, METRICS_FILE, SUMMARY_FILE

# The paper's figures (shared/paper.md). Keys are our variant names.
PAPER = {
    "table1": {
        "title": "Table 1: algorithm comparison on the plain sparse task (paper: 5 seeds, 400k steps)",
        "rows": {
            "td3": {"mean": 0.460, "std": 0.114, "max": 4, "foul_inn": 84},
            "sac": {"mean": 0.418, "std": 0.038, "max": 4, "foul_inn": 90},
            "ppo": {"mean": 0.170, "std": 0.040, "max": 3, "foul_inn": 70},
        },
        "labels": {"td3": "TD3", "sac": "SAC", "ppo": "PPO"},
        "columns": ["mean", "max", "foul_inn"],
    },
    "table2": {
        "title": "Table 2: training paradigms, SAC, unified eval (paper: 3 seeds, 400k steps)",
        "rows": {
            "canonical_reset": {"mean": 0.073, "std": 0.045, "canonical": 1.00, "foul_sh": 9.3, "succ_sh": 0.7},
            "canonical_continue": {"mean": 0.353, "std": 0.101, "canonical": 1.33, "foul_sh": 20.4, "succ_sh": 3.5},
            "random_reset": {"mean": 0.407, "std": 0.046, "canonical": 0.67, "foul_sh": 18.6, "succ_sh": 4.1},
            "random_continue": {"mean": 0.453, "std": 0.012, "canonical": 0.67, "foul_sh": 20.3, "succ_sh": 4.5},
        },
        "labels": {
            "canonical_reset": "canonical, reset", "canonical_continue": "canonical, continue",
            "random_reset": "random, reset", "random_continue": "random, continue",
        },
        "columns": ["mean", "canonical", "foul_sh", "succ_sh"],
    },
    "table3": {
        "title": "Table 3: structure-free aids on the plain SAC baseline (paper: 3 seeds, 1M steps; "
                 "the RM rows cost 10^7 offline shots; plain and aim rows shared with Table 4)",
        "rows": {
            "plain": {"mean": 0.487, "std": 0.097, "max": 4, "foul_sh": 20.5, "succ_sh": 4.9, "rand_eval": 0.053},
            "staged": {"mean": 0.407, "std": 0.052, "max": 4, "rand_eval": 0.053},
            "rm": {"mean": 0.840, "std": 0.000, "max": 4, "rand_eval": 0.087},
            "aim": {"mean": 2.570, "std": 0.128, "max": 6, "foul_sh": 15.4, "succ_sh": 25.7},
            "rm_aim": {"mean": 2.357, "std": 0.139},
        },
        "labels": {"plain": "plain baseline", "staged": "staged curriculum", "rm": "RM-guided",
                   "aim": "aim constraint", "rm_aim": "RM + aim constraint"},
        "columns": ["mean", "max", "foul_sh", "succ_sh", "rand_eval"],
    },
    "table4": {
        "title": "Table 4: domain knowledge on the SAC baseline (paper: 3 seeds, 1M steps)",
        "rows": {
            "plain": {"mean": 0.487, "std": 0.097, "max": 4, "foul_sh": 20.5, "succ_sh": 4.9},
            "aim": {"mean": 2.570, "std": 0.128, "max": 6, "foul_sh": 15.4, "succ_sh": 25.7},
            "aim_features": {"mean": 6.460, "std": 0.123, "max": 10, "foul_sh": 11.1, "succ_sh": 64.6},
        },
        "labels": {"plain": "plain SAC", "aim": "+ aim constraint", "aim_features": "+ extra feat."},
        "columns": ["mean", "max", "foul_sh", "succ_sh"],
    },
    "table5": {
        "title": "Table 5: reward shaping on the constraint+extra base (paper: 3 seeds, 1M steps)",
        "rows": {
            "none": {"mean": 6.460, "std": 0.123, "foul_sh": 11.1, "succ_sh": 64.6},
            "foul_penalty": {"mean": 5.553, "std": 0.162, "foul_sh": 6.0, "succ_sh": 55.5},
            "gentle": {"mean": 5.213, "std": 0.442, "foul_sh": 3.3, "succ_sh": 52.1},
            "near_miss": {"mean": 5.583, "std": 0.370, "foul_sh": 5.0, "succ_sh": 55.8},
            "both": {"mean": 5.520, "std": 0.365, "foul_sh": 5.0, "succ_sh": 55.2},
        },
        "labels": {
            "none": "constraint+extra", "foul_penalty": "+ foul penalty (base)", "gentle": "+ foul penalty + gentle",
            "near_miss": "+ foul penalty + near-miss", "both": "+ foul penalty + both",
        },
        "columns": ["mean", "foul_sh", "succ_sh"],
    },
}

# experiment=cpu_hour: Table 4's strongest row trained for one CPU hour per seed, beside the
# paper's 1M-step figure for that row.
PAPER["cpu_hour"] = {
    **PAPER["table4"],
    "title": "One CPU hour per seed (experiment=cpu_hour): aim constraint + carom features SAC, "
             "against the paper's Table 4 row at 1M steps",
    "rows": {"aim_features": PAPER["table4"]["rows"]["aim_features"]},
}

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


@dataclass
class Run:
    path: Path
    config: dict
    eval: dict  # primary (first eval start)
    extra_evals: dict  # start -> eval dict (e.g. canonical)
    summary: dict = field(default_factory=dict)

    @property
    def table(self) -> str | None:
        return self.config.get("table")

    @property
    def physics(self) -> str:
        """The table the run played: the summary's label (overrides included), else the
        config's preset."""
        return self.summary.get("physics") or self.config["physics"]["preset"]

    @property
    def frames(self) -> int:
        """Env frames trained: summary.json's, else the configured budget."""
        if "frames" in self.summary:
            return int(self.summary["frames"])
        return int(self.config["budget"]["total_steps"])

    def variant(self) -> str:
        c, env = self.config, self.config.get("env", {})
        table = self.table
        if table == "table1":
            return c["algo"]["name"]
        if table == "table2":
            return env["paradigm"]
        if table == "table3":
            return table3_variant(c)
        if table in ("table4", "cpu_hour"):
            return {(False, False): "plain", (True, False): "aim", (True, True): "aim_features"}.get(
                (bool(env.get("constrain_aim")), bool(env.get("extra_features"))), "features_only")
        if table == "table5":
            return c["shaping"]["name"]
        return generic_label(c)


# The table of runs saved before the physics presets existed (billiards.physics.config's
# LEGACY_PHYSICS; not imported, so the report loads without numba). Runs of different physics
# never share a row: split_by_settings compares physics.preset like any other setting.
LEGACY_PHYSICS = "international"

# Top-level config keys that never put two runs in different rows: the seed, run-time switches,
# logging and the table label itself. Everything else does, the budget included (total steps,
# CPU minutes, warm-up, the final evaluation's innings): only runs of one configuration share a
# row, and the steps column shows where each stopped.
SAME_ROW_KEYS = ("seed", "resume", "threads", "progress", "compile", "logger", "checkpoint", "table", "paper_steps", "device")
# Budget keys that only set a cadence (how often to log, evaluate on the way, checkpoint).
CADENCE_KEYS = ("budget.name", "budget.eval_every", "budget.eval_innings", "budget.checkpoint_every", "budget.log_every",
                "budget.kill_after_checkpoint")


def flatten_config(d: dict, prefix: str = "") -> dict:
    """A nested config as ``{"algo.lr": 0.001, ...}`` (lists as tuples, so values compare and hash)."""
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(flatten_config(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = tuple(v) if isinstance(v, list) else v
    return out


def split_by_settings(items: list, config_of) -> dict[str, list]:
    """Split the runs (or curves) of one row by the settings that differ between them, so runs
    with, say, another learning rate never merge into one mean: ``{"": items}`` when they agree,
    else ``{" (algo.lr=0.001, algo.gamma=0.9)": [...], ...}``. Keys missing from some configs
    (written before the schema had them) are not compared."""
    flats = [{k: v for k, v in flatten_config(config_of(it)).items() if k.split(".")[0] not in SAME_ROW_KEYS and k not in CADENCE_KEYS}
             for it in items]
    common = set.intersection(*(set(f) for f in flats)) if flats else set()
    differing = sorted(k for k in common if len({repr(f[k]) for f in flats}) > 1)
    if not differing:
        return {"": items}
    out: dict[str, list] = defaultdict(list)
    for it, f in zip(items, flats):
        out[" (" + ", ".join(f"{k}={f[k]}" for k in differing) + ")"].append(it)
    return dict(sorted(out.items()))


def split_repeats(items: list, config_of) -> dict[str, list]:
    """Runs of one row that repeat a seed never count as more seeds: the n-th run of a seed goes
    to the row suffixed ``" (repeat n)"``, so the seeds column counts distinct seeds."""
    seen: dict = defaultdict(int)
    out: dict[str, list] = defaultdict(list)
    for it in items:
        seed = config_of(it).get("seed")
        seen[seed] += 1
        out["" if seen[seed] == 1 else f" (repeat {seen[seed]})"].append(it)
    return dict(out)


def split_rows(items: list, config_of) -> dict[str, list]:
    """One row per configuration and per repeat of a seed (:func:`split_by_settings`, :func:`split_repeats`)."""
    return {suffix + again: part for suffix, group in split_by_settings(items, config_of).items()
            for again, part in split_repeats(group, config_of).items()}


def base_variant(variant: str) -> str:
    """The table's variant name of a row key that :func:`split_by_settings` may have suffixed."""
    return variant.split(" (", 1)[0]


def table3_variant(c: dict) -> str:
    env, shaping = c.get("env", {}), c.get("shaping", {})
    if c.get("curriculum", {}).get("name", "none") != "none":
        return "staged" if not env.get("constrain_aim") else "staged_aim"
    rm = bool(shaping.get("rm"))
    aim = bool(env.get("constrain_aim"))
    if env.get("extra_features") or shaping.get("name") not in ("none", "rm"):
        return generic_label(c)
    return {(False, False): "plain", (True, False): "rm", (False, True): "aim", (True, True): "rm_aim"}[(rm, aim)]


def generic_label(c: dict) -> str:
    env = c.get("env", {})
    knowledge = "+".join(k for k, on in (("aim", env.get("constrain_aim")), ("features", env.get("extra_features"))) if on) or "plain"
    return f"{c['algo']['name']}, {env.get('paradigm')}, {knowledge}, shaping={c.get('shaping', {}).get('name', 'none')}"


# Files a training run writes into its directory: any of them marks a run directory.
RUN_FILES = (CONFIG_FILE, EVAL_FILE, SUMMARY_FILE, EVAL_HISTORY_FILE, METRICS_FILE, CHECKPOINT_FILE)
EVAL_KEYS = ("mean", "best", "foul_innings_pct", "foul_per_shot_pct", "success_per_shot_pct")


def warn(message: str) -> None:
    print(f"warning: {message}", file=sys.stderr)


def run_dirs(d: Path) -> list[Path]:
    """Every directory under ``d`` (``d`` included) holding a file a training run writes,
    Hydra's own ``.hydra*`` directories excluded."""
    found = {p.parent for name in RUN_FILES for p in d.rglob(name)}
    return sorted(r for r in found if not any(part.startswith(".hydra") for part in r.relative_to(d).parts))


def _json_object(path: Path) -> dict:
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{path.name} is not valid JSON ({err})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path.name} is not a JSON object")
    return data


def read_config(run_dir: Path) -> dict:
    """The run's ``config.yaml`` as a dict; ValueError saying what is wrong if it is missing,
    unparsable or lacks an integer seed."""
    path = run_dir / CONFIG_FILE
    if not path.is_file():
        raise ValueError("no config.yaml (the run's settings)")
    try:
        config = yaml.safe_load(path.read_text())
    except yaml.YAMLError as err:
        raise ValueError(f"config.yaml is not valid YAML ({err})") from None
    if not isinstance(config, dict) or not isinstance(config.get("seed"), int):
        raise ValueError("config.yaml is not a training config (no integer seed)")
    config.setdefault("physics", {"preset": LEGACY_PHYSICS})
    return config


def read_run(run_dir: Path) -> Run | None:
    """The finished run in ``run_dir``, or None if it has no eval.json yet (unfinished).
    Raises ValueError (or OSError) saying what is wrong with a broken one."""
    config = read_config(run_dir)
    eval_path = run_dir / EVAL_FILE
    if not eval_path.is_file():
        return None
    result = _json_object(eval_path)
    missing = [k for k in EVAL_KEYS if not isinstance(result.get(k), (int, float))]
    if missing:
        raise ValueError(f"eval.json lacks {missing}")
    extra = {p.stem[len("eval_"):]: _json_object(p) for p in run_dir.glob("eval_*.json")}
    summary_path = run_dir / SUMMARY_FILE
    summary = _json_object(summary_path) if summary_path.is_file() else {}
    run = Run(run_dir, config, result, extra, summary)
    _check_config(lambda: (run.variant(), run.frames, run.physics))
    return run


def _check_config(read) -> None:
    """Call ``read`` (what the report reads from a run's config), so that a config lacking it
    fails while the run is loaded, as a ValueError saying so, not in the middle of a table."""
    try:
        read()
    except (KeyError, TypeError, AttributeError) as err:
        raise ValueError(f"config.yaml lacks what the report reads ({type(err).__name__}: {err})") from None


def find_runs(dirs: list[Path]) -> tuple[list[Run], list[Path], list[str]]:
    """Finished runs under dirs, run dirs without an eval.json (unfinished), and the broken
    run dirs (``"<dir>: <what is wrong>"``), each also warned about on stderr and skipped."""
    runs, unfinished, broken = [], [], []
    for d in dirs:
        if not d.exists():
            raise SystemExit(f"Error: {d} does not exist")
    for run_dir in dict.fromkeys(r for d in dirs for r in run_dirs(d)):
        try:
            run = read_run(run_dir)
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
            broken.append(f"{run_dir}: {err}")
            warn(f"skipping run directory {broken[-1]}")
            continue
        if run is None:
            unfinished.append(run_dir)
        else:
            runs.append(run)
    return runs, unfinished, broken


def aggregate(runs: list[Run]) -> dict:
    means = np.array([r.eval["mean"] for r in runs])
    canonical = [r.extra_evals["canonical"]["mean"] for r in runs if "canonical" in r.extra_evals]
    if not canonical:
        canonical = [r.eval["mean"] for r in runs if r.eval.get("start") == "canonical"]
    random_evals = [r.eval if r.eval.get("start", "random") == "random" else r.extra_evals.get("random") for r in runs]
    first_miss = [np.mean(e["first_miss_points"]) for e in random_evals if e and e.get("first_miss_points")]
    seconds = [r.summary["train_seconds"] for r in runs if "train_seconds" in r.summary]
    cpu = [r.summary["cpu_seconds"] for r in runs if "cpu_seconds" in r.summary]
    frames = sorted({r.frames for r in runs})
    return {
        "n": len(runs),
        "mean": float(means.mean()),
        "std": float(means.std()),
        "max": int(max(r.eval["best"] for r in runs)),
        "foul_inn": float(np.mean([r.eval["foul_innings_pct"] for r in runs])),
        "foul_sh": float(np.mean([r.eval["foul_per_shot_pct"] for r in runs])),
        "succ_sh": float(np.mean([r.eval["success_per_shot_pct"] for r in runs])),
        "canonical": float(np.mean(canonical)) if canonical else None,
        # only when every run recorded it (runs finished before it existed did not)
        "rand_eval": float(np.mean(first_miss)) if first_miss and len(first_miss) == len(runs) else None,
        "seeds": sorted(r.config.get("seed") for r in runs),
        "frames": frames,
        "minutes": float(np.mean(seconds)) / 60 if seconds else None,
        "cpu_minutes": float(np.mean(cpu)) / 60 if cpu else None,
    }


def _fmt(col: str, row: dict | None) -> str:
    if row is None or row.get(col) is None:
        return "–"
    if col == "mean":
        return f"{row['mean']:.3f} ± {row['std']:.3f}" if row.get("std") is not None else f"{row['mean']:.3f}"
    if col == "max":
        return str(int(row["max"]))
    if col == "canonical":
        return f"{row['canonical']:.2f}"
    if col == "rand_eval":
        return f"{row['rand_eval']:.3f}"
    return f"{row[col]:.1f}"


def _steps(frames: list[int]) -> str:
    """Steps of a row's runs, 3 significant digits: "100k", "100k/200k", or "1.23M–1.29M" for
    more than two different counts (runs stopped by a CPU budget)."""
    def k(n: int) -> str:
        return f"{n / 1e6:.3g}M" if n >= 1_000_000 else f"{n / 1e3:.3g}k" if n >= 1000 else str(n)

    labels = list(dict.fromkeys(k(f) for f in frames))
    return f"{labels[0]}–{labels[-1]}" if len(labels) > 2 else "/".join(labels)


def render_table(table: str | None, groups: dict[str, list[Run]]) -> str:
    spec = PAPER.get(table or "")
    lines = []
    if spec:
        columns, rows = spec["columns"], list(spec["rows"])
        rank = {v: i for i, v in enumerate(rows)}
        order = sorted(groups, key=lambda v: (rank.get(base_variant(v), len(rows)), v))
        lines.append(f"### {spec['title']}")
        lines.append("")
        header = ["variant", "seeds", "steps", "wall min", "CPU min"]
        for c in columns:
            header += [f"{COLUMN_TITLES[c]} (ours)", "(paper)"]
        header.append("physics")
    else:
        columns, order = GENERIC_COLUMNS, sorted(groups)
        lines.append(f"### {table or 'Runs without a paper table'}")
        lines.append("")
        header = ["variant", "seeds", "steps", "wall min", "CPU min"] + [COLUMN_TITLES[c] for c in columns] + ["physics"]
    lines.append("| " + " | ".join(header) + " |")
    lines.append("|" + "---|" * len(header))
    for variant in order:
        if variant not in groups:
            continue
        agg = aggregate(groups[variant])
        label = _label(table, variant)
        minutes = [f"{agg[k]:.1f}" if agg[k] is not None else "–" for k in ("minutes", "cpu_minutes")]
        cells = [label, str(agg["n"]), _steps(agg["frames"]), *minutes]
        for c in columns:
            cells.append(_fmt(c, agg))
            if spec:
                cells.append(_fmt(c, spec["rows"].get(base_variant(variant))))
        cells.append(", ".join(sorted({r.physics for r in groups[variant]})))
        lines.append("| " + " | ".join(cells) + " |")
    present = {base_variant(v) for v in groups}
    missing = [spec["labels"][v] for v in spec["rows"] if v not in present] if spec else []
    if missing:
        lines.append("")
        lines.append(f"No runs yet for: {', '.join(missing)}.")
    lines.append("")
    return "\n".join(lines)


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
    by_table: dict[str | None, dict[str, list[Run]]] = defaultdict(lambda: defaultdict(list))
    for run in runs:
        by_table[run.table][run.variant()].append(run)
    # Rows that are the same config in two tables: Table 3's plain and aim rows are Table 4's
    # plain and aim runs, Table 5's constraint+extra row is Table 4's aim_features runs.
    for table, row, source in (("table3", "plain", "plain"), ("table3", "aim", "aim"), ("table5", "none", "aim_features")):
        if table in by_table and row not in by_table[table] and source in by_table.get("table4", {}):
            by_table[table][row] = by_table["table4"][source]
    for table, groups in by_table.items():
        by_table[table] = {variant + suffix: part for variant, group in groups.items()
                           for suffix, part in split_rows(group, lambda r: r.config).items()}
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
        parts.append(f"Unfinished runs (no eval.json), skipped: {', '.join(str(p) for p in unfinished)}")
        parts.append("")
    if broken:
        parts.append(f"Broken run directories, skipped: {'; '.join(broken)}")
        parts.append("")
    if searches:
        parts += ["## Search results", "", table6_markdown(searches)]
    return "\n".join(parts)


SMALL_RUN_FILES = (CONFIG_FILE, EVAL_FILE, "eval_*.json", SUMMARY_FILE, EVAL_HISTORY_FILE, METRICS_FILE)


@dataclass
class Curve:
    """One run's periodic evaluations from the run's primary start (``eval_history.jsonl``)."""

    path: Path
    config: dict
    points: list[dict]  # step, updates, cpu_time, wall_time, eval_mean, ... in step order

    @property
    def variant(self) -> str:
        return Run(self.path, self.config, {}, {}).variant()

    @property
    def table(self) -> str | None:
        return self.config.get("table")

    def within_cpu(self, seconds: float) -> dict | None:
        """The last evaluation made within ``seconds`` of process CPU time, or None."""
        inside = [p for p in self.points if p["cpu_time"] <= seconds]
        return inside[-1] if inside else None


def read_curve(run_dir: Path) -> Curve | None:
    """The learning curve of the run in ``run_dir``, or None without evaluations yet. Raises
    ValueError (or OSError) saying what is wrong with a broken one."""
    config = read_config(run_dir)
    hist = run_dir / EVAL_HISTORY_FILE
    if not hist.is_file():
        return None
    try:
        rows = [json.loads(line) for line in hist.read_text().splitlines() if line.strip()]
    except json.JSONDecodeError as err:
        raise ValueError(f"{EVAL_HISTORY_FILE} has a line that is not JSON ({err})") from None
    if not rows:
        return None
    start = rows[0].get("start", "random")
    points = sorted((r for r in rows if r.get("start", "random") == start), key=lambda r: r["step"])
    for p in points:
        missing = [k for k in ("step", "cpu_time", "wall_time", "eval_mean", "eval_best") if k not in p]
        if missing:
            raise ValueError(f"{EVAL_HISTORY_FILE} has an evaluation without {missing}")
    curve = Curve(run_dir, config, points)
    _check_config(lambda: curve.variant)
    return curve


def find_curves(dirs: list[Path]) -> list[Curve]:
    """Every run dir under ``dirs`` with a ``config.yaml`` and an ``eval_history.jsonl``
    (finished or not); broken ones are warned about on stderr and skipped."""
    curves = []
    for run_dir in dict.fromkeys(r for d in dirs for r in run_dirs(d)):
        try:
            curve = read_curve(run_dir)
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
            warn(f"skipping run directory {run_dir}: {err}")
            continue
        if curve is not None:
            curves.append(curve)
    return curves


def _label(table: str | None, variant: str) -> str:
    spec = PAPER.get(table or "")
    if not spec:
        return variant
    base = base_variant(variant)
    return spec["labels"].get(base, base) + variant[len(base):]


def _group_curves(curves: list[Curve]) -> dict[tuple, list[Curve]]:
    groups: dict[tuple, list[Curve]] = defaultdict(list)
    for c in curves:
        groups[(c.table or "", c.variant)].append(c)
    split = {(table, variant + suffix): part for (table, variant), group in groups.items()
             for suffix, part in split_rows(group, lambda c: c.config).items()}
    return dict(sorted(split.items()))


def curves_markdown(curves: list[Curve], cpu_budget_min: float | None = None) -> str:
    """Learning curves as markdown: per variant, the mean ± std over seeds of the evaluation
    mean at each evaluated step (only steps every seed has reached), with mean CPU minutes."""
    lines = ["## Learning curves", "",
             "Periodic evaluations (unified protocol, the run's own eval innings) from each run's "
             "eval_history.jsonl; mean ± std over the seeds that reached the step; CPU min: mean "
             "process CPU minutes at that evaluation.", ""]
    for (table, variant), group in _group_curves(curves).items():
        seeds = sorted(c.config.get("seed") for c in group)
        lines += [f"### {table + ': ' if table else ''}{_label(table, variant)} (seeds {', '.join(map(str, seeds))})", ""]
        # runs with an averaged actor (algo.actor_ema) evaluate it, and the live actor beside it
        live = any("live_eval_mean" in p for c in group for p in c.points)
        lines += ["| steps | seeds | updates | CPU min | mean ± std | best |" + (" live actor |" if live else ""),
                  "|---|---|---|---|---|---|" + ("---|" if live else "")]
        steps = sorted({p["step"] for c in group for p in c.points})
        for step in steps:
            pts = [p for c in group for p in c.points if p["step"] == step]
            means = np.array([p["eval_mean"] for p in pts])
            cpu = np.mean([p["cpu_time"] for p in pts]) / 60
            updates = int(np.mean([p.get("updates", 0) for p in pts]))
            best = max(int(p["eval_best"]) for p in pts)
            row = f"| {step:,} | {len(pts)} | {updates:,} | {cpu:.1f} | {means.mean():.3f} ± {means.std():.3f} | {best} |"
            if live:
                lives = np.array([p["live_eval_mean"] for p in pts if "live_eval_mean" in p])
                row += f" {lives.mean():.3f} ± {lives.std():.3f} |" if len(lives) else " – |"
            lines.append(row)
        if cpu_budget_min is not None:
            lines += ["", f"Within {cpu_budget_min:g} CPU minutes of training, per seed:", "",
                      "| seed | steps | CPU min | wall min | mean | final evaluation? |", "|---|---|---|---|---|---|"]
            picks = []
            for c in sorted(group, key=lambda c: c.config.get("seed")):
                p = c.within_cpu(cpu_budget_min * 60)
                if p is None:
                    lines.append(f"| {c.config.get('seed')} | – | – | – | no evaluation yet | – |")
                    continue
                picks.append(p["eval_mean"])
                lines.append(f"| {c.config.get('seed')} | {p['step']:,} | {p['cpu_time'] / 60:.1f} | "
                             f"{p['wall_time'] / 60:.1f} | {p['eval_mean']:.3f} | {'yes' if p.get('final') else 'no'} |")
            if picks:
                lines += ["", f"Mean over seeds: {np.mean(picks):.3f} ± {np.std(picks):.3f}"]
        lines.append("")
    return "\n".join(lines)


def plot_curves(curves: list[Curve], path: Path) -> Path:
    """Evaluation mean against env steps and against CPU minutes, one colour per variant,
    one line per seed."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4.2), dpi=110)
    axes = fig.subplots(1, 2, sharey=True)
    for i, ((table, variant), group) in enumerate(_group_curves(curves).items()):
        colour = f"C{i % 10}"
        for j, c in enumerate(sorted(group, key=lambda c: c.config.get("seed"))):
            steps = [p["step"] for p in c.points]
            cpu = [p["cpu_time"] / 60 for p in c.points]
            means = [p["eval_mean"] for p in c.points]
            label = f"{table + ': ' if table else ''}{_label(table, variant)}" if j == 0 else None
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


def mean_curve(group: list[Curve]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Steps every run of ``group`` has evaluated at, and the mean and population std over the
    runs of their evaluation means there."""
    common = sorted(set.intersection(*({p["step"] for p in c.points} for c in group))) if group else []
    if not common:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    means = np.array([[next(p["eval_mean"] for p in c.points if p["step"] == s) for s in common] for c in group])
    return np.array(common, dtype=float), means.mean(axis=0), means.std(axis=0)


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


def copy_runs(dirs: list[Path], dest: Path) -> list[Path]:
    """Copy the small files of every finished run under ``dirs`` (no checkpoint) to
    ``dest/<run dir name>/``; the report reads the copies like the originals."""
    import shutil

    runs, _, _ = find_runs(dirs)
    copied = []
    for run in runs:
        target = dest / run.path.name
        target.mkdir(parents=True, exist_ok=True)
        for pattern in SMALL_RUN_FILES:
            for f in run.path.glob(pattern):
                shutil.copy2(f, target / f.name)
        copied.append(target)
    print(f"copied {len(copied)} runs to {dest}", file=sys.stderr)
    return copied


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m billiards.report", description=__doc__.split("\n\n")[0])
    parser.add_argument("dirs", nargs="+", type=Path, help="run or sweep directories (searched recursively)")
    parser.add_argument("--out", type=Path, default=None, help="markdown file (default DIR/report.md or ./report.md)")
    parser.add_argument("--copy-to", type=Path, default=None,
                        help="also copy each finished run's small files (config, evaluations, summary, metrics) "
                             "to COPY_TO/<run name>/, e.g. to commit them under results/")
    parser.add_argument("--curves", action="store_true",
                        help="learning curves: every periodic evaluation per variant (unfinished runs included)")
    parser.add_argument("--cpu-budget", type=float, default=None, metavar="MIN",
                        help="with --curves: each run's last evaluation within MIN CPU minutes of training")
    parser.add_argument("--plot", type=Path, default=None, metavar="FILE.png",
                        help="draw the learning curves against env steps and CPU minutes")
    args = parser.parse_args(argv)
    if args.cpu_budget is not None and (not args.curves or not args.cpu_budget > 0):
        parser.error("--cpu-budget needs --curves and a positive number of minutes")
    if args.copy_to is not None:
        copy_runs(args.dirs, args.copy_to)
    if args.curves or args.plot:
        curves = find_curves(args.dirs)
        if not curves:
            raise SystemExit(f"Error: no eval_history.jsonl under {', '.join(map(str, args.dirs))}")
    if args.plot:
        print(f"(learning curves drawn to {plot_curves(curves, args.plot)})", file=sys.stderr)
    if args.curves:
        text = curves_markdown(curves, args.cpu_budget)
    else:
        text = report(args.dirs)
    out = args.out or (args.dirs[0] / "report.md" if len(args.dirs) == 1 else Path("report.md"))
    out.write_text(text)
    sys.stdout.write(text)
    print(f"\n(written to {out})", file=sys.stderr)


if __name__ == "__main__":
    main()
