"""Search actors: TensorDict modules that a TorchRL collector runs in place of a policy.

They read the exact table state ``"positions"`` (float64) from the TensorDict, search with the
simulator as verifier, and write the chosen raw action ``"action"`` (theta, p, a, b) as float64
so the environment plays exactly the shot that was verified. Use them on a bare
:class:`billiards.envs.BilliardsEnv` (raw actions); the proposers apply their own aim
constraint and features.

Under variable execution noise the env carries each shot's level as ``"noise_level"``; the
actors read it with the table and the noise-aware ones (robust, noisy PUCT) search at that level
(it is refused to search a variable noise blind: a ``ValueError`` names the missing level).
"""

from __future__ import annotations

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from billiards.physics import DEFAULT_PARAMS, PhysicsParams

from .lookahead import H2Config, h2_search
from .puct import PUCTConfig, puct_search
from .puct_noise import noisy_puct_search
from .robust import RobustConfig, robust_search


class SearchActor(TensorDictModuleBase):
    """Base class: ``positions`` (and under variable noise ``noise_level``) in; ``action`` and
    ``search_r1`` (the verified reward of the chosen shot, which P1 checks against what the env
    played) out."""

    in_keys = ["positions"]
    out_keys = ["action", "search_r1"]

    def __init__(self, proposer, cfg, seed: int = 0, params: PhysicsParams = DEFAULT_PARAMS):
        super().__init__()
        self.proposer, self.cfg, self.params = proposer, cfg, params
        self.reseed(seed)

    def reseed(self, seed: int) -> None:
        """Restart the candidate stream: the same seed replays the same decisions."""
        self.rng = np.random.default_rng(seed)
        self.n_sims = 0
        self.n_decisions = 0

    def search(self, positions: np.ndarray, levels: np.ndarray | None = None):
        """The search's result for tables (S, 4, 2) whose shots play at noise ``levels`` (S,)
        (variable noise: multipliers of the noise's sigmas; ignored by the exact searches)."""
        raise NotImplementedError

    def search_with(self, positions: np.ndarray, proposer, rng: np.random.Generator, levels: np.ndarray | None = None):
        """:meth:`search` over ``proposer``'s candidates drawn from ``rng`` instead of the actor's
        own (expert iteration labels with each round's policy and the run's own stream); the
        actor keeps its own proposer and stream for its later decisions."""
        own = self.proposer, self.rng
        self.proposer, self.rng = proposer, rng
        try:
            return self.search(positions, levels)
        finally:
            self.proposer, self.rng = own

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        positions = tensordict.get("positions").detach().cpu().numpy().astype(np.float64, copy=False)
        batch = positions.shape[:-2]
        levels = tensordict.get("noise_level", None)
        levels = None if levels is None else levels.detach().cpu().to(torch.float64).numpy().reshape(-1)
        positions = positions.reshape(-1, 4, 2)
        result = self.search(positions) if levels is None else self.search(positions, levels)
        self.n_sims += result.n_sims
        self.n_decisions += int(np.prod(batch))
        tensordict.set("action", torch.from_numpy(result.actions.reshape(*batch, 4)))
        tensordict.set("search_r1", torch.from_numpy(result.r1.reshape(*batch, 1)))
        return tensordict


class LookaheadActor(SearchActor):
    """Greedy depth-2 K-expansion lookahead (:func:`billiards.search.lookahead.h2_search`)."""

    def __init__(self, proposer, cfg: H2Config = H2Config(), seed: int = 0, params: PhysicsParams = DEFAULT_PARAMS):
        super().__init__(proposer, cfg, seed, params)

    def search(self, positions, levels=None):
        return h2_search(positions, self.proposer, self.cfg, self.rng, self.params)


class PUCTActor(SearchActor):
    """PUCT with progressive widening over the proposer's samples (:mod:`billiards.search.puct`)."""

    def __init__(self, proposer, cfg: PUCTConfig = PUCTConfig(), seed: int = 0, params: PhysicsParams = DEFAULT_PARAMS):
        super().__init__(proposer, cfg, seed, params)

    def search(self, positions, levels=None):
        return puct_search(positions, self.proposer, self.cfg, self.rng, self.params)


