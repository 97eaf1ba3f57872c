"""Players of a two-player match (:mod:`billiards.envs.sagu_v0`).

A player sees the table from its own point of view (its cue ball in slot 0, as the simulator's
shooter: :func:`billiards.envs.sagu.shooter_view`) and returns the normalised action the env
takes. Four kinds, one schema each (:data:`PLAYERS`):

* ``random``: uniform actions;
* ``policy``: a trained single-player policy (``policy``: a training run dir, its checkpoint or an
  exported policy file, e.g. ``results/policies/base/seed0.pt``), acting deterministically on the
  single-player observation of its own view (with the aim constraint and features it was trained
  with);
* ``search`` (*greedy*): a search of :mod:`billiards.search` (by default the noise-aware robust
  search) maximising its own chance to score, blind to the leave;
* ``safety`` (*safety-aware*): the same search's shot and ``k`` of its proposer's candidates,
  each replayed ``replays`` times under the execution noise; a candidate is worth its chance to
  score, less ``foul_penalty`` times its chance to foul, less ``leave_weight`` times, over the
  replays that do not score, the opponent's best chance to score from the table it leaves (the opponent's own
  ``opp_k`` candidates from that leave, each replayed ``opp_replays`` times). It plays a safety
  when a hard shot would hand the opponent an easy table. With a ``threshold`` it plays the
  search's shot whenever the search rates it at least that, and weighs leaves only below it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar, Optional, Union

import numpy as np

from billiards import domain
from billiards.envs._common import with_levels
from billiards.envs.sagu import SWAP
from billiards.physics import PhysicsParams, simulate_batch
from billiards.physics.noise import NoiseModel

@dataclass
class RandomPlayer:
    """``kind: random``: uniform actions."""

    kind: str = "random"

    def errors(self, name: str) -> list[str]:
        """What is wrong with the player's knobs (its files: :meth:`file_errors`)."""
        return []

    def file_errors(self, name: str, noise: NoiseModel | None) -> list[str]:
        """The player's files loaded and checked, before a league writes anything."""
        return []

    def build(self, noise: NoiseModel, params: PhysicsParams):
        return RandomAgent()


@dataclass
class PolicyPlayer:
    """``kind: policy``: a trained single-player policy (``policy``: its file or run dir)."""

    kind: str = "policy"
    policy: Optional[str] = None

    def errors(self, name: str) -> list[str]:
        from billiards.files import repo_path

        if not self.policy or not repo_path(self.policy).exists():
            return [f"agents.{name}.policy: no trained policy at {self.policy!r} (a run dir or an exported policy file)"]
        return []

    def file_errors(self, name: str, noise: NoiseModel | None) -> list[str]:
        from billiards.files import repo_path
        from billiards.rl.policy import policy_file_error

        err = policy_file_error(repo_path(self.policy))
        return [f"agents.{name}.policy: {err}"] if err else []

    def build(self, noise: NoiseModel, params: PhysicsParams):
        return PolicyAgent(self.policy, params)


