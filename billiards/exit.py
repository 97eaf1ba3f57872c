"""Expert iteration: the search teaches a policy, the policy proposes for the search
(``python train.py algo=exit env=aim_features``; docs/expert_iteration.md).

A run is rounds of ``algo.shots_per_round`` labelled shots. In a round, blocks of
``algo.innings`` innings (the benchmark's ``innings-v1`` protocol: a random rack, continue on a
miss, 10 shots) are played side by side; at every table the depth-2 lookahead
(:func:`billiards.search.lookahead.h2_values`, ``algo.search_budget`` simulations: ``algo.k1``
candidates, the ``algo.m1`` best expanded) values the proposer's candidates, and the label is
:func:`nearest_best`: among the candidates of the best value, the one nearest the proposer's own
shot (candidate 0). The labelled shot is played, so the tables are those the search visits.
The proposer is the geometric one in round 0 and the policy itself from round 1 on
(:class:`~billiards.search.proposers.PolicyProposer`: its deterministic shot, then draws from
its distribution; from round 0 on where ``algo.init_policy`` names a trained policy to start
from): the label is the search's improvement of the policy's own shot, the nearest
one that does best, which keeps the targets one function of the table where plain imitation of
the search's choice averages over its many equally good shots.

Under execution noise (``noise=fastfiz`` or ``fastfiz_x5``) the labeller is what ``search.py``
plays under that noise over its shot ranker (:func:`noisy_search`: the position-aware robust search with its table
value, ``algo.search_budget`` simulations), its proposer in round 0 the preset's shot ranker;
the label is the search's chosen shot (:func:`noisy_labels`; with ``algo.label_tolerance`` > 0
the proposer's own shot where the chosen one's statistic beats it by no more), played with the noise. With
``algo.policy_share`` < 1 the policy proposes that share of the candidates from round 1 on and
round 0's proposer the rest (:class:`~billiards.search.proposers.MixedProposer`), so the
labeller never loses the candidates it started from. After the round's last block,
``algo.epochs`` passes of maximum likelihood (:class:`~billiards.rl.learners.ExItAgent`) over the
last ``algo.buffer_size`` labelled shots, continuing from the round before.

Everything else is the trainer's: the run directory, ``resume=``, checkpoints (the labelled
shots included) every ``budget.checkpoint_every`` shots and on a stop request at a block's end
or between two updates, the periodic and final evaluations of the policy alone
(``eval.json``), ``metrics.csv`` (``train_score_pct``: the searched shots' success),
``summary.json``. Rack and search seeds come from the run's seed and the block's index
(:data:`EXIT_SEED`, far from every benchmark track's held-out seeds), so a resumed run labels
exactly what the uninterrupted one did.
"""

from __future__ import annotations

import logging

import numpy as np
import torch
from tensordict import TensorDict

from billiards import domain
from billiards.physics import PhysicsParams, simulate_batch
from billiards.physics.config import params_from_config
from billiards.physics.noise import noise_from_config
from billiards.rl.config import EXIT_SHOTS
from billiards.rl.train import Run, StopRequests, after_updates, finish, gradient_updates, session
from billiards.search.lookahead import h2_values
from billiards.search.proposers import GeometricProposer, MixedProposer, PolicyProposer
from billiards.search.settings import H2Config

log = logging.getLogger("billiards.exit")

EXIT_SEED = 20_000_000  # inning i of seed s plays the rack of EXIT_SEED + 10,000,000 s + i


def nearest_best(positions: np.ndarray, proposer, cfg: H2Config, rng: np.random.Generator, params: PhysicsParams):
    """The depth-2 lookahead's labels for tables (S, 4, 2): among the expanded candidates of the
    best value (:func:`~billiards.search.lookahead.h2_values`; all candidates by r1 without
    expansion), the one nearest candidate 0 (the proposer's own shot) in the normalised
    aim-constrained action (:func:`billiards.domain.normalized_aim_action`; ties: proposer order). Returns
    ``(raw shots (S, 4), targets (S, 4), simulations)``."""
    v = h2_values(positions, proposer, cfg, rng, params)
    S = positions.shape[0]
    rows = np.arange(S)[:, None]
    x = domain.normalized_aim_action(positions[:, None], v.candidates, params.ball_radius)  # (S, K1, 4)
    if v.top.shape[1]:
        pool, value = v.top, v.value
    else:
        pool, value = np.broadcast_to(np.arange(v.r1.shape[1]), v.r1.shape), v.r1
    distance = np.linalg.norm(x[rows, pool] - x[:, :1], axis=-1)
    distance = np.where(value >= value.max(axis=1, keepdims=True), distance, np.inf)
    pick = pool[rows[:, 0], np.argmin(distance, axis=1)]
    return v.candidates[rows[:, 0], pick], x[rows[:, 0], pick], v.n_sims


