"""The match app's schema (``python match.py``, ``conf/match.yaml``): the players, the league
and the game, typed and closed; :func:`validate` checks what types cannot say, before Hydra
writes anything (:class:`ValidateMatchConfig`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Dict, List

from omegaconf import MISSING, DictConfig

from billiards.app_config import AppConfig, ValidatingCallback, numeric_bound_errors, register_app, resolved_config, upper_bound_errors
from billiards.device import threads_error
from billiards.physics.config import physics_errors
from billiards.physics.noise import noise_errors

from .players import player_config


@dataclass
class MatchAppConfig(AppConfig):
    """match.py's root schema: the shared keys (:class:`~billiards.app_config.AppConfig`; a
    resumed league plays only its missing matches, with its own settings) and the league's own."""

    # every player the app knows, by name: each a player schema by its kind (agents.PLAYERS),
    # checked by errors() (the map is untyped so that a player can be added on the command line:
    # +agents.mine={kind: search, ...}; OmegaConf cannot merge a dict into a map of structured values)
    agents: Dict[str, Any] = field(default_factory=dict)
    players: List[str] = MISSING  # who plays the league (names of agents)
    target: int = 10  # points to win a match
    max_innings: int = 200  # then the match is truncated (a draw unless the scores differ)
    foul_penalty: float = 1.0  # points a foul costs
    start: str = "canonical"  # canonical (the opening rack) | random
    matches: int = 20  # per ordered pair of players (the break alternating)
    threads: int = 1
    picture: bool = True  # match.gif: the league's first match replayed shot by shot

    # the upper bounds of the league's numbers (docs/reliability.md; the players': their schemas' UPPER)
    UPPER: ClassVar[dict] = {"target": (10_000, "points"), "max_innings": (10**5, "innings of a match"),
                             "matches": (10**5, "matches per ordered pair"),
                             "foul_penalty": (100.0, "points; a score is worth 1")}
    RUNTIME = (*AppConfig.RUNTIME, "picture", "resume")  # a resumed league plays on with its own settings


register_app("match_schema", MatchAppConfig, {})


class MatchConfigError(ValueError):
    """An invalid match config; the message names the key."""


def errors(cfg: DictConfig) -> list[str]:
    """Every problem of a match config, each naming its key; checked on its resolved values
    (:func:`resolved_config`), the players' files (policies, rankers, table values) loaded and
    checked now, before anything is written."""
    cfg, errs = resolved_config(cfg)
    if errs:
        return errs
    errs = numeric_bound_errors(cfg) + physics_errors(cfg.physics) + noise_errors(cfg.noise)
    errs += upper_bound_errors(cfg, "", MatchAppConfig.UPPER)
    noise = None
    if not errs:
        from billiards.envs.sagu import noise_cap_error
        from billiards.physics.noise import noise_from_config

        noise = noise_from_config(cfg.noise)
        if err := noise_cap_error(noise):
            errs.append(err)
    for name, agent in cfg.agents.items():
        try:
            agent = player_config(agent, name)
            own = agent.errors(name)
        except ValueError as err:
            errs.append(str(err))
            continue
        errs += own
        if name in cfg.players and not own:  # a player's files, once its knobs are right
            errs += agent.file_errors(name, noise)
    unknown = [p for p in cfg.players if p not in cfg.agents]
    if unknown or len(set(cfg.players)) != len(cfg.players) or len(cfg.players) < 2:
        errs.append(f"players must name at least two different agents of {sorted(cfg.agents)}; got {list(cfg.players)}")
    for key in ("target", "max_innings", "matches"):
        if cfg[key] < 1:
            errs.append(f"{key} must be >= 1, got {cfg[key]}")
    if not cfg.foul_penalty >= 0:
        errs.append(f"foul_penalty must be >= 0, got {cfg.foul_penalty}")
    if cfg.start not in ("canonical", "random"):
        errs.append(f"start must be canonical or random, got {cfg.start!r}")
    if cfg.seed < 0:
        errs.append(f"seed must be >= 0, got {cfg.seed}")
    if err := threads_error(cfg.threads):
        errs.append(err)
    return errs


def validate(cfg: DictConfig) -> None:
    if errs := errors(cfg):
        raise MatchConfigError("invalid match config:\n  - " + "\n  - ".join(errs))


class ValidateMatchConfig(ValidatingCallback):
    """Hydra callback (``hydra.callbacks`` in conf/match.yaml): :func:`validate` before Hydra
    creates the run directory."""

    validate = staticmethod(validate)


__all__ = ["MatchAppConfig", "MatchConfigError", "ValidateMatchConfig", "errors", "validate"]
