"""Training runs as data: find the run directories under some folders, read what each wrote
(``config.yaml``, ``eval.json``, ``summary.json``, ``eval_history.jsonl``), group them by table
and row (``table``, ``row`` in the config; runs of no table by the settings that differ between
them) and aggregate each row over its seeds:

* mean ± std: the mean over seeds of each run's mean points per inning, and the population std
  over seeds (ddof = 0);
* max: the best single inning over all seeds' evaluation innings;
* foul and success percentages: means over seeds.

A run directory that cannot be read is skipped with a warning naming it (and listed by the
report); an unfinished one (no ``eval.json``) is listed as such.
"""

from __future__ import annotations

import json
import sys
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from billiards import compat, files
from billiards.files import CHECKPOINT_FILE, CONFIG_FILE, EVAL_FILE, EVAL_HISTORY_FILE, METRICS_FILE, SUMMARY_FILE

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
        """The table's row this run trains (``row``, recorded by its ``variant=<table>/<row>``),
        else a label made of the settings that tell runs apart."""
        return self.config.get("row") or generic_label(self.config)



# Top-level config keys that never put two runs in different rows: the seed, run-time switches,
# logging and the table label itself. Everything else does, the budget included (total steps,
# CPU minutes, warm-up, the final evaluation's innings): only runs of one configuration share a
# row, and the steps column shows where each stopped.
SAME_ROW_KEYS = ("seed", "resume", "threads", "progress", "compile", "logger", "checkpoint", "table", "paper_steps", "device")
# Budget keys that only set a cadence (how often to log, evaluate on the way, checkpoint).
CADENCE_KEYS = ("budget.name", "budget.eval_every", "budget.eval_innings", "budget.checkpoint_every", "budget.log_every")


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
    else ``{" (algo.lr=0.001, algo.gamma=0.9)": [...], ...}``. Only the keys every config of
    them has are compared (a key that some leave out says nothing about the others)."""
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
        data = files.read_run_json(path)  # the one reader of run-folder files (no link, no FIFO, bounded)
    except files.RunFileError as err:
        raise ValueError(f"{path.name} is not valid JSON, or not a file the report reads ({err})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path.name} is not a JSON object")
    return data


def read_config(run_dir: Path) -> dict:
    """The run's ``config.yaml`` as a dict in today's form (:func:`billiards.compat.upgrade_training_config`);
    ValueError saying what is wrong if it is missing, unparsable or lacks an integer seed."""
    path = run_dir / CONFIG_FILE
    if not path.is_file():
        raise ValueError("no config.yaml (the run's settings)")
    try:
        config = yaml.safe_load(files.read_run_text(path, "config"))
    except yaml.YAMLError as err:
        raise ValueError(f"config.yaml is not valid YAML ({err})") from None
    if not isinstance(config, dict) or not isinstance(config.get("seed"), int):
        raise ValueError("config.yaml is not a training config (no integer seed)")
    return compat.upgrade_training_config(config)


def read_run(run_dir: Path) -> Run | None:
    """The finished run in ``run_dir``, or None if it has no eval.json yet (unfinished).
    Raises ValueError (or OSError) saying what is wrong with a broken one."""
    config = read_config(run_dir)
    eval_path = run_dir / EVAL_FILE
    if not eval_path.is_file():
        return None
    result = compat.upgrade_eval_record(_json_object(eval_path))
    missing = [k for k in EVAL_KEYS if not isinstance(result.get(k), (int, float))]
    if missing:
        raise ValueError(f"eval.json lacks {missing}")
    extra = {p.stem[len("eval_"):]: compat.upgrade_eval_record(_json_object(p)) for p in run_dir.glob("eval_*.json")}
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
    first_miss = [np.mean(e["first_miss_points"]) for e in random_evals if e and e["first_miss_points"]]
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
        # only when every run recorded it (an empty first_miss_points: not recorded)
        "rand_eval": float(np.mean(first_miss)) if first_miss and len(first_miss) == len(runs) else None,
        "seeds": sorted(r.config.get("seed") for r in runs),
        "frames": frames,
        "minutes": float(np.mean(seconds)) / 60 if seconds else None,
        "cpu_minutes": float(np.mean(cpu)) / 60 if cpu else None,
    }


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
        rows = [json.loads(line) for line in files.read_run_text(hist, "ledger").splitlines() if line.strip()]
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


def group_curves(curves: list[Curve]) -> dict[tuple, list[Curve]]:
    groups: dict[tuple, list[Curve]] = defaultdict(list)
    for c in curves:
        groups[(c.table or "", c.variant)].append(c)
    split = {(table, variant + suffix): part for (table, variant), group in groups.items()
             for suffix, part in split_rows(group, lambda c: c.config).items()}
    return dict(sorted(split.items()))


def mean_curve(group: list[Curve]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Steps every run of ``group`` has evaluated at, and the mean and population std over the
    runs of their evaluation means there."""
    common = sorted(set.intersection(*({p["step"] for p in c.points} for c in group))) if group else []
    if not common:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    means = np.array([[next(p["eval_mean"] for p in c.points if p["step"] == s) for s in common] for c in group])
    return np.array(common, dtype=float), means.mean(axis=0), means.std(axis=0)


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