@dataclass
class SearchPlayer:
    """``kind: search`` (*greedy*): ``search`` and ``proposer`` are options of ``search.py``
    (``conf/search/``, the ``proposer=`` names; ``proposer: for_noise``: the match's noise
    preset's shot proposer, ``search.py``'s ``proposer=for_noise_<preset>``, e.g. the shot ranker
    trained for it);
    ``search_budget``: simulations per decision; ``overrides``: further knobs of the search
    option (e.g. a table value's weights, ``{position: 1, leave: 1, value: results/values/value.pt}``)."""

    kind: str = "search"
    search: str = "robust"
    proposer: str = "ranked"
    search_budget: int = 400
    overrides: dict = field(default_factory=dict)  # further knobs of the search option, by name

    # the upper bounds of a player's numbers (docs/reliability.md); search_budget: the search's own
    UPPER: ClassVar[dict] = {"search_budget": (10**5, "simulations per decision")}

    def errors(self, name: str) -> list[str]:
        from billiards.app_config import upper_bound_errors

        errs = [f"agents.{name}.search_budget must be >= 1, got {self.search_budget}"] if self.search_budget < 1 else []
        errs += self.own_errors(name) + upper_bound_errors(self, f"agents.{name}.", self.UPPER)
        if not errs:
            errs += [f"agents.{name}: {e}" for e in self.search_option_errors()]
        return errs

    def own_errors(self, name: str) -> list[str]:
        """The knobs a subclass adds (none here)."""
        return []

    def proposer_config(self, noise: NoiseModel | None):
        """The proposer option this player plays (``for_noise``: the shot proposer of the match's
        noise preset); ValueError under a noise that is no preset, None where the noise is not known."""
        from billiards.search.config import NOISE_SHOT_PROPOSERS, proposer_options

        if self.proposer != "for_noise":
            return proposer_options()[self.proposer]
        if noise is None:
            return None
        if (preset := noise.describe()) not in NOISE_SHOT_PROPOSERS:
            raise ValueError(f"proposer: for_noise needs a noise preset ({', '.join(NOISE_SHOT_PROPOSERS)}); "
                             f"this match plays {preset}")
        return NOISE_SHOT_PROPOSERS[preset]

    def file_errors(self, name: str, noise: NoiseModel | None) -> list[str]:
        """Its proposer's ranker or policies (``noise`` None: not known yet). Its table value:
        :meth:`errors`."""
        try:
            proposer = self.proposer_config(noise)
        except ValueError as err:
            return [f"agents.{name}: {err}"]
        return [] if proposer is None else [f"agents.{name}: {e}" for e in proposer.errors()]

    def search_option(self):
        """The search option (``search.py``'s schema) this player plays."""
        from billiards.search.config import OPTIONS

        return OPTIONS["search"][1][self.search](budget=self.search_budget, **self.overrides)

    def search_option_errors(self) -> list[str]:
        from billiards.search.config import OPTIONS, proposer_options

        if self.search not in OPTIONS["search"][1]:
            return [f"search must be one of {', '.join(OPTIONS['search'][1])}, got {self.search!r}"]
        if self.proposer != "for_noise" and self.proposer not in proposer_options():
            return [f"proposer must be for_noise or one of {', '.join(proposer_options())}, got {self.proposer!r}"]
        try:
            option = self.search_option()
        except TypeError as err:
            return [f"overrides: {err}"]
        return option.errors()

    def build(self, noise: NoiseModel, params: PhysicsParams):
        from billiards.search.actors import build_actor

        proposer = self.proposer_config(noise).build(params)
        return SearchAgent(build_actor(self.search_option(), proposer, 0, params, noise=noise))


@dataclass
class SafetyPlayer(SearchPlayer):
    """``kind: safety`` (*safety-aware*): the search player's search, then the safety knobs of
    the module docstring (``k``, ``replays``, ``opp_k``, ``opp_replays``, ``foul_penalty``,
    ``leave_weight``, ``threshold``)."""

    kind: str = "safety"
    k: int = 32
    replays: int = 12
    opp_k: int = 32
    opp_replays: int = 2
    foul_penalty: float = 1.0
    leave_weight: float = 1.0  # how much the opponent's chance from a leave costs (0: greedy over the candidates)
    # play the search's shot when its own statistic (its chance to score less the foul penalty's
    # share) is at least this; weigh the leaves only below it (None: always weigh them)
    threshold: Optional[float] = None

    UPPER: ClassVar[dict] = {**SearchPlayer.UPPER,
                             **{key: (10_000, "candidates or replays per decision") for key in ("k", "replays", "opp_k",
                                                                                                 "opp_replays")},
                             **{key: (100.0, "points; a score is worth 1") for key in ("foul_penalty", "leave_weight")}}

    def own_errors(self, name: str) -> list[str]:
        errs = [f"agents.{name}.{key} must be >= 1, got {getattr(self, key)}"
                for key in ("k", "replays", "opp_k", "opp_replays") if getattr(self, key) < 1]
        errs += [f"agents.{name}.{key} must be >= 0, got {getattr(self, key)}"
                 for key in ("foul_penalty", "leave_weight") if not (math.isfinite(getattr(self, key)) and getattr(self, key) >= 0)]
        if self.threshold is not None and not 0.0 <= self.threshold <= 1.0:
            errs.append(f"agents.{name}.threshold must be null or lie in [0, 1] (the search's own rating of its shot), "
                        f"got {self.threshold!r}")
        return errs

    def build(self, noise: NoiseModel, params: PhysicsParams):
        from billiards.search.actors import build_actor
        from billiards.search.config import proposer_options

        proposer = self.proposer_config(noise).build(params)
        actor = build_actor(self.search_option(), proposer, 0, params, noise=noise)
        return SafetyAgent(actor, proposer, proposer_options()["geometric"].build(params), self, noise, params)


