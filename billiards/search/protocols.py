"""The paper's two search protocols (Table 6).

* **P1**, random-start throughput: ``n_innings`` innings of ``shots`` shots each from random
  racks, continue-on-miss, all innings stepped together through the search collector; the
  metric is points per inning (out of ``shots``).
* **P3**, long chains: from the canonical rack, shoot until the first miss or foul, capped at
  ``cap`` shots; one chain per seed (the seed drives the proposer's sampling); the metric is the
  chain length (scoring shots before the first failure), mean and longest over seeds.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from billiards.envs import BilliardsEnv
from billiards.physics import DEFAULT_PARAMS, PhysicsParams

from .actors import SearchActor, make_search_collector


@dataclass
class ProtocolResult:
    protocol: str
    mean: float
    std: float
    max: float
    min: float
    values: list  # per inning (P1) or per chain (P3)
    shots: int
    seconds: float
    sims_per_decision: float
    ms_per_decision: float
    extra: dict = field(default_factory=dict)

    def to_json(self, path: str | Path | None = None) -> str:
        text = json.dumps(asdict(self), indent=2)
        if path is not None:
            Path(path).write_text(text + "\n")
        return text


def run_p1(actor: SearchActor, n_innings: int = 100, shots: int = 100, seed: int = 0,
           params: PhysicsParams = DEFAULT_PARAMS, progress: bool = True) -> ProtocolResult:
    """P1: random-start innings of ``shots`` shots (continue-on-miss), points per inning."""
    env = BilliardsEnv(batch_size=[n_innings], start="random", on_miss="continue", max_shots=shots, seed=seed, params=params)
    actor.reseed(seed)
    collector = make_search_collector(env, actor, frames_per_batch=n_innings, total_frames=n_innings * shots)
    score = np.zeros((n_innings, shots), dtype=bool)
    foul = np.zeros((n_innings, shots), dtype=bool)
    predicted = np.zeros((n_innings, shots))
    t0 = time.perf_counter()
    bar = tqdm(total=shots, desc="P1", unit="shot", disable=not progress, mininterval=1.0)
    for t, batch in enumerate(collector):  # one batched step of every inning per iteration
        score[:, t] = batch["next", "score"].reshape(n_innings).numpy()
        foul[:, t] = batch["next", "foul"].reshape(n_innings).numpy()
        predicted[:, t] = batch["search_r1"].reshape(n_innings).numpy()
        bar.update(1)
        bar.set_postfix(points=f"{score[:, : t + 1].sum(1).mean():.2f}/{t + 1}",
                        shots_s=f"{n_innings * (t + 1) / (time.perf_counter() - t0):.0f}")
    bar.close()
    collector.shutdown()
    seconds = time.perf_counter() - t0
    points = score.sum(axis=1).astype(float)
    return ProtocolResult(
        protocol="p1", mean=float(points.mean()), std=float(points.std()), max=float(points.max()),
        min=float(points.min()), values=points.tolist(), shots=n_innings * shots, seconds=seconds,
        sims_per_decision=actor.n_sims / max(actor.n_decisions, 1),
        ms_per_decision=1e3 * seconds / (n_innings * shots),
        extra={"foul_per_shot": float(foul.mean()), "success_per_shot": float(score.mean()),
               # shots whose outcome in the env differed from the search's simulation (must be 0)
               "mispredicted_shots": int((predicted != score - actor.cfg.foul_penalty * foul).sum()),
               "n_innings": n_innings, "shots_per_inning": shots, "seed": seed},
    )


def run_chain(actor: SearchActor, seed: int, cap: int = 10_000, keep_last: int = 6,
              params: PhysicsParams = DEFAULT_PARAMS, bar=None):
    """One P3 chain from the canonical rack: (length, last shots [(positions, action, score)])."""
    actor.reseed(seed)
    env = BilliardsEnv(batch_size=[1], start="canonical", on_miss="reset", max_shots=cap, seed=seed, params=params)
    td = env.reset()
    history: list = []
    length = 0
    while True:
        before = td["positions"][0].numpy().copy()
        td = env.step(actor(td))
        nxt = td["next"]
        scored = bool(nxt["score"].item())
        history.append((before, td["action"][0].numpy().copy(), scored))
        del history[:-keep_last]
        if not scored:
            break
        length += 1
        if bar is not None:
            bar.update(1)
            bar.set_postfix(seed=seed, chain=length)
        if length >= cap:
            break
        td = nxt.select("positions", "shot", "observation").clone()
    return length, history


def run_p3(actor: SearchActor, seeds=range(10), cap: int = 10_000, params: PhysicsParams = DEFAULT_PARAMS,
           progress: bool = True, picture: str | Path | None = None) -> ProtocolResult:
    """P3: canonical-start chains until the first miss or foul (cap ``cap``), one per seed."""
    lengths, longest_history, longest = [], None, -1
    t0 = time.perf_counter()
    bar = tqdm(desc="P3", unit="shot", disable=not progress, mininterval=1.0)
    decisions = 0
    for seed in seeds:
        length, history = run_chain(actor, seed, cap, params=params, bar=bar)
        decisions += actor.n_decisions
        lengths.append(length)
        if length > longest:
            longest, longest_history = length, history
    bar.close()
    seconds = time.perf_counter() - t0
    if picture is not None and longest_history:
        draw_last_shots(longest_history, picture, params, title=f"last shots of the longest chain ({longest} points)")
    arr = np.asarray(lengths, dtype=float)
    return ProtocolResult(
        protocol="p3", mean=float(arr.mean()), std=float(arr.std()), max=float(arr.max()), min=float(arr.min()),
        values=lengths, shots=int(arr.sum() + len(lengths)), seconds=seconds,
        sims_per_decision=actor.cfg.sims_per_decision, ms_per_decision=1e3 * seconds / max(decisions, 1),
        extra={"cap": cap, "seeds": list(seeds), "reached_cap": int((arr >= cap).sum())},
    )


def draw_last_shots(history, path: str | Path, params: PhysicsParams = DEFAULT_PARAMS, title: str = "") -> None:
    """A row of panels, one per shot: (positions, action, scored) tuples from :func:`run_chain`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from billiards.render import draw_shot

    n = len(history)
    fig, axes = plt.subplots(1, n, figsize=(1.9 * n, 3.6), dpi=100, squeeze=False)
    for ax, (positions, action, scored) in zip(axes[0], history):
        draw_shot(ax, positions, action, params)
        ax.set_title("score" if scored else "miss/foul", fontsize=8)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


__all__ = ["ProtocolResult", "draw_last_shots", "run_chain", "run_p1", "run_p3"]
