"""``python -m billiards.campaign status``: per stage, the runs done, started and not started,
the CPU-hours they spent and an estimate of the CPU-hours left, read from the run directories
alone (it can run beside the stages).

CPU-hours spent: a training run's own account (``summary.json``'s ``cpu_seconds``; for an
unfinished run the last ``cpu_time`` of its ``metrics.csv``), a search run's ``seconds``. Left:
the stage's training steps still to go at the paper's budget, at the CPU seconds per step its
runs have measured so far
(nothing measured yet: no estimate); searches are not estimated (a P3 chain ends at its first
miss, which no step count predicts).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

from billiards.report.reproduction import STARTS, Sources, read_json, train_state
from billiards.tables import paper_tables

from .stages import Stage


@dataclass
class StageStatus:
    stage: Stage
    done: list[str] = field(default_factory=list)
    started: list[str] = field(default_factory=list)
    new: list[str] = field(default_factory=list)
    cpu_seconds: float = 0.0
    steps_done: int = 0
    steps_left: int = 0

    @property
    def cpu_hours_left(self) -> float | None:
        if not self.steps_done or not self.cpu_seconds:
            return None if self.steps_left else 0.0
        return self.cpu_seconds / self.steps_done * self.steps_left / 3600


def _progress(run_dir: Path) -> tuple[int, float]:
    """(steps, CPU seconds) of an unfinished training run: the last row of its metrics.csv."""
    try:
        with (run_dir / "metrics.csv").open(newline="") as f:
            rows = [r for r in csv.DictReader(f) if r.get("step") and r.get("cpu_time")]
    except OSError:
        return 0, 0.0
    return (int(float(rows[-1]["step"])), float(rows[-1]["cpu_time"])) if rows else (0, 0.0)


def stage_status(stage: Stage) -> StageStatus:
    table, status = paper_tables()[stage.table], StageStatus(stage)
    src = Sources("", stage.root, stage.root)
    if table.app == "search":
        for proposer, method, protocol in table.search_cells():
            run_dir = src.search_dir(proposer, method, protocol)
            key = str(run_dir.relative_to(stage.root))
            res = read_json(run_dir / "results.json")
            if res is None:
                (status.started if (run_dir / "config.yaml").is_file() else status.new).append(key)
                continue
            status.cpu_seconds += float(res.get("seconds", 0.0))
            (status.started if res.get("extra", {}).get("partial") else status.done).append(key)
        return status
    for row in table.trained():
        for seed in table.seeds:
            run_dir, key = src.train_dir(f"{table.name}/{row}", seed), f"{row}/seed{seed}"
            state = train_state(run_dir)
            steps, cpu = (state.frames, state.cpu_seconds) if state.done else _progress(run_dir)
            status.cpu_seconds += cpu
            status.steps_done += steps
            status.steps_left += 0 if state.done else max(0, (table.steps or 0) - steps)
            started = (run_dir / STARTS).is_file() or (run_dir / "checkpoint.pt").is_file()
            (status.done if state.done else status.started if started else status.new).append(key)
    return status


def status_text(stages: list[Stage], verbose: bool = False) -> str:
    from billiards.report.markdown import md_table

    rows, details, spent, left = [], [], 0.0, 0.0
    for stage in stages:
        s = stage_status(stage)
        hours_left = s.cpu_hours_left
        spent += s.cpu_seconds / 3600
        left += hours_left or 0.0
        total = len(s.done) + len(s.started) + len(s.new)
        rows.append([stage.table, f"{len(s.done)}/{total}", str(len(s.started)), str(len(s.new)),
                     f"{s.cpu_seconds / 3600:.2f}", "–" if hours_left is None else f"{hours_left:.2f}"])
        if verbose:
            details += [f"{stage.table}: started {', '.join(s.started)}" if s.started else "",
                        f"{stage.table}: not started {', '.join(s.new)}" if s.new else ""]
    root = stages[0].root if stages else Path(".")
    text = md_table(["stage", "done", "started", "not started", "CPU-h spent", "CPU-h left (est.)"], rows)
    text += f"\n\nunder {root}: {spent:.2f} CPU-h spent, about {left:.2f} CPU-h of training left\n"
    return text + "".join(d + "\n" for d in details if d)
