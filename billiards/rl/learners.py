"""Actors, critics, TorchRL losses and optimizers for SAC, TD3 and PPO.

Action convention. Every policy here first produces ``"action_norm"`` in [-1, 1]^4 and a
fixed affine layer (:class:`ScaleAction`) maps it onto the env's bounds as ``"action"``
(``[0, 2pi] x [0, 1] x [-1, 1]^2``, or ``[-1, 1]`` for the aim offset under the aim
constraint). Losses, critics and the replay buffer work on ``"action_norm"``: the critics see
well-scaled inputs, and TD3's exploration and target-smoothing noise (absolute numbers in
TorchRL) mean a fraction of each coordinate's half-range, as in stable-baselines3. The full
policy (``agent.policy``) writes ``"action"``, so it plugs straight into the env, the
collector and :func:`billiards.evaluation.evaluate_policy`.

Specs. Built from ``env.action_spec_unbatched`` (shape (4,)), never the batched spec: a
batched (B, 4) spec silently gives SAC a target entropy of -4B instead of -4.

Interface. The training loops (:mod:`billiards.rl.train`), evaluations and checkpoints use an
agent only through :class:`Agent` and its two kinds, :class:`OffPolicy` (SAC, TD3: a replay
buffer and a warm-up of random actions) and :class:`OnPolicy` (PPO: advantages of a rollout).

Device. :func:`make_agent` builds an agent on ``device``: networks, losses, optimizers, the
action bounds its distributions and noise modules keep as plain tensors, and its warm-up
sampler all live there; the env (the simulator) stays on the CPU and the collector moves each
step's TensorDict across once.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol, runtime_checkable

import torch
from tensordict import TensorDictBase
from tensordict.nn import (
    NormalParamExtractor,
    TensorDictModule,
    TensorDictModuleBase,
    TensorDictSequential,
)
from torch import nn
from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn
from torchrl.data import Bounded
from torchrl.modules import (
    MLP,
    AdditiveGaussianModule,
    ProbabilisticActor,
    RandomPolicy,
    TanhModule,
    TanhNormal,
    ValueOperator,
)
from torchrl.objectives import (
    ClipPPOLoss,
    SACLoss,
    SoftUpdate,
    TD3Loss,
    ValueEstimators,
)

from .config import ALGO_SCHEMAS, OFF_POLICY, ExItConfig, PPOConfig, SACConfig, TD3Config  # noqa: F401  (OFF_POLICY re-exported)
from .curriculum import HoldActions

ACTION_NORM = "action_norm"


@runtime_checkable
class Agent(Protocol):
    """What training, evaluation and checkpoints use of an agent (SAC, TD3, PPO).

    ``policy`` plays the live actor and ``eval_policy`` what evaluations measure (the averaged
    actor ``eval_actor`` when ``algo.actor_ema > 0``, else the live one); both read
    ``"observation"`` and write ``"action"``, deterministic under
    ``ExplorationType.DETERMINISTIC``. ``explore`` is the collection policy. ``update`` makes
    one gradient step and returns its loss outputs (``metric_names`` among them).
    ``state_dict`` holds the networks (modules), ``state_dict_extra`` the optimizers and
    the update counter (plain types and tensors) -- the checkpoint's ``agent`` and ``agent_extra``.
    ``actor_kind`` names the actor's form: ``"tanh_gaussian"`` (:func:`gaussian_actor`: SAC,
    PPO, expert iteration; one such actor's weights fit another's) or ``"deterministic"`` (TD3).
    """

    metric_names: tuple[str, ...]
    actor_kind: str
    n_updates: int
    policy: TensorDictModuleBase
    eval_policy: TensorDictModuleBase
    eval_actor: nn.Module
    explore: TensorDictModuleBase
    scale: ScaleAction

    def update(self, batch: TensorDictBase) -> Mapping[str, torch.Tensor]: ...

    def state_dict(self) -> dict[str, Any]: ...

    def load_state_dict(self, state_dict: Mapping[str, Any]) -> Any: ...

    def state_dict_extra(self) -> dict[str, Any]: ...

    def load_state_dict_extra(self, state: dict[str, Any]) -> None: ...

    def compile(self) -> None: ...


@runtime_checkable
class OffPolicy(Agent, Protocol):
    """SAC, TD3: ``replay_keys`` are what the replay buffer stores of a frame; while
    ``set_warmup(True)``, ``explore`` plays uniformly random actions."""

    replay_keys: tuple

    def set_warmup(self, warm: bool) -> None: ...


@runtime_checkable
class OnPolicy(Agent, Protocol):
    """PPO: ``advantage`` adds GAE advantages and value targets to a rollout."""

    def advantage(self, data: TensorDictBase) -> TensorDictBase: ...


class ScaleAction(TensorDictModuleBase):
    """``action = mid + half * action_norm`` (float32), mapping [-1, 1] onto the env's bounds.

    First, ``self.hold`` (:class:`~billiards.rl.curriculum.HoldActions`, the identity unless a
    staged curriculum holds some dimensions) fixes the held coordinates of ``"action_norm"``,
    so the stored and the played action agree. It has no parameters or buffers: checkpoint
    keys are the same with and without a curriculum.
    """

    def __init__(self, low: torch.Tensor, high: torch.Tensor):
        super().__init__()
        self.in_keys, self.out_keys = [ACTION_NORM], [ACTION_NORM, "action"]
        self.register_buffer("mid", ((high + low) / 2).float())
        self.register_buffer("half_range", ((high - low) / 2).float())
        self.hold = HoldActions(torch.zeros(low.shape[-1]), key=ACTION_NORM)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        tensordict = self.hold(tensordict)
        tensordict.set("action", self.mid + self.half_range * tensordict.get(ACTION_NORM))
        return tensordict


class WarmUp(TensorDictModuleBase):
    """Plays ``random`` (a :class:`~torchrl.modules.RandomPolicy` writing ``"action_norm"``)
    while ``self.warm`` is True, then ``main`` (same output keys). ``random`` is no submodule,
    so the state dict is that of ``main``."""

    def __init__(self, random: RandomPolicy, main: nn.Module, warm: bool):
        super().__init__()
        self.random, self.main, self.warm = random, main, warm
        self.in_keys, self.out_keys = list(main.in_keys), list(main.out_keys)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        return (self.random if self.warm else self.main)(tensordict)


def warm_up_policy(norm_spec: Bounded, num_envs: int) -> RandomPolicy:
    """Uniform actions on [-1, 1]^4 for a batch of ``num_envs`` innings (torch's RNG on the
    spec's device; the same draws as ``torch.rand((num_envs, 4)) * 2 - 1``)."""
    return RandomPolicy(norm_spec.expand(num_envs, *norm_spec.shape), action_key=ACTION_NORM)


def normalized_spec(action_spec, device: torch.device | str = "cpu") -> Bounded:
    """[-1, 1] box of the unbatched action spec's shape on ``device``; rejects batched specs."""
    if action_spec.shape != torch.Size([4]):
        raise ValueError(f"expected the unbatched (4,) action spec (env.action_spec_unbatched), got shape {tuple(action_spec.shape)}")
    ones = torch.ones(action_spec.shape, device=device)
    return Bounded(-ones, ones, shape=action_spec.shape, dtype=torch.float32, device=device)


def mlp(in_features: int, out_features: int, hidden: list[int]) -> MLP:
    return MLP(in_features=in_features, out_features=out_features, num_cells=list(hidden), activation_class=nn.ReLU)


def gaussian_actor(obs_dim: int, norm_spec: Bounded, hidden: list[int], return_log_prob: bool) -> ProbabilisticActor:
    """Tanh-squashed Gaussian policy on [-1, 1]^4 writing ``"action_norm"``."""
    act_dim = norm_spec.shape[-1]
    net = nn.Sequential(mlp(obs_dim, 2 * act_dim, hidden), NormalParamExtractor(scale_mapping="biased_softplus_1.0", scale_lb=1e-4))
    return ProbabilisticActor(
        TensorDictModule(net, in_keys=["observation"], out_keys=["loc", "scale"]),
        in_keys=["loc", "scale"],
        out_keys=[ACTION_NORM],
        spec=norm_spec,
        distribution_class=TanhNormal,
        distribution_kwargs={"low": norm_spec.space.low, "high": norm_spec.space.high},
        return_log_prob=return_log_prob,
    )


def q_critic(obs_dim: int, act_dim: int, hidden: list[int]) -> ValueOperator:
    return ValueOperator(mlp(obs_dim + act_dim, 1, hidden), in_keys=["observation", ACTION_NORM], out_keys=["state_action_value"])


def _params(module_params) -> list[torch.Tensor]:
    return list(module_params.flatten_keys().values())


def _float32(x: float) -> float:
    """``x`` rounded to float32, as torch rounds a scalar weight for float32 tensors."""
    return torch.tensor(x, dtype=torch.float32).item()


class _OffPolicyBase(nn.Module):
    """Common part of SAC and TD3: a loss module (actor, critics, targets), a soft target
    update, the warm-up switch of ``explore`` and the optional averaged actor.

    With ``algo.actor_ema > 0`` the agent also keeps ``actor_avg``, an exponential moving
    average of the actor's parameters (``avg += actor_ema * (live - avg)`` after every actor
    update: every gradient step for SAC, every ``policy_delay``-th for TD3), kept by
    :class:`torch.optim.swa_utils.AveragedModel` with ``get_ema_multi_avg_fn``, and
    ``eval_policy`` plays it; without, ``eval_policy`` is ``policy``. ``actor_avg`` is the
    AveragedModel's module, registered under that name, so checkpoints carry it with the same
    keys as before the library took over (its ``n_averaged`` counter only tells a first copy
    from an average: it is set at construction and needs no saving)."""

    metric_names: tuple[str, ...] = ()
    replay_keys = ("observation", ACTION_NORM, ("next", "observation"), ("next", "reward"), ("next", "done"), ("next", "terminated"))

    def _init_policies(self, exploring: nn.Module, rate: float, norm: Bounded, num_envs: int) -> None:
        """``policy``, ``explore`` (random while warming up, then ``exploring``) and the
        averaged actor. Call after ``self.actor`` and ``self.scale`` exist, before the loss
        module is built."""
        self.policy = TensorDictSequential(self.actor, self.scale)
        self.explore = TensorDictSequential(WarmUp(warm_up_policy(norm, num_envs), exploring, warm=True), self.scale)
        self.ema_rate = float(rate)
        if self.ema_rate > 0:
            # decay = 1 - rate is applied as the lerp weight 1 - decay; taking rate at float32
            # first makes that weight exactly the float32 rate the tensors are moved by.
            averager = AveragedModel(self.actor, multi_avg_fn=get_ema_multi_avg_fn(1.0 - _float32(self.ema_rate)))
            averager.requires_grad_(False).update_parameters(self.actor)  # n_averaged 0 -> 1: a copy of the actor
            object.__setattr__(self, "averager", averager)  # not a submodule: its module is actor_avg
            self.actor_avg = averager.module
            self.eval_policy = TensorDictSequential(self.actor_avg, self.scale)
        else:
            self.averager = self.actor_avg = None
            self.eval_policy = self.policy

    @property
    def eval_actor(self) -> nn.Module:
        """The actor ``eval_policy`` plays (a property: registering it twice would add keys)."""
        return self.actor if self.actor_avg is None else self.actor_avg

    def _average_actor(self) -> None:
        if self.averager is not None:
            self.averager.update_parameters(self.actor)

    def state_dict_extra(self) -> dict:
        return {"optimizer": self.optimizer.state_dict(), "n_updates": self.n_updates}

    def load_state_dict_extra(self, state: dict) -> None:
        self.optimizer.load_state_dict(state["optimizer"])
        self.n_updates = int(state["n_updates"])

    def set_warmup(self, warm: bool) -> None:
        self.explore[0].warm = warm

    def compile(self, **kwargs) -> None:
        """torch.compile the gradient step (the counter and the branching stay eager)."""
        self._step = torch.compile(self._step, **kwargs)


class SACAgent(_OffPolicyBase):
    actor_kind = "tanh_gaussian"
    metric_names = ("loss_actor", "loss_qvalue", "loss_alpha", "alpha", "entropy")

    def __init__(self, cfg, obs_dim: int, action_spec, num_envs: int = 1, device: torch.device | str = "cpu"):
        super().__init__()
        norm = normalized_spec(action_spec, device)
        act_dim = norm.shape[-1]
        self.actor = gaussian_actor(obs_dim, norm, cfg.hidden_sizes, return_log_prob=False)
        self.critic = q_critic(obs_dim, act_dim, cfg.hidden_sizes)
        self.scale = ScaleAction(action_spec.space.low, action_spec.space.high)
        self._init_policies(self.actor, cfg.actor_ema, norm, num_envs)
        self.loss = SACLoss(
            self.actor,
            self.critic,
            num_qvalue_nets=2,
            loss_function="l2",
            alpha_init=cfg.alpha_init,
            action_spec=norm,
            target_entropy="auto" if cfg.target_entropy is None else cfg.target_entropy,
        )
        self.loss.set_keys(action=ACTION_NORM)
        self.loss.make_value_estimator(ValueEstimators.TD0, gamma=cfg.gamma)
        _ = self.loss.target_entropy  # a lazily created buffer: create it now so state_dicts always match
        self.to(device)
        self.target_update = SoftUpdate(self.loss, tau=cfg.tau)
        self.optimizer = torch.optim.Adam(
            [
                {"params": _params(self.loss.actor_network_params)},
                {"params": _params(self.loss.qvalue_network_params)},
                {"params": [self.loss.log_alpha]},
            ],
            lr=cfg.lr,
        )
        self.n_updates = 0

    def _step(self, batch: TensorDictBase) -> TensorDictBase:
        out = self.loss(batch)
        (out["loss_actor"] + out["loss_qvalue"] + out["loss_alpha"]).backward()
        self.optimizer.step()
        self.optimizer.zero_grad(set_to_none=True)
        self.target_update.step()
        return out.detach()

    def update(self, batch: TensorDictBase) -> TensorDictBase:
        out = self._step(batch)
        self._average_actor()
        self.n_updates += 1
        return out


class TD3Agent(_OffPolicyBase):
    actor_kind = "deterministic"
    metric_names = ("loss_actor", "loss_qvalue")

    def __init__(self, cfg, obs_dim: int, action_spec, num_envs: int = 1, device: torch.device | str = "cpu"):
        super().__init__()
        norm = normalized_spec(action_spec, device)
        act_dim = norm.shape[-1]
        self.actor = TensorDictSequential(
            TensorDictModule(mlp(obs_dim, act_dim, cfg.hidden_sizes), in_keys=["observation"], out_keys=["param"]),
            TanhModule(in_keys=["param"], out_keys=[ACTION_NORM], spec=norm),
        )
        self.critic = q_critic(obs_dim, act_dim, cfg.hidden_sizes)
        self.scale = ScaleAction(action_spec.space.low, action_spec.space.high)
        noisy = TensorDictSequential(
            self.actor,
            AdditiveGaussianModule(spec=norm, sigma_init=1.0, sigma_end=1.0, std=cfg.exploration_noise, action_key=ACTION_NORM),
        )
        self._init_policies(noisy, cfg.actor_ema, norm, num_envs)
        self.loss = TD3Loss(
            self.actor,
            self.critic,
            action_spec=norm,
            num_qvalue_nets=2,
            policy_noise=cfg.policy_noise,
            noise_clip=cfg.noise_clip,
            loss_function="l2",
        )
        self.loss.set_keys(action=ACTION_NORM)
        self.loss.make_value_estimator(ValueEstimators.TD0, gamma=cfg.gamma)
        self.to(device)
        self.target_update = SoftUpdate(self.loss, tau=cfg.tau)
        self.q_optimizer = torch.optim.Adam(_params(self.loss.qvalue_network_params), lr=cfg.lr)
        self.actor_optimizer = torch.optim.Adam(_params(self.loss.actor_network_params), lr=cfg.lr)
        self.policy_delay = cfg.policy_delay
        self.n_updates = 0
        self._last_actor_loss = torch.zeros((), device=device)

    def _critic_step(self, batch: TensorDictBase) -> torch.Tensor:
        q_loss, _ = self.loss.value_loss(batch)
        q_loss.backward()
        self.q_optimizer.step()
        self.q_optimizer.zero_grad(set_to_none=True)
        return q_loss.detach()

    def _actor_step(self, batch: TensorDictBase) -> torch.Tensor:
        actor_loss, _ = self.loss.actor_loss(batch)
        actor_loss.backward()
        self.actor_optimizer.step()
        self.actor_optimizer.zero_grad(set_to_none=True)
        self.target_update.step()
        return actor_loss.detach()

    def update(self, batch: TensorDictBase) -> dict[str, torch.Tensor]:
        q_loss = self._critic_step(batch)
        self.n_updates += 1
        if self.n_updates % self.policy_delay == 0:
            self._last_actor_loss = self._actor_step(batch)
            self._average_actor()
        return {"loss_qvalue": q_loss, "loss_actor": self._last_actor_loss}

    def compile(self, **kwargs) -> None:
        self._critic_step = torch.compile(self._critic_step, **kwargs)
        self._actor_step = torch.compile(self._actor_step, **kwargs)

    def state_dict_extra(self) -> dict:
        return {
            "q_optimizer": self.q_optimizer.state_dict(),
            "actor_optimizer": self.actor_optimizer.state_dict(),
            "n_updates": self.n_updates,
        }

    def load_state_dict_extra(self, state: dict) -> None:
        self.q_optimizer.load_state_dict(state["q_optimizer"])
        self.actor_optimizer.load_state_dict(state["actor_optimizer"])
        self.n_updates = int(state["n_updates"])


class _OneOptimizer(nn.Module):
    """An agent with one optimiser over its losses' parameters (PPO, expert iteration): an update
    is ``self._step`` on a batch (its loss outputs returned), counted; the optimiser's state and
    the count are what a checkpoint keeps beside the networks."""

    optimizer: torch.optim.Optimizer
    n_updates: int

    def _step(self, batch: TensorDictBase):
        raise NotImplementedError

    def update(self, batch: TensorDictBase):
        out = self._step(batch)
        self.n_updates += 1
        return out

    def compile(self, **kwargs) -> None:
        self._step = torch.compile(self._step, **kwargs)

    def state_dict_extra(self) -> dict:
        return {"optimizer": self.optimizer.state_dict(), "n_updates": self.n_updates}

    def load_state_dict_extra(self, state: dict) -> None:
        self.optimizer.load_state_dict(state["optimizer"])
        self.n_updates = int(state["n_updates"])


class PPOAgent(_OneOptimizer):
    """Clipped PPO with GAE on a tanh-Gaussian policy (``"action_norm"`` log-probabilities).
    No averaged actor: ``eval_policy`` is ``policy`` and ``explore`` too (sampling)."""

    actor_kind = "tanh_gaussian"
    metric_names = ("loss_objective", "loss_critic", "loss_entropy", "entropy", "kl_approx", "clip_fraction")

    def __init__(self, cfg, obs_dim: int, action_spec, num_envs: int = 1, device: torch.device | str = "cpu"):
        super().__init__()
        norm = normalized_spec(action_spec, device)
        self.actor = gaussian_actor(obs_dim, norm, cfg.hidden_sizes, return_log_prob=True)
        self.critic = ValueOperator(mlp(obs_dim, 1, cfg.hidden_sizes), in_keys=["observation"])
        self.scale = ScaleAction(action_spec.space.low, action_spec.space.high)
        self.policy = TensorDictSequential(self.actor, self.scale)
        self.explore = self.eval_policy = self.policy
        self.loss = ClipPPOLoss(
            self.actor,
            self.critic,
            clip_epsilon=cfg.clip_epsilon,
            entropy_bonus=cfg.entropy_coeff > 0,
            entropy_coeff=cfg.entropy_coeff if cfg.entropy_coeff > 0 else None,
            critic_coeff=cfg.critic_coeff,
            loss_critic_type="l2",
            normalize_advantage=cfg.normalize_advantage,
        )
        self.loss.set_keys(action=ACTION_NORM, sample_log_prob=self.actor.log_prob_keys[0])
        self.loss.make_value_estimator(ValueEstimators.GAE, gamma=cfg.gamma, lmbda=cfg.gae_lambda, average_gae=False)
        self.to(device)
        self.optimizer = torch.optim.Adam(self.loss.parameters(), lr=cfg.lr)
        self.max_grad_norm = cfg.max_grad_norm
        self.n_updates = 0

    @property
    def eval_actor(self) -> nn.Module:
        return self.actor

    @torch.no_grad()
    def advantage(self, data: TensorDictBase) -> TensorDictBase:
        return self.loss.value_estimator(data)

    def _step(self, batch: TensorDictBase) -> TensorDictBase:
        out = self.loss(batch)
        loss = out["loss_objective"] + out["loss_critic"]
        if "loss_entropy" in out.keys():
            loss = loss + out["loss_entropy"]
        loss.backward()
        torch.nn.utils.clip_grad_norm_(self.loss.parameters(), self.max_grad_norm)
        self.optimizer.step()
        self.optimizer.zero_grad(set_to_none=True)
        return out.detach()


class ExItAgent(_OneOptimizer):
    """The policy of expert iteration (:mod:`billiards.exit`): the tanh-Gaussian actor of SAC and
    PPO (so its exported files play, propose and evaluate like theirs), trained by maximum
    likelihood on the search's labelled shots. A replayed row holds ``"observation"`` and
    ``"target"``, the label's normalised action in [-1, 1]^4; the loss is the Gaussian negative
    log-likelihood of ``atanh(target)`` (the label kept :data:`TARGET_EDGE` inside the box), which
    is the TanhNormal's up to a term that does not depend on the network. With ``nll_beta`` =
    beta > 0 each coordinate's term is weighted by its scale to the power 2 beta, the weight held
    constant (beta-NLL, Seitzer et al. 2022): the plain likelihood lets the network widen its
    scale where labels are hard to fit and learn the mean there less; beta = 1 gives the mean
    the squared error's gradient. ``eval_policy`` and ``explore`` are ``policy``."""

    actor_kind = "tanh_gaussian"
    metric_names = ("loss_nll", "scale_mean")
    replay_keys = ("observation", "target")
    TARGET_EDGE = 1e-3

    def __init__(self, cfg, obs_dim: int, action_spec, num_envs: int = 1, device: torch.device | str = "cpu"):
        super().__init__()
        norm = normalized_spec(action_spec, device)
        self.actor = gaussian_actor(obs_dim, norm, cfg.hidden_sizes, return_log_prob=False)
        self.scale = ScaleAction(action_spec.space.low, action_spec.space.high)
        self.policy = TensorDictSequential(self.actor, self.scale)
        self.explore = self.eval_policy = self.policy
        self.to(device)
        self.optimizer = torch.optim.Adam(self.actor.parameters(), lr=cfg.lr)
        self.nll_beta = float(cfg.get("nll_beta", 0.0))
        self.n_updates = 0

    @property
    def eval_actor(self) -> nn.Module:
        return self.actor

    def _step(self, batch: TensorDictBase) -> dict[str, torch.Tensor]:
        loc, scale = self.actor.module[0].module(batch.get("observation"))
        edge = 1.0 - self.TARGET_EDGE
        z = torch.atanh(batch.get("target").clamp(-edge, edge))
        nll = torch.log(scale) + 0.5 * ((z - loc) / scale) ** 2
        if self.nll_beta:  # beta-NLL: each coordinate's term weighted by its scale^(2 beta), held constant
            nll = nll * scale.detach() ** (2.0 * self.nll_beta)
        loss = nll.sum(-1).mean()
        loss.backward()
        self.optimizer.step()
        self.optimizer.zero_grad(set_to_none=True)
        return {"loss_nll": loss.detach(), "scale_mean": scale.detach().mean()}

    def set_warmup(self, warm: bool) -> None:
        pass


# algo.name -> its agent, for the algorithms of the one list (billiards.rl.config.ALGO_SCHEMAS,
# each name's schema); OFF_POLICY (re-exported): those with a replay buffer
_AGENT_OF = {SACConfig: SACAgent, TD3Config: TD3Agent, PPOConfig: PPOAgent, ExItConfig: ExItAgent}
AGENTS = {name: _AGENT_OF[schema] for name, schema in ALGO_SCHEMAS.items()}


def make_agent(algo_cfg, obs_dim: int, action_spec, *, num_envs: int = 1, device: torch.device | str = "cpu") -> Agent:
    """The agent of ``algo_cfg.name`` on ``device`` for an env with ``obs_dim`` observations,
    the unbatched action spec ``action_spec`` (``env.action_spec_unbatched``) and
    ``num_envs`` innings per step (the batch of the warm-up's random actions). ``algo_cfg``:
    the algorithm's node with every key of its schema (a saved one merged into it)."""
    return AGENTS[algo_cfg.name](algo_cfg, obs_dim, action_spec, num_envs=num_envs, device=device)

