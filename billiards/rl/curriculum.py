"""The staged action curriculum of paper §3.1 (Table 3): release the 4-D action in stages.

With ``curriculum=staged`` the default stages are

1. aim only        -- the policy chooses theta (or the aim offset u under the aim constraint);
2. aim + power     -- theta and p;
3. full action     -- (theta, p, a, b);

switching at fixed fractions of ``budget.total_steps`` (``curriculum.switch_at``). One SAC
(or TD3) agent is trained throughout: its networks, optimizer state and replay buffer carry
over from stage to stage (the warm start), only the set of free action dimensions changes.

A held dimension takes a documented fixed value in every action the agent plays, collects
and stores: power ``p = curriculum.hold_power`` (default 0.5, i.e. half the maximum cue
speed) and the tip offsets ``a = b = curriculum.hold_english`` (default 0: a centre-ball hit).
:class:`HoldActions` overwrites those coordinates of ``"action_norm"`` before the policy's
affine map onto the env's bounds, so the replay buffer, the critics and the evaluations all
see the action that was actually played. The actor's own output for a held dimension is
ignored until that dimension is released.
"""

from __future__ import annotations

import bisect
import logging

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

ACTION_NAMES = ("aim", "power", "english_a", "english_b")

log = logging.getLogger(__name__)


class HoldActions(TensorDictModuleBase):
    """Overwrites the held coordinates of ``"action_norm"`` with fixed values.

    ``set_free(dims)`` chooses the free dimensions; with all four free it is the identity.
    It holds no parameters or buffers, so checkpoints of agents with and without a
    curriculum have the same keys (the stage is recomputed from the frame count on resume).
    """

    def __init__(self, held_norm: torch.Tensor, key: str = "action_norm"):
        super().__init__()
        self.in_keys, self.out_keys = [key], [key]
        self.key = key
        self.held_norm = torch.as_tensor(held_norm, dtype=torch.float32).clone()
        self.mask: torch.Tensor | None = None  # True where the action is held; None = nothing held

    def set_free(self, dims) -> None:
        free = torch.zeros(self.held_norm.shape[-1], dtype=torch.bool)
        free[list(dims)] = True
        self.mask = None if bool(free.all()) else ~free

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        if self.mask is not None:
            action = tensordict.get(self.key)
            held = self.held_norm.to(action.device, action.dtype)
            tensordict.set(self.key, torch.where(self.mask.to(action.device), held, action))
        return tensordict


class Curriculum:
    """Which action dimensions are free at a given frame count.

    Args:
        stages: free dimensions of each stage, e.g. ``[[0], [0, 1], [0, 1, 2, 3]]``.
        switch_at: stage boundaries as fractions of ``total_steps`` (one fewer than stages).
        total_steps: the run's budget in frames.
    """

    def __init__(self, stages, switch_at, total_steps: int):
        self.stages = [tuple(int(d) for d in s) for s in stages]
        self.boundaries = [int(round(f * total_steps)) for f in switch_at]

    def stage_at(self, frames: int) -> int:
        """Index of the stage in force once ``frames`` frames have been collected."""
        return bisect.bisect_right(self.boundaries, frames)

    def free_dims(self, stage: int) -> tuple[int, ...]:
        return self.stages[stage]

    def describe(self) -> list[dict]:
        starts = [0] + self.boundaries
        return [{"stage": i, "from_step": s, "free": [ACTION_NAMES[d] for d in dims]}
                for i, (s, dims) in enumerate(zip(starts, self.stages))]


def held_norm_values(scale, hold_power: float, hold_english: float) -> torch.Tensor:
    """The held values (p, a, b in env units; theta is never held) in ``"action_norm"`` units
    of the agent's :class:`~billiards.rl.learners.ScaleAction` (``norm = (v - mid) / half``)."""
    env_values = torch.tensor([0.0, hold_power, hold_english, hold_english], device=scale.mid.device)
    norm = (env_values - scale.mid) / scale.half_range
    norm[0] = 0.0
    return norm


class Stages:
    """A run's curriculum as it goes: :meth:`update` frees the action dimensions of the stage
    in force at a frame count and records each stage entered in ``stage_log`` (the run
    state's, so a resume goes on with the same log). The agent -- networks, optimizer, replay
    buffer -- carries over unchanged: the warm start."""

    def __init__(self, curriculum: Curriculum, hold: HoldActions):
        self.curriculum, self.hold = curriculum, hold
        self.stage: int | None = None

    def update(self, frames: int, stage_log: list[dict]) -> None:
        stage = self.curriculum.stage_at(frames)
        if stage == self.stage:
            return
        self.stage = stage
        self.hold.set_free(self.curriculum.free_dims(stage))
        entry = self.curriculum.describe()[stage] | {"step": frames}
        if not stage_log or stage_log[-1]["stage"] != stage:
            stage_log.append(entry)
        log.info("curriculum: stage %d from step %d, free action dims %s", stage, frames, entry["free"])


def make_curriculum(cfg, agent) -> Stages | None:
    """The run's curriculum, holding the agent's actions (its :class:`HoldActions`), or None
    without one."""
    c = cfg.curriculum
    if c.name == "none":
        return None
    curriculum = Curriculum(c.stages, c.switch_at, cfg.budget.total_steps)
    hold = agent.scale.hold
    hold.held_norm = held_norm_values(agent.scale, c.hold_power, c.hold_english)
    return Stages(curriculum, hold)


__all__ = ["Curriculum", "HoldActions", "Stages", "held_norm_values", "make_curriculum", "ACTION_NAMES"]
