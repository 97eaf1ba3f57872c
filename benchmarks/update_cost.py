"""Where a SAC gradient update's time goes on this CPU, by network width and batch size.

For each (hidden width, batch size) the script builds the SAC agent of ``conf/`` (TorchRL
``SACLoss``, twin critics, learned temperature) and times, on a fixed random batch, the four
phases of ``agent.update``: the loss forward (``SACLoss.__call__``: actor, critics, target
critics, log-probs), the backward pass, the Adam step and the soft target update. Settings
run interleaved, ``--repeats`` times, and the median is printed, so all see the same machine
load. The fixed per-update cost is what a 64x64 network still pays.

    python benchmarks/update_cost.py                         # 1 thread, about a minute
    python benchmarks/update_cost.py --widths 64 128 256 --batches 64 256 1024 --out results/update_cost.json
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
PHASES = ("loss_forward", "backward", "optimizer", "target_update")


def make_agent(width: int, obs_dim: int = 32):
    import torch
    from torchrl.data import Bounded
    from train_throughput import compose

    from billiards.rl.learners import make_agent as build

    cfg = compose([f"algo.hidden_sizes=[{width},{width}]"])  # the defaults of conf/algo/sac.yaml otherwise
    low, high = torch.tensor([-1.0, 0.0, -1.0, -1.0]), torch.ones(4)  # the aim-constraint action box
    return build(cfg.algo, obs_dim, Bounded(low, high, shape=(4,)))


def random_batch(batch: int, obs_dim: int = 32):
    import torch
    from tensordict import TensorDict

    g = torch.Generator().manual_seed(0)
    return TensorDict({
        "observation": torch.randn(batch, obs_dim, generator=g),
        "action_norm": torch.rand(batch, 4, generator=g) * 2 - 1,
        "next": {
            "observation": torch.randn(batch, obs_dim, generator=g),
            "reward": (torch.rand(batch, 1, generator=g) < 0.2).float(),
            "done": torch.zeros(batch, 1, dtype=torch.bool),
            "terminated": torch.zeros(batch, 1, dtype=torch.bool),
        },
    }, [batch])


def time_phases(agent, batch, n: int) -> dict[str, float]:
    """Milliseconds per update in each phase, averaged over n updates."""
    total = dict.fromkeys(PHASES, 0.0)
    for _ in range(n):
        t0 = time.perf_counter()
        out = agent.loss(batch)
        t1 = time.perf_counter()
        (out["loss_actor"] + out["loss_qvalue"] + out["loss_alpha"]).backward()
        t2 = time.perf_counter()
        agent.optimizer.step()
        agent.optimizer.zero_grad(set_to_none=True)
        t3 = time.perf_counter()
        agent.target_update.step()
        t4 = time.perf_counter()
        for k, dt in zip(PHASES, (t1 - t0, t2 - t1, t3 - t2, t4 - t3)):
            total[k] += dt
    return {k: v / n * 1e3 for k, v in total.items()}


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--widths", type=int, nargs="+", default=[64, 128, 256])
    parser.add_argument("--batches", type=int, nargs="+", default=[64, 256, 1024])
    parser.add_argument("--updates", type=int, default=40, help="updates per timing")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", type=Path, default=None, help="JSON file for the figures")
    args = parser.parse_args(argv)
    if min(args.widths + args.batches + [args.updates, args.repeats, args.threads]) < 1:
        parser.error("widths, batches, updates, repeats and threads must be positive")

    import torch

    from billiards.provenance import git_commit

    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    settings = [(w, b) for w in args.widths for b in args.batches]
    agents = {w: make_agent(w) for w in args.widths}
    batches = {b: random_batch(b) for b in args.batches}
    samples: dict[tuple, list[dict]] = {s: [] for s in settings}
    for w, b in settings:  # warm-up: lazy buffers, allocator, first-call paths
        time_phases(agents[w], batches[b], 5)
    for _ in range(args.repeats):
        for w, b in settings:
            samples[(w, b)].append(time_phases(agents[w], batches[b], args.updates))
    rows = []
    print(f"SAC update cost, {args.threads} thread(s), median of {args.repeats} x {args.updates} updates (ms per update)")
    print(f"{'width':>6} {'batch':>6} {'total':>7} " + " ".join(f"{p:>13}" for p in PHASES) + f" {'updates/s':>10}")
    for w, b in settings:
        med = {p: statistics.median(s[p] for s in samples[(w, b)]) for p in PHASES}
        total = sum(med.values())
        rows.append({"width": w, "batch": b, "ms_total": round(total, 2), **{f"ms_{p}": round(v, 2) for p, v in med.items()},
                     "updates_per_s": round(1e3 / total, 1)})
        print(f"{w:>6} {b:>6} {total:7.2f} " + " ".join(f"{med[p]:13.2f}" for p in PHASES) + f" {1e3 / total:10.1f}")
    result = {
        "command": "python benchmarks/update_cost.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        "commit": git_commit(),
        "threads": args.threads,
        "rows": rows,
    }
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=2) + "\n")
        print(f"written to {args.out}")
    return result


if __name__ == "__main__":
    main()