def centred(positions: np.ndarray, raw: np.ndarray, x: np.ndarray, probes: int, scale: float, rng: np.random.Generator,
            params: PhysicsParams) -> tuple[np.ndarray, np.ndarray, int]:
    """Labels ``x`` (S, 4) in the normalised aim-constrained action (the raw shots ``raw``) on
    tables (S, 4, 2) moved to the centre of the region of good shots around them: ``probes``
    draws of x + ``scale`` * N(0, 1) (clipped to the box) are played; the label becomes the mean of itself and the probes that
    score without a foul, where the label itself does and that mean does too, and stays
    otherwise. A label at the edge of a narrow region is the least forgiving target a policy can
    imitate; the centre keeps the shot the search chose and tolerates the policy's error
    (results/exit/README.md). Returns ``(raw shots (S, 4), labels (S, 4), simulations)``."""
    S, R = x.shape[0], params.ball_radius
    inside = np.clip(x, -1.0, 1.0)
    trial = np.concatenate([inside[:, None], np.clip(inside[:, None] + scale * rng.standard_normal((S, probes, 4)), -1.0, 1.0)], 1)
    shots = domain.raw_action(trial, positions[:, None], R, constrain_aim=True, normalized=True)
    res = simulate_batch(np.repeat(positions, probes + 1, axis=0), shots.reshape(-1, 4), params)
    good = ((res.score > 0) & ~res.foul).reshape(S, probes + 1)
    centre = (trial * good[..., None]).sum(1) / np.maximum(good.sum(1), 1)[:, None]
    moved = domain.raw_action(centre, positions, R, constrain_aim=True, normalized=True)
    check = simulate_batch(positions, moved, params)
    keep = (good[:, 0] & (check.score > 0) & ~check.foul)[:, None]
    return np.where(keep, moved, raw), np.where(keep, centre, x), S * (probes + 2)


def labeller(run: Run, round_index: int, params: PhysicsParams, first=None):
    """The proposer of round ``round_index``: ``first`` in round 0 (default: the geometric
    proposer), then the policy (built anew: the batched proposer copies the weights), with
    ``algo.policy_share`` < 1 sharing the candidates with ``first`` (the policy's first). A run
    with ``algo.init_policy`` starts from a trained policy, which proposes from round 0 on."""
    first = first if first is not None else GeometricProposer(R=params.ball_radius)
    if round_index == 0 and run.cfg.algo.init_policy is None:
        return first
    policy = PolicyProposer([run.agent.policy], constrain_aim=True, extra_features=bool(run.cfg.env.extra_features),
                            name="exit", R=params.ball_radius)
    share = float(run.cfg.algo.policy_share)
    return policy if share >= 1.0 else MixedProposer(policy, first, share, name="exit")


def noisy_search(run: Run, params: PhysicsParams, noise):
    """The labeller under execution noise: what ``python search.py noise=<the run's preset>
    search.budget=<algo.search_budget> proposer=for_noise_<preset>`` plays (the position-aware
    robust search, its value and settings: docs/search.md), over the policy from round 1 on;
    round 0's proposer is the preset's shot ranker. Returns ``(actor, round 0's proposer)``."""
    from billiards.search.config import labelling_search
    from billiards.search.run import make_actor, make_proposer

    scfg = labelling_search(run.cfg)
    first = make_proposer(scfg.proposer, params)
    return make_actor(scfg, first, params, noise=noise), first


def noisy_labels(positions: np.ndarray, actor, proposer, rng: np.random.Generator, params: PhysicsParams,
                 tolerance: float = 0.0):
    """The noisy search's labels for tables (S, 4, 2): its chosen shot (the best by the
    statistic over noisy replays: the replays rarely tie), or, where that statistic beats the
    proposer's own shot's (candidate 0) by no more than ``tolerance``, that own shot (the
    policy's shot where the search cannot tell it from the best). Returns ``(raw shots (S, 4),
    targets (S, 4), simulations)``."""
    result = actor.search_with(positions, proposer, rng)
    actions = result.actions
    if tolerance > 0:
        actions = np.where((result.own_margin <= tolerance)[:, None], result.own, actions)
    return actions, domain.normalized_aim_action(positions, actions, params.ball_radius), result.n_sims


