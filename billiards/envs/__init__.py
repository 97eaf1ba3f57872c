"""Environments: a gymnasium env (``Billiards4Ball-v0``) and a batched TorchRL env, plus the
TorchRL transforms of the paper's domain knowledge and :func:`make_env`.

``import billiards`` registers ``Billiards4Ball-v0`` (``gymnasium.make_vec`` of it builds the
batched vector env of :mod:`billiards.envs.gym_vector`); importing this package loads only the gymnasium side
(numpy, numba, gymnasium). The TorchRL names (:class:`BilliardsEnv`, :func:`make_env`, the
transforms) load torch and TorchRL on first use, so a gymnasium-only user neither pays for
that import nor gets the multiprocessing start method TorchRL sets.
"""

import importlib

from billiards import GYM_ID  # registered by ``import billiards``

from ._common import ON_MISS, PARADIGMS, STARTS, EnvOptions
from .gym_env import INFO_KEYS as GYM_INFO_KEYS
from .gym_env import Billiards4BallInningEnv

# TorchRL names -> the submodule that defines them, imported on first attribute access.
_LAZY = {
    "INFO_KEYS": "torchrl_env",
    "BilliardsEnv": "torchrl_env",
    "reset_to": "torchrl_env",
    "exact_positions": "torchrl_env",
    "AimConstraint": "transforms",
    "CaromFeatures": "transforms",
    "FoulPenalty": "transforms",
    "GentleShotBonus": "transforms",
    "NearMissBonus": "transforms",
    "NoiseLevelFeature": "transforms",
    "NormalizedActions": "transforms",
    "RewardModelBonus": "transforms",
    "make_env": "transforms",
}


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "EnvOptions",
    "GYM_ID",
    "GYM_INFO_KEYS",
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
    "NoiseLevelFeature",
    "NormalizedActions",
    "RewardModelBonus",
    "exact_positions",
    "make_env",
    "reset_to",
]
