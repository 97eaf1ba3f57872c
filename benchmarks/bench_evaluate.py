"""What scoring costs beside the agent: a NumPy callable on p1-exact-v1 against the raw simulator.

Both measured side by side in one process, one thread (numba and torch), after a warm-up:

* raw: ``simulate_batch`` on the same kind of work, random racks and random shots in batches of
  the track's block (its innings played side by side), shots per second;
* evaluate: ``billiards.bench.evaluate(act, "p1-exact-v1")`` with ``act`` a NumPy function
  returning uniform random shots in the normalised box, shots (decisions) per second, wall clock.

The goal (docs/benchmark.md): evaluate at >= 50 % of raw. Writes results/bench_evaluate.json.

    python benchmarks/bench_evaluate.py [--repeats 3] [--out results/bench_evaluate.json]
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default="results/bench_evaluate.json")
    args = parser.parse_args()

    from billiards.bench import evaluate, get_track
    from billiards.device import set_threads
    from billiards.files import atomic_write_text
    from billiards.physics import get_params, simulate_batch
    from billiards.physics.api import random_racks
    from billiards.provenance import cpu, git_commit

    set_threads(1)
    track = get_track("p1-exact-v1")
    params = get_params(track.physics)
    rng = np.random.default_rng(0)

    def act(obs):
        return rng.uniform(-1.0, 1.0, (len(obs), 4))

    def raw_once() -> float:
        from billiards import domain

        shots = track.units * track.shots
        t0 = time.perf_counter()
        for _ in range(shots // track.block):
            tables = random_racks(rng, track.block, params)
            simulate_batch(tables, domain.unnormalize_action(rng.uniform(-1, 1, (track.block, 4))), params)
        return shots / (time.perf_counter() - t0)

    def eval_once() -> float:
        t0 = time.perf_counter()
        card = evaluate(act, track, progress=False)
        return card["decisions"] / (time.perf_counter() - t0)

    raw_once(), eval_once()  # warm-up: compiled kernels loaded, imports done
    raw, ev = [], []
    for _ in range(args.repeats):  # alternated, so that load drifts hit both alike
        raw.append(raw_once())
        ev.append(eval_once())
    result = {
        "command": f"python benchmarks/bench_evaluate.py --repeats {args.repeats}",
        "commit": git_commit(),
        "cpu": cpu(),
        "threads": 1,
        "track": track.name,
        "block": track.block,
        "raw_shots_per_s": [round(v) for v in raw],
        "evaluate_shots_per_s": [round(v) for v in ev],
        "median_ratio": round(float(np.median(ev) / np.median(raw)), 3),
        "goal": ">= 0.5",
        "load_average_after": [round(x, 2) for x in os.getloadavg()],
    }
    print(json.dumps(result, indent=2))
    atomic_write_text(args.out, json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
