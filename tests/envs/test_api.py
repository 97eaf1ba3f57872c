"""One API test every environment passes (as Pgx's ``api_test`` is for its games): the
gymnasium env, the batched vector env, the TorchRL env (bare and with the paper's transforms,
exact and noisy) and the two-player PettingZoo env.

Each family is driven through a small adapter (reset with a seed, step with an action drawn
from its own action space, the observation and reward it returns) and :func:`api_test` checks
the same contract on all of them:

* a reset's observation lies in the declared observation space;
* every step's observation lies in the space, its reward is a finite real number, its flags
  are booleans, and an ended episode ends the same way in each env of a batch;
* the same seed and the same actions replay the same observations and rewards bit for bit,
  and another seed plays otherwise (a two-player match always breaks from the same table);
* the family's own checker has no complaint (gymnasium's ``check_env``, TorchRL's
  ``check_env_specs``, PettingZoo's ``api_test``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

STEPS = 6


class GymAdapter:
    name = "gymnasium"

    def __init__(self, **options):
        import gymnasium as gym

        from billiards import GYM_ID

        self.env = gym.make(GYM_ID, **options)

    def reset(self, seed):
        obs, _ = self.env.reset(seed=seed)
        self.env.action_space.seed(seed)
        return obs

    def step(self):
        obs, reward, term, trunc, info = self.env.step(self.env.action_space.sample())
        assert isinstance(term, bool) and isinstance(trunc, bool)
        assert isinstance(info, dict)
        return obs, [float(reward)], term or trunc

    def contains(self, obs):
        return self.env.observation_space.contains(obs)

    def checker(self):
        from gymnasium.utils.env_checker import check_env

        check_env(self.env.unwrapped, skip_render_check=True)


class VectorAdapter:
    name = "gymnasium vector"

    def __init__(self, **options):
        import gymnasium as gym

        from billiards import GYM_ID

        self.env = gym.make_vec(GYM_ID, num_envs=3, **options)

    def reset(self, seed):
        obs, _ = self.env.reset(seed=seed)
        self.env.action_space.seed(seed)
        return obs

    def step(self):
        obs, reward, term, trunc, _ = self.env.step(self.env.action_space.sample())
        assert term.dtype == bool and trunc.dtype == bool and reward.shape == (3,)
        return obs, list(map(float, reward)), False  # the vector env resets finished envs itself

    def contains(self, obs):
        return self.env.observation_space.contains(obs)

    def checker(self):
        pass  # gymnasium has no checker for vector envs; the vector env's own tests compare it to the sync one


class TorchRLAdapter:
    name = "torchrl"

    def __init__(self, **options):
        from billiards.envs import make_env

        self.options = options
        self.env = make_env(3, **options)

    def reset(self, seed):
        import torch

        self.env.set_seed(seed)
        torch.manual_seed(seed)
        self.td = self.env.reset()
        return self.td["observation"].numpy().copy()

    def step(self):
        from torchrl.envs.utils import step_mdp

        self.td.set("action", self.env.action_spec.rand())
        out = self.env.step(self.td)
        nxt = out["next"]
        assert nxt["done"].dtype.is_floating_point is False
        done = bool(nxt["done"].any())
        rewards = nxt["reward"].reshape(-1).tolist()
        obs = nxt["observation"].numpy().copy()
        self.td = self.env.reset(step_mdp(out)) if done else step_mdp(out)
        return obs, rewards, False

    def contains(self, obs):
        import torch

        return bool(self.env.observation_spec["observation"].is_in(torch.as_tensor(obs)))

    def checker(self):
        from torchrl.envs.utils import check_env_specs

        check_env_specs(self.env, seed=0)


class PettingZooAdapter:
    name = "pettingzoo"

    def __init__(self, **options):
        from billiards.envs import sagu_v0

        self.options = options
        self.env = sagu_v0.env(**options)

    def reset(self, seed):
        self.env.reset(seed=seed)
        for agent in self.env.possible_agents:
            self.env.action_space(agent).seed(seed)
        return self.env.observe(self.env.agent_selection)

    def step(self):
        agent = self.env.agent_selection
        self.env.step(self.env.action_space(agent).sample())
        obs, reward, term, trunc, _ = self.env.last()
        assert isinstance(term, bool) and isinstance(trunc, bool)
        return obs, [float(self.env.rewards[a]) for a in self.env.possible_agents], term or trunc

    def contains(self, obs):
        return self.env.observation_space(self.env.agent_selection).contains(obs)

    def checker(self):
        from pettingzoo.test import api_test

        from billiards.envs import sagu_v0

        api_test(sagu_v0.env(**self.options), num_cycles=10)


def play(adapter, seed: int):
    """The observations and rewards of STEPS steps from a reset with ``seed``."""
    obs = adapter.reset(seed)
    assert adapter.contains(obs), f"{adapter.name}: the reset observation is outside the observation space"
    trace = [np.asarray(obs).copy()]
    for _ in range(STEPS):
        obs, rewards, ended = adapter.step()
        assert adapter.contains(obs), f"{adapter.name}: a step's observation is outside the observation space"
        assert all(isinstance(r, float) and math.isfinite(r) for r in rewards), rewards
        trace += [np.asarray(obs).copy(), np.asarray(rewards)]
        if ended:
            obs = adapter.reset(seed + 1000)
            trace.append(np.asarray(obs).copy())
    return trace


def api_test(make) -> None:
    first, again, other = play(make(), 3), play(make(), 3), play(make(), 4)
    assert len(first) == len(again)
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)  # bit for bit: the same seed and actions replay
    assert any(a.shape != b.shape or not np.array_equal(a, b) for a, b in zip(first, other)), "another seed plays the same"
    make().checker()


FAMILIES = {
    "gym": (GymAdapter, {}),
    "gym-aim-features-fastfiz": (GymAdapter, {"constrain_aim": True, "extra_features": True, "noise": "fastfiz"}),
    "gym-variable": (GymAdapter, {"noise": "variable"}),
    "vector": (VectorAdapter, {}),
    "vector-aim-features": (VectorAdapter, {"constrain_aim": True, "extra_features": True}),
    "torchrl": (TorchRLAdapter, {}),
    "torchrl-aim-features-shaped": (TorchRLAdapter, {"constrain_aim": True, "extra_features": True, "foul_penalty": 0.5,
                                                     "near_miss": 0.05}),
    "torchrl-variable": (TorchRLAdapter, {"noise": "variable"}),
    "pettingzoo": (PettingZooAdapter, {}),
    "pettingzoo-fastfiz": (PettingZooAdapter, {"noise": "fastfiz"}),
}


@pytest.mark.parametrize("family", list(FAMILIES))
def test_every_env_passes_the_one_api_test(family):
    adapter, options = FAMILIES[family]
    api_test(lambda: adapter(**options))
