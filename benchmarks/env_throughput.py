#!/usr/bin/env python
"""Environment throughput: TorchRL env frames/s vs the raw simulator on the same shots.

For each batch size B and each configuration (``bare``: no transforms; ``all``: aim
constraint + carom features + foul penalty + gentle + near-miss), the env is stepped with
``step_and_maybe_reset`` (what TorchRL collectors call) on seeded uniform random actions;
right after each env step the same shots (table and executed theta, p, a, b) are replayed
through ``simulate_batch`` directly, timed, and checked to give bit-identical tables. The
interleaving makes the ratio robust to load from other processes. Rates are totals over
``--repeats`` runs (different seeds). One frame = one shot.

    python benchmarks/env_throughput.py                 # B in 64, 256, 4096; one thread and two
    python benchmarks/env_throughput.py --batch 256 --threads 1 --json results/env_throughput.json

``--threads``: the numba and torch threads of each row (the env and the raw batch alike); the
goals of the env-speed issue are printed beside the ratios (0.6 at B = 256 with every
transform, 0.85 at B = 4096).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time

import numba
import numpy as np
import torch

from billiards import domain
from billiards.envs import make_env
from billiards.physics import simulate_batch

GOALS = {(256, "all"): 0.6, (4096, "all"): 0.85}  # env/raw, the env-speed issue's goals

CONFIGS = {
    "bare": {},
    "all": dict(constrain_aim=True, extra_features=True, foul_penalty=1.0, gentle=0.5, near_miss=0.5),
}


def measure(B: int, layers: dict, n_steps: int, seed: int = 0) -> tuple[float, float]:
    """Seconds spent in env steps and in raw ``simulate_batch`` calls on the same shots.

    The two are interleaved shot batch by shot batch, so both see the same machine load.
    """
    env = make_env(B, seed=seed, **layers)
    gen = torch.Generator().manual_seed(seed)
    spec = env.action_spec
    low, high = spec.space.low, spec.space.high
    actions = [low + (high - low) * torch.rand(spec.shape, generator=gen) for _ in range(n_steps)]
    td = env.reset()
    t_env = t_raw = 0.0
    for action in actions:
        td["action"] = action
        t0 = time.perf_counter()
        full, td = env.step_and_maybe_reset(td)
        t_env += time.perf_counter() - t0
        pos = full["positions"].numpy()
        raw = action.numpy().astype(np.float64)
        if layers.get("constrain_aim"):
            raw[:, 0] = domain.constrained_theta(pos, raw[:, 0])
        t0 = time.perf_counter()
        result = simulate_batch(pos, raw)
        t_raw += time.perf_counter() - t0
        if not np.array_equal(result.positions, full["next", "positions"].numpy()):
            raise RuntimeError("replay through simulate_batch differs from the env's step")
    return t_env, t_raw


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--batch", type=int, nargs="+", default=[64, 256, 4096])
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="numba and torch threads per row")
    parser.add_argument("--frames", type=int, default=8192, help="target shots per measurement")
    parser.add_argument("--min-steps", type=int, default=8)
    parser.add_argument("--max-steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", default=None, help="also write the rows to this JSON file")
    args = parser.parse_args()

    from billiards.device import set_threads

    make_env(2, seed=0, **CONFIGS["all"]).rollout(2)  # compile / warm up numba and torchrl
    print(f"python {platform.python_version()}, {platform.machine()}, numba up to {numba.config.NUMBA_NUM_THREADS} threads")
    header = (f"{'thr':>3} {'B':>5} {'config':>6} {'steps':>5} {'env frames/s':>13} {'raw frames/s':>13} "
              f"{'env/raw':>8} {'goal':>5}")
    print(header)
    print("-" * len(header))
    rows = []
    for threads in args.threads:
        set_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
        for B in args.batch:
            n_steps = int(np.clip(args.frames // B, args.min_steps, args.max_steps))
            for name, layers in CONFIGS.items():
                times = np.array([measure(B, layers, n_steps, seed=rep) for rep in range(args.repeats)])
                frames = B * n_steps * args.repeats
                env_fps, raw_fps = frames / times[:, 0].sum(), frames / times[:, 1].sum()
                goal = GOALS.get((B, name))
                row = dict(threads=numba.get_num_threads(), B=B, config=name, steps=n_steps, env_fps=env_fps,
                           raw_fps=raw_fps, ratio=env_fps / raw_fps, goal=goal)
                rows.append(row)
                print(f"{row['threads']:>3} {B:>5} {name:>6} {n_steps:>5} {env_fps:>13,.0f} {raw_fps:>13,.0f} "
                      f"{row['ratio']:>8.2f} {'' if goal is None else f'{goal:.2f}':>5}")
    if args.json:
        from billiards.provenance import git_commit

        payload = {"command": "python benchmarks/env_throughput.py " + " ".join(sys.argv[1:]), "commit": git_commit(),
                   "rows": rows}
        with open(args.json, "w") as f:
            json.dump(payload, f, indent=2)


if __name__ == "__main__":
    main()
