"""Proposers: where the search's candidate actions come from.

A proposer maps S table states to k raw candidate actions each:
``propose(positions (S, 4, 2), k, rng) -> actions (S, k, 4)`` of (theta, p, a, b) in the
simulator's convention (theta in radians, exact float64). Candidate 0 of every state is the
proposer's own best guess (a policy's deterministic action, the geometric baseline shot), so a
search with one candidate and no expansion plays exactly what the proposer would.

* :class:`GeometricProposer` needs no training: it samples inside the aim-constraint cone.
* :class:`PolicyProposer` samples an ensemble of trained policies (e.g. the three seeds of
  one Table 5 variant); :func:`load_policy_proposer` makes one from training runs or exported
  policy files (this adapter lives here: search builds on training, never the reverse).
"""

from __future__ import annotations

from typing import Protocol, Sequence

import numpy as np
import torch

from billiards import domain, numerics
from billiards.physics import DEFAULT_PARAMS, PhysicsParams


class Proposer(Protocol):
    name: str

    def propose(self, positions: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
        """positions (S, 4, 2) -> candidate actions (S, k, 4), float64; candidate 0 is the mode."""


class GeometricProposer:
    """Shots inside the guaranteed-contact cone of the nearest red, no learning.

    Candidate 0 is the nearest-red baseline (u = 0, p = ``power_mode``, centre hit). The others
    draw u ~ U[-1, 1] (theta = theta_target + u * asin(2R/d), :func:`domain.constrained_theta`),
    p ~ U[power_low, power_high] and tip offsets a, b ~ U[-1, 1].

    Narrower draws make *forgiving* candidates more common under execution noise (the
    ``forgiving`` proposer, results/noise/): ``u_low <= |u| <= u_high`` (a half-ball-ish cut
    rather than a full hit or a graze) and the vertical tip offset ``b`` in
    ``[spin_low, spin_high]`` (follow rather than draw). Each draw is the default draw mapped
    onto the narrower range, so the defaults give exactly the default candidates.

    ``far_share`` > 0 sends that share of the candidates (never candidate 0) into the cone of
    the *farther* red instead, the same u on that cone (one more uniform draw per candidate
    decides; with the default 0 nothing more is drawn).
    """

    name = "geometric"

    def __init__(self, power_low: float = 0.15, power_high: float = 0.9, power_mode: float = 0.5,
                 R: float = DEFAULT_PARAMS.ball_radius, u_low: float = 0.0, u_high: float = 1.0,
                 spin_low: float = -1.0, spin_high: float = 1.0, far_share: float = 0.0):
        if not 0.0 <= power_low <= power_high <= 1.0:
            raise ValueError(f"GeometricProposer needs 0 <= power_low <= power_high <= 1, got {power_low}, {power_high}")
        if not 0.0 <= u_low <= u_high <= 1.0:
            raise ValueError(f"GeometricProposer needs 0 <= u_low <= u_high <= 1, got {u_low}, {u_high}")
        if not -1.0 <= spin_low <= spin_high <= 1.0:
            raise ValueError(f"GeometricProposer needs -1 <= spin_low <= spin_high <= 1, got {spin_low}, {spin_high}")
        self.power_low, self.power_high, self.power_mode, self.R = power_low, power_high, power_mode, R
        if not 0.0 <= far_share <= 1.0:
            raise ValueError(f"GeometricProposer needs 0 <= far_share <= 1, got {far_share}")
        self.u_low, self.u_high, self.spin_low, self.spin_high = u_low, u_high, spin_low, spin_high
        self.far_share = far_share

    def propose(self, positions: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
        S = positions.shape[0]
        u = rng.uniform(-1.0, 1.0, (S, k))
        p = rng.uniform(self.power_low, self.power_high, (S, k))
        ab = rng.uniform(-1.0, 1.0, (S, k, 2))
        if (self.u_low, self.u_high) != (0.0, 1.0):
            u = np.sign(u) * (self.u_low + np.abs(u) * (self.u_high - self.u_low))
        if (self.spin_low, self.spin_high) != (-1.0, 1.0):
            ab[..., 1] = self.spin_low + 0.5 * (ab[..., 1] + 1.0) * (self.spin_high - self.spin_low)
        u[:, 0], p[:, 0], ab[:, 0] = 0.0, self.power_mode, 0.0
        theta = domain.constrained_theta(positions[:, None], u, self.R)
        if self.far_share > 0:
            far = rng.random((S, k)) < self.far_share
            far[:, 0] = False
            other = domain.RED1 + domain.RED2 - domain.nearest_red(positions)
            target, half = domain.aim_window(positions, self.R, red=other)
            theta = np.where(far, target[:, None] + u * half[:, None], theta)
        return np.concatenate([theta[..., None], p[..., None], ab], axis=-1)


class EnsembleHeads:
    """The Gaussian heads of an ensemble of identical policy networks as stacked float32 arrays.

    Every layer of the E policies is one compiled call over the stacked weights
    (:func:`billiards.numerics.dense`), so the whole ensemble's forward pass at S states costs a
    few calls instead of E framework calls
    (TensorDict, distribution and transform objects) that dwarf a 32->256->256->8 network at
    the batch sizes the search uses (S <= a few hundred). It reproduces, in float32 like the
    torch modules: the MLP (Linear/ReLU), TorchRL's ``NormalParamExtractor`` (biased softplus
    scale, lower bound), the ``TanhNormal`` on [-1, 1] (tanh clamped to +-(1 - float32
    resolution), TorchRL's safe tanh) and :class:`~billiards.rl.agents.ScaleAction`.
    """

    def __init__(self, weights, biases, scale_bias, scale_min, scale_lb, tanh_lim, mid, half, held):
        self.weights, self.biases = weights, biases  # per layer: (E, in, out), (E, out)
        self.scale_bias, self.scale_min, self.scale_lb, self.tanh_lim = scale_bias, scale_min, scale_lb, tanh_lim
        self.mid, self.half, self.held = mid, half, held  # (E, 1, 1, A); held: None or (mask, values)
        self.size = weights[0].shape[0]

    @classmethod
    def from_policies(cls, policies) -> "EnsembleHeads":
        """Stack the weights of ``policies`` (see :class:`PolicyProposer`); raises ValueError
        naming the first part it does not recognise or that differs between the policies."""
        parts = [_head_parts(p) for p in policies]
        shapes = {tuple(tuple(w.shape) for w in part["weights"]) for part in parts}
        if len(shapes) != 1:
            raise ValueError(f"the policies' networks differ in shape: {sorted(shapes)}")
        for key in ("scale_bias", "scale_min", "scale_lb", "held"):
            if len({repr(part[key]) for part in parts}) != 1:
                raise ValueError(f"the policies differ in {key}")
        stack = lambda key: [np.stack(ws) for ws in zip(*(part[key] for part in parts))]
        p0 = parts[0]
        tanh_lim = 1.0 - float(np.finfo(np.float32).resolution)
        mid = np.stack([part["mid"] for part in parts])[:, None, None]
        half = np.stack([part["half"] for part in parts])[:, None, None]
        return cls(stack("weights"), stack("biases"), p0["scale_bias"], p0["scale_min"],
                   p0["scale_lb"], tanh_lim, mid, half, p0["held"])

    def heads(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """obs (S, D) float32 -> loc, scale (E, S, A) float32 of every policy's Gaussian.

        Every layer is :func:`billiards.numerics.dense` (float32, a fixed summation order), the
        softplus and tanh go through the C library in float64: the same bits on every CPU,
        whatever BLAS kernel or NumPy loops it would choose (equal to the torch modules up to
        float32 rounding).
        """
        x = numerics.mlp(np.asarray(obs, dtype=np.float32)[None], self.weights, self.biases)
        A = x.shape[-1] // 2
        scale = numerics.softplus32(x[..., A:] + np.float32(self.scale_bias)) + np.float32(self.scale_min)
        return x[..., :A], np.maximum(scale, np.float32(self.scale_lb))

    def actions(self, pre_tanh: np.ndarray) -> np.ndarray:
        """Pre-tanh draws (E, S, n, A) -> actions in the env's bounds (E, S, n, A), float32."""
        y = np.clip(numerics.tanh32(pre_tanh), np.float32(-self.tanh_lim), np.float32(self.tanh_lim))
        if self.held is not None:
            y = np.where(self.held[0], self.held[1], y)
        return self.mid + self.half * y


def _head_parts(policy) -> dict:
    """The arrays and constants of one policy laid out as ``(actor, ScaleAction)`` with actor =
    ProbabilisticActor(TensorDictModule(Sequential(MLP, NormalParamExtractor)), TanhNormal)."""
    from torchrl.modules import NormalParamExtractor, TanhNormal

    try:
        actor, scale = policy[0], policy[1]
        net, dist_module = actor.module[0].module, actor.module[1]
        mlp, extractor = net[0], net[1]
    except (TypeError, IndexError, AttributeError, KeyError) as err:
        raise ValueError(f"not an (actor, ScaleAction) policy over an MLP Gaussian head: {err}") from None
    if not isinstance(extractor, NormalParamExtractor) or type(extractor.scale_mapping).__name__ != "biased_softplus":
        raise ValueError("the head is not a NormalParamExtractor with a biased softplus scale")
    kwargs = dict(dist_module.distribution_kwargs)
    bounds = [torch.as_tensor(kwargs.pop(k, d)) for k, d in (("low", -1.0), ("high", 1.0))]
    if (dist_module.distribution_class is not TanhNormal or kwargs.get("tanh_loc", False)
            or not kwargs.get("safe_tanh", True) or set(kwargs) - {"tanh_loc", "safe_tanh"}
            or not (bool((bounds[0] == -1).all()) and bool((bounds[1] == 1).all()))):
        raise ValueError(f"the distribution is not a safe TanhNormal on [-1, 1]: {dist_module.distribution_class.__name__} {kwargs}")
    layers = list(mlp)
    linear = layers[0::2]
    if (not all(isinstance(m, torch.nn.Linear) for m in linear)
            or not all(isinstance(m, torch.nn.ReLU) for m in layers[1::2]) or len(layers) % 2 != 1):
        raise ValueError(f"the network is not Linear/ReLU layers: {[type(m).__name__ for m in layers]}")
    mask = scale.hold.mask
    held = None if mask is None else (mask.numpy().copy(), scale.hold.held_norm.numpy().astype(np.float32))
    f32 = lambda t: t.detach().to(torch.float32).numpy().copy()
    return {"weights": [f32(m.weight).T.copy() for m in linear], "biases": [f32(m.bias) for m in linear],
            "scale_bias": float(extractor.scale_mapping.bias), "scale_min": float(extractor.scale_mapping.min_val),
            "scale_lb": float(extractor.scale_lb), "held": held, "mid": f32(scale.mid), "half": f32(scale.half_range)}


class PolicyProposer:
    """An ensemble of stochastic policies emitting k candidates jointly.

    ``policies`` are TorchRL probabilistic actors (TensorDict in with "observation", out with
    "action" and the distribution's "loc"), all trained with the same observation and action
    layout: ``extra_features`` appends :func:`domain.carom_features`; ``constrain_aim`` means
    action[0] is u in [-1, 1] and is mapped to theta with :func:`domain.constrained_theta`.
    Candidate j goes to policy j mod E; each policy's first candidate is its deterministic
    action (policy 0's is candidate 0), the rest are samples.

    ``impl``: ``"batched"`` evaluates the ensemble with :class:`EnsembleHeads` (one compiled
    call per layer for all policies, the same bits on every CPU); ``"reference"`` calls each policy's torch modules;
    ``"auto"`` (default) is batched when the networks are of the kind it reproduces, else
    reference. Both consume the caller's generator identically (same draws, same order) and
    give the same candidates up to float32 rounding of the network (torch's kernels sum in
    their own, CPU-dependent orders; see ``tests/test_search.py``). ``self.impl`` is the one in use.
    The batched proposer copies the weights when it is built: later changes to the torch
    modules do not reach it (build a new proposer).

    ``device``: where the networks run. The default, the CPU, allows either implementation; a
    GPU takes the reference one with the modules moved there, the observation sent once per
    decision and the candidates brought back once per policy (the draws stay the caller's
    NumPy generator's, so the candidates equal the CPU's up to float32 rounding).
    """

    IMPLS = ("auto", "batched", "reference")

    def __init__(self, policies: Sequence[torch.nn.Module], *, constrain_aim: bool, extra_features: bool,
                 name: str = "policy", R: float = DEFAULT_PARAMS.ball_radius, impl: str = "auto",
                 device: torch.device | str | None = None):
        if not policies:
            raise ValueError("PolicyProposer needs at least one policy")
        if impl not in self.IMPLS:
            raise ValueError(f"PolicyProposer impl must be one of {', '.join(self.IMPLS)}; got {impl!r}")
        self.device = torch.device("cpu") if device is None else torch.device(device)
        if self.device.type != "cpu":
            if impl == "batched":
                raise ValueError(f"proposer {name!r}: the batched implementation runs in NumPy on the CPU; "
                                 f"device={self.device} needs impl='reference' (or 'auto')")
            impl = "reference"  # the torch modules on the device
        self.policies = [p.to(self.device) for p in policies] if impl == "reference" else list(policies)
        self.constrain_aim, self.extra_features, self.name, self.R = constrain_aim, extra_features, name, R
        self.heads = None
        if impl != "reference":
            try:
                self.heads = EnsembleHeads.from_policies(self.policies)
            except ValueError as err:
                if impl == "batched":
                    raise ValueError(f"proposer {name!r} cannot be batched: {err}") from None
        self.impl = "reference" if self.heads is None else "batched"

    def observation_array(self, positions: np.ndarray) -> np.ndarray:
        """The policies' float32 observation (S, D) of tables at rest (S, 4, 2): the envs' own,
        :func:`billiards.domain.observation`."""
        return domain.observation(positions, self.extra_features)

    def observation(self, positions: np.ndarray) -> torch.Tensor:
        """The observation tensor on the proposer's device (one transfer per decision)."""
        return torch.from_numpy(self.observation_array(positions)).to(self.device)

    @staticmethod
    def _actions(policy, obs: torch.Tensor, n: int, rng: np.random.Generator) -> torch.Tensor:
        """(S, n, 4) actions of one policy: its deterministic action, then n - 1 samples.

        One network call per policy: the policy's action distribution (``get_dist`` of its
        probabilistic actor) gives the deterministic action, and the samples are the
        distribution's reparameterised draws ``transforms(loc + scale * eps)`` with eps from
        the caller's numpy ``rng``, so torch's global RNG is never touched. The policy's last
        module (:class:`~billiards.rl.agents.ScaleAction`) maps them onto the env's bounds.
        """
        from tensordict import TensorDict

        actor, scale = policy[0], policy[1]
        S = obs.shape[0]
        dist = actor.get_dist(TensorDict({"observation": obs}, batch_size=[S]))
        draws = [dist.deterministic_sample[:, None]]
        if n > 1:
            normal = dist.base_dist.base_dist
            eps = torch.from_numpy(rng.standard_normal((S, n - 1, normal.loc.shape[-1]))).to(normal.loc.device, normal.loc.dtype)
            x = normal.loc[:, None] + normal.scale[:, None] * eps
            for t in dist.transforms:
                x = t(x)
            draws.append(x)
        norm = torch.cat(draws, dim=1).reshape(S * n, -1)
        return scale(TensorDict({"action_norm": norm}, batch_size=[S * n]))["action"].reshape(S, n, -1)

    def _raw_batched(self, positions: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
        """(S, k, 4) float32 actions in the env's bounds, all policies in one pass.

        Policy e's i-th candidate is candidate j = i * E + e; its draw eps is the i-th row of
        the (S, n_e - 1, A) normals the reference draws for policy e (the same calls in the
        same order), 0 for the deterministic candidate i = 0: tanh(loc + scale * 0) = tanh(loc).
        """
        S, E = positions.shape[0], self.heads.size
        loc, scale = self.heads.heads(self.observation_array(positions))  # (E, S, A)
        counts = [len(range(e, k, E)) for e in range(E)]
        eps = np.zeros((E, S, max(counts), loc.shape[-1]), dtype=np.float32)
        for e, n in enumerate(counts):
            if n > 1:
                eps[e, :, 1:n] = rng.standard_normal((S, n - 1, loc.shape[-1]))
        acts = self.heads.actions(loc[:, :, None] + scale[:, :, None] * eps)  # (E, S, n_max, A)
        return acts.transpose(1, 2, 0, 3).reshape(S, -1, acts.shape[-1])[:, :k]

    @torch.no_grad()
    def _raw_reference(self, positions: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
        """(S, k, 4) actions in the env's bounds, one torch call per policy."""
        S, E = positions.shape[0], len(self.policies)
        obs = self.observation(positions)
        out = np.empty((S, k, 4))
        for e, policy in enumerate(self.policies):
            cols = np.arange(e, k, E)
            if cols.size:
                out[:, cols] = self._actions(policy, obs, cols.size, rng).double().cpu().numpy()
        return out

    def propose(self, positions: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
        raw = self._raw_batched if self.impl == "batched" else self._raw_reference
        out = raw(positions, k, rng).astype(np.float64)
        out[..., 1] = np.clip(out[..., 1], 0.0, 1.0)
        out[..., 2:] = np.clip(out[..., 2:], -1.0, 1.0)
        if self.constrain_aim:
            out[..., 0] = domain.constrained_theta(positions[:, None], np.clip(out[..., 0], -1.0, 1.0), self.R)
        return out


def load_policy_proposer(paths, name: str = "policy", params: PhysicsParams | None = None,
                         device: torch.device | str | None = None) -> PolicyProposer:
    """A :class:`PolicyProposer` over the policies of several runs (e.g. the three seeds of one
    Table 5 variant): ``paths`` are training run dirs, their checkpoint.pt or exported policy
    files (:func:`billiards.rl.policy.load_policy`); they must share the observation and
    action layout. ``params`` is the table it will propose for (default: the default preset);
    ``device``: where the networks run (a GPU takes the torch implementation; default CPU);
    policies trained on another table are used with a :class:`PhysicsMismatchWarning`."""
    from billiards.physics.config import warn_physics_mismatch
    from billiards.rl.policy import load_policy, policy_physics

    params = DEFAULT_PARAMS if params is None else params
    loaded = [load_policy(p) for p in paths]
    layouts = {(bool(c.env.constrain_aim), bool(c.env.extra_features)) for _, c in loaded}
    if len(layouts) != 1:
        raise ValueError(f"proposer {name!r}: checkpoints mix observation/action layouts {sorted(layouts)}")
    for path, (_, cfg) in zip(paths, loaded):
        warn_physics_mismatch(f"proposer {name!r} policy {path}", policy_physics(cfg), params)
    constrain_aim, extra_features = layouts.pop()
    return PolicyProposer([p for p, _ in loaded], constrain_aim=constrain_aim, extra_features=extra_features, name=name,
                          R=params.ball_radius, device=device)


__all__ = ["EnsembleHeads", "GeometricProposer", "PolicyProposer", "Proposer", "load_policy_proposer"]
