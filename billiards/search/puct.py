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

The trees live in arrays (:mod:`billiards.search.puct_tree`): walking down, widening and
backing up are compiled, so a round costs one ``simulate_batch`` call plus a few compiled
calls, and the proposer is called once per node whose prior samples are used up (``pool`` at
a time), in the same order as :func:`billiards.search.puct_reference.puct_reference`, the
pure-Python tree (``impl="reference"``): from the same generator state both make the same
decisions.
"""

from __future__ import annotations

import numba
import numpy as np

from billiards import domain
from billiards.physics import DEFAULT_PARAMS, PhysicsParams, core, simulate_batch
from billiards.physics.api import PARALLEL_MIN_BATCH, POSITION_TOL

from . import puct_tree as tree
from .lookahead import SearchResult, verifier_reward
from .settings import PUCTConfig  # the options of puct_search

IMPLS = ("compiled", "reference")


def puct_search(positions: np.ndarray, proposer, cfg: PUCTConfig, rng: np.random.Generator,
                params: PhysicsParams = DEFAULT_PARAMS, impl: str = "compiled") -> SearchResult:
    """Choose one action for each of S table states (positions (S, 4, 2)) by PUCT.

    ``impl="compiled"`` walks the array trees of :mod:`billiards.search.puct_tree`;
    ``"reference"`` runs the pure-Python tree (same decisions, several times slower). ValueError
    if ``cfg`` has a knob out of range (:meth:`PUCTConfig.check`).
    """
    cfg.check()
    if impl not in IMPLS:
        raise ValueError(f"puct_search impl must be one of {', '.join(IMPLS)}; got {impl!r}")
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 3 or positions.shape[1:] != (4, 2):
        raise ValueError(f"puct_search needs positions of shape (S, 4, 2); got {positions.shape}")
    if impl == "reference":
        from .puct_reference import puct_reference

        return puct_reference(positions, proposer, cfg, rng, params)
    S, P = positions.shape[0], cfg.pool
    t = tree.new_trees(positions, cfg.budget, P, cfg.max_depth)
    ints, floats, pool = t["ints"], t["floats"], t["pool"]
    pool[:, 0] = proposer.propose(positions, P, rng)
    ints[:, 0, tree.DRAWN] = P
    start, actions, rounds = np.empty((S, 4, 2)), np.empty((S, 4)), np.zeros(1, dtype=np.int64)
    after, score, reward = np.empty((S, 4, 2)), np.empty(S, dtype=bool), np.empty(S)
    out_int, out_float = np.empty((S, core.N_OUT_INT), dtype=np.int64), np.empty((S, core.N_OUT_FLOAT))
    io = np.zeros(2, dtype=np.int64)  # (shots gathered, not yet simulated; shots simulated this round)
    # rounds run compiled, simulating their own shots (tree.run_rounds), except batches large
    # enough for simulate_batch's threads; the outcomes are the same bits either way
    max_serial = _max_serial(S)
    c = domain.check_coefficient("foul penalty c", cfg.foul_penalty)
    widen = tree.widening(cfg.budget, cfg.pw_c, cfg.pw_alpha)
    while True:
        m = tree.run_rounds(ints, floats, t["positions"], t["actions"], pool, t["n_nodes"], t["sims"], t["path"],
                            t["path_len"], t["kind"], start, actions, after, score, reward, out_int, out_float, io,
                            rounds, cfg.budget, cfg.max_depth, cfg.c_puct, widen, cfg.gamma,
                            params.array, POSITION_TOL, c, max_serial)
        if m == tree.DONE:
            break
        if m == tree.STALLED:
            raise RuntimeError("PUCT made no progress: every path ends at max_depth")
        if m == tree.DRAW_POOLS:
            _draw_pools(t, proposer, rng, P)
            io[:] = tree.gather(ints, t["positions"], pool, t["path"], t["path_len"], t["kind"], start, actions), 0
            continue
        if m == tree.BAD_SHOTS:
            m = int(io[0])
        res = simulate_batch(start[:m], actions[:m], params)  # raises the message for BAD_SHOTS
        after[:m], score[:m], reward[:m] = res.positions, res.score, verifier_reward(res, cfg.foul_penalty)
        io[:] = 0, m

    best, value = np.empty(S, dtype=np.int64), np.empty(S)
    tree.root_choice(ints, floats, t["n_nodes"], cfg.gamma, best, value)
    rows = np.arange(S)
    return SearchResult(t["actions"][rows, best], value, floats[rows, best, tree.REWARD].copy(),
                        t["positions"][rows, best], int(t["sims"].sum()))


def _max_serial(S: int) -> int:
    """Rounds of at least this many shots go to :func:`simulate_batch` (its threads); smaller
    ones are simulated inside the compiled rounds (0: every round through simulate_batch)."""
    return PARALLEL_MIN_BATCH if numba.get_num_threads() > 1 else S + 1


def _draw_pools(t: dict, proposer, rng: np.random.Generator, P: int) -> None:
    """Fresh prior samples for every leaf that has used its own up, one proposer call per leaf
    in tree order (the reference's calls and draws), then mark those leaves ready to expand."""
    ints, path, path_len, kind = t["ints"], t["path"], t["path_len"], t["kind"]
    for s in np.flatnonzero(kind == tree.NEEDS_POOL):
        leaf = path[s, path_len[s] - 1]
        t["pool"][s, leaf] = proposer.propose(t["positions"][s, leaf][None], P, rng)[0]
        ints[s, leaf, tree.DRAWN] += P
        kind[s] = tree.EXPAND


__all__ = ["PUCTConfig", "puct_search"]
