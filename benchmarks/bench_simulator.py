"""Simulator speed: simulate_shot and simulate_batch against pooltool 0.6.0 on the same shots.

    bash benchmarks/setup_pooltool.sh        # once
    python benchmarks/bench_simulator.py --n 500 --batch-n 50000 --out results/bench_simulator.json

Prints microseconds per shot for pooltool (same physics, one core), simulate_shot (one call
per shot from Python, validation, event log and reading the result's positions and score
included), the compiled kernel alone, and
simulate_batch on 1 thread and on all cores, with the ratios; plus the first-call compile
time (empty numba cache) and the cached start-up time (import + first calls), each measured
in a fresh subprocess. Every timing is the best of --repeat runs.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

# This checkout's benchmarks and package first (the figures are those of the code the script
# lives beside, whatever billiards is installed).
HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]
from _shots import ROOT, git_commit, write_json, random_shots, run_pooltool  # noqa: E402

from billiards.physics import DEFAULT_PARAMS, simulate_batch, simulate_shot  # noqa: E402
from billiards.physics import core  # noqa: E402

STARTUP = """
import time; t0 = time.perf_counter()
import numpy as np
from billiards.physics import simulate_shot, simulate_batch, canonical_rack
simulate_shot(canonical_rack(), [3.0, 0.5, 0.1, 0.2])
simulate_batch(canonical_rack()[None].repeat(4, 0), np.tile([3.0, 0.5, 0.1, 0.2], (4, 1)))
print(time.perf_counter() - t0)
"""


def startup_seconds(cache_dir: str | None) -> float:
    env = dict(os.environ)
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    out = subprocess.run([sys.executable, "-c", STARTUP], env=env, cwd=ROOT, capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def best_of(repeat: int, fn) -> float:
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


@numba.njit(cache=True)
def _kernel_loop(racks, actions, p):
    total = 0
    for n in range(racks.shape[0]):
        total += core.run_action(racks[n], actions[n], p, False)[1][core.O_NEVENTS]
    return total


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=500, help="shots timed in pooltool and simulate_shot")
    ap.add_argument("--batch-n", type=int, default=50000, help="shots per simulate_batch call")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-pooltool", action="store_true")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)

    racks, actions = random_shots(args.n, args.seed)
    fig: dict[str, float] = {}
    if not args.no_pooltool:
        ref = run_pooltool(racks, actions, repeat=args.repeat)
        fig["pooltool_us_per_shot"] = float(ref["seconds"].mean() * 1e6)

    simulate_shot(racks[0], actions[0])
    def shots():  # a typical caller reads the rest positions and the outcome
        for r, a in zip(racks, actions):
            res = simulate_shot(r, a)
            res.positions, res.score

    fig["simulate_shot_us_per_shot"] = best_of(args.repeat, shots) / args.n * 1e6
    p = DEFAULT_PARAMS.array
    _kernel_loop(racks[:2], actions[:2], p)
    fig["kernel_us_per_shot"] = best_of(args.repeat, lambda: _kernel_loop(racks, actions, p)) / args.n * 1e6

    big_racks, big_actions = random_shots(args.batch_n, args.seed + 1)
    simulate_batch(big_racks[:8], big_actions[:8])
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    fig["batch_1thread_shots_per_s"] = args.batch_n / best_of(args.repeat, lambda: simulate_batch(big_racks, big_actions))
    numba.set_num_threads(threads)
    fig["batch_shots_per_s"] = args.batch_n / best_of(args.repeat, lambda: simulate_batch(big_racks, big_actions))
    fig["batch_threads"] = threads

    with tempfile.TemporaryDirectory() as empty:
        fig["first_call_compile_s"] = startup_seconds(empty)
    startup_seconds(None)  # make sure the default cache is warm
    fig["cached_startup_s"] = min(startup_seconds(None) for _ in range(args.repeat))

    if "pooltool_us_per_shot" in fig:
        fig["speedup_simulate_shot"] = fig["pooltool_us_per_shot"] / fig["simulate_shot_us_per_shot"]
        fig["speedup_kernel"] = fig["pooltool_us_per_shot"] / fig["kernel_us_per_shot"]
        fig["speedup_batch_per_core"] = fig["pooltool_us_per_shot"] / (1e6 / fig["batch_1thread_shots_per_s"])
    print(f"{'measure':32s} {'value':>14s}")
    for k, v in fig.items():
        print(f"{k:32s} {v:14.2f}")
    if args.out:
        summary = {"command": " ".join(["python", "benchmarks/bench_simulator.py"] + (argv or sys.argv[1:])),
                   "commit": git_commit(), "n": args.n, "batch_n": args.batch_n, "seed": args.seed,
                   "cpu_count": os.cpu_count(), **fig}
        write_json(args.out, summary)


if __name__ == "__main__":
    main()
