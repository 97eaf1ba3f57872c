"""The batched proposer: its one compiled call is the NumPy formulation, to the bit."""

from pathlib import Path

import numpy as np
import pytest

from billiards.physics import random_racks
from billiards.search import PolicyProposer

ROOT = Path(__file__).resolve().parents[2]


def base_policies():
    """The three shipped policies of the Table 5 "base" proposer, as torch modules (fresh copies)."""
    from billiards.rl.policy import load_policy

    return [load_policy(ROOT / "results" / "policies" / "base" / f"seed{s}.pt")[0] for s in range(3)]


def numpy_candidates(prop, positions, k, rng):
    """The batched proposer's candidates written out in NumPy: numerics.mlp, softplus32 and
    tanh32 in float32, the draws policy by policy, then the clips and the aim."""
    from billiards import domain, numerics

    h, S = prop.heads, positions.shape[0]
    E, A = h.size, h.mid.shape[-1]
    x = numerics.mlp(domain.observation(positions, prop.extra_features)[None], h.weights, h.biases)
    loc = x[..., :A]
    scale = np.maximum(numerics.softplus32(x[..., A:] + np.float32(h.scale_bias)) + np.float32(h.scale_min),
                       np.float32(h.scale_lb))
    counts = [len(range(e, k, E)) for e in range(E)]
    eps = np.zeros((E, S, max(counts), A), dtype=np.float32)
    for e, n in enumerate(counts):
        if n > 1:
            eps[e, :, 1:n] = rng.standard_normal((S, n - 1, A))
    y = np.clip(numerics.tanh32(loc[:, :, None] + scale[:, :, None] * eps), np.float32(-h.tanh_lim), np.float32(h.tanh_lim))
    acts = h.mid[:, None, None] + h.half[:, None, None] * y
    out = acts.transpose(1, 2, 0, 3).reshape(S, -1, A)[:, :k].astype(np.float64)
    out[..., 1] = np.clip(out[..., 1], 0.0, 1.0)
    out[..., 2:] = np.clip(out[..., 2:], -1.0, 1.0)
    if prop.constrain_aim:
        out[..., 0] = domain.constrained_theta(positions[:, None], np.clip(out[..., 0], -1.0, 1.0), prop.R)
    return out


@pytest.mark.parametrize("S, k", [(1, 16), (4, 7), (2, 1), (3, 50)])
@pytest.mark.parametrize("layout", [dict(constrain_aim=True, extra_features=True), dict(constrain_aim=False, extra_features=False)])
def test_batched_proposer_is_its_numpy_formula_to_the_bit(S, k, layout):
    """The batched proposer's one compiled call (observation, stacked layers, heads, squashed
    draws, clips, aim) gives the bits of the NumPy formulas, and draws what they draw."""
    policies = base_policies()
    if not layout["extra_features"]:  # 28 inputs: the first layer cut to the rest observation
        for p in policies:
            first = p[0].module[0].module[0][0]
            first.weight.data, first.in_features = first.weight.data[:, :28].clone(), 28
    prop = PolicyProposer(policies, name="base", **layout)
    assert prop.impl == "batched"
    racks = random_racks(np.random.default_rng(k), S)
    rng_c, rng_n = np.random.default_rng(k + 1), np.random.default_rng(k + 1)
    got, want = prop.propose(racks, k, rng_c), numpy_candidates(prop, racks, k, rng_n)
    assert got.dtype == want.dtype == np.float64 and got.shape == want.shape == (S, k, 4)
    assert np.array_equal(got.view(np.uint64), want.view(np.uint64))
    assert rng_c.bit_generator.state == rng_n.bit_generator.state
