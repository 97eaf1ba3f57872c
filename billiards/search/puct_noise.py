"""PUCT under execution noise: revisiting a child draws a new noisy outcome.

The paper argues that in a deterministic game PUCT's revisits add nothing: a shot simulated
once is known. Under execution noise (:mod:`billiards.physics.noise`) a shot's outcome is a
random variable, and a revisit is a new sample of it. This is PUCT at the root, open loop: the
root's children are actions sampled from the proposer (the prior), revealed by progressive
widening (a root visited N times may have ``ceil(pw_c * (N + 1) ** pw_alpha)`` children, a
new one taken from the prior's samples, ``pool`` drawn at a time); otherwise a child is chosen
by

    argmax_child  Q(child) + c_puct * P(child) * sqrt(N) / (1 + N(child)),

with the uniform prior P = 1 / (number of children) and Q the mean verifier reward of the
child's noisy outcomes so far. Either way the chosen action is played with a fresh draw from
the noise model and simulated: one simulation per visit, exactly ``budget`` per state and
decision. The executed action is the most visited child (ties: higher Q, then sampling order).

Depth: the tree is one level deep (``PUCTConfig.max_depth`` is not used). Below a noisy shot
the next table is itself random, so deeper nodes would need a table per outcome (double
progressive widening) or an open-loop replay of every path; neither is implemented.
"""

from __future__ import annotations

import math

import numpy as np

from billiards.physics import DEFAULT_PARAMS, PhysicsParams, simulate_batch
from billiards.physics.noise import NoiseModel

from .lookahead import SearchResult, verifier_reward
from .puct import PUCTConfig


def noisy_puct_search(positions: np.ndarray, proposer, cfg: PUCTConfig, rng: np.random.Generator,
                      params: PhysicsParams = DEFAULT_PARAMS, noise: NoiseModel | None = None,
                      levels: np.ndarray | None = None) -> SearchResult:
    """Choose one action for each of S table states (positions (S, 4, 2)) by root-level PUCT
    whose visits are noisy replays (see the module docstring); ``levels`` (S,), optional: each
    state's multiplier of ``noise``'s sigmas (variable noise: the level told with the shot)."""
    noise = noise if noise is not None else NoiseModel()
    positions = np.asarray(positions, dtype=np.float64)
    S, B, P = positions.shape[0], cfg.budget, cfg.pool
    pool = list(proposer.propose(positions, P, rng))  # per state: (drawn, 4) prior samples
    n_child = np.zeros(S, dtype=np.int64)
    visits = np.zeros((S, B), dtype=np.int64)  # per child (at most B children)
    value_sum = np.zeros((S, B))
    leave = np.empty((S, B, 4, 2))  # each child's latest outcome table
    for _ in range(B):
        choice = np.empty(S, dtype=np.int64)
        for s in range(S):
            n = n_child[s]
            total = int(visits[s, :n].sum())
            if n < math.ceil(cfg.pw_c * (total + 1) ** cfg.pw_alpha):
                if n == len(pool[s]):  # prior samples used up: draw more
                    pool[s] = np.concatenate([pool[s], proposer.propose(positions[s][None], P, rng)[0]])
                choice[s] = n
                n_child[s] += 1
                continue
            q = value_sum[s, :n] / visits[s, :n]
            score = q + cfg.c_puct * (1.0 / n) * math.sqrt(total) / (1 + visits[s, :n])
            choice[s] = int(np.argmax(score))
        acts = np.stack([pool[s][choice[s]] for s in range(S)])
        res = simulate_batch(positions, noise.perturb(acts, rng, params, levels=levels), params)
        reward = verifier_reward(res, cfg.foul_penalty)
        rows = np.arange(S)
        visits[rows, choice] += 1
        value_sum[rows, choice] += reward
        leave[rows, choice] = res.positions

    actions, value, after = np.empty((S, 4)), np.empty(S), np.empty((S, 4, 2))
    for s in range(S):
        n = n_child[s]
        q = value_sum[s, :n] / visits[s, :n]
        k = int(np.lexsort((np.arange(n), -q, -visits[s, :n]))[0])
        actions[s], value[s], after[s] = pool[s][k], q[k], leave[s, k]
    return SearchResult(actions, value, value.copy(), after, S * B)


__all__ = ["noisy_puct_search"]
