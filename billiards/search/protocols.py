"""The paper's two search protocols (Table 6).

* **P1**, random-start throughput: ``n_innings`` innings of ``shots`` shots each from random
  racks, continue-on-miss, all innings stepped together through the search collector; the
  metric is points per inning (out of ``shots``).
* **P3**, long chains: from the canonical rack, shoot until the first miss or foul, capped at
  ``cap`` shots; one chain per seed (the seed drives the proposer's sampling); the metric is the
  chain length (scoring shots before the first failure), mean and longest over seeds.

Under execution noise (``noise=``, :mod:`billiards.physics.noise`) the env plays the commanded
shot perturbed by its own generator, seeded from the protocol's seed (P1: ``seed``; P3: each
chain's seed), so the same seed replays the same noisy innings and chains. P3 records the
commanded and the played action of each kept shot. Under variable noise (``noise=variable``)
the env draws each shot's level from that generator and hands it to the search with the table
(``"noise_level"``).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from billiards import domain
from billiards.envs import BilliardsEnv
from billiards.physics import DEFAULT_PARAMS, PhysicsParams
from billiards.files import CHAINS, CHAINS_FILE, append_record, read_ledger
from billiards.physics.noise import get_noise
from billiards.protocol import Protocol

from .actors import SearchActor, make_search_collector


@dataclass
class ProtocolResult:
    protocol: Protocol
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
           params: PhysicsParams = DEFAULT_PARAMS, progress: bool = True, noise=None) -> ProtocolResult:
    """P1: random-start innings of ``shots`` shots (continue-on-miss), points per inning.

    All innings advance together, one shot per step. Interrupted (Ctrl-C), it returns what the
    finished steps give, marked ``extra["partial"]`` with ``extra["shots_done"]`` per inning (a
    P1 cannot be continued: a new run starts it again)."""
    noise = get_noise(noise)
    spec = Protocol.P1.spec
    env = BilliardsEnv(batch_size=[n_innings], start=spec.start, on_miss=spec.on_miss, max_shots=shots, seed=seed, params=params,
                       noise=noise)
    actor.reseed(seed)
    collector = make_search_collector(env, actor, frames_per_batch=n_innings, total_frames=n_innings * shots)
    score = np.zeros((n_innings, shots), dtype=bool)
    foul = np.zeros((n_innings, shots), dtype=bool)
    predicted = np.zeros((n_innings, shots))
    t0 = time.perf_counter()
    bar = tqdm(total=shots, desc="P1", unit="shot", disable=not progress, mininterval=1.0)
    done = 0
    try:
        for t, batch in enumerate(collector):  # one batched step of every inning per iteration
            score[:, t] = batch["next", "score"].reshape(n_innings).numpy()
            foul[:, t] = batch["next", "foul"].reshape(n_innings).numpy()
            predicted[:, t] = batch["search_r1"].reshape(n_innings).numpy()
            done = t + 1
            bar.update(1)
            bar.set_postfix(points=f"{score[:, : t + 1].sum(1).mean():.2f}/{t + 1}",
                            shots_s=f"{n_innings * (t + 1) / (time.perf_counter() - t0):.0f}")
    except KeyboardInterrupt:
        pass
    bar.close()
    collector.shutdown()
    seconds = time.perf_counter() - t0
    score, foul, predicted = score[:, :done], foul[:, :done], predicted[:, :done]
    points = score.sum(axis=1).astype(float)
    extra = {"foul_per_shot": float(foul.mean()) if done else float("nan"),
             "success_per_shot": float(score.mean()) if done else float("nan"),
             "n_innings": n_innings, "shots_per_inning": shots, "seed": seed}
    if noise.is_exact:  # shots whose outcome in the env differed from the search's simulation (must be 0)
        extra["mispredicted_shots"] = int((predicted != domain.shot_reward(score, foul, actor.cfg.foul_penalty)).sum())
    else:  # the search's own estimate of the chosen shots' immediate reward, against what they got
        extra.update(noise=noise.describe(), predicted_r1_mean=float(predicted.mean()) if done else float("nan"),
                     reward_mean=float(domain.shot_reward(score, foul, actor.cfg.foul_penalty).mean()) if done else float("nan"))
    if done < shots:
        extra.update(partial=True, shots_done=done)
    return ProtocolResult(
        protocol=Protocol.P1, mean=float(points.mean()), std=float(points.std()), max=float(points.max()),
        min=float(points.min()), values=points.tolist(), shots=n_innings * done, seconds=seconds,
        sims_per_decision=actor.n_sims / max(actor.n_decisions, 1),
        ms_per_decision=1e3 * seconds / max(n_innings * done, 1), extra=extra,
    )


def run_chain(actor: SearchActor, seed: int, cap: int = 10_000, keep_last: int = 6,
              params: PhysicsParams = DEFAULT_PARAMS, bar=None, noise=None):
    """One P3 chain from the canonical rack: (length, last shots [(positions, action, score)],
    under noise [(positions, commanded action, score, played action)], under variable noise
    [(..., played action, the shot's level)])."""
    actor.reseed(seed)
    noise = get_noise(noise)
    spec = Protocol.P3.spec
    env = BilliardsEnv(batch_size=[1], start=spec.start, on_miss=spec.on_miss, max_shots=cap, seed=seed, params=params,
                       noise=noise)
    td = env.reset()
    history: list = []
    length = 0
    while True:
        before = td["positions"][0].numpy().copy()
        level = td["noise_level"][0].numpy().copy() if noise.is_variable else None  # the level the env told
        td = env.step(actor(td))
        nxt = td["next"]
        scored = bool(nxt["score"].item())
        shot = (before, td["action"][0].numpy().copy(), scored)
        if not noise.is_exact:
            shot += (nxt["played_action"][0].numpy().copy(),)
        if level is not None:
            shot += (level.reshape(()),)
        history.append(shot)
        del history[:-keep_last]
        if not scored:
            break
        length += 1
        if bar is not None:
            bar.set_postfix(seed=seed, chain=length, refresh=False)
        if length >= cap:
            break
        td = nxt.select("positions", "shot", "observation", *(["noise_level"] if noise.is_variable else [])).clone()
    return length, history


def read_chains(path: str | Path | None, run: str | None = None, *, repair: bool = False) -> dict[int, dict]:
    """The finished chains of a P3 ledger (``chains.jsonl``), by seed: every line a sealed chain
    record of the run ``run`` (None: of one run, whichever), each seed once
    (:func:`billiards.files.read_ledger`; :class:`billiards.files.LedgerError` naming the file
    and the line otherwise). A torn last line (a kill mid-append) is left out; with ``repair``
    (the resume path) it is cut off the file, so its chain is played again. (A read-only view of
    any ledger: :func:`billiards.compat.ledger_records`.)"""
    if path is None:
        return {}
    return {r["seed"]: r for r in read_ledger(path, CHAINS, run, repair=repair).records}


def run_p3(actor: SearchActor, seeds=range(10), cap: int = 10_000, params: PhysicsParams = DEFAULT_PARAMS,
           progress: bool = True, picture: str | Path | None = None, ledger: str | Path | None = None,
           noise=None, run: str | None = None) -> ProtocolResult:
    """P3: canonical-start chains until the first miss or foul (cap ``cap``), one per seed.

    With a ``ledger`` file, each finished chain is appended to it as it ends, sealed with the
    run's identity ``run`` (:func:`billiards.files.run_identity` of the settings that determine
    the chains; required with a ledger), and chains already in it are not played again: an
    interrupted P3 keeps every finished chain and continues from the next seed (each chain
    depends only on its seed, so the result is the same as one uninterrupted run). A ledger line
    that is unsealed, edited, of another run or a repeated seed is refused
    (:class:`billiards.files.LedgerError`); a torn last line is cut off and its chain played again."""
    seeds = list(seeds)
    if ledger is not None and run is None:
        raise ValueError("run_p3 with a ledger needs the run's identity (run=billiards.files.run_identity(settings))")
    done = {s: r for s, r in read_chains(ledger, run, repair=True).items() if s in seeds}
    todo = [s for s in seeds if s not in done]
    if progress and todo:  # how long it may take, said before it starts (each chain reseeds the actor: no effect on results)
        ms = _ms_per_decision(actor, params)
        print(f"P3: {len(todo)} chain{'s' if len(todo) > 1 else ''} to play, each up to {cap:,} shots; at about {ms:.1f} ms a "
              f"shot on the opening rack, {_duration(len(todo) * cap * ms / 1e3)} (most chains end far sooner)",
              flush=True)
    bar = tqdm(total=len(seeds), initial=len(done), desc="P3 chains", unit="chain", disable=not progress, mininterval=1.0)
    for seed in seeds:
        if seed in done:
            continue
        t0 = time.perf_counter()
        length, history = run_chain(actor, seed, cap, params=params, bar=bar, noise=noise)
        rec = {"seed": seed, "length": length, "decisions": actor.n_decisions, "seconds": time.perf_counter() - t0,
               "last_shots": [[pos.tolist(), act.tolist(), bool(scored), *(p.tolist() for p in played)]
                              for pos, act, scored, *played in history]}
        if ledger is not None:
            rec = append_record(Path(ledger), rec, run)
        done[seed] = rec
        bar.update(1)
        ms = 1e3 * rec["seconds"] / max(rec["decisions"], 1)
        bar.set_postfix(seed=seed, chain=length, ms_shot=f"{ms:.1f}")
        left = sum(1 for s in seeds if s not in done)
        if progress and left and len(done) == 1:
            bar.write(f"P3: {ms:.1f} ms per shot; {_chains_left(left)} {_duration(left * cap * ms / 1e3)} "
                      f"(if every one reaches the {cap:,}-shot cap)")
    bar.close()
    recs = [done[s] for s in seeds]
    if picture is not None:
        best = max(recs, key=lambda r: r["length"])
        history = [(np.asarray(p), np.asarray(a), s) for p, a, s, *_ in best["last_shots"]]
        if history:
            draw_last_shots(history, picture, params, title=f"last shots of the longest chain ({best['length']} points)")
    return _p3_result(recs, cap, actor.cfg.sims_per_decision)


def _ms_per_decision(actor: SearchActor, params: PhysicsParams, decisions: int = 3) -> float:
    """The actor's milliseconds per decision on the opening rack (after one untimed decision)."""
    from billiards.physics.api import canonical_rack

    table = canonical_rack(params)[None]
    noise = getattr(actor, "noise", None)
    args = (np.array([sum(noise.level_range) / 2]),) if noise is not None and noise.is_variable else ()  # a mid level
    actor.search(table, *args)
    t0 = time.perf_counter()
    for _ in range(decisions):
        actor.search(table, *args)
    return 1e3 * (time.perf_counter() - t0) / decisions


def _chains_left(n: int) -> str:
    return "the chain left takes" if n == 1 else f"the {n} chains left take"


def _duration(seconds: float) -> str:
    """An upper bound in words: "under a minute", "at most 12 min", "at most 3.5 h"."""
    if seconds < 60:
        return "under a minute"
    if seconds < 5400:
        return f"at most {seconds / 60:.0f} min"
    return f"at most {seconds / 3600:.1f} h"


def _p3_result(recs: list[dict], cap: int, sims_per_decision: float, partial: bool = False) -> ProtocolResult:
    arr = np.asarray([r["length"] for r in recs], dtype=float)
    seconds = sum(r["seconds"] for r in recs)
    decisions = sum(r["decisions"] for r in recs)
    extra = {"cap": cap, "seeds": [r["seed"] for r in recs], "reached_cap": int((arr >= cap).sum())}
    if partial:
        extra["partial"] = True
    if not recs:
        return ProtocolResult(Protocol.P3, float("nan"), float("nan"), float("nan"), float("nan"), [], 0, 0.0,
                              sims_per_decision, float("nan"), extra)
    return ProtocolResult(
        protocol=Protocol.P3, mean=float(arr.mean()), std=float(arr.std()), max=float(arr.max()), min=float(arr.min()),
        values=[int(v) for v in arr], shots=int(arr.sum() + len(recs)), seconds=seconds,
        sims_per_decision=sims_per_decision, ms_per_decision=1e3 * seconds / max(decisions, 1), extra=extra,
    )


def partial_p3(ledger: str | Path, seeds, cap: int, sims_per_decision: float, run: str | None = None) -> ProtocolResult:
    """The result of the chains a ledger (of the run ``run``) holds so far, marked ``extra["partial"]``."""
    done = read_chains(ledger, run)
    return _p3_result([done[s] for s in seeds if s in done], cap, sims_per_decision, partial=True)


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


__all__ = ["CHAINS_FILE", "ProtocolResult", "draw_last_shots", "partial_p3", "read_chains", "run_chain", "run_p1", "run_p3"]
