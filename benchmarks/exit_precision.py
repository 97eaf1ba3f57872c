"""What limits a policy that plays without the simulator: how precise a shot must be, and how
precise the expert-iteration policy is.

    python benchmarks/exit_precision.py --policy results/policies/exit/seed0.pt --out results/exit/precision.json

On the tables of ``--innings`` innings (random racks, continue on a miss, 10 shots; seeds from
30,000,000: no benchmark track's, no training run's) played by the depth-2 search over the
geometric proposer (the label rule of expert iteration, :func:`billiards.exit.nearest_best`):

* **the labels' tolerance**: the per-shot success of the search's shots as labelled, then with
  Gaussian errors of standard deviation sigma added to their normalised aim-constrained action
  (u, 2p - 1, a, b): to every coordinate, and to u (the aim inside the nearest red's window) alone;
  with ``--centre-probes P`` the labels are first centred as ``algo.centre_probes=P`` centres them
  (:func:`billiards.exit.centred`, ``--centre-scale``; the same tables);
* **the policy's precision**: on the same tables, the policy's own shot (its deterministic
  action), its success, and its distance to the label the search gives it as proposer (the
  best-valued candidate nearest its shot): per coordinate, the median and 90th percentile.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from _shots import git_commit, write_json  # noqa: E402

SEED = 30_000_000
SIGMAS = (0.003, 0.01, 0.03, 0.1)
COORDS = ("u", "power", "a", "b")


def main(argv=None) -> None:
    import torch

    torch.set_num_threads(1)
    from billiards import domain
    from billiards.envs.gym_vector import Billiards4BallVectorEnv
    from billiards.exit import nearest_best
    from billiards.physics import DEFAULT_PARAMS, simulate_batch
    from billiards.search.proposers import GeometricProposer, load_policy_proposer
    from billiards.search.settings import H2Config

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="results/policies/exit/seed0.pt")
    parser.add_argument("--innings", type=int, default=200)
    parser.add_argument("--centre-probes", type=int, default=0, help="centre the labels first (billiards.exit.centred)")
    parser.add_argument("--centre-scale", type=float, default=0.02)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)

    params, search = DEFAULT_PARAMS, H2Config(budget=400, k1=200, m1=10).settings()
    env = Billiards4BallVectorEnv(args.innings, start="random", on_miss="continue", max_shots=10, normalize_actions=False)
    _, info = env.reset(seed=SEED)
    rng = np.random.default_rng(SEED)
    tables, labels, raws = [], [], []
    for _ in range(10):
        raw, x, _ = nearest_best(info["positions"], GeometricProposer(), search, rng, params)
        tables.append(info["positions"])
        labels.append(x)
        raws.append(raw)
        _, _, _, _, info = env.step(raw)
    tables, labels = np.concatenate(tables), np.concatenate(labels)
    if args.centre_probes:
        from billiards.exit import centred

        _, labels, _ = centred(tables, np.concatenate(raws), labels, args.centre_probes, args.centre_scale,
                               np.random.default_rng(SEED + 3), params)

    def success(x: np.ndarray) -> float:
        shots = domain.raw_action(np.clip(x, -1.0, 1.0), tables, params.ball_radius, constrain_aim=True, normalized=True)
        return round(100.0 * float(simulate_batch(tables, shots, params).score.mean()), 2)

    noise = np.random.default_rng(SEED + 1)
    tolerance = {"labels": success(labels), "all": {}, "u": {}}
    for sigma in SIGMAS:
        err = noise.normal(0.0, sigma, labels.shape)
        tolerance["all"][str(sigma)] = success(labels + err)
        only_u = labels.copy()
        only_u[:, 0] += err[:, 0]
        tolerance["u"][str(sigma)] = success(only_u)

    proposer = load_policy_proposer([args.policy], params=params)
    own = proposer.propose(tables, 1, np.random.default_rng(0))[:, 0]
    own_x = domain.normalized_aim_action(tables, own, params.ball_radius)
    _, nearest, _ = nearest_best(tables, proposer, search, np.random.default_rng(SEED + 2), params)
    gap = np.abs(nearest - own_x)
    policy = {"success": success(own_x),
              "distance_to_nearest_best": {c: {"median": round(float(np.median(gap[:, i])), 4),
                                               "p90": round(float(np.quantile(gap[:, i], 0.9)), 4)}
                                           for i, c in enumerate(COORDS)},
              "at_the_label": round(100.0 * float((gap.max(axis=1) == 0).mean()), 2)}
    out = {"commit": git_commit(), "policy_file": args.policy, "tables": int(len(tables)), "seed": SEED,
           "search": {"budget": 400, "k1": 200, "m1": 10}, "tolerance": tolerance, "policy": policy,
           **({"centre": {"probes": args.centre_probes, "scale": args.centre_scale}} if args.centre_probes else {}),
           "command": "python benchmarks/exit_precision.py " + " ".join(argv if argv is not None else sys.argv[1:])}
    print(f"{len(tables)} tables; the labels score {tolerance['labels']} % per shot")
    for sigma in SIGMAS:
        print(f"  sigma {sigma}: {tolerance['all'][str(sigma)]} % (every coordinate), {tolerance['u'][str(sigma)]} % (u alone)")
    print(f"the policy alone: {policy['success']} % per shot; its shot is the search's label on {policy['at_the_label']} % of tables")
    for c, d in policy["distance_to_nearest_best"].items():
        print(f"  |policy - nearest best| in {c}: median {d['median']}, 90th percentile {d['p90']}")
    if args.out:
        write_json(args.out, out)


if __name__ == "__main__":
    main()
