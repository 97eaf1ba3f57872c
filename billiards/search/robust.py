"""Search that knows the execution noise: candidates scored over noisy replays of their shot.

Under execution noise (:mod:`billiards.physics.noise`) the shot played is the commanded one
plus a Gaussian error, so the exact verifier reward of a candidate says little: the shots
that plain lookahead picks are often knife-edge. Here each candidate's immediate value is a
statistic (mean, or a quantile) of its verifier reward over noisy samples -- the candidate's
shot perturbed by the search's own draws from the noise model and simulated. Every simulation,
exact or noisy, counts in the budget. At each of S states:

1. **screen** (optional, ``screen=True``): the proposer's candidates are simulated once
   exactly and only those that score go on -- ``k1`` of them at once, or (adaptive screen,
   ``target > 0``) in waves of ``wave`` until a state has ``target`` scoring candidates or has
   screened ``k1``, so easy tables leave more of the budget to the noisy samples. If none
   scores, the best by exact reward is played and the rest of the budget is left unspent
   (``SearchResult.n_sims`` says what was spent). Without the screen all ``k1`` go on.
2. **noisy samples**, by ``schedule``:

   * ``uniform``: ``samples`` noisy replays of every candidate (needs ``screen=False``, so the
     budget is exactly ``k1 * samples + m1 * k2``);
   * ``halving``: successive halving over the candidates left with the rest of the budget
     (``budget`` less the screen and ``m1 * k2``): rounds of equal samples per candidate, the better half by
     the statistic so far going on, the last round spending exactly what is left (its
     remainder one extra sample each for the best-ranked candidates).

   The noisy errors are the search's own draws from the noise model; with ``antithetic``
   a candidate's samples come in pairs (z, -z).
3. **expansion** (optional, ``m1 > 0``): the ``m1`` best candidates by the statistic are
   expanded as in :mod:`billiards.search.lookahead` -- ``k2`` children proposed from the table
   the candidate leaves (its exact outcome when screened, else its first noisy one) and
   simulated exactly -- and valued ``stat + gamma * max r2``.

With a table value (:mod:`billiards.search.value`) the replays' leaves are priced too
(:func:`leave_terms`): ``position`` > 0 plays position (a replay that scores is worth ``1 +
position * V(leave)``: the chance that the next shot scores from there), ``leave`` > 0 plays
safe in a two-player match (a replay that misses costs ``leave * V`` of the table the opponent
is left), and with ``safeties`` > 0 the noisy rounds also weigh that many safety shots: screened
candidates that neither score nor foul, those whose exact leave the value rates hardest for the
opponent (``safety_draws`` > 0 adds that many soft shots into a red's contact cone to the screen,
deliberate safeties to choose from beside the proposer's misses; they count in the budget).
The statistic is then over reward plus term; the noisy replays are the same ones.

The played action is the best by value; ties go to the higher statistic, then proposer order.
Simulations per decision: at most ``budget`` (exactly ``budget`` whenever a candidate is left
after the screen).
"""

from __future__ import annotations

import math
from typing import Optional

import numpy as np

from billiards.physics import DEFAULT_PARAMS, PhysicsParams, simulate_batch
from billiards.envs.sagu import SWAP
from billiards.physics.noise import NoiseModel, noise_level

from .lookahead import SearchResult, verifier_reward
from .settings import SCHEDULES, RobustConfig  # RobustConfig: the options of robust_search


def _stat(samples: list, quantile: Optional[float]) -> float:
    return float(np.mean(samples)) if quantile is None else float(np.quantile(samples, quantile))


