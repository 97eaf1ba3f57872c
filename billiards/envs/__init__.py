"""Environments: a gymnasium env (``Billiards4Ball-v0``) and a batched TorchRL env, plus the
TorchRL transforms of the paper's domain knowledge and :func:`make_env`."""

import gymnasium

from ._common import ON_MISS, PARADIGMS, STARTS
from .gym_env import Billiards4BallInningEnv
from .torchrl_env import INFO_KEYS, BilliardsEnv, reset_to
from .transforms import (
    AimConstraint,
    CaromFeatures,
    FoulPenalty,
    GentleShotBonus,
    NearMissBonus,
    RewardModelBonus,
    make_env,
)

GYM_ID = "Billiards4Ball-v0"
if GYM_ID not in gymnasium.registry:
    gymnasium.register(id=GYM_ID, entry_point="billiards.envs.gym_env:Billiards4BallInningEnv")

__all__ = [
    "GYM_ID",
    "INFO_KEYS",
    "ON_MISS",
    "PARADIGMS",
    "STARTS",
    "AimConstraint",
    "Billiards4BallInningEnv",
    "BilliardsEnv",
    "CaromFeatures",
    "FoulPenalty",
    "GentleShotBonus",
    "NearMissBonus",
    "RewardModelBonus",
    "make_env",
    "reset_to",
]
