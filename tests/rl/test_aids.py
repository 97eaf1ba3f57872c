"""Table 3's structure-free aids in training: the staged action curriculum and the
reward-model bonus (the reward model itself is tested in test_rm.py)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir

import billiards.rl.config  # noqa: F401  (schema + resolvers)
from billiards import domain
from billiards.envs import RewardModelBonus, make_env, reset_to
from billiards.evaluation import EvalResult, evaluate_policy
from billiards.physics import random_racks
from billiards.rl.curriculum import Curriculum, HoldActions, held_norm_values
from billiards.rl.train import make_run, train_off_policy
from billiards.rm import RewardModel, save_model

REPO = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "WANDB_MODE": "offline", "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1", "HYDRA_FULL_ERROR": "0"}


def compose_cfg(*overrides: str):
    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base="1.3"):
        return compose(config_name="config", overrides=list(overrides))


# ----------------------------------------------------------------------------- curriculum


def test_curriculum_stage_boundaries_and_hold():
    c = Curriculum([[0], [0, 1], [0, 1, 2, 3]], [0.25, 0.5], total_steps=1000)
    assert [c.stage_at(f) for f in (0, 249, 250, 499, 500, 10_000)] == [0, 0, 1, 1, 2, 2]
    hold = HoldActions(torch.tensor([0.0, -0.2, 0.3, 0.3]))
    from tensordict import TensorDict

    td = TensorDict({"action_norm": torch.full((5, 4), 0.9)}, batch_size=[5])
    hold.set_free([0])
    assert torch.equal(hold(td.clone())["action_norm"][0], torch.tensor([0.9, -0.2, 0.3, 0.3]))
    hold.set_free([0, 1])
    assert torch.equal(hold(td.clone())["action_norm"][0], torch.tensor([0.9, 0.9, 0.3, 0.3]))
    hold.set_free([0, 1, 2, 3])
    assert torch.equal(hold(td.clone())["action_norm"], td["action_norm"])


def test_held_values_map_onto_the_documented_env_action():
    from billiards.rl.learners import ScaleAction

    scale = ScaleAction(torch.tensor(domain.ACTION_LOW, dtype=torch.float32), torch.tensor(domain.ACTION_HIGH, dtype=torch.float32))
    norm = held_norm_values(scale, hold_power=0.25, hold_english=-0.5)
    env_action = scale.mid + scale.half_range * norm
    assert env_action[1:].tolist() == pytest.approx([0.25, -0.5, -0.5])


@pytest.mark.slow
def test_staged_curriculum_switches_at_the_configured_steps_and_keeps_the_weights(tmp_path):
    cfg = compose_cfg("curriculum=staged", "budget=smoke", "budget.eval_every=0", "budget.checkpoint_every=0",
                      "curriculum.switch_at=[0.25,0.5]", "progress=false", "logger=none")
    run = make_run(cfg, tmp_path / "run")
    actor = run.agent.actor
    snapshots = []  # (frames, stage before, params before, params after) at each switch
    update = run.stages.update

    def spy(frames, stage_log):
        before = (run.stages.stage, [p.detach().clone() for p in actor.parameters()])
        update(frames, stage_log)
        if run.stages.stage != before[0]:
            snapshots.append((run.state.frames, before[1], [p.detach().clone() for p in actor.parameters()]))

    run.stages.update = spy
    train_off_policy(run)

    n = cfg.env.num_envs
    expected = [int(np.ceil(round(f * 2048) / n) * n) for f in (0.25, 0.5)]
    assert [s["step"] for s in run.state.stage_log] == [0, *expected]
    assert [s["free"] for s in run.state.stage_log] == [["aim"], ["aim", "power"], ["aim", "power", "english_a", "english_b"]]
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["curriculum"] == run.state.stage_log
    # the same actor carries over: a switch leaves its weights as they are ...
    assert [s[0] for s in snapshots] == expected
    for _, before, after in snapshots:
        assert all(torch.equal(a, b) for a, b in zip(before, after))
    # ... and training goes on from them
    final = list(actor.parameters())
    assert any(not torch.equal(a, b) for a, b in zip(snapshots[-1][2], final))
    # the replay buffer stores the action played: held dims at their value until released
    stored = run.rb.storage[: len(run.rb)]["action_norm"]
    first, second = expected
    assert torch.all(stored[:first, 1:] == 0) and stored[:first, 0].std() > 0
    assert torch.all(stored[first:second, 2:] == 0) and stored[first:second, 1].std() > 0
    assert stored[second:, 2:].std() > 0


# ----------------------------------------------------------------------------- reward-model bonus


class FakeModel:
    """A known V_rm: a smooth function of the raw action and the white's position."""

    def prob(self, positions, actions):
        positions, actions = np.asarray(positions), np.asarray(actions)
        return 1.0 / (1.0 + np.exp(-(np.cos(actions[..., 0]) + actions[..., 1] - positions[..., 0, 0])))


