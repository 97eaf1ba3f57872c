#!/usr/bin/env python
"""Evaluate the baseline policies with the unified protocol and record the results.

Protocol (:func:`billiards.evaluation.evaluate_policy`): 100 continue-on-miss innings of 10 shots,
one batched env, deterministic policy, raw carom score. Writes ``results/baselines.json`` and
``results/baselines.md`` (with the command and the git commit), and optionally renders a few
baseline shots to ``results/img/``.

    python benchmarks/baselines.py                    # evaluate, write results/baselines.*
    python benchmarks/baselines.py --images           # also render example shots to results/img/
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
import sys
from pathlib import Path

from billiards.baselines import make_policy
from billiards.evaluation import evaluate_policy
from billiards.physics import DEFAULT_PRESET, PRESETS
from billiards.provenance import git_commit

# (row name, policy, start, constrain_aim)
RUNS = [
    ("random", "random", "random", False),
    ("nearest red (p=0.5, centre)", "nearest", "random", False),
    ("random", "random", "canonical", False),
    ("nearest red (p=0.5, centre)", "nearest", "canonical", False),
    ("random u inside the aim constraint", "random", "random", True),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n-innings", type=int, default=100)
    parser.add_argument("--max-shots", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--physics", default=DEFAULT_PRESET, choices=sorted(PRESETS), help="the table (default %(default)s)")
    parser.add_argument("--out", default="results")
    parser.add_argument("--images", action="store_true", help="render a scoring, a foul and a missed nearest-red shot to OUT/img/")
    args = parser.parse_args()

    command = "python " + " ".join(shlex.quote(a) for a in sys.argv)
    commit = git_commit()
    rows = []
    for name, policy, start, constrain_aim in RUNS:
        result = evaluate_policy(
            make_policy(policy, constrain_aim=constrain_aim, seed=args.seed),
            n_innings=args.n_innings,
            max_shots=args.max_shots,
            start=start,
            seed=args.seed,
            constrain_aim=constrain_aim,
            env_kwargs=dict(params=PRESETS[args.physics]),
        )
        rows.append(dict(name=name, policy=policy, constrain_aim=constrain_aim, physics=args.physics, **dataclasses.asdict(result)))
        print(f"{name:>36} | {start:>9} start | {result.summary()}")

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = "baselines" if args.physics == DEFAULT_PRESET else f"baselines_{args.physics}"
    (out / f"{stem}.json").write_text(json.dumps(dict(command=command, commit=commit, physics=args.physics, results=rows), indent=2) + "\n")
    lines = [
        f"# Baseline policies, unified evaluation protocol, physics `{args.physics}`",
        "",
        (
            f"{args.n_innings} continue-on-miss innings of {args.max_shots} shots, rack seed {args.seed}, "
            "deterministic policy, raw carom score (`billiards.evaluation.evaluate_policy`). mean ± std (population) "
            "points per inning; foul inn. = innings with at least one foul; foul/shot and success/shot over all shots."
        ),
        "",
        f"Command: `{command}`  ",
        f"Commit: `{commit}`",
        "",
        "| policy | start | mean ± std | best | foul inn. (%) | foul/shot (%) | success/shot (%) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['name']} | {r['start']} | {r['mean']:.3f} ± {r['std']:.3f} | {r['best']} | "
            f"{r['foul_innings_pct']:.1f} | {r['foul_per_shot_pct']:.1f} | {r['success_per_shot_pct']:.1f} |"
        )
    (out / f"{stem}.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out / f'{stem}.json'} and {out / f'{stem}.md'}")

    if args.images:
        render_examples(out / "img", args.seed, PRESETS[args.physics])


def render_examples(img_dir: Path, seed: int, params, n_racks: int = 256) -> None:
    """PNGs of the nearest-red baseline's first shot on the first random rack (of n_racks drawn
    from ``seed``) where it scores, fouls and misses."""
    import numpy as np

    from billiards.envs import make_env
    from billiards.render import render_shot

    img_dir.mkdir(parents=True, exist_ok=True)
    env = make_env(n_racks, seed=seed, params=params)
    td = make_policy("nearest")(env.reset())
    nxt = env.step(td)["next"]
    for outcome in ("score", "foul", "miss"):
        hits = np.flatnonzero(nxt[outcome][:, 0].numpy())
        if hits.size == 0:
            continue
        k = int(hits[0])
        path = img_dir / f"nearest_{outcome}.png"
        pos, act = td["positions"][k].numpy(), td["action"][k].numpy().astype(np.float64)
        render_shot(pos, act, path, params=params, title=f"nearest-red baseline, rack {k} of seed {seed}", dpi=80)
        print(f"{path}: rack {k}")

if __name__ == "__main__":
    main()
