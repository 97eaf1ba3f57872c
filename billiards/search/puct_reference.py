"""The pure-Python PUCT tree, kept as the reference for :mod:`billiards.search.puct`.

The same algorithm as :func:`billiards.search.puct.puct_search` (read its module docstring),
one Python object per node and a Python loop per simulation. The compiled tree must make the
same decisions from the same generator state (``tests/search/test_search.py``), and
``benchmarks/bench_search.py`` times both; select it with ``puct_search(..., impl="reference")``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from billiards.physics import DEFAULT_PARAMS, PhysicsParams, simulate_batch

from .lookahead import SearchResult, verifier_reward


@dataclass
class _Node:
    positions: np.ndarray
    depth: int
    terminal: bool = False
    pool: np.ndarray | None = None  # (pool, 4) prior samples
    children: list = field(default_factory=list)  # child indices into the tree's node list
    actions: list = field(default_factory=list)
    rewards: list = field(default_factory=list)
    visits: int = 0
    value_sum: float = 0.0


def _q(node: _Node) -> float:
    return node.value_sum / node.visits if node.visits else 0.0


def puct_reference(positions: np.ndarray, proposer, cfg, rng: np.random.Generator,
                   params: PhysicsParams = DEFAULT_PARAMS) -> SearchResult:
    """:func:`billiards.search.puct.puct_search`, one Python object per node."""
    positions = np.asarray(positions, dtype=np.float64)
    S = positions.shape[0]
    trees = [[_Node(positions[s], 0)] for s in range(S)]
    pools = proposer.propose(positions, cfg.pool, rng)
    for s in range(S):
        trees[s][0].pool = pools[s]
    sims = np.zeros(S, dtype=np.int64)
    guard = 0
    while (sims < cfg.budget).any():
        guard += 1
        if guard > 20 * cfg.budget:
            raise RuntimeError("PUCT made no progress: every path ends at max_depth")
        pending = []  # (tree, path of node ids, parent id, action)
        for s in range(S):
            if sims[s] >= cfg.budget:
                continue
            tree, path = trees[s], [0]
            while True:
                node = tree[path[-1]]
                if node.depth >= cfg.max_depth:
                    pending.append((s, path, None, None))
                    break
                live = [k for k, c in enumerate(node.children) if not tree[c].terminal]
                allowed = math.ceil(cfg.pw_c * (node.visits + 1) ** cfg.pw_alpha)
                n_child = len(node.children)
                if n_child < allowed or not live:
                    if node.pool is None:  # first expansion of this node: draw its prior samples
                        node.pool = proposer.propose(node.positions[None], cfg.pool, rng)[0]
                    elif n_child == len(node.pool):  # prior samples used up: draw more
                        more = proposer.propose(node.positions[None], cfg.pool, rng)[0]
                        node.pool = np.concatenate([node.pool, more])
                    pending.append((s, path, path[-1], node.pool[n_child]))
                    break
                sqrt_n = math.sqrt(node.visits)
                prior = 1.0 / n_child
                best, best_score = -1, -math.inf
                for k in live:
                    child = tree[node.children[k]]
                    score = node.rewards[k] + cfg.gamma * _q(child) + cfg.c_puct * prior * sqrt_n / (1 + child.visits)
                    if score > best_score:
                        best, best_score = k, score
                path.append(node.children[best])
        expand = [p for p in pending if p[2] is not None]
        if expand:
            start = np.stack([trees[s][parent].positions for s, _, parent, _ in expand])
            acts = np.stack([a for *_, a in expand])
            res = simulate_batch(start, acts, params)
            rewards = verifier_reward(res, cfg.foul_penalty)
            for n, (s, path, parent, a) in enumerate(expand):
                tree = trees[s]
                child = _Node(res.positions[n], tree[parent].depth + 1, terminal=not bool(res.score[n]))
                tree.append(child)
                tree[parent].children.append(len(tree) - 1)
                tree[parent].actions.append(a)
                tree[parent].rewards.append(float(rewards[n]))
                path.append(len(tree) - 1)
                sims[s] += 1
        for s, path, _, _ in pending:  # back up discounted returns along each path
            tree, ret = trees[s], 0.0
            for depth in range(len(path) - 1, -1, -1):
                node = tree[path[depth]]
                node.visits += 1
                node.value_sum += ret
                if depth:
                    parent = tree[path[depth - 1]]
                    ret = parent.rewards[parent.children.index(path[depth])] + cfg.gamma * ret

    actions, value, r1, after = np.empty((S, 4)), np.empty(S), np.empty(S), np.empty((S, 4, 2))
    for s in range(S):
        root, tree = trees[s][0], trees[s]
        keys = [(tree[c].visits, root.rewards[k] + cfg.gamma * _q(tree[c]), -k) for k, c in enumerate(root.children)]
        k = max(range(len(keys)), key=keys.__getitem__)
        actions[s], r1[s] = root.actions[k], root.rewards[k]
        value[s], after[s] = keys[k][1], tree[root.children[k]].positions
    return SearchResult(actions, value, r1, after, int(sims.sum()))


__all__ = ["puct_reference"]
