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
    return result.score.astype(np.float64) + domain.foul_penalty(result.foul, foul_penalty)


@dataclass(frozen=True)
class SearchResult:
    actions: np.ndarray  # (S, 4) chosen raw actions
    value: np.ndarray  # (S,) value of the chosen action (r1 + gamma max r2, or r1)
    r1: np.ndarray  # (S,) immediate verifier reward predicted for the chosen action
    positions: np.ndarray  # (S, 4, 2) predicted table after the chosen action
    n_sims: int  # shots simulated for this decision (all states)


def h2_search(positions: np.ndarray, proposer, cfg: H2Config, rng: np.random.Generator,
              params: PhysicsParams = DEFAULT_PARAMS) -> SearchResult:
    """Choose one action for each of S table states (positions (S, 4, 2)) by depth-2 lookahead
    (ValueError if ``cfg`` has a knob out of range, :meth:`H2Config.check`)."""
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
        best = np.argmax(r1, axis=1)
        return SearchResult(a1[rows[:, 0], best], r1[rows[:, 0], best], r1[rows[:, 0], best], next1[rows[:, 0], best], n_sims)

    top = np.argsort(-r1, axis=1, kind="stable")[:, : cfg.m1]  # (S, M1)
    mid = next1[rows, top].reshape(-1, 4, 2)  # (S*M1, 4, 2)
    a2 = proposer.propose(mid, cfg.k2, rng)
    res2 = simulate_batch(np.repeat(mid, cfg.k2, axis=0), a2.reshape(-1, 4), params)
    n_sims += S * cfg.m1 * cfg.k2
    r2 = verifier_reward(res2, cfg.foul_penalty).reshape(S, cfg.m1, cfg.k2)
    value = r1[rows, top] + cfg.gamma * r2.max(axis=-1)  # (S, M1)
    robustness = res2.score.reshape(S, cfg.m1, cfg.k2).mean(axis=-1)
    # lexicographic: highest value, then most robust, then proposer order (stable)
    pick = np.lexsort((top, -robustness, -value), axis=-1)[:, 0] if S else np.zeros(0, dtype=np.int64)
    best = top[rows[:, 0], pick]
    return SearchResult(a1[rows[:, 0], best], value[rows[:, 0], pick], r1[rows[:, 0], best],
                        next1[rows[:, 0], best], n_sims)


__all__ = ["H2Config", "SearchResult", "VERIFIER_FOUL_PENALTY", "h2_search", "verifier_reward"]
