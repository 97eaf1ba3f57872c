"""Proposers: where the search's candidate actions come from.

A proposer maps S table states to k raw candidate actions each:
``propose(positions (S, 4, 2), k, rng) -> actions (S, k, 4)`` of (theta, p, a, b) in the
simulator's convention (theta in radians, exact float64). Candidate 0 of every state is the
proposer's own best guess (a policy's deterministic action, the geometric baseline shot), so a
search with one candidate and no expansion plays exactly what the proposer would.

* :class:`GeometricProposer` needs no training: it samples inside the aim-constraint cone.
* :class:`PolicyProposer` samples an ensemble of trained policies (e.g. the three seeds of
  one Table 5 variant); see :func:`load_policy_proposer`.
"""

from __future__ import annotations

from typing import Protocol, Sequence

import numpy as np
import torch

from billiards import domain
from billiards.physics import DEFAULT_PARAMS


class Proposer(Protocol):
    name: str

    def propose(self, positions: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
        """positions (S, 4, 2) -> candidate actions (S, k, 4), float64; candidate 0 is the mode."""


class GeometricProposer:
    """Shots inside the guaranteed-contact cone of the nearest red, no learning.

    Candidate 0 is the nearest-red baseline (u = 0, p = ``power_mode``, centre hit). The others
    draw u ~ U[-1, 1] (theta = theta_target + u * asin(2R/d), :func:`domain.constrained_theta`),
    p ~ U[power_low, power_high] and tip offsets a, b ~ U[-1, 1].
    """

    name = "geometric"

    def __init__(self, power_low: float = 0.15, power_high: float = 0.9, power_mode: float = 0.5,
                 R: float = DEFAULT_PARAMS.ball_radius):
        if not 0.0 <= power_low <= power_high <= 1.0:
            raise ValueError(f"GeometricProposer needs 0 <= power_low <= power_high <= 1, got {power_low}, {power_high}")
        self.power_low, self.power_high, self.power_mode, self.R = power_low, power_high, power_mode, R

    def propose(self, positions: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
        S = positions.shape[0]
        u = rng.uniform(-1.0, 1.0, (S, k))
        p = rng.uniform(self.power_low, self.power_high, (S, k))
        ab = rng.uniform(-1.0, 1.0, (S, k, 2))
        u[:, 0], p[:, 0], ab[:, 0] = 0.0, self.power_mode, 0.0
        theta = domain.constrained_theta(positions[:, None], u, self.R)
        return np.concatenate([theta[..., None], p[..., None], ab], axis=-1)


class PolicyProposer:
    """An ensemble of stochastic policies emitting k candidates jointly.

    ``policies`` are TorchRL probabilistic actors (TensorDict in with "observation", out with
    "action" and the distribution's "loc"), all trained with the same observation and action
    layout: ``extra_features`` appends :func:`domain.carom_features`; ``constrain_aim`` means
    action[0] is u in [-1, 1] and is mapped to theta with :func:`domain.constrained_theta`.
    Candidate j goes to policy j mod E; each policy's first candidate is its deterministic
    action (policy 0's is candidate 0), the rest are samples.
    """

    def __init__(self, policies: Sequence[torch.nn.Module], *, constrain_aim: bool, extra_features: bool,
                 name: str = "policy", R: float = DEFAULT_PARAMS.ball_radius):
        if not policies:
            raise ValueError("PolicyProposer needs at least one policy")
        self.policies = list(policies)
        self.constrain_aim, self.extra_features, self.name, self.R = constrain_aim, extra_features, name, R

    def observation(self, positions: np.ndarray) -> torch.Tensor:
        obs = domain.rest_observation(positions)
        if self.extra_features:
            obs = np.concatenate([obs, domain.carom_features(positions).astype(np.float32)], axis=-1)
        return torch.from_numpy(obs)

    @staticmethod
    def _actions(policy, obs: torch.Tensor, n: int, rng: np.random.Generator) -> torch.Tensor:
        """(S, n, 4) actions of one policy: its deterministic action, then n - 1 samples.

        One network call per policy: the policy's action distribution (``get_dist`` of its
        probabilistic actor) gives the deterministic action, and the samples are the
        distribution's reparameterised draws ``transforms(loc + scale * eps)`` with eps from
        the caller's numpy ``rng``, so torch's global RNG is never touched. The policy's last
        module (:class:`~billiards.rl.agents.ScaleAction`) maps them onto the env's bounds.
        """
        from tensordict import TensorDict

        actor, scale = policy[0], policy[1]
        S = obs.shape[0]
        dist = actor.get_dist(TensorDict({"observation": obs}, batch_size=[S]))
        draws = [dist.deterministic_sample[:, None]]
        if n > 1:
            normal = dist.base_dist.base_dist
            eps = torch.from_numpy(rng.standard_normal((S, n - 1, normal.loc.shape[-1]))).to(normal.loc.dtype)
            x = normal.loc[:, None] + normal.scale[:, None] * eps
            for t in dist.transforms:
                x = t(x)
            draws.append(x)
        norm = torch.cat(draws, dim=1).reshape(S * n, -1)
        return scale(TensorDict({"action_norm": norm}, batch_size=[S * n]))["action"].reshape(S, n, -1)

    @torch.no_grad()
    def propose(self, positions: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
        S, E = positions.shape[0], len(self.policies)
        obs = self.observation(positions)
        out = np.empty((S, k, 4))
        for e, policy in enumerate(self.policies):
            cols = np.arange(e, k, E)
            if cols.size:
                out[:, cols] = self._actions(policy, obs, cols.size, rng).double().numpy()
        out[..., 1] = np.clip(out[..., 1], 0.0, 1.0)
        out[..., 2:] = np.clip(out[..., 2:], -1.0, 1.0)
        if self.constrain_aim:
            out[..., 0] = domain.constrained_theta(positions[:, None], np.clip(out[..., 0], -1.0, 1.0), self.R)
        return out


__all__ = ["GeometricProposer", "PolicyProposer", "Proposer"]
