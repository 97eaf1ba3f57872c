"""A shot ranker's own pick as a policy: the best of a pool of geometric candidates by the ranker,
played without any simulation at decision time.

    python benchmarks/ranker_top1.py results/rankers/fastfiz/ranker.pt --pools 50 200 500 2000 --out ranker_top1.json

On ``--tables`` random racks (``random_racks``, seed 123: none of them a ranker's training
rack), for each pool size the ranked proposer's candidate 0 (:class:`billiards.search.ranker.RankedProposer`)
is played exactly and under each noise of ``--noise`` (one draw per shot, averaged over
``--draws`` draws), with its cost per decision (the pool's draws, features and the network, one
core). How often the ranker's first choice scores says how precise it is at the top of its
ranking, where the search over its top candidates needs it only to keep a good shot among them.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from _shots import git_commit, write_json  # noqa: E402

SEED = 123


def main(argv=None) -> None:
    import numpy as np

    from billiards.files import display_path
    from billiards.physics import random_racks, simulate_batch
    from billiards.physics.noise import NOISE_PRESETS
    from billiards.search.ranker import RankedProposer, ShotRanker

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("ranker", type=Path)
    parser.add_argument("--pools", type=int, nargs="+", default=[50, 200, 500, 2000])
    parser.add_argument("--tables", type=int, default=2000)
    parser.add_argument("--noise", nargs="*", default=["fastfiz", "fastfiz_x5"], choices=sorted(NOISE_PRESETS))
    parser.add_argument("--draws", type=int, default=4)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)
    if min(args.pools) < 1 or args.tables < 1 or args.draws < 1:
        parser.error("--pools, --tables and --draws must be >= 1")
    ranker = ShotRanker.load(args.ranker)
    params = ranker.params
    rng = np.random.default_rng(SEED)
    tables = random_racks(rng, args.tables, params)
    record = {"command": "python benchmarks/ranker_top1.py " + " ".join(sys.argv[1:] if argv is None else argv),
              "commit": git_commit(), "ranker": display_path(args.ranker), "trained_for": ranker.meta.get("noise_preset"),
              "tables": args.tables, "pools": []}
    for pool in args.pools:
        proposer = RankedProposer(ranker, pool=pool, params=params)
        proposer.propose(tables[:2], 1, np.random.default_rng(0))  # compiled before it is timed
        start = time.process_time()
        shots = proposer.propose(tables, 1, rng)[:, 0]
        ms = (time.process_time() - start) / args.tables * 1e3
        row = {"pool": pool, "ms_per_decision": round(ms, 3), "exact": float(simulate_batch(tables, shots, params).score.mean())}
        for name in args.noise:
            noise = NOISE_PRESETS[name]
            row[name] = float(np.mean([simulate_batch(tables, noise.apply(shots, noise.draw((len(shots),), rng), params),
                                                      params).score.mean() for _ in range(args.draws)]))
        record["pools"].append(row)
        print(", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()), flush=True)
    write_json(args.out, record)


if __name__ == "__main__":
    main()
