"""The paper's unified evaluation protocol (:data:`billiards.protocol.Protocol.INNINGS`) for a
TorchRL policy, as one function.

Protocol: continue-on-miss innings of ``max_shots`` shots (default 10), ``n_innings`` of them
(default 100) played side by side in one batched env (B = n_innings), random starting racks
drawn from ``seed`` (or the canonical rack), deterministic policy
(``ExplorationType.DETERMINISTIC``), raw carom score (no shaping). Reported:

* points per inning: mean and std (population std, ddof = 0) over innings, and the best inning;
* foul innings %: share of innings with at least one foul;
* foul % per shot and success (score) % per shot, over all ``n_innings * max_shots`` shots;
* points to the first miss (``first_miss_points``, mean ``first_miss_mean``): the shots each
  inning scores before its first miss or foul. With a deterministic policy and exact play the
  inning is, up to that shot, the inning an end-at-first-miss protocol plays from the same
  rack, so from random racks this is the paper's "random-start eval" (Table 3's "rand. eval",
  which for i.i.d. success p per shot is about p / (1 - p)).

Execution noise (``noise=``, :mod:`billiards.physics.noise`; off by default) perturbs every
shot the policy commands; the env draws the errors from its own generator seeded with
``seed``, so the same seed replays the same noisy innings. The result records the noise.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

from billiards import compat, domain
from billiards.envs import make_env
from billiards.files import atomic_write_text
from billiards.physics.noise import get_noise
from billiards.protocol import Protocol


@dataclasses.dataclass
class EvalResult:
    """Outcome of :func:`evaluate_policy`. Percentages are in [0, 100]. ``eval.json`` holds its fields
    (:meth:`from_json` reads one of any version through :func:`billiards.compat.upgrade_eval_record`)."""

    mean: float  # points per inning
    std: float  # population std of points per inning
    best: int  # best inning (points)
    foul_innings_pct: float  # innings with >= 1 foul
    foul_per_shot_pct: float
    success_per_shot_pct: float
    n_innings: int
    shots: int  # total shots played = n_innings * max_shots
    max_shots: int
    start: str
    seed: int
    points: list[int]  # per inning
    noise: str  # the execution noise the shots were played under (NoiseModel.describe())
    first_miss_points: list[int]  # per inning, the points scored before its first miss or foul (empty: not recorded)

    @property
    def first_miss_mean(self) -> float | None:
        """Mean points before the first miss (the end-at-first-miss inning), None if not recorded."""
        return float(np.mean(self.first_miss_points)) if self.first_miss_points else None

    def to_json(self, path: str | Path) -> None:
        """Write the result as JSON, atomically (:func:`billiards.files.atomic_write_text`)."""
        atomic_write_text(path, json.dumps(dataclasses.asdict(self), indent=2) + "\n")

    @classmethod
    def from_json(cls, path: str | Path) -> EvalResult:
        """The result an ``eval.json`` records, in today's form whatever version wrote it."""
        return cls(**compat.upgrade_eval_record(json.loads(Path(path).read_text())))

    def summary(self) -> str:
        return (
            f"{self.mean:.3f} ± {self.std:.3f} points/inning (best {self.best}), "
            f"foul innings {self.foul_innings_pct:.1f}%, foul/shot {self.foul_per_shot_pct:.1f}%, "
            f"success/shot {self.success_per_shot_pct:.1f}% ({self.n_innings} innings x {self.max_shots} shots, "
            f"{self.start} start, seed {self.seed}{'' if self.noise == 'none' else ', noise ' + self.noise})"
        )


def summarize(score: np.ndarray, foul: np.ndarray, *, start: str = "random", seed: int = 0, noise: str = "none") -> EvalResult:
    """EvalResult from per-shot outcomes ``score``, ``foul`` of shape (n_innings, max_shots)."""
    score, foul = np.asarray(score, dtype=bool), np.asarray(foul, dtype=bool)
    points = score.sum(axis=1)
    streak = np.where(score.all(axis=1), score.shape[1], np.argmin(score, axis=1))  # leading scores
    return EvalResult(
        mean=float(points.mean()),
        std=float(points.std()),
        best=int(points.max()),
        foul_innings_pct=100.0 * float(foul.any(axis=1).mean()),
        foul_per_shot_pct=100.0 * float(foul.mean()),
        success_per_shot_pct=100.0 * float(score.mean()),
        n_innings=int(score.shape[0]),
        shots=int(score.size),
        max_shots=int(score.shape[1]),
        start=start,
        seed=int(seed),
        points=[int(p) for p in points],
        noise=noise,
        first_miss_points=[int(k) for k in streak],
    )


def evaluate_policy(
    policy,
    n_innings: int = 100,
    max_shots: int = 10,
    start: str = Protocol.INNINGS.spec.start,
    seed: int = 0,
    *,
    constrain_aim: bool = False,
    extra_features: bool = False,
    env_kwargs: dict | None = None,
    noise=None,
) -> EvalResult:
    """Evaluate ``policy`` with the unified protocol (see the module docstring).

    Args:
        policy: a TensorDict module (or any callable td -> td) that writes ``"action"`` in the
            parameterisation of the env built here (u for the aim when ``constrain_aim``).
        n_innings: innings, all played at once in one env with batch_size [n_innings].
        max_shots: shots per inning (continue-on-miss: every inning plays exactly this many).
        start: ``"random"`` (racks from ``seed``) or ``"canonical"``.
        seed: seed of the rack generator.
        constrain_aim, extra_features: the domain-knowledge layers the policy was trained
            with (they change its action/observation, not the task).
        env_kwargs: further :func:`billiards.envs.make_env` keyword arguments (e.g. params).
        noise: execution noise (:func:`billiards.physics.noise.get_noise`: None/"none" exact,
            "fastfiz", "fastfiz_x5", a NoiseModel or a dict of sigmas).
    """
    noise = get_noise(noise)
    env = make_env(
        n_innings,
        start=start,
        on_miss=Protocol.INNINGS.spec.on_miss,
        max_shots=max_shots,
        constrain_aim=constrain_aim,
        extra_features=extra_features,
        seed=seed,
        noise=noise,
        **(env_kwargs or {}),
    )
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        rollout = env.rollout(max_shots, policy, break_when_any_done=False)
    score = rollout["next", "score"][..., 0].numpy()
    foul = rollout["next", "foul"][..., 0].numpy()
    assert score.shape == (n_innings, max_shots), score.shape
    return summarize(score, foul, start=start, seed=seed, noise=noise.describe())


def numpy_policy(act, *, normalized: bool = True, constrain_aim: bool = False):
    """A policy for :func:`evaluate_policy` from a NumPy one, e.g. a Stable-Baselines3 model's
    ``lambda obs: model.predict(obs, deterministic=True)[0]``.

    ``act(observation)`` gets the (B, D) float32 observations of the TorchRL env (the gymnasium
    env's observations, batched) and returns (B, 4) actions: normalised x in [-1, 1]^4, the
    gymnasium env's default, mapped by :func:`billiards.domain.unnormalize_action`, or with
    ``normalized=False`` raw (theta | u, p, a, b). The shot is written as float64 so theta is
    not rounded, as the gymnasium env plays it.
    """

    def policy(td):
        obs = td.get("observation").detach().cpu().numpy()
        action = np.asarray(act(obs), dtype=np.float64).reshape(obs.shape[0], domain.ACTION_DIM)
        if normalized:
            action = domain.unnormalize_action(action, constrain_aim)
        td.set("action", torch.from_numpy(action))
        return td

    return policy
