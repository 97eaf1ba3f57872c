"""Two reference policies, as TensorDict modules that write ``"action"``.

* :func:`random_policy` -- every action coordinate uniform within the env's action bounds
  (its own seeded torch Generator, so runs are reproducible);
* :func:`nearest_red_policy` -- aim at the centre of the red nearest the white (a full-ball
  hit, ``theta = theta_target`` of :func:`billiards.domain.aim_window`), centre tip
  (a = b = 0), medium power p = 0.5.

Both work batched over any leading dims and in both action parameterisations (raw theta or
the aim constraint's u, where the nearest-red shot is u = 0).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from tensordict.nn import TensorDictModule
from torch import nn

from billiards import domain
from billiards.physics import DEFAULT_PARAMS

POLICIES = ("random", "nearest")


class UniformActor(nn.Module):
    """action ~ U[low, high], one row per leading index of the observation."""

    def __init__(self, low, high, seed: int = 0):
        super().__init__()
        self.register_buffer("low", torch.as_tensor(low, dtype=torch.float32))
        self.register_buffer("high", torch.as_tensor(high, dtype=torch.float32))
        self.generator = torch.Generator().manual_seed(int(seed))

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        shape = (*observation.shape[:-1], self.low.shape[-1])
        return self.low + (self.high - self.low) * torch.rand(shape, generator=self.generator)


class NearestRedActor(nn.Module):
    """action = (aim at the nearest red's centre, power, 0, 0) from the exact positions."""

    def __init__(self, power: float = 0.5, constrain_aim: bool = False, R: float = DEFAULT_PARAMS.ball_radius):
        super().__init__()
        self.power, self.constrain_aim, self.R = float(power), bool(constrain_aim), float(R)

    def forward(self, positions: torch.Tensor) -> torch.Tensor:
        pos = positions.detach().cpu().numpy()
        if self.constrain_aim:
            aim = np.zeros(pos.shape[:-2])  # u = 0: the centre of the contact window
        else:
            aim = np.mod(domain.aim_window(pos, self.R)[0], 2.0 * math.pi)  # into the spec's [0, 2pi)
        action = np.zeros(pos.shape[:-2] + (domain.ACTION_DIM,), dtype=np.float32)
        action[..., 0] = aim
        action[..., 1] = self.power
        return torch.from_numpy(action)


def random_policy(action_spec=None, seed: int = 0, constrain_aim: bool = False) -> TensorDictModule:
    """Uniform random actions within ``action_spec`` (use ``env.action_spec_unbatched``); by
    default within the raw bounds, or the aim-constrained ones if ``constrain_aim``."""
    if action_spec is not None:
        low, high = action_spec.space.low, action_spec.space.high
    else:
        low, high = domain.action_bounds(constrain_aim)
    return TensorDictModule(UniformActor(low, high, seed), in_keys=["observation"], out_keys=["action"])


def nearest_red_policy(power: float = 0.5, constrain_aim: bool = False, R: float = DEFAULT_PARAMS.ball_radius) -> TensorDictModule:
    """Full-ball hit on the nearest red at power p (default 0.5), no spin. Reads ``"positions"``."""
    return TensorDictModule(NearestRedActor(power, constrain_aim, R), in_keys=["positions"], out_keys=["action"])


def make_policy(name: str, *, constrain_aim: bool = False, seed: int = 0) -> TensorDictModule:
    """A baseline by name: ``"random"`` or ``"nearest"``."""
    if name == "random":
        return random_policy(seed=seed, constrain_aim=constrain_aim)
    if name == "nearest":
        return nearest_red_policy(constrain_aim=constrain_aim)
    raise ValueError(f"unknown baseline policy {name!r}; choose from {POLICIES}")
