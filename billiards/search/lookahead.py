"""Greedy depth-2 K-expansion lookahead (the paper's §5), batched over table states.

At each of S states:

1. the proposer emits K1 candidates a1; all S*K1 shots go through ONE ``simulate_batch`` call
   and get the verifier reward r1 (:func:`verifier_reward`);
2. the top M1 candidates by r1 (ties: proposer order) are expanded: the proposer emits K2
   children a2 from each resulting table, and all S*M1*K2 shots go through one more call;
3. the executed action is ``argmax_{a1} r1 + gamma * max_{a2} r2`` over the expanded a1; exact
   ties go to the candidate whose children score most often (mean child score), then to
   proposer order. Without expansion (M1 = 0 or K2 = 0) it is ``argmax r1``.

Simulations per decision: exactly K1 + M1*K2 per state (``SearchResult.n_sims`` counts them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from billiards import domain
from billiards.physics import DEFAULT_PARAMS, BatchResult, PhysicsParams, simulate_batch

from .settings import VERIFIER_FOUL_PENALTY, H2Config  # H2Config: the options of h2_search


def verifier_reward(result: BatchResult, foul_penalty: float = VERIFIER_FOUL_PENALTY) -> np.ndarray:
    """The verifier's reward of simulated shots: carom score plus the foul penalty term."""
    return domain.shot_reward(result.score, result.foul, foul_penalty)


@dataclass(frozen=True)
class SearchResult:
    actions: np.ndarray  # (S, 4) chosen raw actions
    value: np.ndarray  # (S,) value of the chosen action (r1 + gamma max r2, or r1)
    r1: np.ndarray  # (S,) immediate verifier reward predicted for the chosen action
    positions: np.ndarray  # (S, 4, 2) predicted table after the chosen action
    n_sims: int  # shots simulated for this decision (all states)
    # the robust search's: candidate 0 (the proposer's own shot) and the margin by which the
    # chosen action's statistic beats its (S,) (inf where candidate 0 was not sampled); None elsewhere
    own: np.ndarray | None = None
    own_margin: np.ndarray | None = None


@dataclass(frozen=True)
class H2Values:
    """What the depth-2 lookahead knows of each state's candidates (:func:`h2_values`)."""

    candidates: np.ndarray  # (S, K1, 4) the proposer's raw actions, candidate 0 its own shot
    r1: np.ndarray  # (S, K1) verifier reward of each candidate
    after: np.ndarray  # (S, K1, 4, 2) the table after each candidate
    top: np.ndarray  # (S, M1) the expanded candidates (best r1 first, ties in proposer order); empty without expansion
    value: np.ndarray  # (S, M1) r1 + gamma * max r2 of each expanded candidate
    robustness: np.ndarray  # (S, M1) mean child score of each expanded candidate
    n_sims: int


def h2_values(positions: np.ndarray, proposer, cfg: H2Config, rng: np.random.Generator,
              params: PhysicsParams = DEFAULT_PARAMS) -> H2Values:
    """Steps 1 and 2 of the lookahead for S table states (positions (S, 4, 2)): every candidate's
    r1 and table after, and the values of the expanded ones (ValueError if ``cfg`` has a knob
    out of range, :meth:`H2Config.check`). :func:`h2_search` picks from them."""
    cfg.check()
    positions = np.asarray(positions, dtype=np.float64)
    S, K1 = positions.shape[0], cfg.k1
    rows = np.arange(S)[:, None]
    a1 = proposer.propose(positions, K1, rng)
    res1 = simulate_batch(np.repeat(positions, K1, axis=0), a1.reshape(-1, 4), params)
    r1 = verifier_reward(res1, cfg.foul_penalty).reshape(S, K1)
    next1 = res1.positions.reshape(S, K1, 4, 2)
    n_sims = S * K1
    if cfg.m1 == 0 or cfg.k2 == 0:
        empty = np.zeros((S, 0))
        return H2Values(a1, r1, next1, empty.astype(np.int64), empty, empty, n_sims)
    top = np.argsort(-r1, axis=1, kind="stable")[:, : cfg.m1]  # (S, M1)
    mid = next1[rows, top].reshape(-1, 4, 2)  # (S*M1, 4, 2)
    a2 = proposer.propose(mid, cfg.k2, rng)
    res2 = simulate_batch(np.repeat(mid, cfg.k2, axis=0), a2.reshape(-1, 4), params)
    n_sims += S * cfg.m1 * cfg.k2
    r2 = verifier_reward(res2, cfg.foul_penalty).reshape(S, cfg.m1, cfg.k2)
    value = r1[rows, top] + cfg.gamma * r2.max(axis=-1)  # (S, M1)
    robustness = res2.score.reshape(S, cfg.m1, cfg.k2).mean(axis=-1)
    return H2Values(a1, r1, next1, top, value, robustness, n_sims)


def h2_search(positions: np.ndarray, proposer, cfg: H2Config, rng: np.random.Generator,
              params: PhysicsParams = DEFAULT_PARAMS) -> SearchResult:
    """Choose one action for each of S table states (positions (S, 4, 2)) by depth-2 lookahead
    (ValueError if ``cfg`` has a knob out of range, :meth:`H2Config.check`)."""
    v = h2_values(positions, proposer, cfg, rng, params)
    S = v.r1.shape[0]
    rows = np.arange(S)[:, None]
    a1, r1, next1, top = v.candidates, v.r1, v.after, v.top
    if top.shape[1] == 0:
        best = np.argmax(r1, axis=1)
        return SearchResult(a1[rows[:, 0], best], r1[rows[:, 0], best], r1[rows[:, 0], best], next1[rows[:, 0], best], v.n_sims)
    # lexicographic: highest value, then most robust, then proposer order (stable)
    pick = np.lexsort((top, -v.robustness, -v.value), axis=-1)[:, 0] if S else np.zeros(0, dtype=np.int64)
    best = top[rows[:, 0], pick]
    return SearchResult(a1[rows[:, 0], best], v.value[rows[:, 0], pick], r1[rows[:, 0], best],
                        next1[rows[:, 0], best], v.n_sims)


__all__ = ["H2Config", "H2Values", "SearchResult", "VERIFIER_FOUL_PENALTY", "h2_search", "h2_values", "verifier_reward"]
