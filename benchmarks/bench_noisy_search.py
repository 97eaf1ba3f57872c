"""Decision time of the noise-aware searches against the raw 400-shot batch, one core.

    python benchmarks/bench_noisy_search.py --decisions 200 --out results/bench_noisy_search.json

For single table states (B = 1) from random racks it times, interleaved state by state so that
load from other processes hits every measure alike: ``raw``, the 400 shots alone (one
``simulate_batch`` call), and each configuration of ``python search.py`` named below (built by
the app's own config, so ``default_<noise>`` is exactly what ``python search.py noise=<noise>``
plays). Prints milliseconds per decision and each mean as a multiple of raw's mean on the same
states in the same run (the noisy track's cost goal: at most 15x).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # before numpy loads BLAS
    os.environ[_var] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # time this checkout's billiards
from _shots import ROOT, cpu, git_commit, write_json  # noqa: E402

CONFIGS = {
    "ranked_pool2000": ["noise=fastfiz", "search=robust", "proposer=ranked"],  # the default before the value
    "ranked_pool500": ["noise=fastfiz", "search=robust"],
    "default_fastfiz": ["noise=fastfiz"],  # position-aware
    "default_fastfiz_x5": ["noise=fastfiz_x5", "proposer=for_noise_fastfiz_x5"],  # over the x5 shot ranker, as recorded
    "default_fastfiz_x5_mixed": ["noise=fastfiz_x5"],  # the default now: over the x5 policy and shot ranker
    "deep_fastfiz_x5": ["noise=fastfiz_x5", "search=deep_fastfiz_x5", "proposer=exit_x5"],  # 2,400 simulations
    "default_fastfiz_x5_1600": ["noise=fastfiz_x5", "search.budget=1600", "search.k1=1200", "search.target=40"],  # its screen scaled
}


def actor(overrides: list[str]):
    from hydra import compose, initialize_config_dir

    import billiards.search.config  # noqa: F401  (registers the search app's schemas)
    from billiards.physics import get_params
    from billiards.search.run import make_actor

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="search", overrides=overrides)
    params = get_params(cfg.physics.preset)
    from billiards.search.config import option

    return make_actor(cfg, option("proposer", cfg.proposer).build(params), params)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--decisions", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()

    import numba

    numba.set_num_threads(1)
    import torch

    torch.set_num_threads(1)
    from billiards.physics import DEFAULT_PARAMS, random_racks, simulate_batch

    rng = np.random.default_rng(args.seed)
    states = random_racks(rng, args.decisions, DEFAULT_PARAMS)
    actors = {name: actor(over) for name, over in CONFIGS.items()}
    raw_actions = np.column_stack([rng.uniform(0, 2 * np.pi, 400), rng.uniform(0.2, 1, 400), np.zeros(400), np.zeros(400)])
    for a in actors.values():  # warm-up: compile and load
        a.search(states[:1])
    simulate_batch(np.repeat(states[:1], 400, axis=0), raw_actions, DEFAULT_PARAMS)
    times = {name: [] for name in ["raw", *actors]}
    for s in states:
        t0 = time.perf_counter()
        simulate_batch(np.repeat(s[None], 400, axis=0), raw_actions, DEFAULT_PARAMS)
        times["raw"].append(time.perf_counter() - t0)
        for name, a in actors.items():
            t0 = time.perf_counter()
            a.search(s[None])
            times[name].append(time.perf_counter() - t0)
    raw = float(np.mean(times["raw"]))
    rows = {name: {"ms_per_decision": round(1e3 * float(np.mean(t)), 3), "times_raw": round(float(np.mean(t)) / raw, 2)}
            for name, t in times.items()}
    for name, r in rows.items():
        print(f"{name:20s} {r['ms_per_decision']:8.2f} ms  {r['times_raw']:6.2f} x raw", flush=True)
    if args.out:
        write_json(args.out, {"command": "python benchmarks/bench_noisy_search.py " + " ".join(sys.argv[1:]),
                              "commit": git_commit(), "cpu": cpu(), "decisions": args.decisions, "threads": 1,
                              "configs": {k: " ".join(v) for k, v in CONFIGS.items()}, "results": rows,
                              "load_average": os.getloadavg()})


if __name__ == "__main__":
    main()
