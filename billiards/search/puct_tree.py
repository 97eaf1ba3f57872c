"""The PUCT trees as arrays, and the compiled steps that walk them (numba, ``cache=True``).

S trees, each with room for C nodes (a decision at budget B creates at most B + 1). Node n of
tree s is a table at rest; its integer fields are ``ints[s, n, FIELD]`` and its floats
``value_sum, reward, q = floats[s, n]`` (``reward``: verifier reward of the shot into the node;
``q = value_sum / visits``, 0 before the first visit, kept up to date by the back-up so the
selection reads it instead of dividing again). Node ids follow creation order, so a node's
children, in sampling order, are the nodes of depth + 1 created under it; its *live*
(non-terminal) children also form a singly linked list in that order, ``FIRST``, ``LAST``,
``NEXT``, the only children the selection looks at (terminal ones are counted in ``N_CHILD``).

A round of the search is: every unfinished tree walks down to the node it acts on
(:func:`descend`), the caller draws prior samples for leaves that have used theirs up,
:func:`gather` collects the new shots, one ``simulate_batch`` call simulates them, and
:func:`attach_and_back_up` adds them as children and backs the returns up. :func:`advance`
chains the compiled parts between two simulation calls. The arithmetic is written in the
reference's order (``puct_reference.py``), so both compute bit-identical scores.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit

from billiards.physics.core import ERR_OK, O_HIT1, O_HIT2, O_HIT3, check_actions, check_positions, run_batch_serial

# integer fields of a node
DEPTH, TERMINAL, VISITS, N_CHILD, FIRST, LAST, NEXT, DRAWN, FAV, NLB = range(10)
N_INT = 10
VALUE_SUM, REWARD, Q, AUB = range(4)
N_FLOAT = 4
_NO_VISITS = 1 << 62  # NLB of a node whose only live child is its favourite

MAX_ROUNDS = 20  # rounds per simulation of the budget before a search counts as stalled

# what a tree does this round
IDLE, EXPAND, MAX_DEPTH, NEEDS_POOL = 0, 1, 2, 3
# what advance() asks of its caller
DONE, DRAW_POOLS, STALLED = -1, -2, -3


def new_trees(positions: np.ndarray, budget: int, pool: int, max_depth: int):
    """Empty trees holding only their roots (positions (S, 4, 2)); arrays as described above,
    plus ``pool`` (S, C, pool, 4): each node's current batch of prior samples, of which
    children take ``DRAWN - pool .. DRAWN - 1`` in order, and the per-round path buffers."""
    S, C = positions.shape[0], budget + 1
    ints = np.empty((S, C, N_INT), dtype=np.int64)
    ints[:, 0] = (0, 0, 0, 0, -1, -1, -1, 0, -1, _NO_VISITS)
    floats = np.empty((S, C, N_FLOAT))
    floats[:, 0] = (0.0, 0.0, 0.0, -math.inf)
    node_pos = np.empty((S, C, 4, 2))
    node_pos[:, 0] = positions
    return {
        "ints": ints, "floats": floats, "positions": node_pos,
        "actions": np.empty((S, C, 4)), "pool": np.empty((S, C, pool, 4)),
        "n_nodes": np.ones(S, dtype=np.int64), "sims": np.zeros(S, dtype=np.int64),
        "path": np.empty((S, max_depth + 2), dtype=np.int64), "path_len": np.zeros(S, dtype=np.int64),
        "kind": np.zeros(S, dtype=np.int64),
    }


def widening(budget: int, pw_c: float, pw_alpha: float) -> np.ndarray:
    """Progressive widening as a table: ``widen[N] = ceil(pw_c * (N + 1) ** pw_alpha)``, the
    children a node visited N times may have, for every N a search at this budget reaches
    (a node's visits never exceed the rounds, at most ``MAX_ROUNDS * budget``). Read-only;
    one table per setting, computed once."""
    return _widening(budget, float(pw_c), float(pw_alpha))


@functools.lru_cache(maxsize=32)
def _widening(budget: int, pw_c: float, pw_alpha: float) -> np.ndarray:
    widen = _widening_table(MAX_ROUNDS * budget + 1, pw_c, pw_alpha)
    widen.setflags(write=False)
    return widen


@njit(cache=True)
def _widening_table(n, pw_c, pw_alpha):
    widen = np.empty(n, dtype=np.int64)
    for visits in range(n):
        widen[visits] = math.ceil(pw_c * (visits + 1) ** pw_alpha)
    return widen


@njit(cache=True, inline="always")
def _select(ints, floats, s, node, c_puct, gamma):
    """argmax over the live children of r + gamma * Q + c_puct * P * sqrt(N) / (1 + N_child);
    first wins ties; -1 if every child is terminal.

    Each score is ``a + bonus / (1 + n)`` with ``a = r + gamma * Q`` (the same operations in the
    same order as the formula). Only the node's favourite ``FAV`` (the child chosen last time)
    and newly added children change between two selections at a node -- a back-up only
    reaches children on the walked path, which its parent chose -- so the node keeps, over its
    other live children, the largest ``a`` (``AUB``) and the fewest visits (``NLB``). Rounding
    is monotone, so no other child scores above ``AUB + bonus / (1 + NLB)``: a favourite that
    scores strictly more is the argmax, and only otherwise are the children scanned (which
    also finds the new favourite and its bounds).
    """
    visits = ints[s, node, VISITS]
    sqrt_n = math.sqrt(visits)
    prior = 1.0 / ints[s, node, N_CHILD]
    bonus = c_puct * prior * sqrt_n  # the same operations, in the same order, as c_puct * prior * sqrt_n / (1 + n)
    f = ints[s, node, FAV]
    if f >= 0:
        score = floats[s, f, REWARD] + gamma * floats[s, f, Q] + bonus / (1 + ints[s, f, VISITS])
        if score > floats[s, node, AUB] + bonus / (1 + ints[s, node, NLB]):
            return f
    best, best_score = -1, -math.inf
    a1, a1_child, a2 = -math.inf, -1, -math.inf  # the two largest a (NaN never counts)
    n1, n1_child, n2 = _NO_VISITS, -1, _NO_VISITS  # the two fewest visits
    c = ints[s, node, FIRST]
    while c >= 0:  # live children only
        n = ints[s, c, VISITS]
        a = floats[s, c, REWARD] + gamma * floats[s, c, Q]
        score = a + bonus / (1 + n)
        if score > best_score:
            best, best_score = c, score
        if a > a1:
            a1, a1_child, a2 = a, c, a1
        elif a > a2:
            a2 = a
        if n < n1:
            n1, n1_child, n2 = n, c, n1
        elif n < n2:
            n2 = n
        c = ints[s, c, NEXT]
    ints[s, node, FAV] = best
    floats[s, node, AUB] = a2 if a1_child == best else a1
    ints[s, node, NLB] = n2 if n1_child == best else n1
    return best


@njit(cache=True, inline="always")
def descend(ints, floats, sims, path, path_len, kind, budget, max_depth, c_puct, widen, gamma):
    """Walk every tree with sims < budget from its root to the node this round acts on.

    The walk stops at a node of depth ``max_depth`` (``MAX_DEPTH``: nothing to simulate) or
    at a node that may widen -- fewer children than ``widen[N]`` (:func:`widening`), or no
    live (scoring) child -- (``EXPAND``, or ``NEEDS_POOL`` if its prior samples are used up);
    otherwise it follows :func:`_select`. Returns how many trees need prior samples.
    """
    needs = 0
    for s in range(ints.shape[0]):
        kind[s] = IDLE
        path_len[s] = 0
        if sims[s] >= budget:
            continue
        node, n = 0, 1
        path[s, 0] = 0
        while True:
            if ints[s, node, DEPTH] >= max_depth:
                kind[s] = MAX_DEPTH
                break
            n_child = ints[s, node, N_CHILD]
            child = -1
            if n_child >= widen[ints[s, node, VISITS]]:
                child = _select(ints, floats, s, node, c_puct, gamma)
            if child < 0:  # may widen, or every child is terminal
                if n_child == ints[s, node, DRAWN]:
                    kind[s] = NEEDS_POOL
                    needs += 1
                else:
                    kind[s] = EXPAND
                break
            node = child
            path[s, n] = node
            n += 1
        path_len[s] = n
    return needs


@njit(cache=True, inline="always")
def gather(ints, node_pos, pool, path, path_len, kind, start, actions):
    """The shots of this round's ``EXPAND`` leaves, in tree order: each leaf's table into
    ``start`` and its next unused prior sample into ``actions``. Returns their number."""
    P = pool.shape[2]
    m = 0
    for s in range(ints.shape[0]):
        if kind[s] != EXPAND:
            continue
        leaf = path[s, path_len[s] - 1]
        k = ints[s, leaf, N_CHILD] - (ints[s, leaf, DRAWN] - P)
        for b in range(4):
            start[m, b, 0], start[m, b, 1] = node_pos[s, leaf, b, 0], node_pos[s, leaf, b, 1]
            actions[m, b] = pool[s, leaf, k, b]
        m += 1
    return m


@njit(cache=True, inline="always")
def attach_and_back_up(ints, floats, node_pos, node_actions, n_nodes, sims, path, path_len, kind,
                       actions, after, score, reward, gamma):
    """Add each simulated shot (rows in :func:`gather`'s order) as the newest child of its leaf,
    then back the discounted return up every walked path (terminal value 0 below a leaf)."""
    m = 0
    for s in range(ints.shape[0]):
        if kind[s] == EXPAND:
            leaf = path[s, path_len[s] - 1]
            c = n_nodes[s]
            n_nodes[s] += 1
            ints[s, c, DEPTH] = ints[s, leaf, DEPTH] + 1
            ints[s, c, TERMINAL] = not score[m]
            ints[s, c, VISITS] = 0
            ints[s, c, N_CHILD] = 0
            ints[s, c, FIRST] = -1
            ints[s, c, LAST] = -1
            ints[s, c, NEXT] = -1
            ints[s, c, DRAWN] = 0
            ints[s, c, FAV] = -1
            ints[s, c, NLB] = _NO_VISITS
            floats[s, c, VALUE_SUM] = 0.0
            floats[s, c, REWARD] = reward[m]
            floats[s, c, Q] = 0.0
            floats[s, c, AUB] = -math.inf
            for b in range(4):
                node_pos[s, c, b, 0], node_pos[s, c, b, 1] = after[m, b, 0], after[m, b, 1]
                node_actions[s, c, b] = actions[m, b]
            if score[m]:  # a live child: linked after the leaf's last one
                if ints[s, leaf, LAST] >= 0:
                    ints[s, ints[s, leaf, LAST], NEXT] = c
                else:
                    ints[s, leaf, FIRST] = c
                ints[s, leaf, LAST] = c
            ints[s, leaf, N_CHILD] += 1
            path[s, path_len[s]] = c
            path_len[s] += 1
            sims[s] += 1
            m += 1
        ret = 0.0
        for d in range(path_len[s] - 1, -1, -1):
            node = path[s, d]
            ints[s, node, VISITS] += 1
            floats[s, node, VALUE_SUM] += ret
            floats[s, node, Q] = floats[s, node, VALUE_SUM] / ints[s, node, VISITS]
            ret = floats[s, node, REWARD] + gamma * ret
        if kind[s] == EXPAND and not ints[s, path[s, path_len[s] - 1], TERMINAL]:
            # a new live child (now visited once) joins its parent's bounds (see _select)
            c, leaf = path[s, path_len[s] - 1], path[s, path_len[s] - 2]
            a = floats[s, c, REWARD] + gamma * floats[s, c, Q]
            if a > floats[s, leaf, AUB]:
                floats[s, leaf, AUB] = a
            ints[s, leaf, NLB] = min(ints[s, leaf, NLB], ints[s, c, VISITS])


@njit(cache=True)
def root_choice(ints, floats, n_nodes, gamma, best_child, best_value):
    """Each root's most visited child (ties: higher r + gamma * Q, then sampling order) into
    ``best_child[s]``, and its value r + gamma * Q into ``best_value[s]``. The root's children,
    terminal ones included, are the nodes of depth 1, in creation order."""
    for s in range(ints.shape[0]):
        best, best_n, best_v = -1, -1, -math.inf
        for c in range(1, n_nodes[s]):
            if ints[s, c, DEPTH] != 1:
                continue
            n = ints[s, c, VISITS]
            v = floats[s, c, REWARD] + gamma * (floats[s, c, VALUE_SUM] / n if n else 0.0)
            if n > best_n or (n == best_n and v > best_v):
                best, best_n, best_v = c, n, v
        best_child[s] = best
        best_value[s] = best_v


@njit(cache=True, inline="always")
def _all_done(sims, budget):
    for s in range(sims.shape[0]):
        if sims[s] < budget:
            return False
    return True


@njit(cache=True, inline="always")
def advance(ints, floats, node_pos, node_actions, pool, n_nodes, sims, path, path_len, kind, start, actions,
            after, score, reward, rounds, budget, max_depth, c_puct, widen, gamma):
    """Finish the current round with its simulated shots (``after, score, reward``; none in the
    first call, whose ``kind`` is all ``IDLE``), then run rounds until one has shots to simulate.

    Rounds in which every walk ends at ``max_depth`` simulate nothing and are finished here.
    Returns the number of shots gathered into ``start, actions`` (> 0), ``DRAW_POOLS`` (the
    caller draws prior samples, then calls :func:`gather`), ``DONE`` when every tree has
    simulated ``budget`` shots, or ``STALLED`` after ``MAX_ROUNDS * budget`` rounds (``rounds[0]``
    counts them).
    """
    attach_and_back_up(ints, floats, node_pos, node_actions, n_nodes, sims, path, path_len, kind,
                       actions, after, score, reward, gamma)
    while True:
        if _all_done(sims, budget):
            return DONE
        rounds[0] += 1
        if rounds[0] > MAX_ROUNDS * budget:
            return STALLED
        if descend(ints, floats, sims, path, path_len, kind, budget, max_depth, c_puct, widen, gamma):
            return DRAW_POOLS
        m = gather(ints, node_pos, pool, path, path_len, kind, start, actions)
        if m:
            return m
        attach_and_back_up(ints, floats, node_pos, node_actions, n_nodes, sims, path, path_len, kind,
                           actions, after, score, reward, gamma)


# what run_rounds() may also answer: the gathered shots hold an invalid action or table
BAD_SHOTS = -4


@njit(cache=True)
def run_rounds(ints, floats, node_pos, node_actions, pool, n_nodes, sims, path, path_len, kind, start, actions,
               after, score, reward, out_int, out_float, io, rounds, budget, max_depth, c_puct, widen,
               gamma, p, tol, foul_penalty, max_serial):
    """:func:`advance`, simulating the gathered shots itself, so the caller only hears of the
    rounds that need it: ``DONE``, ``STALLED``, ``DRAW_POOLS`` (it draws, gathers and sets
    ``io[0]``), ``BAD_SHOTS`` (it builds the error message from ``start, actions[:io[0]]``), or
    a batch of ``m >= max_serial`` shots (``m`` > 0) to simulate on all threads (it fills ``after,
    score, reward[:m]`` and sets ``io = 0, m``).

    ``io = (to simulate, simulated)``: the shots gathered in ``start, actions`` and not yet
    simulated, and how many of ``after, score, reward`` hold the current round's outcomes. A
    shot is simulated as :func:`billiards.physics.simulate_batch` does (the same kernel on the
    calling thread, same validation); its verifier reward is score - foul_penalty * foul with
    the carom rule of :func:`billiards.physics.rules.carom_outcome` (score: both reds and not
    the yellow; foul: the yellow), bit for bit what :func:`~billiards.search.lookahead.verifier_reward` computes.
    """
    while True:
        m = io[0]
        if m > 0:
            if m >= max_serial:
                return m
            if check_actions(actions[:m])[0] != ERR_OK or check_positions(start[:m], p, tol)[0] != ERR_OK:
                return BAD_SHOTS
            run_batch_serial(start[:m], actions[:m], p, after[:m], out_int[:m], out_float[:m])
            for i in range(m):
                foul = out_int[i, O_HIT1] != 0
                score[i] = out_int[i, O_HIT2] != 0 and out_int[i, O_HIT3] != 0 and not foul
                reward[i] = (1.0 if score[i] else 0.0) + -foul_penalty * (1.0 if foul else 0.0)
            io[0], io[1] = 0, m
        k = io[1]
        m = advance(ints, floats, node_pos, node_actions, pool, n_nodes, sims, path, path_len, kind, start, actions,
                    after[:k], score[:k], reward[:k], rounds, budget, max_depth, c_puct, widen, gamma)
        io[1] = 0
        if m <= 0:
            return m
        io[0] = m
