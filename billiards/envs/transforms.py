"""TorchRL transforms for the domain knowledge of the paper, and :func:`make_env`.

The math of every transform is in :mod:`billiards.domain` and the env step code of
``_common`` (shared with the gymnasium env, which runs the same functions on a batch of one);
this module only moves tensors in and out of tensordicts and specs.

* :class:`AimConstraint` -- action[..., 0] becomes u in [-1, 1]:
  ``theta = theta_target + u * asin(min(1, 2R/d))`` (:func:`billiards.domain.constrained_theta`).
* :class:`NormalizedActions` -- the policy acts in [-1, 1]^4, mapped to the raw action by
  :func:`billiards.domain.unnormalize_action` (opt-in; the training env keeps the raw box).
* :class:`CaromFeatures` -- appends (d1, d2, sin phi, cos phi) to ``"observation"``
  (:func:`billiards.domain.carom_features`), 28 -> 32 floats.
* :class:`NoiseLevelFeature` -- under variable noise, appends the next shot's noise level
  ``"noise_level"`` to ``"observation"``, last (as the gymnasium env does).
* :class:`FoulPenalty` -- reward += ``-c * foul``.
* :class:`GentleShotBonus` -- on a score, reward += ``beta * exp(-(d - 0.2)^2 / (2 0.1^2))``,
  d the white's rest distance to the second red it hit (the paper's leave-position bonus), or
  ``beta * score * (1 - p)`` with ``kind="power"``.
* :class:`NearMissBonus` -- reward += ``beta * exp(-gap / sigma)`` for a miss that hit exactly
  one red, gap = closest approach to the other red.
* :class:`RewardModelBonus` -- reward += ``beta * V_rm(s, a)``, a learned P(score | s, a).

The reward transforms only add to ``"reward"``; the raw carom outcome stays in ``"score"``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.data import Bounded, Composite, Unbounded
from torchrl.envs import Compose, Transform, TransformedEnv

from billiards import domain
from billiards.physics import DEFAULT_PARAMS, PhysicsParams, get_params
from billiards.physics.checks import finite_number
from billiards.physics.config import warn_physics_mismatch

from ._common import (
    EnvOptions,
    Shaping,
    check_aim_offset,
    check_flag,
    resolve_paradigm,
    unnormalize_checked,
    validate_action,
)
from .torchrl_env import BilliardsEnv, exact_positions


def _np(x: torch.Tensor) -> np.ndarray:
    return x.detach().cpu().numpy()


def _bounded(spec, low: np.ndarray, high: np.ndarray) -> Bounded:
    """A Bounded spec like ``spec`` (shape, dtype, device) with the per-coordinate bounds
    (low, high) (4,) of :func:`billiards.domain.action_bounds`, broadcast over its batch."""
    as_tensor = lambda x: torch.as_tensor(x, dtype=spec.dtype, device=spec.device).expand(spec.shape).clone()
    return Bounded(as_tensor(low), as_tensor(high), shape=spec.shape, dtype=spec.dtype, device=spec.device)


class _ActionMap(Transform):
    """Maps the policy's action to the one the next layer expects, before the step:
    ``action <- _map(validated action, tensordict)``; a missing action is an error naming
    the transform (unless ``missing_tolerance``)."""

    def _map(self, action: np.ndarray, tensordict: TensorDictBase) -> np.ndarray:
        raise NotImplementedError

    def _inv_call(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get("action", None)
        if action is None:
            if self.missing_tolerance:
                return tensordict
            raise KeyError(f'{type(self).__name__} needs "action" in the input tensordict')
        x = validate_action(action, (*tensordict.batch_size, domain.ACTION_DIM))
        tensordict.set("action", torch.from_numpy(self._map(x, tensordict)))
        return tensordict


class AimConstraint(_ActionMap):
    """First-contact aim constraint (paper §4.1).

    The policy's first action coordinate is ``u in [-1, 1]`` instead of theta. Before the
    step, with the current table ``"positions"``::

        theta = theta_target + u * half_width,  half_width = asin(min(1, 2R / d))

    where theta_target points from the white's centre at the nearest red's and d is their
    centre distance (:func:`billiards.domain.aim_window`). Any u strictly inside (-1, 1)
    makes the nearest red the first ball the white touches, unless another ball blocks the
    path or the shot is too weak to reach it. The transformed action spec has
    ``low[0] = -1, high[0] = 1``; p, a and b pass through unchanged. The mapped action sent
    to the simulator is float64 so theta keeps full precision.

    A u outside [-1, 1] is refused with a ValueError naming ``"action"``
    (:func:`~billiards.envs._common.check_aim_offset`, as in the gymnasium envs).

    Args:
        R: ball radius (m), the simulator's by default.
    """

    def __init__(self, R: float = DEFAULT_PARAMS.ball_radius):
        super().__init__()
        self.R = finite_number(R, "R", 0.0, lo_open=True, what="a finite ball radius > 0 (m)")

    def _map(self, u_action, tensordict):
        return domain.aim_action(check_aim_offset(u_action), exact_positions(tensordict), self.R)

    def transform_input_spec(self, input_spec: Composite) -> Composite:
        input_spec = input_spec.clone()
        spec = input_spec["full_action_spec", "action"]
        input_spec["full_action_spec", "action"] = _bounded(spec, *domain.action_bounds(constrain_aim=True))
        return input_spec


class NormalizedActions(_ActionMap):
    """The policy acts in the normalised box [-1, 1]^4, as in the gymnasium env's default.

    Before the step the action x becomes the raw action by
    :func:`billiards.domain.unnormalize_action` (theta = pi (x0 + 1), p = (x1 + 1) / 2,
    a = x2, b = x3; with ``constrain_aim`` u = x0, and this transform must then come after
    :class:`AimConstraint` so that the u it produces goes through the constraint). The
    transformed action spec is [-1, 1]^4. Opt-in (``make_env(normalize_actions=True)``); the
    training env's default action space is the paper's raw box.
    """

    def __init__(self, constrain_aim: bool = False):
        super().__init__()
        self.constrain_aim = check_flag("constrain_aim", constrain_aim)

    def _map(self, x, tensordict):
        return unnormalize_checked(x, self.constrain_aim)

    def transform_input_spec(self, input_spec: Composite) -> Composite:
        input_spec = input_spec.clone()
        spec = input_spec["full_action_spec", "action"]
        low, high = domain.action_bounds(self.constrain_aim)
        below = (_np(spec.space.low).reshape(-1, domain.ACTION_DIM), _np(spec.space.high).reshape(-1, domain.ACTION_DIM))
        if not (np.allclose(below[0], low, atol=1e-6) and np.allclose(below[1], high, atol=1e-6)):
            raise ValueError(
                f"NormalizedActions(constrain_aim={self.constrain_aim}) maps onto the action bounds {low.tolist()} .. "
                f"{high.tolist()}, but the env below it has {below[0][0].tolist()} .. {below[1][0].tolist()}: "
                "with AimConstraint, pass constrain_aim=True and put NormalizedActions after it"
            )
        input_spec["full_action_spec", "action"] = _bounded(spec, *domain.action_bounds(self.constrain_aim, normalized=True))
        return input_spec


class CaromFeatures(Transform):
    """Appends the four carom features of paper §4.2 to ``"observation"``.

    From the exact ``"positions"`` (:func:`billiards.domain.carom_features`), float32::

        d1 = |n - w|, d2 = |o - w|, sin phi, cos phi,   phi = angle(n - w -> o - n)

    with w the white, n the red nearest the white, o the other red; phi is signed,
    counter-clockwise positive. The observation grows from 28 to 32 floats
    (``obs[..., 28:32] = (d1, d2, sin phi, cos phi)``), on reset and on every step.
    """

    def __init__(self):
        super().__init__()

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        obs = next_tensordict.get("observation")
        feats = domain.feature_observation(exact_positions(next_tensordict))
        next_tensordict.set("observation", torch.cat([obs, torch.from_numpy(feats)], dim=-1))
        return next_tensordict

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        return self._call(tensordict_reset)

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        spec = observation_spec["observation"]
        shape = (*spec.shape[:-1], spec.shape[-1] + domain.N_CAROM_FEATURES)
        observation_spec["observation"] = Unbounded(shape=shape, dtype=spec.dtype, device=spec.device)
        return observation_spec


class NoiseLevelFeature(Transform):
    """Appends the next shot's noise level (``"noise_level"``, which :class:`BilliardsEnv` carries
    under variable noise) to ``"observation"``, last: 28 -> 29 floats (32 -> 33 after
    :class:`CaromFeatures`), the layout of the gymnasium env's observation, on reset and on
    every step. :func:`make_env` adds it whenever the noise is variable."""

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        obs = next_tensordict.get("observation")
        level = next_tensordict.get("noise_level").to(obs.dtype)
        next_tensordict.set("observation", torch.cat([obs, level], dim=-1))
        return next_tensordict

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        return self._call(tensordict_reset)

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        spec = observation_spec["observation"]
        shape = (*spec.shape[:-1], spec.shape[-1] + 1)
        observation_spec["observation"] = Unbounded(shape=shape, dtype=spec.dtype, device=spec.device)
        return observation_spec


class _RewardTerm(Transform):
    """Adds ``term(tensordict_t, tensordict_t+1)`` to ``"reward"`` after each step."""

    def _term(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> np.ndarray:
        raise NotImplementedError

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        reward = next_tensordict.get("reward")
        term = torch.from_numpy(np.asarray(self._term(tensordict, next_tensordict), dtype=np.float32))
        next_tensordict.set("reward", reward + term.reshape(reward.shape))
        return next_tensordict


class FoulPenalty(_RewardTerm):
    """Reward shaping: ``reward += -c * foul`` (:func:`billiards.domain.foul_penalty`)."""

    def __init__(self, c: float = 1.0):
        super().__init__()
        self.c = domain.check_coefficient("foul penalty c", c)

    def _term(self, tensordict, next_tensordict):
        return domain.foul_penalty(_np(next_tensordict.get("foul")), self.c)


class GentleShotBonus(_RewardTerm):
    """Reward shaping on a scoring shot. ``kind="leave"`` (the paper's): ``reward += beta *
    exp(-(d - 0.2)^2 / (2 * 0.1^2))``, d the distance from the white at rest to the second red
    it contacted (:func:`billiards.domain.gentle_bonus`); ``kind="power"``: ``reward += beta *
    (1 - p)``, p = action[..., 1] the shot's power (:func:`billiards.domain.gentle_power_bonus`)."""

    def __init__(self, beta: float, kind: str = "leave"):
        super().__init__()
        if kind not in domain.GENTLE_KINDS:
            raise ValueError(f"GentleShotBonus kind must be one of {domain.GENTLE_KINDS}, got {kind!r}")
        self.beta, self.kind = domain.check_coefficient("gentle beta", beta), kind

    def _term(self, tensordict, next_tensordict):
        score = _np(next_tensordict.get("score"))
        if self.kind == "power":
            return domain.gentle_power_bonus(score, _np(tensordict.get("action"))[..., 1:2], self.beta)
        bonus = domain.gentle_bonus(score[..., 0], exact_positions(next_tensordict),
                                    _np(next_tensordict.get("second_red"))[..., 0], self.beta)
        return bonus[..., None]


class NearMissBonus(_RewardTerm):
    """Reward shaping: ``reward += beta * exp(-gap / sigma)`` when the white hit exactly one
    red and the shot was neither a score nor a foul; gap = the white's closest surface gap (m)
    to the red it missed (:func:`billiards.domain.near_miss_bonus`)."""

    def __init__(self, beta: float, sigma: float = domain.NEAR_MISS_SIGMA):
        super().__init__()
        self.beta = domain.check_coefficient("near-miss beta", beta)
        self.sigma = domain.check_coefficient("near-miss sigma", sigma, strict=True)

    def _term(self, tensordict, next_tensordict):
        get = lambda key: _np(next_tensordict.get(key))
        bonus = domain.near_miss_bonus(get("score")[..., 0], get("foul")[..., 0], get("hits"), get("closest"), self.beta, self.sigma)
        return bonus[..., None]


class RewardModelBonus(_RewardTerm):
    """Reward shaping with a learned reward model (paper 3.2): ``reward += beta * V_rm(s, a)``,
    ``V_rm(s, a) ~ P(score = 1 | s, a)`` (:class:`billiards.rm.RewardModel`, fitted on random
    offline shots; inputs :func:`billiards.rm.rm_inputs` of the table before the shot and the
    raw action). A transform's step sees the input after every inverse transform, i.e. the
    action the simulator played: under the aim constraint that is theta, not the offset u, so
    the model always scores the shot actually played.

    Args:
        model: a :class:`billiards.rm.RewardModel` (anything with ``prob(positions, actions)``)
            or a path to one (:func:`billiards.rm.load_model`).
        beta: bonus strength.
    """

    def __init__(self, model, beta: float, params: PhysicsParams | None = None):
        super().__init__()
        from billiards.rm import load_model

        self.beta = domain.check_coefficient("reward-model beta", beta)  # before loading anything
        self.model = model if hasattr(model, "prob") else load_model(model)
        if params is not None and hasattr(self.model, "params"):
            warn_physics_mismatch("the reward model", self.model.params, params)

    def _term(self, tensordict, next_tensordict):
        positions = exact_positions(tensordict)
        action = _np(tensordict.get("action")).astype(np.float64)
        return self.beta * self.model.prob(positions, action)


def make_env(batch_size: int = 1, options: EnvOptions | None = None, *, seed: int | None = None, **kwargs) -> TransformedEnv:
    """The environment of every experiment: a :class:`BilliardsEnv` with the chosen layers.

    ``options`` (an :class:`EnvOptions`) holds every choice below but the batch size and seed,
    as one object; keyword arguments given beside it replace its fields
    (``make_env(4, options, seed=0, max_shots=5)``), or stand alone.

    Args:
        batch_size: B innings stepped together by one ``simulate_batch`` call per step.
        start: ``"random"`` (default) or ``"canonical"`` starting rack.
        on_miss: ``"continue"`` (default; innings always last ``max_shots``) or ``"reset"``
            (a miss or a foul terminates the inning).
        paradigm: shorthand for (start, on_miss): ``"random_continue"``, ``"random_reset"``,
            ``"canonical_continue"`` or ``"canonical_reset"``; explicit start/on_miss must agree.
        max_shots: shots per inning before truncation (default 10).
        constrain_aim: add :class:`AimConstraint` (action[0] is u in [-1, 1]).
        normalize_actions: add :class:`NormalizedActions` (the policy acts in [-1, 1]^4, as in
            the gymnasium env); off by default, the training env acts in the raw box.
        extra_features: add :class:`CaromFeatures` (observation 28 -> 32).
        foul_penalty: c of :class:`FoulPenalty` (reward -= c * foul); 0 disables it.
        gentle: beta of :class:`GentleShotBonus` (the paper: 0.2); 0 disables it.
        gentle_kind: ``"leave"`` (the paper's leave-position bonus) or ``"power"`` (beta * (1 - p)).
        near_miss: beta of :class:`NearMissBonus` (the paper: 0.05); 0 disables it.
        near_miss_sigma: its length scale sigma in metres (the paper: 0.03).
        rm: beta of :class:`RewardModelBonus` (reward += beta * V_rm(s, a)); 0 disables it.
        rm_model: the reward model (a :class:`billiards.rm.RewardModel` or a path), needed if rm.
        seed: seed of the rack generator (``env.set_seed`` re-seeds it).
        noise: execution noise of the played shots (:class:`BilliardsEnv`; default none);
            under variable noise (``"variable"``) the next shot's level is the observation's
            last entry (:class:`NoiseLevelFeature`).
        params: the physics: a preset name (``"korean_medium"``, the default, or
            ``"international"``), a :class:`~billiards.physics.PhysicsParams`, or a dict of fields
            (:func:`billiards.physics.get_params`).

    Returns:
        ``TransformedEnv(BilliardsEnv(...), Compose(...))`` with batch_size [B], always a
        TransformedEnv (possibly with no transforms). Policies and losses should use
        ``env.action_spec_unbatched`` / ``env.observation_spec_unbatched``.

    Raises:
        ValueError: a shaping coefficient (foul_penalty, gentle, near_miss, rm) that is NaN,
            inf or negative, near_miss_sigma <= 0 (named as passed), or an unknown gentle_kind.
        TypeError: a keyword that is not a field of :class:`EnvOptions`.
    """
    try:
        o = dataclasses.replace(options if options is not None else EnvOptions(), **kwargs)
    except TypeError:
        unknown = sorted(set(kwargs) - {f.name for f in dataclasses.fields(EnvOptions)})
        raise TypeError(f"make_env got unknown options {unknown}") from None
    return _build(batch_size, o, seed)


def _build(batch_size: int, o: EnvOptions, seed: int | None) -> TransformedEnv:
    start, on_miss = resolve_paradigm(o.paradigm, o.start, o.on_miss)
    shaping = Shaping.of(o)  # checked before anything is built
    constrain_aim, normalize_actions = check_flag("constrain_aim", o.constrain_aim), check_flag("normalize_actions", o.normalize_actions)
    extra_features = check_flag("extra_features", o.extra_features)
    params = get_params(o.params)
    base = BilliardsEnv(batch_size, start=start, on_miss=on_miss, max_shots=o.max_shots, params=params, seed=seed, noise=o.noise)
    transforms: list[Transform] = []
    if constrain_aim:
        transforms.append(AimConstraint(params.ball_radius))
    if normalize_actions:
        transforms.append(NormalizedActions(constrain_aim))
    if extra_features:
        transforms.append(CaromFeatures())
    if base.noise.is_variable:
        transforms.append(NoiseLevelFeature())
    if shaping.foul_penalty:
        transforms.append(FoulPenalty(shaping.foul_penalty))
    if shaping.gentle:
        transforms.append(GentleShotBonus(shaping.gentle, shaping.gentle_kind))
    if shaping.near_miss:
        transforms.append(NearMissBonus(shaping.near_miss, shaping.near_miss_sigma))
    if shaping.rm:
        if shaping.rm_model is None:
            raise ValueError("rm > 0 needs rm_model (a billiards.rm.RewardModel or a path to one)")
        transforms.append(RewardModelBonus(shaping.rm_model, shaping.rm, params))
    return TransformedEnv(base, Compose(*transforms))


__all__ = ["AimConstraint", "CaromFeatures", "NoiseLevelFeature", "NormalizedActions",
           "FoulPenalty", "GentleShotBonus", "NearMissBonus", "RewardModelBonus", "make_env"]