def play_block(run: Run, block: int, proposer, search, params: PhysicsParams, noise=None) -> tuple[TensorDict, int, int]:
    """Block ``block`` of the run (``algo.innings`` innings of :data:`EXIT_SHOTS` shots): every
    table's observation and label, and how many of the played shots scored and how many fouled.
    ``search``: the exact lookahead's settings (:class:`H2Config`, labels by :func:`nearest_best`)
    or, under execution ``noise`` (a NoiseModel the shots are played with), the noisy search's
    actor (:func:`noisy_search`, labels by :func:`noisy_labels`)."""
    from billiards.envs.gym_vector import Billiards4BallVectorEnv

    cfg, a = run.cfg, run.cfg.algo
    env = Billiards4BallVectorEnv(a.innings, start="random", on_miss="continue", max_shots=EXIT_SHOTS, physics=params,
                                  noise=noise, normalize_actions=False)
    _, info = env.reset(seed=EXIT_SEED + 10_000_000 * int(cfg.seed) + block * a.innings)
    rng = np.random.default_rng([int(cfg.seed), block])
    positions, observations, targets, scored, fouls = info["positions"], [], [], 0, 0
    for _ in range(EXIT_SHOTS):
        if isinstance(search, H2Config):
            raw, x, _ = nearest_best(positions, proposer, search, rng, params)
            if a.centre_probes:
                raw, x, _ = centred(positions, raw, x, int(a.centre_probes), float(a.centre_scale), rng, params)
        else:
            raw, x, _ = noisy_labels(positions, search, proposer, rng, params, float(a.label_tolerance))
        observations.append(domain.observation(positions, bool(cfg.env.extra_features)))
        targets.append(x.astype(np.float32))
        _, _, _, _, info = env.step(raw)
        scored += int(info["score"].sum())
        fouls += int(info["foul"].sum())
        positions = info["positions"]
    data = TensorDict({"observation": torch.from_numpy(np.concatenate(observations)),
                       "target": torch.from_numpy(np.concatenate(targets))}, batch_size=[a.innings * EXIT_SHOTS])
    return data.to(run.device), scored, fouls


def train_exit(run: Run) -> float:
    """Expert iteration to the budget (the module docstring); returns the final mean points per
    inning of the policy alone."""
    cfg, rb, state = run.cfg, run.rb, run.state
    a = cfg.algo
    params, noise = params_from_config(cfg.physics), noise_from_config(cfg.noise)
    if noise.is_exact:
        search, first = H2Config(budget=a.search_budget, k1=a.k1, m1=a.m1).settings(), None
    else:
        search, first = noisy_search(run, params, noise)
    if a.init_policy is not None and state.frames == 0 and run.agent.n_updates == 0:  # a fresh run (a resumed one has its own)
        from billiards.rl.policy import init_actor_state

        run.agent.actor.load_state_dict(init_actor_state(a.init_policy))
        log.info("the policy starts from %s", a.init_policy)
    block_shots = a.innings * EXIT_SHOTS
    with session(run) as bar, StopRequests() as stop:
        spent = False
        if state.owed >= 1:  # stopped amid a round's updates: the rest first, as the uninterrupted run made them
            spent = after_updates(run, bar, stop, gradient_updates(run, stop, state.take_updates(0.0)), 0)
        proposers: dict[int, object] = {}  # the round's proposer, built at its first block (the weights of that round)
        while not (spent or run.budget_spent()):
            round_index = state.frames // a.shots_per_round
            if round_index not in proposers:
                proposers = {round_index: labeller(run, round_index, params, first)}
            data, scored, fouls = play_block(run, state.frames // block_shots, proposers[round_index], search, params,
                                             None if noise.is_exact else noise)
            rb.extend(data)
            state.frames += block_shots
            run.window.add_shots(block_shots, reward=scored, score=scored, foul=fouls)
            complete = True
            if state.frames % a.shots_per_round == 0 or run.budget_spent():  # the round's end: learn
                log.info("round %d: the search scored %.2f %% of the block's shots; %d labelled shots kept",
                         round_index, 100.0 * scored / block_shots, len(rb))
                complete = gradient_updates(run, stop, state.take_updates(a.epochs * len(rb) / a.batch_size))
            spent = after_updates(run, bar, stop, complete, block_shots)
        return finish(run, bar)


def _history(run_dir) -> list[dict]:
    import json
    from pathlib import Path

    return [json.loads(line) for line in (Path(run_dir) / "eval_history.jsonl").read_text().splitlines()]


