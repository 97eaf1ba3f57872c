"""The reward shaping's options, as one schema: :class:`ShapingOptions`.

Every place that takes the shaping's coefficients derives from it, so their keys, types,
defaults and meaning are written once:

* :class:`billiards.envs._common.Shaping` -- the coefficients an env rewards with, checked
  (the gymnasium envs, and the TorchRL transforms :func:`billiards.envs.make_env` adds);
* :class:`billiards.envs.EnvOptions` -- :func:`~billiards.envs.make_env`'s options;
* :class:`billiards.rl.config.ShapingConfig` -- the training config's ``shaping`` node (a Hydra
  schema: mutable, so this one is too, and the env's read-only ones enforce that themselves).

The terms themselves are :mod:`billiards.domain`'s (:func:`~billiards.domain.shaped_reward`).
This module imports nothing, so the training config's schema derives from it without loading
the simulator's kernels (its checks stay fast).
"""

from __future__ import annotations

import dataclasses


@dataclasses.dataclass(kw_only=True)
class ShapingOptions:
    """Reward shaping added to the carom score (evaluation never shapes); 0 switches a term off.
    The defaults are the env's: no shaping, no reward model. Checked where they enter an env
    (:class:`billiards.envs._common.Shaping`) or a training config
    (:meth:`billiards.rl.config.ShapingConfig.errors`)."""

    foul_penalty: float = 0.0  # reward -= foul_penalty * foul
    # on a score, reward += gentle * exp(-(d - 0.2)^2 / (2 0.1^2)), d the white's rest distance to
    # the second red it hit (the paper: 0.2)
    gentle: float = 0.0
    gentle_kind: str = "leave"  # leave: the paper's leave-position bonus above; power: gentle * (1 - p)
    near_miss: float = 0.0  # reward += near_miss * exp(-gap / near_miss_sigma) for a one-red miss (the paper: 0.05)
    near_miss_sigma: float = 0.03  # metres: billiards.domain.NEAR_MISS_SIGMA, the paper's (tests/envs pin the two together)
    rm: float = 0.0  # reward += rm * V_rm(s, a), the learned reward model's P(score | s, a) (TorchRL env only)
    rm_model: object = None  # the reward model (a billiards.rm.RewardModel or a path), needed if rm


__all__ = ["ShapingOptions"]
