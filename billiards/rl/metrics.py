"""Metric logging of a training run: ``metrics.csv`` in the run dir, optionally mirrored to
Weights & Biases (offline by default: no login, no prompt, no network)."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

from billiards.files import atomic_open

from .config import METRICS_FILE, LoggerBackend, wandb_env_defaults

# Columns of metrics.csv, in order; a row leaves the ones it does not have empty.
BASE_COLUMNS = (
    "step", "updates", "wall_time", "cpu_time", "fps", "ups",
    "train_reward", "train_score_pct", "train_foul_pct",
)
EVAL_COLUMNS = ("eval_mean", "eval_std", "eval_best", "eval_foul_innings_pct", "eval_foul_pct", "eval_success_pct")


class MetricLogger:
    """Writes one CSV row per :meth:`log` call (``step`` = env frames so far) and mirrors it
    to wandb when ``cfg.logger.backend == "wandb"``.

    On resume, rows logged after the checkpoint's step (by the killed process) are dropped
    from metrics.csv so that the file reads as one run; the wandb run continues under the
    same id (``resume="allow"``).
    """

    def __init__(self, cfg, run_dir: Path, metric_names: tuple[str, ...], resume_step: int | None = None,
                 wandb_id: str | None = None):
        self.columns = list(BASE_COLUMNS) + [m for m in metric_names if m not in BASE_COLUMNS] + list(EVAL_COLUMNS)
        backend = LoggerBackend(cfg.logger.backend)
        self.path = run_dir / METRICS_FILE
        self._file = None
        if cfg.logger.csv or backend is LoggerBackend.wandb:
            self._open_csv(resume_step)
        self.wandb = None
        self.wandb_id = wandb_id
        if backend is LoggerBackend.wandb:
            self._init_wandb(cfg, run_dir, wandb_id)

    def _open_csv(self, resume_step: int | None) -> None:
        """Write the header (and on resume the rows kept) atomically, so a kill while a resume
        rewrites the file leaves the old file, never an empty one; then append to it."""
        rows = []
        if resume_step is not None and self.path.is_file():
            with self.path.open(newline="") as f:
                rows = [r for r in csv.DictReader(f) if _row_step(r) <= resume_step]
        with atomic_open(self.path, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=self.columns, extrasaction="ignore")
            writer.writeheader()
            writer.writerows(rows)
        self._file = self.path.open("a", newline="")
        self._csv = csv.DictWriter(self._file, fieldnames=self.columns, extrasaction="ignore")

    def _init_wandb(self, cfg, run_dir: Path, wandb_id: str | None) -> None:
        wandb_env_defaults()
        import wandb
        from omegaconf import OmegaConf

        self.wandb = wandb.init(
            project=cfg.logger.project,
            entity=cfg.logger.entity,
            group=cfg.logger.group or cfg.table,
            mode=cfg.logger.mode.value if hasattr(cfg.logger.mode, "value") else str(cfg.logger.mode),
            dir=str(run_dir),
            name=run_dir.name,
            id=wandb_id,
            resume="allow" if wandb_id else None,
            config=OmegaConf.to_container(cfg, resolve=True, enum_to_str=True),
            settings=wandb.Settings(silent=True, console="off", disable_git=True, x_disable_stats=True),
        )
        self.wandb_id = self.wandb.id

    def log(self, row: dict[str, Any]) -> None:
        row = {k: v for k, v in row.items() if v is not None}
        if self._file is not None:
            self._csv.writerow(row)
            self._file.flush()
        if self.wandb is not None:
            self.wandb.log({k: v for k, v in row.items() if k != "step"}, step=int(row["step"]))

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
        if self.wandb is not None:
            self.wandb.finish()
            self.wandb = None


def _row_step(row: dict) -> float:
    """A metrics.csv row's step; inf (never kept on resume) for a row cut short -- the last
    line a killed process was writing -- or without a numeric step."""
    if None in row.values() or None in row:
        return math.inf
    try:
        return float(row["step"])
    except (KeyError, TypeError, ValueError):
        return math.inf


def eval_row(result) -> dict[str, float]:
    """The EVAL_COLUMNS of an :class:`billiards.evaluation.EvalResult`."""
    return {
        "eval_mean": result.mean,
        "eval_std": result.std,
        "eval_best": result.best,
        "eval_foul_innings_pct": result.foul_innings_pct,
        "eval_foul_pct": result.foul_per_shot_pct,
        "eval_success_pct": result.success_per_shot_pct,
    }
