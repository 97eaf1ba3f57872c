"""PUCT over sampled continuous actions, at a fixed simulation budget (the paper's baseline).

One tree per table state, all trees advanced in lockstep so each round's new shots go through
one ``simulate_batch`` call. A node is a table at rest; its children are actions sampled from
the proposer (the prior), revealed by progressive widening: a node visited N times may have
``ceil(pw_c * (N + 1) ** pw_alpha)`` children. Each simulation descends by the PUCT rule

    argmax_child  Q(child) + c_puct * P(child) * sqrt(N(node)) / (1 + N(child)),

with the uniform prior P = 1 / (number of children) over the prior's samples, until it reaches
a node that may widen; it simulates one new child (one shot), scores it with the verifier
reward, and backs the discounted return up the path. A shot that does not score ends the
chain, so its node is terminal (value 0 below it); the exact value of a terminal child is
known, so descents never re-enter one: a node whose children are all terminal widens. The executed action is the root's most
visited child (ties: higher Q, then sampling order). Exactly ``budget`` shots are simulated
per state and decision.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from billiards.physics import DEFAULT_PARAMS, PhysicsParams, simulate_batch

from .lookahead import VERIFIER_FOUL_PENALTY, SearchResult, verifier_reward


@dataclass(frozen=True)
class PUCTConfig:
    budget: int = 400
    c_puct: float = 1.0
    pw_c: float = 1.0
    pw_alpha: float = 0.5
    pool: int = 16  # prior samples drawn when a node is created (more on demand)
    max_depth: int = 8
    gamma: float = 0.99
    foul_penalty: float = VERIFIER_FOUL_PENALTY

    def __post_init__(self):
        if self.budget < 1 or self.pool < 1 or self.max_depth < 1:
            raise ValueError(f"PUCT needs budget, pool and max_depth >= 1; got {self.budget}, {self.pool}, {self.max_depth}")
        if self.c_puct < 0 or self.pw_c <= 0 or not 0 < self.pw_alpha <= 1:
            raise ValueError("PUCT needs c_puct >= 0, pw_c > 0 and 0 < pw_alpha <= 1")

    @property
    def sims_per_decision(self) -> int:
        return self.budget


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


def puct_search(positions: np.ndarray, proposer, cfg: PUCTConfig, rng: np.random.Generator,
                params: PhysicsParams = DEFAULT_PARAMS) -> SearchResult:
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


__all__ = ["PUCTConfig", "puct_search"]
