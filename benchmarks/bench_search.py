"""Search decision time: one shot's decision at 400 simulations, on one core.

    python benchmarks/bench_search.py --decisions 200 --out results/bench_search.json

Times `h2_search` (K1 = 200, M1 = 10, K2 = 20) and `puct_search` (budget 400) for single table
states (B = 1) drawn at random, with numba limited to one thread, and prints milliseconds per
decision (mean and median) beside the time of the 400 raw simulations alone.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _shots import git_commit, write_json  # noqa: E402

from billiards.physics import random_racks, simulate_batch  # noqa: E402
from billiards.search import GeometricProposer, H2Config, PUCTConfig, h2_search, puct_search  # noqa: E402


def time_each(fn, racks) -> np.ndarray:
    out = np.empty(len(racks))
    for n, rack in enumerate(racks):
        t0 = time.perf_counter()
        fn(rack[None])
        out[n] = time.perf_counter() - t0
    return out * 1e3


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--decisions", type=int, default=200)
    ap.add_argument("--puct-decisions", type=int, default=30)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    numba.set_num_threads(args.threads)
    rng = np.random.default_rng(args.seed)
    racks = random_racks(rng, args.decisions)
    prop = GeometricProposer()
    h2 = H2Config.from_budget(400, 200, 10)
    puct = PUCTConfig(budget=400)
    h2_search(racks[:1], prop, h2, rng)  # warm-up (compiles nothing new, fills caches)
    acts = prop.propose(racks, 400, rng)

    fig = {
        "h2_ms": time_each(lambda r: h2_search(r, prop, h2, rng), racks),
        "puct_ms": time_each(lambda r: puct_search(r, prop, puct, rng), racks[: args.puct_decisions]),
        "raw_400_sims_ms": time_each(lambda r: simulate_batch(np.repeat(r, 400, 0), acts[0]), racks),
    }
    summary = {"command": " ".join(["python", "benchmarks/bench_search.py"] + (argv or sys.argv[1:])),
               "commit": git_commit(), "threads": args.threads, "proposer": "geometric"}
    print(f"{'measure':18s} {'mean ms':>9s} {'median ms':>10s}   (one decision, {args.threads} numba thread(s))")
    for k, v in fig.items():
        summary[k] = {"mean": float(v.mean()), "median": float(np.median(v)), "n": int(v.size)}
        print(f"{k:18s} {v.mean():9.2f} {np.median(v):10.2f}")
    write_json(args.out, summary)


if __name__ == "__main__":
    main()