@pytest.mark.parametrize("constrain_aim", [False, True])
def test_rm_bonus_adds_beta_times_v_rm_of_the_shot_played(constrain_aim):
    rng = np.random.default_rng(3)
    racks = random_racks(rng, 8)
    actions = np.stack([rng.uniform(-1, 1, 8) if constrain_aim else rng.uniform(0, 2 * np.pi, 8),
                        rng.uniform(0, 1, 8), rng.uniform(-1, 1, 8), rng.uniform(-1, 1, 8)], axis=-1)
    beta = 0.7
    steps = {}
    for rm in (0.0, beta):
        env = make_env(8, constrain_aim=constrain_aim, rm=rm, rm_model=FakeModel() if rm else None, seed=0)
        td = reset_to(env, racks)
        td["action"] = torch.as_tensor(actions, dtype=torch.float32)
        steps[rm] = env.step(td)["next"]
    raw = actions.astype(np.float32).astype(np.float64)
    if constrain_aim:
        raw[:, 0] = domain.constrained_theta(racks, raw[:, 0])
    expected = beta * FakeModel().prob(racks, raw)
    bonus = (steps[beta]["reward"] - steps[0.0]["reward"]).squeeze(-1).double().numpy()
    np.testing.assert_allclose(bonus, expected, rtol=1e-5, atol=1e-6)
    assert torch.equal(steps[beta]["score"], steps[0.0]["score"])  # the carom outcome is untouched
    assert torch.equal(steps[beta]["positions"], steps[0.0]["positions"])


def test_rm_bonus_loads_a_model_file(tmp_path):
    torch.manual_seed(0)
    model = RewardModel(hidden=(8,))
    path = save_model(tmp_path / "rm.pt", model)
    bonus = RewardModelBonus(str(path), beta=1.0)
    racks = random_racks(np.random.default_rng(0), 4)
    actions = np.tile([1.0, 0.5, 0.0, 0.0], (4, 1))
    np.testing.assert_allclose(bonus.model.prob(racks, actions), model.prob(racks, actions))


@pytest.mark.slow
def test_training_with_rm_shaping_evaluates_the_true_score(tmp_path):
    torch.manual_seed(0)
    model_path = save_model(tmp_path / "rm.pt", RewardModel(hidden=(8,)))
    run_dir = tmp_path / "run"
    from conftest import app_here

    proc = app_here("train.py", "shaping=rm", f"shaping.rm_model={model_path}", "shaping.rm=2.0", "budget=smoke",
                    "budget.total_steps=1024", "budget.eval_every=0", "budget.checkpoint_every=0", f"hydra.run.dir={run_dir}",
                    "progress=false", cwd=tmp_path, env=ENV)
    assert proc.returncode == 0, proc.stderr[-4000:]
    # training rewards carry the bonus (every shot gets 2 * V_rm > 0) ...
    import csv

    rows = list(csv.DictReader((run_dir / "metrics.csv").open()))
    train = [r for r in rows if r["train_reward"]]
    assert all(float(r["train_reward"]) > float(r["train_score_pct"]) / 100 for r in train)
    # ... the evaluation is the plain protocol on the true score: re-evaluating the saved
    # policy without any shaping gives the same result
    from billiards.rl.policy import load_policy

    saved = EvalResult.from_json(run_dir / "eval.json")
    policy, _ = load_policy(run_dir)
    again = evaluate_policy(policy, n_innings=saved.n_innings, max_shots=10, start="random", seed=0)
    assert again.points == saved.points and again.mean == saved.mean


@pytest.mark.slow
@pytest.mark.parametrize("variant,aim,shaping,curriculum", [
    ("table4/plain", False, "none", "none"), ("table3/staged", False, "none", "staged"), ("table3/rm", False, "rm", "none"),
    ("table4/aim", True, "none", "none"), ("table3/rm_aim", True, "rm", "none"),
])
def test_table3_variants_compose_and_record_their_row(variant, aim, shaping, curriculum):
    """Table 3's rows (its plain and aim rows are Table 4's runs) compose with the aid they name
    and record the table and row the report groups them by."""
    cfg = compose_cfg(f"experiment={variant.split('/')[0]}", f"variant={variant}")
    assert (cfg.algo.name, cfg.env.constrain_aim, cfg.env.extra_features) == ("sac", aim, False)
    assert (cfg.shaping.name, cfg.curriculum.name) == (shaping, curriculum)
    assert cfg.shaping.rm == (1.0 if shaping == "rm" else 0.0)
    assert f"{cfg.table}/{cfg.row}" == variant
