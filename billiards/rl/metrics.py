"""Metric logging of a training run: ``metrics.csv`` in the run dir, optionally mirrored to
Weights & Biases (offline by default: no login, no prompt, no network) or to TensorBoard event
files in the run dir (TorchRL's ``TensorboardLogger``)."""

from __future__ import annotations

import csv
import math
import numbers
import time
from pathlib import Path
from typing import Any

from billiards.files import atomic_open

from .config import METRICS_FILE, LoggerBackend, wandb_env_defaults

TENSORBOARD_DIR = "tensorboard"  # event files: <run dir>/tensorboard/events.out.tfevents.*
# TensorBoard tags: metrics.csv's columns grouped into sections (eval_mean -> eval/mean ...).
_TB_SECTIONS = (("eval_", "eval/"), ("train_", "train/"))
_TB_SPEED = ("updates", "wall_time", "cpu_time", "fps", "ups")

# Columns of metrics.csv, in order; a row leaves the ones it does not have empty.
BASE_COLUMNS = (
    "step", "updates", "wall_time", "cpu_time", "fps", "ups",
    "train_reward", "train_score_pct", "train_foul_pct",
)
EVAL_COLUMNS = ("eval_mean", "eval_std", "eval_best", "eval_foul_innings_pct", "eval_foul_pct", "eval_success_pct")


def tensorboard_tag(column: str) -> str:
    """The TensorBoard tag of a metrics.csv column: eval_mean -> eval/mean,
    train_reward -> train/reward, fps -> speed/fps, an agent's loss_actor -> agent/loss_actor."""
    for prefix, section in _TB_SECTIONS:
        if column.startswith(prefix):
            return section + column[len(prefix):]
    return ("speed/" if column in _TB_SPEED else "agent/") + column


class MetricLogger:
    """Writes one CSV row per :meth:`log` call (``step`` = env frames so far) and mirrors it
    to wandb (``logger=wandb``) or to TensorBoard event files (``logger=tensorboard``).

    On resume, rows logged after the checkpoint's step (by the killed process) are dropped
    from metrics.csv so that the file reads as one run; the wandb run continues under the
    same id (``resume="allow"``); TensorBoard is told to purge the killed process's events
    after that step (``purge_step``), so its curves read as one run too.
    """

    def __init__(self, cfg, run_dir: Path, metric_names: tuple[str, ...], resume_step: int | None = None,
                 wandb_id: str | None = None):
        self.columns = list(BASE_COLUMNS) + [m for m in metric_names if m not in BASE_COLUMNS] + list(EVAL_COLUMNS)
        backend = LoggerBackend(cfg.logger.backend)
        self.path = run_dir / METRICS_FILE
        self._file = None
        if cfg.logger.csv or backend in (LoggerBackend.wandb, LoggerBackend.tensorboard):
            self._open_csv(resume_step)
        self.wandb = None
        self.wandb_id = wandb_id
        if backend is LoggerBackend.wandb:
            self._init_wandb(cfg, run_dir, wandb_id)
        self.tensorboard = None
        if backend is LoggerBackend.tensorboard:
            self._init_tensorboard(cfg, run_dir, resume_step)

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

    def _init_tensorboard(self, cfg, run_dir: Path, resume_step: int | None) -> None:
        from omegaconf import OmegaConf
        from torchrl.record.loggers.tensorboard import TensorboardLogger

        class _Logger(TensorboardLogger):
            # TorchRL's logger with SummaryWriter's purge_step: a resumed run hides the events
            # the killed process wrote after the checkpoint.
            def _create_experiment(self):
                from torch.utils.tensorboard import SummaryWriter

                purge = None if resume_step is None else resume_step + 1
                return SummaryWriter(log_dir=str(Path(self.log_dir) / self.exp_name), purge_step=purge)

        self.tensorboard = _Logger(exp_name=TENSORBOARD_DIR, log_dir=str(run_dir))
        if resume_step is None:
            yaml = OmegaConf.to_yaml(OmegaConf.to_container(cfg, resolve=True, enum_to_str=True))
            self.tensorboard.experiment.add_text("config", "```\n" + yaml + "```", global_step=0)

    def log(self, row: dict[str, Any]) -> None:
        row = {k: v for k, v in row.items() if v is not None}
        if self._file is not None:
            self._csv.writerow(row)
            self._file.flush()
        if self.wandb is not None:
            self.wandb.log({k: v for k, v in row.items() if k != "step"}, step=int(row["step"]))
        if self.tensorboard is not None:
            step = int(row["step"])
            for k, v in row.items():
                if k != "step" and isinstance(v, numbers.Real):
                    self.tensorboard.log_scalar(tensorboard_tag(k), float(v), step=step)
            self.tensorboard.experiment.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
        if self.wandb is not None:
            self.wandb.finish()
            self.wandb = None
        if self.tensorboard is not None:
            self.tensorboard.experiment.close()
            self.tensorboard = None


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


class Window:
    """Training statistics since the last metric row: frames collected, their reward, score
    and foul sums, the last update's loss outputs (``metrics``), and the update count and
    time at the window's start (for updates and frames per second)."""

    def __init__(self, n_updates: int):
        self.reset(n_updates)

    def reset(self, n_updates: int) -> None:
        self.frames, self.updates0, self.t0 = 0, n_updates, time.perf_counter()
        self.reward = self.score = self.foul = 0.0
        self.metrics: Any = None

    def add(self, data) -> None:
        """Adds a collected batch (its ``("next", "reward" / "score" / "foul")``)."""
        nxt = data.get("next")
        self.add_shots(data.numel(), reward=float(nxt.get("reward").sum()), score=float(nxt.get("score").sum()),
                       foul=float(nxt.get("foul").sum()))

    def add_shots(self, frames: int, *, reward: float, score: float, foul: float) -> None:
        """Adds ``frames`` shots with these sums of reward, score and fouls (a loop without a
        collector: expert iteration's searched shots)."""
        self.frames += frames
        self.reward += reward
        self.score += score
        self.foul += foul

    def ups(self, n_updates: int) -> float:
        return (n_updates - self.updates0) / max(time.perf_counter() - self.t0, 1e-9)

    def row(self, step: int, n_updates: int, times: tuple[float, float], metric_names: tuple[str, ...],
            stage: int | None = None) -> dict[str, Any]:
        """The metrics.csv row at ``step`` frames (``times``: wall-clock and CPU seconds)."""
        dt = max(time.perf_counter() - self.t0, 1e-9)
        n = max(self.frames, 1)
        wall, cpu = times
        row = {
            "step": step,
            "updates": n_updates,
            "wall_time": round(wall, 3),
            "cpu_time": round(cpu, 3),
            "fps": round(self.frames / dt, 1),
            "ups": round((n_updates - self.updates0) / dt, 2),
            "train_reward": self.reward / n,
            "train_score_pct": 100.0 * self.score / n,
            "train_foul_pct": 100.0 * self.foul / n,
        }
        if stage is not None:
            row["stage"] = stage
        if self.metrics is not None:
            keys = self.metrics.keys()
            row.update({k: float(self.metrics[k]) for k in metric_names if k in keys})
        return row