def _plan(n_alive: int, left: int, rounds_left: int) -> tuple[int, np.ndarray]:
    """How many candidates (the best-ranked ``k``) get how many samples each this round."""
    if rounds_left <= 1:
        k = min(n_alive, left)
        per = np.full(k, left // k)
        per[: left - per.sum()] += 1  # the remainder: one more each for the best-ranked
        return k, per
    per = max(1, (left // rounds_left) // n_alive)
    k = min(n_alive, left // per)
    return k, np.full(k, per)


def _screen(positions, proposer, cfg: RobustConfig, rng, params):
    """The exact screen: candidates (S, k1, 4), their exact rewards (S, k1; -inf where no
    candidate was drawn), the tables they leave and how many each state screened."""
    S, K = positions.shape[0], cfg.k1
    if not cfg.target:
        a1 = proposer.propose(positions, K, rng)
        res = simulate_batch(np.repeat(positions, K, axis=0), a1.reshape(-1, 4), params)
        exact = verifier_reward(res, cfg.foul_penalty).reshape(S, K)
        return a1, exact, res.positions.reshape(S, K, 4, 2), np.full(S, K)
    a1, exact = np.zeros((S, K, 4)), np.full((S, K), -np.inf)
    leave = np.repeat(positions[:, None], K, axis=1).copy()
    screened = np.zeros(S, dtype=np.int64)
    while True:  # waves of candidates for the states that have screened fewer than k1 and found < target
        active = np.flatnonzero((screened < K) & ((exact > 0).sum(axis=1) < cfg.target))
        if not len(active):
            return a1, exact, leave, screened
        n = min(cfg.wave, K - int(screened[active].min()))
        first = screened[active].min() == 0
        # later waves drop the proposer's mode (candidate 0: the same shot every call)
        cand = proposer.propose(positions[active], n if first else n + 1, rng)[:, 0 if first else 1:]
        take = np.minimum(n, K - screened[active])
        rows = np.repeat(active, take)
        cols = np.concatenate([screened[s] + np.arange(t) for s, t in zip(active, take)])
        a1[rows, cols] = np.concatenate([cand[i, :t] for i, t in enumerate(take)])
        res = simulate_batch(positions[rows], a1[rows, cols], params)
        exact[rows, cols] = verifier_reward(res, cfg.foul_penalty)
        leave[rows, cols] = res.positions
        screened[active] += take


SOFT_SHOTS = dict(power_low=0.1, power_high=0.4, far_share=0.5)  # the safety draws: soft, into either red's cone


def _soft_shots(positions, n: int, cfg: RobustConfig, rng, params):
    """``n`` soft shots per state into a red's contact cone (a geometric proposer at 10-40 %
    power, half into the farther red), simulated exactly: candidates (S, n, 4), their exact
    rewards and leaves, as :func:`_screen` returns them."""
    from .proposers import GeometricProposer

    S = positions.shape[0]
    a = GeometricProposer(R=params.ball_radius, **SOFT_SHOTS).propose(positions, n, rng)
    res = simulate_batch(np.repeat(positions, n, axis=0), a.reshape(-1, 4), params)
    return a, verifier_reward(res, cfg.foul_penalty).reshape(S, n), res.positions.reshape(S, n, 4, 2)


def _errors(noise: NoiseModel, counts: np.ndarray, antithetic: bool, rng) -> np.ndarray:
    """Standard normal errors for rows grouped by candidate (``counts`` rows each); with
    ``antithetic`` every second row of a group is the negative of the one before."""
    z = noise.draw((int(counts.sum()),), rng)
    if antithetic:
        within = np.arange(len(z)) - np.repeat(np.cumsum(counts) - counts, counts)
        odd = np.flatnonzero(within % 2 == 1)
        z[odd] = -z[odd - 1]
    return z


def leave_terms(res, cfg: RobustConfig, value, levels: np.ndarray) -> np.ndarray:
    """The position and leave terms of simulated replays ``res`` (rows at noise ``levels``,
    multiples of fastfiz's): ``position * V(leave)`` where a replay scores (the shooter plays
    on), ``-leave * V(the leave with the cue balls swapped)`` where it does not (the opponent
    plays on, two-player); 0 without a ``value``."""
    terms = np.zeros(len(res.score))
    if value is None:
        return terms
    scored = res.score.astype(bool)
    for rows, weight, table in ((np.flatnonzero(scored), cfg.position, res.positions),
                                (np.flatnonzero(~scored), -cfg.leave, res.positions[:, SWAP])):
        if weight and len(rows):
            terms[rows] = weight * value.predict(table[rows], levels[rows])
    return terms


def _with_safeties(alive: list, exact: np.ndarray, leave: np.ndarray, n: int, value, levels: np.ndarray) -> list:
    """``alive`` (per state, the scoring candidates) and, after them, the ``n`` screened
    candidates that neither score nor foul whose exact leave the value rates lowest for the
    opponent: the safety shots the noisy rounds weigh against the attempts."""
    rows, cols = np.nonzero(exact == 0)  # screened (drawn: not -inf), no score, no foul
    if not len(rows):
        return alive
    theirs = value.predict(leave[rows, cols][:, SWAP], levels[rows])
    return [a + cols[rows == s][np.argsort(theirs[rows == s], kind="stable")[:n]].tolist() for s, a in enumerate(alive)]


def robust_search(positions: np.ndarray, proposer, cfg: RobustConfig, rng: np.random.Generator,
                  params: PhysicsParams = DEFAULT_PARAMS, noise: NoiseModel | None = None,
                  levels: np.ndarray | None = None, value=None) -> SearchResult:
    """Choose one action for each of S table states (positions (S, 4, 2)), each candidate scored
    by noisy replays drawn from ``noise`` with ``rng`` (see the module docstring). ``levels``
    (S,), optional: each state's multiplier of ``noise``'s sigmas (variable noise: the level
    drawn for the shot and told to the player); without it every state plays ``noise`` itself.
    ``value`` (a :class:`~billiards.search.table_value.TableValue`) prices the replays' leaves by
    ``cfg.position`` and ``cfg.leave`` (:func:`leave_terms`); the statistic is then over the
    replays' reward plus that term, ``r1`` stays the mean verifier reward. ValueError if ``cfg``
    has a knob out of range (:meth:`RobustConfig.check`)."""
    cfg.check()
    if (cfg.position or cfg.leave) and value is None:
        raise ValueError("robust search with position or leave weights needs a table value (search.value=<file>)")
    noise = noise if noise is not None else NoiseModel()
    positions = np.asarray(positions, dtype=np.float64)
    S, K = positions.shape[0], cfg.k1
    if levels is not None:
        levels = np.asarray(levels, dtype=np.float64).reshape(-1)
        if levels.shape != (S,) or not (np.isfinite(levels).all() and (levels >= 0).all()):
            raise ValueError(f"levels must be {S} finite multipliers >= 0 (one per state), got {levels!r}")
    n_sims = 0
    state_level = (levels if levels is not None else np.ones(S)) * (noise_level(noise) if value is not None else 0.0)
    if cfg.screen:
        a1, exact, leave, screened = _screen(positions, proposer, cfg, rng, params)
        if cfg.safety_draws:  # soft shots beside the proposer's, for the safety shots to choose from
            soft = _soft_shots(positions, cfg.safety_draws, cfg, rng, params)
            a1, exact, leave = (np.concatenate([x, y], axis=1) for x, y in zip((a1, exact, leave), soft))
            screened = screened + cfg.safety_draws
            K = a1.shape[1]
        has_leave = np.ones((S, K), dtype=bool)
        n_sims += int(screened.sum())
        alive = [list(np.flatnonzero(exact[s] > 0)) for s in range(S)]
        if cfg.safeties:
            alive = _with_safeties(alive, exact, leave, cfg.safeties, value, state_level)
    else:
        a1 = proposer.propose(positions, K, rng)
        exact, screened = np.zeros((S, K)), np.zeros(S, dtype=np.int64)
        leave = np.repeat(positions[:, None], K, axis=1).copy()  # the table each candidate leaves
        has_leave = np.zeros((S, K), dtype=bool)
        alive = [list(range(K)) for _ in range(S)]
    samples = [[[] for _ in range(K)] for _ in range(S)]  # the statistic's: reward + leave term
    rewards = [[[] for _ in range(K)] for _ in range(S)]  # the verifier reward alone (r1)
    left = [cfg.budget - cfg.m1 * cfg.k2 - int(screened[s]) if alive[s] else 0 for s in range(S)]
    rounds = [1 if cfg.schedule == "uniform" else max(1, math.ceil(math.log2(max(len(a), 1))) + 1) for a in alive]
    r = 0
    while any(left):
        rows_s, rows_k, counts = [], [], []
        for s in range(S):
            if not left[s]:
                continue
            if cfg.schedule == "uniform":
                k, per = len(alive[s]), np.full(len(alive[s]), cfg.samples)
            else:
                k, per = _plan(len(alive[s]), left[s], rounds[s] - r)
            alive[s] = alive[s][:k]
            rows_s.extend([s] * k)
            rows_k.extend(alive[s])
            counts.extend(per.tolist())
            left[s] -= int(per.sum())
        counts = np.asarray(counts)
        s_idx, k_idx = np.repeat(rows_s, counts), np.repeat(rows_k, counts)
        z = _errors(noise, counts, cfg.antithetic, rng)
        if levels is not None:  # sigma * (level * z): the state's own noise level
            z *= levels[s_idx][:, None]
        played = noise.apply(a1[s_idx, k_idx], z, params)
        res = simulate_batch(positions[s_idx], played, params)
        reward = verifier_reward(res, cfg.foul_penalty)
        total = reward + leave_terms(res, cfg, value, state_level[s_idx])
        n_sims += len(s_idx)
        for i in range(len(s_idx)):
            s, k = s_idx[i], k_idx[i]
            samples[s][k].append(total[i])
            rewards[s][k].append(reward[i])
            if not has_leave[s, k]:
                leave[s, k], has_leave[s, k] = res.positions[i], True
        for s in set(rows_s):  # rank by the statistic (ties: exact reward, proposer order); halve
            keys = [(-_stat(samples[s][k], cfg.quantile), -exact[s, k], k) for k in alive[s]]
            alive[s] = [k for *_, k in sorted(keys)]
            if left[s] and r + 1 < rounds[s]:
                alive[s] = alive[s][: (len(alive[s]) + 1) // 2]
        r += 1

    stat = np.full((S, K), -np.inf)
    for s in range(S):
        for k in range(K):
            if samples[s][k]:
                stat[s, k] = _stat(samples[s][k], cfg.quantile)
    scored = np.isfinite(stat).any(axis=1)
    stat = np.where(scored[:, None], stat, exact)  # nothing sampled (no candidate scored): exact reward
    order = np.argsort(-stat, axis=1, kind="stable")
    best = order[:, 0].copy()
    chosen_value = stat[np.arange(S), best].copy()
    if cfg.m1 and cfg.k2:
        top = order[:, : cfg.m1]  # (S, M1)
        rows = np.arange(S)[:, None]
        mid = leave[rows, top].reshape(-1, 4, 2)
        a2 = proposer.propose(mid, cfg.k2, rng)
        res2 = simulate_batch(np.repeat(mid, cfg.k2, axis=0), a2.reshape(-1, 4), params)
        n_sims += S * cfg.m1 * cfg.k2
        r2 = verifier_reward(res2, cfg.foul_penalty).reshape(S, cfg.m1, cfg.k2)
        first = stat[rows, top]
        total = first + cfg.gamma * r2.max(axis=-1)
        pick = np.lexsort((np.arange(cfg.m1)[None].repeat(S, 0), -first, -total), axis=-1)[:, 0]
        best = top[np.arange(S), pick]
        chosen_value = total[np.arange(S), pick]
    rows = np.arange(S)
    r1 = stat[rows, best].copy()
    for s in range(S) if value is not None else ():  # the verifier reward alone where leaves were priced
        if rewards[s][best[s]]:
            r1[s] = float(np.mean(rewards[s][best[s]]))
    chosen_stat = stat[rows, best]
    own_margin = np.where(np.isfinite(stat[:, 0]), chosen_stat - stat[:, 0], np.inf)
    return SearchResult(a1[rows, best], chosen_value, r1, leave[rows, best], n_sims, own=a1[:, 0].copy(), own_margin=own_margin)


__all__ = ["RobustConfig", "SCHEDULES", "leave_terms", "robust_search"]
