"""``sagu_v0``: two-player Korean 4-ball matches as a PettingZoo AEC environment.

    from billiards.envs import sagu_v0
    env = sagu_v0.env(noise="fastfiz_x5", target=10)
    env.reset(seed=0)
    for agent in env.agent_iter():
        obs, reward, terminated, truncated, info = env.last()
        env.step(None if terminated or truncated else policy(agent, obs))

The rules, observation, action and reward: :mod:`billiards.envs.sagu`. ``env()`` is
``raw_env()`` inside PettingZoo's order-enforcing wrapper (PettingZoo's convention); TorchRL
runs it through ``torchrl.envs.PettingZooWrapper`` (docs/matches.md). pettingzoo is a
dependency of the package.
"""

from __future__ import annotations

import numpy as np
from pettingzoo import AECEnv
from pettingzoo.utils import wrappers

from billiards.physics.checks import one_of

from .sagu import AGENTS, SaguEnv, shooter_view

FIRST = ("white", "yellow")


def env(**kwargs) -> AECEnv:
    """:func:`raw_env` wrapped by PettingZoo's ``OrderEnforcingWrapper``."""
    return wrappers.OrderEnforcingWrapper(raw_env(**kwargs))


class raw_env(AECEnv):  # noqa: N801  (PettingZoo's convention: a module's env() and raw_env())
    """The match as an AEC env. Keyword arguments: ``target`` (points to win, default 10),
    ``max_innings`` (then the match is truncated, default 200), ``start`` (``"canonical"``: the
    opening rack, or ``"random"``), ``first`` (who breaks: ``"white"``, the default, or
    ``"yellow"``; ``reset(options={"first": ...})`` for one match: a league alternates it),
    ``foul_penalty`` (points a foul costs, default 1),
    ``noise`` (an execution-noise preset or model; default exact), ``physics`` (a table preset,
    default the paper's ``korean_medium``), ``constrain_aim``, ``extra_features`` (as in the
    single-player envs), ``render_mode`` (``"rgb_array"``)."""

    metadata = {"name": "sagu_v0", "render_modes": ["rgb_array"], "is_parallelizable": False, "render_fps": 2}

    def __init__(self, *, first: str = "white", render_mode: str | None = None, **game):
        super().__init__()
        one_of(first, "first", FIRST)
        one_of(render_mode, "render_mode", (None, "rgb_array"))
        self.game = SaguEnv(**game)
        self.first, self.render_mode = first, render_mode
        self.possible_agents = list(AGENTS)
        self._rng = np.random.default_rng()
        self.agents: list[str] = []

    def observation_space(self, agent: str):
        one_of(agent, "agent", AGENTS)
        return self.game.observation_space

    def action_space(self, agent: str):
        one_of(agent, "agent", AGENTS)
        return self.game.action_space

    def observe(self, agent: str) -> np.ndarray:
        return self.game.observe(AGENTS.index(one_of(agent, "agent", AGENTS)))

    def reset(self, seed: int | None = None, options: dict | None = None) -> None:
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        first = (options or {}).get("first", self.first)  # other keys are ignored, as PettingZoo's API test expects
        one_of(first, 'options["first"]', FIRST)
        self.game.reset(self._rng, AGENTS.index(first))
        self.agents = list(AGENTS)
        self.rewards = {a: 0.0 for a in self.agents}
        self._cumulative_rewards = {a: 0.0 for a in self.agents}
        self.terminations = {a: False for a in self.agents}
        self.truncations = {a: False for a in self.agents}
        self.infos = {a: self._info(a) for a in self.agents}
        self.agent_selection = AGENTS[self.game.mover]

    def _info(self, agent: str, shot: dict | None = None) -> dict:
        """The same flat numeric keys for every agent at every step (TorchRL's wrapper stacks
        them): the scores, innings and shots so far, and whether the last shot was this agent's
        and scored or fouled."""
        me = AGENTS.index(agent)
        mine = shot is not None and shot["player"] == me
        return {"own_score": np.float64(self.game.scores[me]), "opponent_score": np.float64(self.game.scores[1 - me]),
                "innings": np.int64(self.game.innings), "shots": np.int64(self.game.shots), "shot_mine": np.array(mine),
                "shot_score": np.array(mine and shot["score"]), "shot_foul": np.array(mine and shot["foul"])}

    def step(self, action) -> None:
        agent = self.agent_selection
        if self.terminations[agent] or self.truncations[agent]:
            self._was_dead_step(action)
            return
        shot = self.game.shoot(action, self._rng)  # a refused action raises here, before anything changes
        self._cumulative_rewards[agent] = 0.0
        other = AGENTS[1 - shot["player"]]
        self.rewards = {agent: shot["gained"], other: -shot["gained"]}
        self.infos = {a: self._info(a, shot) for a in self.agents}
        if shot["won"]:
            self.terminations = {a: True for a in self.agents}
        elif shot["over_limit"]:
            self.truncations = {a: True for a in self.agents}
        self.agent_selection = AGENTS[self.game.mover]
        self._accumulate_rewards()

    def render(self):
        if self.render_mode is None:
            return None
        from billiards.render import table_rgb_array

        last = self.game.last_shot  # (table before the shot, the shot played, its player): drawn from the shooter's view
        return table_rgb_array(self.game.positions, self.game.params,
                               last_shot=None if last is None else (shooter_view(last[0], last[2]), last[1]))

    def close(self) -> None:
        pass


__all__ = ["env", "raw_env"]