class RobustActor(SearchActor):
    """Candidates scored over noisy replays of their shot (:mod:`billiards.search.robust`)."""

    def __init__(self, proposer, cfg: RobustConfig, noise, seed: int = 0, params: PhysicsParams = DEFAULT_PARAMS,
                 value=None):
        self.noise, self.value = noise, value  # value: a TableValue pricing leaves (cfg.position, cfg.leave)
        super().__init__(proposer, cfg, seed, params)

    def search(self, positions, levels=None):
        return robust_search(positions, self.proposer, self.cfg, self.rng, self.params, self.noise,
                             levels=shot_levels(self.noise, levels), value=self.value)


class NoisyPUCTActor(SearchActor):
    """PUCT whose revisits are noisy replays (:mod:`billiards.search.puct_noise`)."""

    def __init__(self, proposer, cfg: PUCTConfig, noise, seed: int = 0, params: PhysicsParams = DEFAULT_PARAMS):
        self.noise = noise
        super().__init__(proposer, cfg, seed, params)

    def search(self, positions, levels=None):
        return noisy_puct_search(positions, self.proposer, self.cfg, self.rng, self.params, self.noise,
                                 levels=shot_levels(self.noise, levels))


def shot_levels(noise, levels):
    """The shots' noise levels a noise-aware search plays at: ``levels`` as given; under variable
    noise they must be given (the level told with each shot)."""
    if levels is None and noise is not None and noise.is_variable:
        raise ValueError(f"noise {noise.describe()} is variable: the search needs each shot's level, the env's "
                         f'"noise_level" (or search(positions, levels=...))')
    return levels


def _h2_actor(settings: H2Config, proposer, seed: int, params, noise) -> SearchActor:
    return LookaheadActor(proposer, settings, seed=seed, params=params)  # it plans with exact simulations, whatever the noise


def _puct_actor(settings: PUCTConfig, proposer, seed: int, params, noise) -> SearchActor:
    if noise is not None and not noise.is_exact:  # revisits are noisy replays (billiards.search.puct_noise)
        return NoisyPUCTActor(proposer, settings, noise, seed=seed, params=params)
    return PUCTActor(proposer, settings, seed=seed, params=params)


def _robust_actor(settings: RobustConfig, proposer, seed: int, params, noise) -> SearchActor:
    from billiards.physics.noise import get_noise

    return RobustActor(proposer, settings, get_noise(noise), seed=seed, params=params, value=settings.table_value(params))


ACTOR_OF = {H2Config: _h2_actor, PUCTConfig: _puct_actor, RobustConfig: _robust_actor}  # a search's settings -> its actor


def build_actor(settings, proposer, seed: int, params: PhysicsParams = DEFAULT_PARAMS, noise=None) -> SearchActor:
    """The actor of a search's checked ``settings`` (:mod:`billiards.search.settings`) over
    ``proposer``, seeded with ``seed``, for the execution noise ``noise`` (a NoiseModel, or None:
    exact play; the robust search samples it, PUCT replays with it, h2 plans exactly)."""
    for kind, build in ACTOR_OF.items():
        if isinstance(settings, kind):
            return build(settings.settings(), proposer, seed, params, noise)
    raise TypeError(f"no search actor for {type(settings).__name__}; the searches: {', '.join(k.__name__ for k in ACTOR_OF)}")


def make_search_collector(env, actor: SearchActor, frames_per_batch: int, total_frames: int):
    """The search collector: a TorchRL ``Collector`` running ``actor`` in place of the policy."""
    from torchrl.collectors import Collector

    return Collector(env, actor, frames_per_batch=frames_per_batch, total_frames=total_frames, trust_policy=True,
                     auto_register_policy_transforms=False)


__all__ = ["ACTOR_OF", "LookaheadActor", "NoisyPUCTActor", "PUCTActor", "RobustActor", "SearchActor", "build_actor",
           "make_search_collector"]
