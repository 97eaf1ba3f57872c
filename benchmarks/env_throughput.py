#!/usr/bin/env python
"""Environment throughput: env frames/s vs the raw simulator on the same shots, in one run.

Three envs, each at every batch size B and in two configurations:

* ``torchrl``: ``BilliardsEnv`` (``make_env``), stepped with ``step_and_maybe_reset`` (what
  TorchRL collectors call) on seeded uniform random actions in its action spec;
* ``gym_vector``: ``gymnasium.make_vec("Billiards4Ball-v0", num_envs=B)``, the native batched
  vector env (``billiards.envs.gym_vector``), and ``gym_sync``: the same through gymnasium's
  ``SyncVectorEnv`` of B single envs (``vectorization_mode="sync"``, bit for bit the same
  outputs), both ``step``-ped on seeded uniform random actions in their (normalised) action
  space, innings autoreset as gymnasium does;
* ``bare``: no transforms / the gym env's defaults; ``all``: aim constraint + carom features +
  foul penalty + gentle + near-miss, as TorchRL transforms or as the gym env's options with the
  same coefficients.

Right after each env step the shots it played (table and executed theta, p, a, b) are replayed
through ``simulate_batch`` directly, timed, and checked to give bit-identical tables. The
interleaving makes the ratio robust to load from other processes. Rates are totals over
``--repeats`` runs (different seeds). One frame = one shot played (a gym inning being reset
plays none that step; its reset counts in the env's time).

    python benchmarks/env_throughput.py                 # B in 64, 256, 4096; one thread and two; every env
    python benchmarks/env_throughput.py --batch 256 --threads 1 --envs torchrl gym_vector --json out.json

``--threads``: the numba and torch threads of each row (the env and the raw batch alike); the
goals of the env-speed issue are printed beside the ratios (0.6 at B = 256 with every
transform, 0.85 at B = 4096).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import gymnasium
import numba
import numpy as np
import torch

from billiards import domain
from billiards.envs import GYM_ID, make_env
from billiards.physics import simulate_batch

GOALS = {(256, "all"): 0.6, (4096, "all"): 0.85}  # env/raw, the env-speed issue's goals

CONFIGS = {
    "bare": {},
    "all": dict(constrain_aim=True, extra_features=True, foul_penalty=1.0, gentle=0.5, near_miss=0.5),
}


def measure_torchrl(B: int, layers: dict, n_steps: int, seed: int = 0) -> tuple[float, float, int]:
    """Seconds spent in TorchRL env steps and in raw ``simulate_batch`` calls on the same shots,
    and the shots played. The two are interleaved shot batch by shot batch, so both see the
    same machine load."""
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
        t_raw += _replay(pos, raw, full["next", "positions"].numpy())
    return t_env, t_raw, B * n_steps


def measure_gym(B: int, layers: dict, n_steps: int, seed: int = 0, mode: str = "vector_entry_point"):
    """:func:`measure_torchrl` for gymnasium's vector env over ``Billiards4Ball-v0`` in ``mode``:
    the shots are the rows whose info counts a shot played (not an inning being reset), from
    the tables of the previous info to those of this one (exact float64 positions)."""
    env = gymnasium.make_vec(GYM_ID, num_envs=B, vectorization_mode=mode, **layers)
    gen = np.random.default_rng(seed)
    low, high = env.single_action_space.low, env.single_action_space.high
    actions = [(low + (high - low) * gen.random((B, domain.ACTION_DIM))).astype(np.float32) for _ in range(n_steps)]
    _, info = env.reset(seed=seed)
    t_env = t_raw = 0.0
    frames = 0
    for action in actions:
        before = info["positions"]
        t0 = time.perf_counter()
        info = env.step(action)[-1]
        t_env += time.perf_counter() - t0
        played = info["shot"] > 0
        t_raw += _replay(before[played], info["raw_action"][played], info["positions"][played])
        frames += int(played.sum())
    env.close()
    return t_env, t_raw, frames


def _replay(positions: np.ndarray, actions: np.ndarray, expected: np.ndarray) -> float:
    """Seconds ``simulate_batch`` takes on the shots; a RuntimeError unless it ends on ``expected``."""
    t0 = time.perf_counter()
    result = simulate_batch(positions, actions)
    seconds = time.perf_counter() - t0
    if not np.array_equal(result.positions, expected):
        raise RuntimeError("replay through simulate_batch differs from the env's step")
    return seconds


ENVS = {
    "torchrl": measure_torchrl,
    "gym_vector": measure_gym,
    "gym_sync": lambda B, layers, n_steps, seed: measure_gym(B, layers, n_steps, seed, mode="sync"),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--batch", type=int, nargs="+", default=[64, 256, 4096])
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="numba and torch threads per row")
    parser.add_argument("--envs", nargs="+", default=list(ENVS), choices=list(ENVS))
    parser.add_argument("--frames", type=int, default=8192, help="target shots per measurement")
    parser.add_argument("--min-steps", type=int, default=8)
    parser.add_argument("--max-steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", default=None, help="also write the rows to this JSON file")
    args = parser.parse_args()

    from billiards.device import set_threads
    from billiards.provenance import git_commit

    commit = git_commit()  # before the runs: the code they measure
    load_start = os.getloadavg()[0]  # 2 shared cores: other jobs' load is recorded beside the figures
    for name in args.envs:  # compile / warm up numba, torchrl and gymnasium (autoresets included)
        ENVS[name](4, CONFIGS["all"], 12, 0)
    print(f"python {platform.python_version()}, {platform.machine()}, numba up to {numba.config.NUMBA_NUM_THREADS} threads")
    header = (f"{'thr':>3} {'B':>5} {'env':>10} {'config':>6} {'steps':>5} {'env frames/s':>13} {'raw frames/s':>13} "
              f"{'env/raw':>8} {'goal':>5}")
    print(header)
    print("-" * len(header))
    rows = []
    for threads in args.threads:
        set_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
        for B in args.batch:
            n_steps = int(np.clip(args.frames // B, args.min_steps, args.max_steps))
            for name, layers in CONFIGS.items():
                for env in args.envs:
                    times = np.array([ENVS[env](B, layers, n_steps, rep) for rep in range(args.repeats)])
                    frames = times[:, 2].sum()
                    env_fps, raw_fps = frames / times[:, 0].sum(), frames / times[:, 1].sum()
                    goal = GOALS.get((B, name))
                    row = dict(threads=numba.get_num_threads(), B=B, env=env, config=name, steps=n_steps, frames=int(frames),
                               env_fps=env_fps, raw_fps=raw_fps, ratio=env_fps / raw_fps, goal=goal)
                    rows.append(row)
                    print(f"{row['threads']:>3} {B:>5} {env:>10} {name:>6} {n_steps:>5} {env_fps:>13,.0f} {raw_fps:>13,.0f} "
                          f"{row['ratio']:>8.2f} {'' if goal is None else f'{goal:.2f}':>5}", flush=True)
    if args.json:
        payload = {"command": "python benchmarks/env_throughput.py " + " ".join(sys.argv[1:]), "commit": commit,
                   "load_average_1min_start": load_start, "load_average_1min_end": os.getloadavg()[0], "rows": rows}
        with open(args.json, "w") as f:
            json.dump(payload, f, indent=2)


if __name__ == "__main__":
    main()
