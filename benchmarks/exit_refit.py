"""Is the expert-iteration policy limited by its network or by its labels? Fit a policy again
to a run's labelled shots and play it.

    python benchmarks/exit_refit.py <exit run dir> --hidden 512 512 512 --start fresh --epochs 30 --out refit.json

Reads the labelled shots a run's checkpoint keeps (``algo.buffer_size`` of them: observations
and targets, ``python train.py algo=exit ...``), holds out 10,000 of them, and trains a policy
on the rest by the run's own loss (:class:`billiards.rl.learners.ExItAgent`, ``algo.nll_beta``
included) with Adam and a cosine learning rate from ``--lr`` to ``--lr-end``: from the run's
policy (``--start run``) or from new weights of ``--hidden`` layers (``--start fresh``). Every
``--every`` epochs (and before the first) it reports, on 10,000 training rows and on the held-out
ones, how far the policy's shot (its deterministic action) lies from the label (the median and
90th percentile of |u| and the share within 0.003 in u and in every coordinate), and the policy's
per-shot success on the run's evaluation protocol (``--innings`` innings, the run's evaluation
seed: the policy alone, no simulator at decision time).

Training rows that the network fits no better than held-out ones, and a success that stays where
the run's own policy is, say the limit is the labels' precision, not the network or the updates.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from _shots import git_commit, write_json  # noqa: E402

HELD_OUT = 10_000
PRECISE = 0.003  # in the normalised action: a shot this close to a label scores about 90 % as often (results/exit)


def main(argv=None) -> None:
    import torch
    from omegaconf import OmegaConf
    from tensordict import TensorDict
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from billiards.files import display_path
    from billiards.rl.checkpoint import agent_from_config, load_checkpoint
    from billiards.rl.train import evaluate_policy

    torch.set_num_threads(1)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="an expert-iteration run directory with its checkpoint")
    parser.add_argument("--start", choices=("run", "fresh"), default="run")
    parser.add_argument("--hidden", type=int, nargs="+", help="hidden layers of a fresh policy (default: the run's)")
    parser.add_argument("--epochs", type=int, default=20)
    parser.add_argument("--lr", type=float, default=1e-3)
    parser.add_argument("--lr-end", type=float, default=1e-5)
    parser.add_argument("--batch", type=int, default=512)
    parser.add_argument("--every", type=int, default=5)
    parser.add_argument("--innings", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)

    state = load_checkpoint(args.run)
    if state["config"]["algo"]["name"] != "exit":
        raise SystemExit(f"{args.run} is not an expert-iteration run (algo={state['config']['algo']['name']})")
    config = OmegaConf.create(state["config"])
    if args.start == "fresh" and args.hidden:
        config.algo.hidden_sizes = list(args.hidden)
    elif args.hidden:
        raise SystemExit("--hidden is for --start fresh (the run's policy has its own layers)")
    agent, cfg = agent_from_config(OmegaConf.to_container(config))
    if args.start == "run":
        agent.load_state_dict(state["agent"])
    agent.optimizer = torch.optim.Adam(agent.actor.parameters(), lr=args.lr)
    rows = int(state["buffer"]["rows"])
    data = state["buffer"]["data"]
    obs, target = data["observation"][:rows].float(), data["target"][:rows].float()
    gen = torch.Generator().manual_seed(args.seed)
    order = torch.randperm(rows, generator=gen)
    held, train = order[:HELD_OUT], order[HELD_OUT:]
    net = agent.actor.module[0].module

    def fit(rows_: torch.Tensor) -> dict:
        with torch.no_grad():
            loc, _ = net(obs[rows_])
        gap = (torch.tanh(loc) - target[rows_]).abs()
        return {"u_median": float(gap[:, 0].median()), "u_p90": float(gap[:, 0].quantile(0.9)),
                "u_within": float((gap[:, 0] < PRECISE).float().mean()),
                "all_within": float((gap.max(1).values < PRECISE).float().mean())}

    def play() -> float:
        agent.eval()
        with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
            result = evaluate_policy(cfg, agent.policy, args.innings, "random")
        agent.train()
        return float(result.success_per_shot_pct)

    def report(epoch: int, seconds: float) -> dict:
        line = {"epoch": epoch, "seconds": round(seconds, 1), "train": fit(train[:HELD_OUT]), "held_out": fit(held),
                "success_per_shot_pct": play()}
        print(f"epoch {epoch:3d} ({seconds:5.0f} s): u within {PRECISE}: train {line['train']['u_within']:.3f}, "
              f"held out {line['held_out']['u_within']:.3f}; u p90 {line['held_out']['u_p90']:.4f}; "
              f"success per shot {line['success_per_shot_pct']:.1f} %", flush=True)
        return line

    per_epoch = len(train) // args.batch
    total, step, t0 = per_epoch * args.epochs, 0, time.perf_counter()
    history = [report(0, 0.0)]
    for epoch in range(1, args.epochs + 1):
        shuffled = train[torch.randperm(len(train), generator=gen)]
        for i in range(per_epoch):
            lr = args.lr_end + (args.lr - args.lr_end) * 0.5 * (1 + math.cos(math.pi * step / total))
            for group in agent.optimizer.param_groups:
                group["lr"] = lr
            batch = shuffled[i * args.batch:(i + 1) * args.batch]
            agent.update(TensorDict({"observation": obs[batch], "target": target[batch]}, batch_size=[len(batch)]))
            step += 1
        if epoch % args.every == 0 or epoch == args.epochs:
            history.append(report(epoch, time.perf_counter() - t0))
    out = {"commit": git_commit(), "run": display_path(args.run), "labelled_shots": rows, "held_out": HELD_OUT,
           "start": args.start, "hidden_sizes": list(cfg.algo.hidden_sizes), "epochs": args.epochs, "lr": args.lr,
           "lr_end": args.lr_end, "batch": args.batch, "eval_innings": args.innings, "history": history,
           "command": "python benchmarks/exit_refit.py " + " ".join(argv if argv is not None else sys.argv[1:])}
    if args.out:
        write_json(args.out, out)


if __name__ == "__main__":
    main()
