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

import math
from typing import Protocol, Sequence

import numba
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

    The whole proposal -- observation, every layer of the E policies over the stacked weights
    (:func:`billiards.numerics.dense`'s kernel), the heads, the squashed draws and the map to
    the raw shot -- is one compiled call (:meth:`candidates`), instead of E framework calls
    (TensorDict, distribution and transform objects) that dwarf a 32->256->256->8 network at
    the batch sizes the search uses (S <= a few hundred; PUCT calls it for one table at a
    time). It reproduces, in float32 like the torch modules: the MLP (Linear/ReLU), TorchRL's
    ``NormalParamExtractor`` (biased softplus scale, lower bound), the ``TanhNormal`` on
    [-1, 1] (tanh clamped to +-(1 - float32 resolution), TorchRL's safe tanh) and
    :class:`~billiards.rl.learners.ScaleAction`.
    """

    def __init__(self, weights, biases, scale_bias, scale_min, scale_lb, tanh_lim, mid, half, held):
        self.weights, self.biases = weights, biases  # per layer: (E, in, out), (E, out)
        self.scale_bias, self.scale_min, self.scale_lb, self.tanh_lim = scale_bias, scale_min, scale_lb, tanh_lim
        self.mid, self.half, self.held = mid, half, held  # (E, A) float32; held: None or (mask, values)
        self.size = weights[0].shape[0]
        # the kernel's operands: every layer's weights and biases in one float32 buffer, each
        # layer's (in, out, weight offset, bias offset), the head's constants as float32
        parts, layout, off = [], [], 0
        for w, b in zip(weights, biases):
            E, n_in, n_out = w.shape
            layout.append((n_in, n_out, off, off + w.size))
            parts += [np.ascontiguousarray(w, dtype=np.float32).ravel(), np.ascontiguousarray(b, dtype=np.float32).ravel()]
            off += w.size + b.size
        self._flat, self._layout = np.concatenate(parts), np.array(layout, dtype=np.int64)
        self._consts = np.array([scale_bias, scale_min, scale_lb, tanh_lim], dtype=np.float64).astype(np.float32)
        A = self.mid.shape[-1]
        self._held_mask = np.zeros(A, dtype=np.bool_) if held is None else np.asarray(held[0], dtype=np.bool_)
        self._held_values = np.zeros(A, dtype=np.float32) if held is None else np.asarray(held[1], dtype=np.float32)

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
        mid = np.stack([part["mid"] for part in parts])
        half = np.stack([part["half"] for part in parts])
        return cls(stack("weights"), stack("biases"), p0["scale_bias"], p0["scale_min"],
                   p0["scale_lb"], tanh_lim, mid, half, p0["held"])

    def draws(self, S: int, k: int) -> int:
        """How many standard normals :meth:`candidates` takes for S tables and k candidates."""
        return S * self.mid.shape[-1] * sum(max(len(range(e, k, self.size)) - 1, 0) for e in range(self.size))

    def candidates(self, positions: np.ndarray, normals: np.ndarray, k: int, extra_features: bool,
                   constrain_aim: bool, R: float) -> np.ndarray:
        """(S, k, 4) float64 raw shots on the tables ``positions`` (S, 4, 2).

        Policy e's i-th candidate is candidate j = i * E + e: its deterministic action for
        i = 0, else squashed from its Gaussian's ``loc + scale * eps`` with eps the i-th row
        of the policy's (S, n_e - 1, A) block of ``normals`` (float64, rounded to float32; the
        blocks of policies 0, 1, ... one after the other, :meth:`draws` in all). Then mapped
        onto the env's bounds, p clipped to [0, 1], a and b to [-1, 1], and with
        ``constrain_aim`` u clipped to [-1, 1] and aimed by :func:`billiards.domain.constrained_theta`.

        In float32 as :func:`billiards.numerics.mlp` and :func:`~billiards.numerics.softplus32`
        / :func:`~billiards.numerics.tanh32` compute (each layer's sums in index order, softplus
        and tanh through the C library in float64), then float64: the same bits on every CPU.
        """
        pos = np.ascontiguousarray(positions, dtype=np.float64)
        if normals.shape != (self.draws(pos.shape[0], k),):
            raise ValueError(f"candidates: {self.draws(pos.shape[0], k)} normals needed, got shape {normals.shape}")
        return _candidates(pos, normals, self._flat, self._layout, self._consts, self.mid, self.half, self._held_mask,
                           self._held_values, k, extra_features, constrain_aim, 2.0 * R,
                           math.sin(domain.AIM_MAX_HALF_WIDTH))


@numba.njit(cache=True, nogil=True)
def _clip(x, low, high):
    """NumPy's clip of one value (NaN passes through; -0.0 stays -0.0 at a low bound of 0)."""
    return low if x < low else (high if x > high else x)


@numba.njit(cache=True, nogil=True)
def _candidates(pos, normals, flat, layout, consts, mid, half, held_mask, held_values, k, extra_features, constrain_aim,
                two_r, cap):
    """:meth:`EnsembleHeads.candidates`: the observation (:func:`billiards.domain.observation`),
    the stacked layers, the heads, the squashed draws and the raw shots, the NumPy formulas'
    operations in their order."""
    S, E, A = pos.shape[0], mid.shape[0], mid.shape[1]
    D = domain.OBS_DIM + (domain.N_CAROM_FEATURES if extra_features else 0)
    x = np.zeros((1, S, D), dtype=np.float32)
    for s in range(S):
        for ball in range(domain.N_BALLS):
            x[0, s, ball * domain.BALL_STATE_DIM] = np.float32(pos[s, ball, 0])
            x[0, s, ball * domain.BALL_STATE_DIM + 1] = np.float32(pos[s, ball, 1])
    if extra_features:
        feats = domain.carom_features_rows(pos)
        for s in range(S):
            for f in range(domain.N_CAROM_FEATURES):
                x[0, s, domain.OBS_DIM + f] = np.float32(feats[s, f])
    n_layers = layout.shape[0]
    for layer in range(n_layers):
        n_in, n_out, w_off, b_off = layout[layer, 0], layout[layer, 1], layout[layer, 2], layout[layer, 3]
        w = flat[w_off:w_off + E * n_in * n_out].reshape((E, n_in, n_out))
        b = flat[b_off:b_off + E * n_out].reshape((E, n_out))
        x = numerics._dense_kernel(x, w, b, layer < n_layers - 1, np.empty((E, S, n_out), dtype=np.float32))
    bias, scale_min, scale_lb, lim = consts[0], consts[1], consts[2], consts[3]
    out = np.empty((S, k, A))
    first = 0  # where policy e's block of normals starts
    for e in range(E):
        n_e = (k - e + E - 1) // E if k > e else 0  # its candidates e, e + E, ...
        for s in range(S):
            for a in range(A):
                loc = x[e, s, a]
                z = x[e, s, A + a] + bias  # softplus32 (identity above 20), + min, then the lower bound
                scale = z if z > np.float32(20.0) else np.float32(math.log1p(math.exp(np.float64(z))))
                scale = scale + scale_min
                if not (scale > scale_lb or scale != scale):  # np.maximum
                    scale = scale_lb
                for i in range(n_e):
                    eps = np.float32(0.0) if i == 0 else np.float32(normals[first + (s * (n_e - 1) + i - 1) * A + a])
                    y = _clip(np.float32(math.tanh(np.float64(loc + scale * eps))), -lim, lim)
                    if held_mask[a]:
                        y = held_values[a]
                    out[s, i * E + e, a] = np.float64(mid[e, a] + half[e, a] * y)
        first += S * max(n_e - 1, 0) * A
    theta_target, half_width = np.zeros(0), np.zeros(0)
    if constrain_aim:
        theta_target, half_width = domain.aim_window_rows(pos, domain.nearest_red_rows(pos), two_r, cap)
    for s in range(S):
        for j in range(k):
            out[s, j, 1] = _clip(out[s, j, 1], 0.0, 1.0)
            out[s, j, 2] = _clip(out[s, j, 2], -1.0, 1.0)
            out[s, j, 3] = _clip(out[s, j, 3], -1.0, 1.0)
            if constrain_aim:
                out[s, j, 0] = theta_target[s] + _clip(out[s, j, 0], -1.0, 1.0) * half_width[s]
    return out


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
    their own, CPU-dependent orders; see ``tests/search/test_search.py``). ``self.impl`` is the one in use.
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
        module (:class:`~billiards.rl.learners.ScaleAction`) maps them onto the env's bounds.
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

    def _batched(self, positions: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
        """(S, k, 4) raw candidates, all policies in one compiled call (:meth:`EnsembleHeads.candidates`).

        Policy e's i-th candidate is candidate j = i * E + e; its draw eps is the i-th row of
        the (S, n_e - 1, A) normals the reference draws for policy e, 0 for the deterministic
        candidate i = 0: tanh(loc + scale * 0) = tanh(loc). A Generator draws normals one
        after the other, so one call for all policies gives the reference's values and leaves
        the generator in its state.
        """
        n = self.heads.draws(positions.shape[0], k)  # the reference's per-policy draws, in one call
        normals = rng.standard_normal(n) if n else np.empty(0)
        return self.heads.candidates(positions, normals, k, self.extra_features, self.constrain_aim, self.R)

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
        if self.impl == "batched":
            return self._batched(positions, k, rng)
        out = self._raw_reference(positions, k, rng).astype(np.float64)
        out[..., 1] = np.clip(out[..., 1], 0.0, 1.0)
        out[..., 2:] = np.clip(out[..., 2:], -1.0, 1.0)
        if self.constrain_aim:
            out[..., 0] = domain.constrained_theta(positions[:, None], np.clip(out[..., 0], -1.0, 1.0), self.R)
        return out


class MixedProposer:
    """Two proposers sharing the candidates: of ``k``, the first ``ceil(share * k)`` are
    ``first``'s (its mode is candidate 0), the rest ``second``'s, each drawn from the caller's
    generator in that order. ``share`` in [0, 1]; 1 is ``first`` alone."""

    def __init__(self, first, second, share: float, name: str = "mixed"):
        if not 0.0 <= share <= 1.0:
            raise ValueError(f"MixedProposer share must lie in [0, 1], got {share!r}")
        self.first, self.second, self.share, self.name = first, second, float(share), name

    def propose(self, positions: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
        n = math.ceil(self.share * k)
        parts = [p.propose(positions, m, rng) for p, m in ((self.first, n), (self.second, k - n)) if m]
        return np.concatenate(parts, axis=1)


def load_policy_proposer(paths, name: str = "policy", params: PhysicsParams | None = None,
                         device: torch.device | str | None = None) -> PolicyProposer:
    """A :class:`PolicyProposer` over the policies of several runs (e.g. the three seeds of one
    Table 5 variant): ``paths`` are training run dirs, their checkpoint.pt or exported policy
    files (:func:`billiards.rl.policy.load_policy`); they must share the observation and
    action layout. ``params`` is the table it will propose for (default: the default preset);
    ``device``: where the networks run (a GPU takes the torch implementation; default CPU);
    policies trained on another table are used with a :class:`PhysicsMismatchWarning`."""
    from billiards.physics.config import warn_physics_mismatch
    from billiards.rl.policy import level_input_error, load_policy, policy_physics, reads_level

    params = DEFAULT_PARAMS if params is None else params
    loaded = [load_policy(p) for p in paths]
    for path, (_, cfg) in zip(paths, loaded):
        if reads_level(cfg):
            raise ValueError(f"proposer {name!r}: " + level_input_error(
                path, "proposers are not given it; play it with match.py (a policy player is told the level) or "
                      "evaluate it with train.py"))
    layouts = {(bool(c.env.constrain_aim), bool(c.env.extra_features)) for _, c in loaded}
    if len(layouts) != 1:
        raise ValueError(f"proposer {name!r}: checkpoints mix observation/action layouts {sorted(layouts)}")
    for path, (_, cfg) in zip(paths, loaded):
        warn_physics_mismatch(f"proposer {name!r} policy {path}", policy_physics(cfg), params)
    constrain_aim, extra_features = layouts.pop()
    return PolicyProposer([p for p, _ in loaded], constrain_aim=constrain_aim, extra_features=extra_features, name=name,
                          R=params.ball_radius, device=device)


__all__ = ["EnsembleHeads", "GeometricProposer", "MixedProposer", "PolicyProposer", "Proposer", "load_policy_proposer"]
