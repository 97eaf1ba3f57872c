"""Stable-Baselines3 PPO and SAC, default settings, on ``Billiards4Ball-v0``, against random.

Trains one SB3 algorithm with its default hyper-parameters on the gymnasium env as a new
user would make it (``gym.make("Billiards4Ball-v0")``: random racks, continue-on-miss,
10-shot innings, the normalised [-1, 1]^4 action space, raw carom reward), and evaluates it
every ``--eval-every`` steps and at the end with the project's protocol
(:func:`billiards.evaluation.evaluate_policy`: 100 continue-on-miss innings of 10 shots, racks from
seed 0, deterministic actions, raw score) through :func:`billiards.evaluation.numpy_policy`.
``--algo random`` evaluates the project's uniform random policy under the same protocol.

Each run writes ``results/sb3/<algo>.json`` after every evaluation (so a cut run still
leaves its last figure) with the command and the commit; ``--table`` rebuilds
``results/sb3/README.md`` from those files. Model checkpoints go to ``outputs/sb3/`` (not
committed). Needs ``pip install -e .[sb3]``.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/sb3_baselines.py --algo ppo --steps 100000
    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/sb3_baselines.py --algo sac --steps 100000
    python benchmarks/sb3_baselines.py --algo random
    python benchmarks/sb3_baselines.py --table
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path

import gymnasium as gym
import torch

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # this checkout's billiards, not another installed one

import billiards.envs  # noqa: F401, E402  (registers Billiards4Ball-v0)
from billiards.baselines import random_policy  # noqa: E402
from billiards.evaluation import evaluate_policy, numpy_policy  # noqa: E402
from billiards.provenance import git_commit  # noqa: E402

OUT = ROOT / "results" / "sb3"
ALGOS = ("ppo", "sac")


def evaluate_model(model, normalized: bool = True) -> dict:
    """The project's protocol on the model's deterministic action."""
    result = evaluate_policy(numpy_policy(lambda obs: model.predict(obs, deterministic=True)[0], normalized=normalized))
    return {k: v for k, v in result.__dict__.items() if k != "points"}


def write(record: dict) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / f"{record['algo']}.json").write_text(json.dumps(record, indent=2) + "\n")


def train(algo: str, steps: int, seed: int, eval_every: int, record: dict, raw: bool = False) -> None:
    import stable_baselines3 as sb3
    from stable_baselines3.common.callbacks import BaseCallback

    cls = {"ppo": sb3.PPO, "sac": sb3.SAC}[algo]
    env = gym.make("Billiards4Ball-v0", normalize_actions=not raw)
    model = cls("MlpPolicy", env, seed=seed, verbose=0, device="cpu")
    record.update(sb3_version=sb3.__version__, evals=[])
    ckpt = ROOT / "outputs" / "sb3"
    ckpt.mkdir(parents=True, exist_ok=True)
    start = time.time()

    def checkpoint(n: int) -> None:
        entry = dict(steps=n, train_seconds=round(time.time() - start, 1), **evaluate_model(model, not raw))
        record["evals"].append(entry)
        write(record)
        model.save(ckpt / f"{record['algo']}_seed{seed}_{n}")
        print(f"[{algo}] {n} steps, {entry['train_seconds']} s: {entry['mean']:.3f} points/inning", flush=True)

    class EvalEvery(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps % eval_every == 0:
                checkpoint(self.num_timesteps)
            return True

    checkpoint(0)
    model.learn(total_timesteps=steps, callback=EvalEvery())
    if record["evals"][-1]["steps"] != model.num_timesteps:
        checkpoint(model.num_timesteps)
    record["done"] = True
    write(record)


def table() -> None:
    """results/sb3/README.md from the JSON files."""
    rows, commands = [], []
    for name in ("random", *ALGOS, *(a + "_raw" for a in ALGOS)):
        path = OUT / f"{name}.json"
        if not path.exists():
            continue
        rec = json.loads(path.read_text())
        cut = "" if name == "random" or rec.get("done") else f"; cut at {rec['evals'][-1]['steps']} of {rec['steps']} steps"
        note = f": {rec['commit_note']}" if rec.get("commit_note") else ""
        commands.append(f"- {name}: `{rec['command']}` (commit `{rec['commit']}`{note}{cut})")
        for e in rec.get("evals", []):
            rows.append(
                f"| {name} | {e['steps']} | {e.get('train_seconds', '')} | {e['mean']:.3f} ± {e['std']:.3f} | {e['best']} "
                f"| {e['foul_innings_pct']:.1f} | {e['foul_per_shot_pct']:.1f} | {e['success_per_shot_pct']:.1f} |"
            )
    text = [
        "# Stable-Baselines3 defaults on Billiards4Ball-v0",
        "",
        "SB3 PPO and SAC with their default hyper-parameters (`PPO/SAC(\"MlpPolicy\", env, seed=0)`) on",
        "`gym.make(\"Billiards4Ball-v0\")` (korean_medium table, random racks, continue-on-miss, 10-shot innings,",
        "normalised [-1, 1]^4 actions, raw carom reward), one seed, evaluated with the project's protocol",
        "(`billiards.evaluation.evaluate_policy`: 100 innings x 10 shots, racks from seed 0, deterministic action).",
        "Two shared CPU cores, `OMP_NUM_THREADS=1`; train_seconds is wall time including the evaluations, and depends",
        "on the load other jobs put on the machine (high during the ppo and sac runs, low during ppo_raw).",
        "`ppo_raw`: the same PPO on the paper's raw box (`normalize_actions=False`, `--raw`), for comparison.",
        "",
        "| policy | env steps | train s | points/inning | best | foul inn. (%) | foul/shot (%) | success/shot (%) |",
        "|---|---|---|---|---|---|---|---|",
        *rows,
        "",
        "Commands:",
        "",
        *commands,
        "- this table: `python benchmarks/sb3_baselines.py --table`",
        "",
        "`+dirty`: `billiards/` had uncommitted edits when the run started.",
        "",
    ]
    (OUT / "README.md").write_text("\n".join(text))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--algo", choices=(*ALGOS, "random"))
    ap.add_argument("--steps", type=int, default=100_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--eval-every", type=int, default=20_000)
    ap.add_argument("--raw", action="store_true", help="the paper's raw action box (normalize_actions=False), for comparison")
    ap.add_argument("--table", action="store_true", help="only rebuild results/sb3/README.md")
    args = ap.parse_args()
    if args.table:
        return table()
    if args.algo is None:
        ap.error("--algo is required (or --table)")
    torch.set_num_threads(1)
    command = "python " + " ".join(shlex.quote(a) for a in sys.argv)
    name = args.algo + ("_raw" if args.raw and args.algo != "random" else "")
    record = dict(algo=name, command=command, commit=git_commit(), seed=args.seed, steps=args.steps)
    if args.algo == "random":
        result = evaluate_policy(random_policy(seed=args.seed))
        record["evals"] = [dict(steps=0, **{k: v for k, v in result.__dict__.items() if k != "points"})]
        write(record)
        print(result.summary())
    else:
        train(args.algo, args.steps, args.seed, args.eval_every, record, raw=args.raw)
    table()


if __name__ == "__main__":
    main()
