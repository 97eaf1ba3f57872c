"""The API's request bodies (pydantic): shapes, types and ranges checked before anything runs;
the simulator's own checks (balls on the table and apart, the action's box) follow in the
handlers with its messages."""

from __future__ import annotations

from typing import Annotated, Literal, Optional

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from billiards.physics import DEFAULT_PRESET, PRESETS
from billiards.physics.noise import NOISE_PRESETS

Number = Annotated[float, Field(strict=True, allow_inf_nan=False)]
Ball = Annotated[list[Number], Field(min_length=2, max_length=2, description="x, y (m)")]
Positions = Annotated[list[Ball], Field(min_length=4, max_length=4, description="white, yellow, red1, red2: (4, 2) metres")]
Action = Annotated[list[Number], Field(min_length=4, max_length=4, description="theta (rad), p in [0, 1], a, b in [-1, 1]")]
Seed = Annotated[int, Field(strict=True, ge=0, le=2**32 - 1)]


def _preset(value: str, presets: dict, what: str) -> str:
    if value not in presets:
        raise ValueError(f"unknown {what} preset {value!r}; presets: {', '.join(presets)}")
    return value


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid")


class _Table(_Body):
    physics: str = DEFAULT_PRESET
    noise: str = "none"

    @field_validator("physics")
    @classmethod
    def _physics(cls, v: str) -> str:
        return _preset(v, PRESETS, "physics")

    @field_validator("noise")
    @classmethod
    def _noise(cls, v: str) -> str:
        return _preset(v, NOISE_PRESETS, "noise")


class ShotRequest(_Table):
    positions: Positions
    action: Action
    seed: Seed = 0
    level: Optional[Annotated[float, Field(strict=True, ge=0.0, le=100.0, allow_inf_nan=False)]] = None
    shooter: Literal[0, 1] = 0
    dt: Annotated[float, Field(strict=True, ge=1 / 480, le=0.1)] = 1.0 / 60.0
    paths: bool = True


class _AgentOnTable(_Table):
    """What every question to an agent holds: the table, the seed the agent is reseeded with, the
    shot's noise level (variable noise) and the noisy replays a candidate is scored over."""

    positions: Positions
    seed: Seed = 0
    level: Optional[Annotated[float, Field(strict=True, ge=0.0, le=100.0, allow_inf_nan=False)]] = None
    replays: Annotated[int, Field(strict=True, ge=0, le=500)] = 50


class AgentRequest(_AgentOnTable):
    agent: Annotated[str, Field(min_length=1, max_length=200)]


class ConsideredRequest(_AgentOnTable):
    """What an agent considers for a recorded shot: the run it played in (``run``: a search run's
    P3 or P1, or a benchmark scorecard's run; its own agent, table and noise) or an agent of the
    list (``agent`` with ``physics`` and ``noise``), the table before the shot, the shot it
    commanded (replayed under the noise), the shooter, the shot's noise level and the seed the
    agent is reseeded with."""

    run: Optional[Annotated[str, Field(min_length=1, max_length=1000)]] = None
    agent: Optional[Annotated[str, Field(min_length=1, max_length=200)]] = None
    commanded: Optional[Action] = None
    shooter: Literal[0, 1] = 0

    @model_validator(mode="after")
    def _one_agent(self):
        if (self.run is None) == (self.agent is None):
            raise ValueError("give either run (a recorded run's path: its own agent) or agent (one of /api/config's agents)")
        return self


class MatchRequest(_Table):
    noise: str = "fastfiz_x5"
    opponent: Annotated[str, Field(min_length=1, max_length=100)] = "random"
    target: Annotated[int, Field(strict=True, ge=1, le=50)] = 5
    seed: Seed = 0
    first: Literal["human", "agent"] = "human"
    max_innings: Annotated[int, Field(strict=True, ge=1, le=1000)] = 200
    key: Optional[Annotated[str, Field(pattern=r"^[A-Za-z0-9_-]{8,64}$")]] = Field(
        None, description="the page's key for this start: the same key again answers the match it started (a repeated click)")


class MatchShotRequest(_Body):
    """The person's shot and the turn it answers (the state's ``turn``: the shots played so far)."""

    action: Action
    turn: Annotated[int, Field(strict=True, ge=0, le=10**6)]


__all__ = ["AgentRequest", "ConsideredRequest", "MatchRequest", "MatchShotRequest", "ShotRequest"]
