"""gymnasium's vector envs over ``Billiards4Ball-v0``: import cost, start-up time and steps/s,
for two checkouts side by side in one run (e.g. before and after the gym path stopped
importing torch/TorchRL, which had switched multiprocessing to "spawn").

Each measurement runs in a fresh interpreter (``--measure``), alternating between the
checkouts ``--repeats`` times; the table reports medians and the after/before ratios:

* import s: ``import billiards.envs``;
* torch loaded / start method: after that import;
* start s: ``gymnasium.make_vec("Billiards4Ball-v0", num_envs=2, vectorization_mode=...)`` plus
  the first ``reset``;
* steps/s: env steps per second over ``--steps`` vector steps of random actions (after 50
  untimed warm-up steps).

    git archive <base commit> | tar -x -C /tmp/billiards-before
    python benchmarks/gym_vector_env.py --before /tmp/billiards-before

writes ``results/gym_vector/README.md`` and ``results/gym_vector/gym_vector.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "results" / "gym_vector"
MODES = ("async", "sync")


def measure(root: str, mode: str, steps: int) -> dict:
    """One measurement in this (fresh) interpreter, with billiards imported from root."""
    sys.path.insert(0, root)
    os.environ["PYTHONPATH"] = root  # the async workers import the same checkout
    import multiprocessing as mp

    t = time.perf_counter()
    import billiards.envs  # noqa: F401

    import_s = time.perf_counter() - t
    torch_loaded, start_method = "torch" in sys.modules, mp.get_start_method(allow_none=True)
    import gymnasium

    t = time.perf_counter()
    envs = gymnasium.make_vec("Billiards4Ball-v0", num_envs=2, vectorization_mode=mode)
    envs.reset(seed=0)
    start_s = time.perf_counter() - t
    envs.action_space.seed(0)
    actions = [envs.action_space.sample() for _ in range(steps)]
    for a in actions[:50]:  # first calls load the compiled kernels: not part of the rate
        envs.step(a)
    t = time.perf_counter()
    for a in actions:
        envs.step(a)
    step_s = time.perf_counter() - t
    envs.close()
    assert billiards.envs.__file__.startswith(root), billiards.envs.__file__
    return dict(import_s=import_s, torch_loaded=torch_loaded, start_method=start_method, start_s=start_s,
                steps_per_s=2 * steps / step_s)


def run_one(root: str, mode: str, steps: int) -> dict:
    env = dict(os.environ, OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1")
    out = subprocess.run([sys.executable, __file__, "--measure", root, "--mode", mode, "--steps", str(steps)],
                         cwd=root, env=env, capture_output=True, text=True, check=True, timeout=600)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=False, help="checkout to compare against (e.g. a git archive of the base commit)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--measure", help=argparse.SUPPRESS)
    ap.add_argument("--mode", default="async", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.measure:
        print(json.dumps(measure(args.measure, args.mode, args.steps)))
        return
    if not args.before:
        ap.error("--before is required")
    sys.path.insert(0, str(ROOT))
    from billiards.provenance import git_commit

    commit = git_commit()  # before the runs: the code they measure
    roots = {"before": str(Path(args.before).resolve()), "after": str(ROOT)}
    runs = {(label, mode): [] for label in roots for mode in MODES}
    for _ in range(args.repeats):
        for mode in MODES:
            for label, root in roots.items():
                runs[label, mode].append(run_one(root, mode, args.steps))
                print(label, mode, runs[label, mode][-1], flush=True)
    med = {k: {f: statistics.median(r[f] for r in v) if isinstance(v[0][f], float) else v[0][f] for f in v[0]} for k, v in runs.items()}
    command = "python " + " ".join(shlex.quote(a) for a in sys.argv)
    rows = []
    for mode in MODES:
        b, a = med["before", mode], med["after", mode]
        for label, m in (("before", b), ("after", a)):
            rows.append(f"| {mode} | {label} | {m['import_s']:.2f} | {m['torch_loaded']} | {m['start_method']} "
                        f"| {m['start_s']:.2f} | {m['steps_per_s']:.0f} |")
        rows.append(f"| {mode} | after/before | {a['import_s'] / b['import_s']:.3g}x | | | {a['start_s'] / b['start_s']:.3g}x "
                    f"| {a['steps_per_s'] / b['steps_per_s']:.3g}x |")
    OUT.mkdir(parents=True, exist_ok=True)
    record = dict(command=command, commit=commit, repeats=args.repeats, steps=args.steps,
                  runs={f"{k[0]}/{k[1]}": v for k, v in runs.items()})
    (OUT / "gym_vector.json").write_text(json.dumps(record, indent=2) + "\n")
    text = [
        "# gymnasium vector envs over Billiards4Ball-v0, before/after",
        "",
        "`gymnasium.make_vec(\"Billiards4Ball-v0\", num_envs=2, vectorization_mode=mode)`, each figure the median of",
        f"{args.repeats} fresh interpreters run alternately; steps/s are env steps over {args.steps} vector steps of",
        "random actions after 50 warm-up steps; start s is make_vec plus the first reset. Two shared CPU cores.",
        "",
        "| mode | checkout | import s | torch loaded | start method | start s | steps/s |",
        "|---|---|---|---|---|---|---|",
        *rows,
        "",
        f"Command: `{command}`  ",
        f"Commit: `{record['commit']}`",
        "",
    ]
    (OUT / "README.md").write_text("\n".join(text))
    print("\n".join(text))


if __name__ == "__main__":
    main()
