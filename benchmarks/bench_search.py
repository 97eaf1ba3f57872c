"""Search decision time against the simulator's own: one decision at 400 simulations, one core.

    python benchmarks/bench_search.py --decisions 200 --puct-decisions 30 --out results/bench_search.json

For single table states (B = 1) it times, interleaved state by state so that load from other
processes hits every measure alike:

* ``raw``: the 400 shots alone, one ``simulate_batch`` call;
* ``h2``: depth-2 lookahead (K1 = 200, M1 = 10, K2 = 20) and ``puct``: PUCT (budget 400),
  each with the geometric proposer and with a trained ensemble (``--ensemble``, three
  exported policies under ``results/policies/<name>/``);
* ``before``: the previous paths (the pure-Python PUCT tree ``impl="reference"``, the
  ensemble evaluated policy by policy through its torch modules), ``after``: the current ones.

States: ``random`` racks, and ``chain`` states (tables met along greedy h2 chains from the
opening rack, the positions P3 searches from). Everything runs on one thread: numba's
(``--threads``), torch's and the BLAS library's. Prints milliseconds per decision, each
measure's mean as a multiple of the raw batch's mean on the same states in the same run, and
each speed-up (before / after) on the states both were timed on.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # before numpy loads BLAS
    os.environ[_var] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numba  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # time this checkout's billiards
from _shots import ROOT, git_commit, write_json  # noqa: E402

from billiards.physics import DEFAULT_PRESET, PRESETS, canonical_rack, get_params, random_racks, simulate_batch  # noqa: E402
from billiards.search import GeometricProposer, H2Config, PolicyProposer, PUCTConfig, h2_search, puct_search  # noqa: E402

GOALS = {"h2 ensemble after": 3.0, "puct ensemble after": 6.0}  # multiples of the raw batch: issue #20 (h2), #36 (PUCT)


def chain_states(n: int, seed: int, params) -> np.ndarray:
    """n tables at rest met along greedy h2 chains (geometric proposer) from the opening rack; a
    chain that fails restarts from the opening rack."""
    rng, cfg = np.random.default_rng(seed), H2Config(budget=100, k1=60, m1=4)
    prop = GeometricProposer(R=params.ball_radius)
    out, pos = [], canonical_rack(params)[None]
    while len(out) < n:
        out.append(pos[0])
        res = h2_search(pos, prop, cfg, rng, params)
        pos = res.positions if res.r1[0] == 1.0 else canonical_rack(params)[None]
    return np.stack(out)


def ensemble(name: str, impl: str, params) -> PolicyProposer:
    from billiards.rl.policy import load_policy

    policies = [load_policy(ROOT / "results" / "policies" / name / f"seed{s}.pt")[0] for s in range(3)]
    return PolicyProposer(policies, constrain_aim=True, extra_features=True, name=name, R=params.ball_radius, impl=impl)


def measures(ens_before, ens_after, seed: int, params) -> dict:
    """name -> function(state (1, 4, 2)); each search with its own generator."""
    geo = GeometricProposer(R=params.ball_radius)
    h2, puct = H2Config.from_budget(400, 200, 10), PUCTConfig(budget=400)
    acts = geo.propose(random_racks(np.random.default_rng(seed), 1, params), 400, np.random.default_rng(seed))[0]
    rngs = {}

    def rng(name):
        return rngs.setdefault(name, np.random.default_rng([seed, len(rngs)]))

    return {
        "raw": lambda r: simulate_batch(np.repeat(r, 400, 0), acts, params),
        "h2 geometric": lambda r: h2_search(r, geo, h2, rng("h2g"), params),
        "h2 ensemble before": lambda r: h2_search(r, ens_before, h2, rng("h2eb"), params),
        "h2 ensemble after": lambda r: h2_search(r, ens_after, h2, rng("h2ea"), params),
        "puct geometric before": lambda r: puct_search(r, geo, puct, rng("pgb"), params, impl="reference"),
        "puct geometric after": lambda r: puct_search(r, geo, puct, rng("pga"), params),
        "puct ensemble before": lambda r: puct_search(r, ens_before, puct, rng("peb"), params, impl="reference"),
        "puct ensemble after": lambda r: puct_search(r, ens_after, puct, rng("pea"), params),
    }


def time_interleaved(fns: dict, states: np.ndarray, counts: dict) -> dict:
    """ms per decision of every measure, state by state, each measure on its first counts[name] states."""
    times = {name: [] for name in fns}
    for n, state in enumerate(states):
        for name, fn in fns.items():
            if n < counts[name]:
                t0 = time.perf_counter()
                fn(state[None])
                times[name].append(time.perf_counter() - t0)
    return {name: 1e3 * np.asarray(v) for name, v in times.items()}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--decisions", type=int, default=200, help="states timed for raw, h2 and the compiled PUCT")
    ap.add_argument("--puct-decisions", type=int, default=30, help="states timed for the pure-Python PUCT (slow)")
    ap.add_argument("--ensemble", default="base", help="results/policies/<name>/seed{0,1,2}.pt")
    ap.add_argument("--states", default="random,chain", help="comma-separated: random, chain")
    ap.add_argument("--physics", default=DEFAULT_PRESET, choices=sorted(PRESETS), help="the table (a physics preset)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    kinds = args.states.split(",")
    if not set(kinds) <= {"random", "chain"}:
        raise SystemExit(f"Error: --states takes random and/or chain, got {args.states!r}")
    numba.set_num_threads(args.threads)
    torch.set_num_threads(1)
    params = get_params(args.physics)
    ens_before, ens_after = ensemble(args.ensemble, "reference", params), ensemble(args.ensemble, "batched", params)
    fns = measures(ens_before, ens_after, args.seed, params)
    counts = {name: args.puct_decisions if name.endswith("before") and name.startswith("puct") else args.decisions
              for name in fns}
    warm = random_racks(np.random.default_rng(args.seed + 1), 1, params)
    for fn in fns.values():  # compiled kernels load from numba's cache; first calls fill other caches
        fn(warm)

    summary = {"command": " ".join(["python", "benchmarks/bench_search.py"] + (sys.argv[1:] if argv is None else argv)),
               "commit": git_commit(), "threads": args.threads, "ensemble": args.ensemble, "physics": args.physics,
               "unit": "ms per decision (one state, 400 simulations)", "goals": GOALS,
               "load_average_1min_start": os.getloadavg()[0]}  # 2 cores shared with other jobs: absolute ms vary
    for kind in kinds:
        states = (random_racks(np.random.default_rng(args.seed), args.decisions, params) if kind == "random"
                  else chain_states(args.decisions, args.seed, params))
        fig = time_interleaved(fns, states, counts)
        print(f"\n{kind} states: {'measure':22s} {'mean ms':>8s} {'median ms':>10s} {'n':>4s} {'x raw':>6s}")
        section = {}
        for name, v in fig.items():
            ratio = v.mean() / fig["raw"][: v.size].mean()  # raw on the same states
            section[name] = {"mean": float(v.mean()), "median": float(np.median(v)), "n": int(v.size), "x_raw": float(ratio)}
            print(f"{'':15s}{name:22s} {v.mean():8.2f} {np.median(v):10.2f} {v.size:4d} {ratio:6.1f}")
        for name, goal in GOALS.items():
            ratio = section[name]["x_raw"]
            print(f"goal {name} <= {goal:.0f}x raw: {ratio:.2f}x {'met' if ratio <= goal else 'MISSED'}")
        section["speed_up"] = {}
        for what in ("h2 ensemble", "puct geometric", "puct ensemble"):
            before, after = fig[what + " before"], fig[what + " after"]
            section["speed_up"][what] = float(before.mean() / after[: before.size].mean())  # the same states
            print(f"speed-up {what}: {section['speed_up'][what]:.1f}x (on the {before.size} states both timed)")
        summary[kind] = section
    summary["load_average_1min_end"] = os.getloadavg()[0]
    write_json(args.out, summary)


if __name__ == "__main__":
    main()