# kind -> the player's schema: the one list of player kinds
PLAYERS: dict[str, type] = {"random": RandomPlayer, "search": SearchPlayer, "safety": SafetyPlayer, "policy": PolicyPlayer}
KINDS = tuple(PLAYERS)
PlayerConfig = Union[RandomPlayer, PolicyPlayer, SearchPlayer, SafetyPlayer]


def player_keys(kind: str) -> set[str]:
    """The keys a player of ``kind`` takes (none for a kind that is not one)."""
    import dataclasses

    return {f.name for f in dataclasses.fields(PLAYERS[kind])} if kind in PLAYERS else set()


def player_config(node, name: str = "?") -> PlayerConfig:
    """A player's schema object from its config node (a mapping; ``kind`` picks the schema,
    default ``search``; the schema's defaults filled in); ValueError naming ``agents.<name>``
    for an unknown kind, a key its kind does not take or a value of the wrong type."""
    import dataclasses

    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    if isinstance(node, tuple(PLAYERS.values())):
        return node
    kind = node.get("kind", "search") if hasattr(node, "get") else None
    if kind not in PLAYERS:
        raise ValueError(f"agents.{name}.kind must be one of {', '.join(KINDS)}, got {kind!r}")
    schema = PLAYERS[kind]
    try:
        return OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(schema), node))
    except OmegaConfBaseException as err:
        keys = ", ".join(f.name for f in dataclasses.fields(schema))
        key = getattr(err, "full_key", None)
        where = f"agents.{name}" + (f".{key}" if key else "")
        raise ValueError(f"{where}: {str(err).splitlines()[0]} (a {kind} player's keys: {keys})") from None


def to_env_action(raw: np.ndarray) -> np.ndarray:
    """A raw (theta, p, a, b) as the env's normalised float32 action (theta wrapped into [0, 2 pi))."""
    raw = np.array(raw, dtype=np.float64)
    raw[0] = raw[0] % (2 * math.pi)
    return np.clip(domain.normalize_action(raw), -1.0, 1.0).astype(np.float32)