def learning_curve(run_dirs, sac_dirs, out) -> dict:
    """The figure of expert iteration's learning (``out``, PNG) and its data: per-shot success
    of the policy alone (each evaluation of ``eval_history.jsonl``) and of the search over it
    (``metrics.csv``'s ``train_score_pct``: the labelled shots as played), against process
    CPU hours, beside the evaluations of SAC runs (``sac_dirs``) on the same axis. A run started
    from a trained policy (``algo.init_policy``) starts at that policy's training CPU hours."""
    import csv
    from pathlib import Path

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from omegaconf import OmegaConf

    from billiards.files import display_path
    from billiards.rl.policy import policy_summary

    data = {"exit": [], "sac": []}
    first = OmegaConf.load(Path(run_dirs[0]) / "config.yaml")  # the runs' noise and labeller, named in the figure
    preset, budget = str(first.noise.preset), int(first.algo.search_budget)
    searcher = (f"h2 ({budget} sims) over the policy" if preset == "none" else
                f"the position-aware robust search ({budget} sims) over the policy"
                + (" and the shot ranker" if float(first.algo.get("policy_share", 1.0)) < 1.0 else ""))
    fig, ax = plt.subplots(figsize=(7.5, 4.2), dpi=120)
    for i, d in enumerate(run_dirs):
        start = OmegaConf.load(Path(d) / "config.yaml").algo.get("init_policy")
        # a run from a trained policy starts at that policy's own training CPU time
        hours = float(policy_summary(start).get("cpu_seconds", 0.0)) / 3600 if start else 0.0
        alone = [(hours + e["cpu_time"] / 3600, e["eval_success_pct"]) for e in _history(d)]
        with (Path(d) / "metrics.csv").open(newline="") as f:
            searched = [(hours + float(r["cpu_time"]) / 3600, float(r["train_score_pct"])) for r in csv.DictReader(f)
                        if r.get("train_score_pct")]
        data["exit"].append({"run": display_path(d), "policy_alone": alone, "search_over_policy": searched,
                             "init_policy": start, "init_cpu_hours": hours})
        ax.plot(*zip(*alone), "o-", color="tab:blue", ms=3, label="expert iteration: the policy alone" if i == 0 else None)
        ax.plot(*zip(*searched), "s--", color="tab:green", ms=3,
                label=f"expert iteration: {searcher}" if i == 0 else None)
    for i, d in enumerate(sac_dirs):
        curve = [(e["cpu_time"] / 3600, e["eval_success_pct"]) for e in _history(d)]
        data["sac"].append({"run": display_path(d), "policy_alone": curve})
        ax.plot(*zip(*curve), "-", color="tab:orange", alpha=0.7, label="SAC aim + features (1 CPU hour)" if i == 0 else None)
    ax.set_xlabel("process CPU hours")
    ax.set_ylabel("success per shot (%)")
    ax.set_ylim(0, 101)
    ax.grid(alpha=0.3)
    ax.legend(loc="center right", fontsize=8)
    play = "exact play" if preset == "none" else f"{preset} execution noise"
    ax.set_title(f"Expert iteration{' against SAC' if sac_dirs else ''}, {play} (random racks, continue on a miss)", fontsize=9)
    fig.tight_layout()
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return data


def main(argv=None) -> None:
    import argparse
    import json
    from pathlib import Path

    from billiards.files import atomic_write_text

    parser = argparse.ArgumentParser(prog="python -m billiards.exit", description="Expert iteration's learning curve.")
    sub = parser.add_subparsers(dest="command", required=True)
    curve = sub.add_parser("curve", help="the figure of expert-iteration runs beside SAC runs, and its data (.json)")
    curve.add_argument("runs", nargs="+", type=Path, help="expert-iteration run dirs")
    curve.add_argument("--sac", nargs="*", type=Path, default=[], help="SAC run dirs (eval_history.jsonl)")
    curve.add_argument("--out", type=Path, required=True, help="the figure (.png); its data beside it (.json)")
    args = parser.parse_args(argv)
    for d in [*args.runs, *args.sac]:
        if not (d / "eval_history.jsonl").is_file():
            raise SystemExit(f"Error: {d} holds no eval_history.jsonl (not a training run)")
    data = learning_curve(args.runs, args.sac, args.out)
    atomic_write_text(args.out.with_suffix(".json"), json.dumps(data, indent=1) + "\n")
    print(f"wrote {args.out} and {args.out.with_suffix('.json')}")


__all__ = ["EXIT_SEED", "labeller", "learning_curve", "nearest_best", "play_block", "train_exit"]


if __name__ == "__main__":
    main()
