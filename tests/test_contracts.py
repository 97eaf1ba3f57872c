"""Strict env and API contracts: calls that would silently do something else are refused, with
a message naming what was wrong (gymnasium's and TorchRL's conventions)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

from billiards.envs import Billiards4BallInningEnv, BilliardsEnv, make_env
from billiards.physics import PRESETS, canonical_rack, simulate_batch, simulate_shot, trajectory

SHOT = np.array([0.3, 0.5, 0.0, 0.0], dtype=np.float32)


def _play_to_the_end(env, action) -> None:
    env.reset(seed=0)
    for _ in range(env.max_shots + 1):
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            return
    raise AssertionError("the inning never ended")


def test_gym_stepping_a_finished_inning_raises_until_reset():
    env = Billiards4BallInningEnv(max_shots=3)
    _play_to_the_end(env, SHOT)
    with pytest.raises(gym.error.ResetNeeded, match="call reset"):
        env.step(SHOT)
    env.reset(seed=1)
    env.step(SHOT)  # a new inning steps again
    env = Billiards4BallInningEnv(max_shots=5, on_miss="reset")  # ended by a miss (terminated)
    env.reset(options={"positions": canonical_rack()})
    _, _, terminated, _, _ = env.step(np.array([0.5, -0.9, 0.0, 0.0], dtype=np.float32))  # a weak shot away: a miss
    assert terminated
    with pytest.raises(gym.error.ResetNeeded):
        env.step(SHOT)


def test_gym_unknown_reset_options_raise():
    env = Billiards4BallInningEnv()
    with pytest.raises(ValueError, match=r"reset options may only be \['positions'\]; got 'postions'"):
        env.reset(options={"postions": canonical_rack()})
    env.reset(options={})  # no option: a random rack
    env.reset(options={"positions": None})


@pytest.mark.parametrize("action", [["0.1", "0.5", "0", "0"], np.array([0.1 + 1j, 0.5, 0, 0]), np.array([True, False, True, False]),
                                    np.array([object(), 0.5, 0, 0], dtype=object)])
def test_actions_must_be_real_numbers(action):
    env = Billiards4BallInningEnv(normalize_actions=False)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="real numbers|numeric"):
        env.step(action)
    with pytest.raises(ValueError, match="real numbers|numeric"):
        simulate_shot(canonical_rack(), action)


@pytest.mark.parametrize("flag", ["constrain_aim", "extra_features", "normalize_actions"])
def test_boolean_options_must_be_booleans(flag):
    with pytest.raises(TypeError, match=f"{flag} must be True or False, got 'no'"):
        Billiards4BallInningEnv(**{flag: "no"})
    with pytest.raises(TypeError, match=f"{flag} must be True or False"):
        make_env(2, **{flag: "no"})
    assert getattr(Billiards4BallInningEnv(**{flag: np.bool_(True)}), flag) is True


def test_torchrl_stepping_without_a_reset_or_past_the_inning_raises():
    env = BilliardsEnv(2, max_shots=3, seed=0)
    td = env.reset()
    td["action"] = torch.from_numpy(np.stack([SHOT, SHOT]).astype(np.float64))
    env.step(td.clone())  # a valid step
    for shot, message in ((torch.tensor([[0], [3]]), "must lie in \\[0, max_shots - 1 = 2\\]"),
                          (torch.tensor([[-1], [0]]), "innings \\[0\\] have \\[-1\\]"),
                          (torch.tensor([[0.5], [0.0]]), "must be an integer tensor")):
        bad = td.clone()
        bad["shot"] = shot
        with pytest.raises(ValueError, match=message):
            env.step(bad)
    with pytest.raises(KeyError, match="call env.reset"):
        env.step(td.select("action"))


def test_an_action_that_requires_grad_is_played_by_its_values():
    action = torch.from_numpy(np.stack([SHOT, SHOT])).requires_grad_(True)
    played = []
    for a in (action * 1.0, action.detach().clone()):  # part of a graph, and plain
        env = make_env(2, seed=0)
        played.append(env.step(env.reset().set("action", a))["next", "positions"])
    assert torch.equal(*played)


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_a_preset_name_is_accepted_wherever_parameters_are(name):
    params = PRESETS[name]
    rack = canonical_rack(name)
    assert np.array_equal(rack, canonical_rack(params))
    by_name, by_params = simulate_shot(rack, SHOT, params=name), simulate_shot(rack, SHOT, params=params)
    assert np.array_equal(by_name.positions, by_params.positions)
    assert np.array_equal(simulate_batch(rack[None], SHOT[None], name).positions, by_params.positions[None])
    assert BilliardsEnv(1, params=name).params == params
    with pytest.raises(ValueError, match="unknown physics preset 'nowhere'"):
        simulate_shot(rack, SHOT, params="nowhere")


@pytest.mark.parametrize("dt", [-1.0, 0.0, float("nan"), float("inf")])
def test_trajectory_needs_a_positive_time_step(dt):
    result = simulate_shot(canonical_rack(), SHOT)
    with pytest.raises(ValueError, match="finite time step dt > 0"):
        trajectory(result, dt=dt)