class RandomAgent:
    def __init__(self):
        self.rng = np.random.default_rng(0)

    def reseed(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def act(self, view: np.ndarray, level: float | None = None) -> np.ndarray:
        return self.rng.uniform(-1.0, 1.0, 4).astype(np.float32)


class SearchAgent:
    """The greedy player: the search's chosen shot."""

    def __init__(self, actor):
        self.actor = actor

    def reseed(self, seed: int) -> None:
        self.actor.reseed(seed)

    def act(self, view: np.ndarray, level: float | None = None) -> np.ndarray:
        result = self.actor.search(view[None], None if level is None else np.array([level]))  # variable noise: the shot's level
        return to_env_action(result.actions[0])


class PolicyAgent:
    """A trained single-player policy as a player (deterministic)."""

    def __init__(self, path: str, params: PhysicsParams):
        from billiards.files import repo_path
        from billiards.rl.policy import load_policy, reads_level

        self.policy, cfg = load_policy(repo_path(path))
        self.constrain_aim, self.extra_features = bool(cfg.env.constrain_aim), bool(cfg.env.extra_features)
        self.reads_level = reads_level(cfg)  # trained under variable noise: the level is its last input
        self.params, self.path = params, path

    def reseed(self, seed: int) -> None:
        pass  # deterministic

    def act(self, view: np.ndarray, level: float | None = None) -> np.ndarray:
        import torch
        from tensordict import TensorDict
        from torchrl.envs.utils import ExplorationType, set_exploration_type

        obs = domain.observation(view[None], self.extra_features)
        if self.reads_level:
            if level is None:
                from billiards.rl.policy import level_input_error

                raise ValueError(level_input_error(self.path, "the match's noise tells none (play it under noise=variable)"))
            obs = with_levels(obs, np.array([level]))
        obs = torch.as_tensor(obs, dtype=torch.float32)
        with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
            action = self.policy(TensorDict({"observation": obs}, batch_size=[1]))["action"].double().numpy()
        raw = domain.raw_action(action, view[None], self.params.ball_radius, self.constrain_aim)
        return to_env_action(raw[0])


def _score_rates(tables: np.ndarray, actions: np.ndarray, replays: int, noise: NoiseModel, rng, params, level=None) -> tuple:
    """Each (table, action) replayed ``replays`` times under ``noise``: (score rate, foul rate,
    the result of every replay), tables (N, 4, 2) and actions (N, 4)."""
    n = len(tables)
    t, a = np.repeat(tables, replays, axis=0), np.repeat(actions, replays, axis=0)
    played = noise.perturb(a, rng, params, levels=level)  # variable noise without a level: each replay draws one
    res = simulate_batch(t, played, params)
    score, foul = res.score.reshape(n, replays), res.foul.reshape(n, replays)
    return score.mean(axis=1), foul.mean(axis=1), res


class SafetyAgent:
    """The safety-aware player (see the module docstring)."""

    def __init__(self, actor, proposer, opponent_proposer, cfg: SafetyPlayer, noise: NoiseModel, params: PhysicsParams):
        self.actor, self.proposer, self.opponent = actor, proposer, opponent_proposer
        self.cfg, self.noise, self.params = cfg, noise, params
        self.rng = np.random.default_rng(0)

    def reseed(self, seed: int) -> None:
        self.actor.reseed(seed)
        self.rng = np.random.default_rng(seed + 1)

    def opponent_chance(self, leaves: np.ndarray) -> np.ndarray:
        """The opponent's best score rate from each leave (mover's frame; (L, 4, 2))."""
        if not len(leaves):
            return np.zeros(0)
        theirs = leaves[:, SWAP]
        cands = self.opponent.propose(theirs, self.cfg.opp_k, self.rng)  # (L, K, 4)
        tables = np.repeat(theirs, self.cfg.opp_k, axis=0)
        rate, _, _ = _score_rates(tables, cands.reshape(-1, 4), self.cfg.opp_replays, self.noise, self.rng, self.params)
        return rate.reshape(len(leaves), self.cfg.opp_k).max(axis=1)

    def values(self, view: np.ndarray, best: np.ndarray | None = None, level: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The candidates (C, 4) (the search's shot, or ``best``, first) and their values."""
        best = self.actor.search(view[None], None if level is None else np.array([level])).actions[0] if best is None else best
        cands = np.concatenate([best[None], self.proposer.propose(view[None], self.cfg.k, self.rng)[0]])
        c, r = len(cands), self.cfg.replays
        score, foul, res = _score_rates(np.repeat(view[None], c, axis=0), cands, r, self.noise, self.rng, self.params, level)
        missed = ~res.score
        q = np.zeros(c * r)
        q[missed] = self.opponent_chance(res.positions[missed])
        leave_cost = (q * missed).reshape(c, r).sum(axis=1) / r  # over all replays: (1 - p) x mean q of the misses
        return cands, domain.shot_reward(score, foul, self.cfg.foul_penalty) - self.cfg.leave_weight * leave_cost

    def act(self, view: np.ndarray, level: float | None = None) -> np.ndarray:
        result = self.actor.search(view[None], None if level is None else np.array([level]))
        if self.cfg.threshold is not None and result.r1[0] >= self.cfg.threshold:
            return to_env_action(result.actions[0])
        cands, value = self.values(view, result.actions[0], level)
        return to_env_action(cands[int(np.argmax(value))])


def make_agent(cfg: PlayerConfig, noise: NoiseModel, params: PhysicsParams):
    """The player ``cfg`` describes (a player schema, or its config node), for the execution
    noise and table of the match."""
    return player_config(cfg).build(noise, params)


__all__ = ["KINDS", "PLAYERS", "PlayerConfig", "PolicyAgent", "PolicyPlayer", "RandomPlayer", "SafetyPlayer", "SearchPlayer",
           "player_config", "player_keys", "RandomAgent", "SafetyAgent", "SearchAgent", "make_agent", "to_env_action"]
