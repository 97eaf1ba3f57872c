"""An agent learns: SAC on ``env=aim_features`` (the aim constraint and the carom features) beats
the random policy by a clear margin within a small budget, both measured with the unified
evaluation protocol on the same 100 evaluation racks.

The budget (24,576 env frames, networks of two 64-unit layers, defaults otherwise) and the seed
were chosen with room to spare: docs/training.md ("An agent learns") has what three seeds scored
at it, and how long it takes.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
FRAMES = 24_576


@pytest.mark.slow
def test_sac_on_aim_features_beats_the_random_policy(tmp_path):
    from billiards.baselines import random_policy
    from billiards.evaluation import EvalResult, evaluate_policy

    run_dir = tmp_path / "run"
    from conftest import app_here

    proc = app_here("train.py", "algo=sac", "env=aim_features", "algo.hidden_sizes=[64,64]", "budget=smoke", f"budget.total_steps={FRAMES}",
                    "budget.eval_every=0", "budget.checkpoint_every=0", "budget.final_eval_innings=100", "seed=0", "threads=1",
                    "progress=false", f"hydra.run.dir={run_dir}", cwd=tmp_path, env={"WANDB_MODE": "offline"})
    assert proc.returncode == 0, proc.stderr[-5000:]
    sac = EvalResult.from_json(run_dir / "eval.json")
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["frames"] == FRAMES and summary["updates"] > 0
    assert summary["eval"][sac.start]["eval_mean"] == sac.mean and sac.n_innings == 100

    # the random policy in the same action space, on the same racks, under the same protocol
    rand = evaluate_policy(random_policy(constrain_aim=True, seed=0), n_innings=sac.n_innings, max_shots=sac.max_shots,
                    start=sac.start, seed=sac.seed, constrain_aim=True, extra_features=True)
    assert rand.points and 0 < rand.mean < 1.0, rand.summary()  # the baseline is what it should be
    # a clear margin: half a point per inning more, twice the random mean, and over four standard
    # errors of the difference of the two means
    standard_error = math.sqrt((sac.std ** 2 + rand.std ** 2) / sac.n_innings)
    gain = sac.mean - rand.mean
    assert gain >= 0.5 and sac.mean >= 2 * rand.mean and gain >= 4 * standard_error, (sac.summary(), rand.summary())
    assert sac.success_per_shot_pct > rand.success_per_shot_pct
