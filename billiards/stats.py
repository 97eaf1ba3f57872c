"""Statistics that survive few seeds (docs/benchmark.md): the methodology of Agarwal et al.,
"Deep RL at the Edge of the Statistical Precipice" (NeurIPS 2021, the ``rliable`` library).

* intervals by resampling the independent unit (an inning, a chain, a match), never a shot
  (shots of one inning are correlated): :func:`bootstrap_ci`, through ``scipy.stats.bootstrap``
  (percentile method, a fixed generator: the same data give the same bytes);
* the interquartile mean (:func:`iqm`, the mean of the middle 50 %: robust to outlying runs,
  more efficient than the median);
* across training seeds, :func:`aggregate`: the IQM of every (seed, evaluation episode) score
  with a stratified bootstrap interval (each seed's episodes resampled within that seed, the
  seeds themselves resampled too);
* :func:`probability_of_improvement`: P(X > Y), the Mann-Whitney statistic of two agents'
  episode scores, averaged over seed pairs, with a stratified bootstrap interval;
* :func:`performance_profile`: the share of episodes scoring above each threshold;
* :func:`wilson`: the Wilson score interval of a win rate (a draw counts half; the league's
  tables use it with z = 1.96 and four digits);
* :func:`chain_interval`: the reproduction report's percentile bootstrap of a mean P3 chain
  (exact integer sums, to one decimal);
* :func:`elo_against`, :func:`elo_interval`: an Elo rating against fixed opponents and its interval.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats as _st

RESAMPLES = 2000
SEED = 20211206  # the generator of every interval (results regenerate byte for byte)


def _round(x: float, digits: int = 6) -> float:
    return float(round(float(x), digits))


def iqm(values, axis=None):
    """Interquartile mean: the mean of the middle 50 %, the 25 %-trimmed mean
    (``scipy.stats.trim_mean(values, 0.25)``: int(n / 4) values cut from each end); along
    ``axis`` when given (as a bootstrap's vectorised statistic), else over every value."""
    if axis is None:
        values = np.asarray(values, dtype=np.float64).reshape(-1)
        if not values.size:
            return float("nan")
        axis = 0
    ordered = np.sort(np.asarray(values, dtype=np.float64), axis=axis)
    n = ordered.shape[axis]
    cut = int(0.25 * n)
    middle = np.take(ordered, np.arange(cut, n - cut), axis=axis).mean(axis=axis)
    return float(middle) if np.ndim(middle) == 0 else middle


def bootstrap_ci(values, statistic=np.mean, confidence: float = 0.95, resamples: int = RESAMPLES) -> list[float]:
    """The percentile bootstrap interval of ``statistic`` (a function taking ``axis``, as
    ``np.mean`` and :func:`iqm`) over independent ``values`` (one per inning, chain or match).
    A constant sample gives a zero-width interval."""
    values = np.asarray(values, dtype=np.float64).reshape(-1)
    if values.size == 0:
        return [float("nan"), float("nan")]
    if values.size == 1 or np.all(values == values[0]):
        v = float(statistic(values))
        return [_round(v), _round(v)]
    res = _st.bootstrap((values,), statistic, confidence_level=confidence, n_resamples=resamples, method="percentile",
                        vectorized=True, rng=np.random.default_rng(SEED))
    return [_round(res.confidence_interval.low), _round(res.confidence_interval.high)]


def chain_interval(values, level: float = 0.95, draws: int = 10_000, seed: int = 0) -> list[float]:
    """The percentile-bootstrap ``level`` interval of the mean of P3 chain lengths ``values``
    (a heavy-tailed, capped distribution: no normal approximation). Integers sum exactly, so the
    same bits on every machine."""
    x = np.asarray(values, dtype=np.float64)
    if x.size == 0:
        return [float("nan"), float("nan")]
    idx = np.random.default_rng(seed).integers(0, x.size, size=(draws, x.size))
    means = np.sort(x[idx].sum(axis=1)) / x.size
    lo, hi = means[int((1 - level) / 2 * draws)], means[int((1 + level) / 2 * draws) - 1]
    return [round(float(lo), 1), round(float(hi), 1)]


def summary(values, statistic=np.mean) -> dict:
    """mean, 95 % interval (bootstrap over the units), median, IQM and count of unit scores."""
    values = np.asarray(values, dtype=np.float64).reshape(-1)
    return {"mean": _round(values.mean()) if values.size else float("nan"), "ci95": bootstrap_ci(values, statistic),
            "median": _round(np.median(values)) if values.size else float("nan"), "iqm": _round(iqm(values)),
            "n": int(values.size)}


def _stratified_resample(runs: list[np.ndarray], rng) -> list[np.ndarray]:
    """One stratified bootstrap draw: the seeds with replacement, then each drawn seed's
    episodes with replacement within it."""
    picks = rng.integers(0, len(runs), len(runs))
    return [runs[i][rng.integers(0, len(runs[i]), len(runs[i]))] for i in picks]


def aggregate(runs, statistic=iqm, resamples: int = RESAMPLES, confidence: float = 0.95) -> dict:
    """The aggregate of several training seeds' evaluation scores (``runs``: one array of
    episode scores per seed): ``statistic`` (IQM by default) over all of them, with a stratified
    bootstrap interval, plus the plain mean and the per-seed means."""
    runs = [np.asarray(r, dtype=np.float64).reshape(-1) for r in runs if len(r)]
    if not runs:
        return {"iqm": float("nan"), "ci95": [float("nan"), float("nan")], "mean": float("nan"), "seeds": 0, "per_seed": []}
    pooled = np.concatenate(runs)
    rng = np.random.default_rng(SEED)
    draws = np.array([statistic(np.concatenate(_stratified_resample(runs, rng))) for _ in range(resamples)])
    alpha = (1 - confidence) / 2
    lo, hi = np.quantile(draws, [alpha, 1 - alpha])
    return {"iqm": _round(statistic(pooled)), "ci95": [_round(lo), _round(hi)], "mean": _round(pooled.mean()),
            "seeds": len(runs), "per_seed": [_round(r.mean()) for r in runs]}


def _prob_greater(x: np.ndarray, y: np.ndarray) -> float:
    """P(X > Y) + P(X = Y) / 2 for one sample each: the Mann-Whitney U of x over n m, counted
    exactly with a sorted y (every count is an integer or a half)."""
    ys = np.sort(y)
    below = np.searchsorted(ys, x, side="left").sum()
    ties = np.searchsorted(ys, x, side="right").sum() - below
    return float(below + 0.5 * ties) / (len(x) * len(y))


def probability_of_improvement(runs_x, runs_y, resamples: int = 500, confidence: float = 0.95) -> dict:
    """P(X > Y): the probability that an episode of agent X scores above one of agent Y (ties
    count half), averaged over every pair of their seeds, with a stratified bootstrap interval."""
    xs = [np.asarray(r, dtype=np.float64).reshape(-1) for r in runs_x]
    ys = [np.asarray(r, dtype=np.float64).reshape(-1) for r in runs_y]

    def stat(a, b):
        return float(np.mean([_prob_greater(x, y) for x in a for y in b]))

    rng = np.random.default_rng(SEED)
    draws = np.array([stat(_stratified_resample(xs, rng), _stratified_resample(ys, rng)) for _ in range(resamples)])
    alpha = (1 - confidence) / 2
    lo, hi = np.quantile(draws, [alpha, 1 - alpha])
    return {"p": _round(stat(xs, ys)), "ci95": [_round(lo), _round(hi)]}


def performance_profile(runs, thresholds) -> list[float]:
    """The share of all episodes (over every seed) scoring strictly above each threshold."""
    pooled = np.concatenate([np.asarray(r, dtype=np.float64).reshape(-1) for r in runs])
    return [_round((pooled > t).mean()) for t in np.asarray(thresholds, dtype=np.float64)]


def wilson(successes: float, n: int, confidence: float = 0.95, *, z: float | None = None, digits: int = 6) -> list[float]:
    """The Wilson score interval of a rate ``successes / n`` (``successes`` may be a half), its
    ends rounded to ``digits``; ``z`` (the normal quantile) defaults to the one of ``confidence``
    (the league's tables use the rounded 1.96 and four digits)."""
    if n == 0:
        return [0.0, 1.0]
    z = float(_st.norm.ppf(0.5 + confidence / 2)) if z is None else float(z)
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return [_round(max(0.0, centre - half), digits), _round(min(1.0, centre + half), digits)]


def elo_for_score(opponents, score: float) -> float:
    """The Elo rating whose mean expected score against ``opponents`` (their ratings, one per
    match) equals ``score`` in (0, 1) (bisection: the expected score grows with the rating)."""
    ratings = np.asarray(opponents, dtype=np.float64)

    def excess(x: float) -> float:
        return float((1 / (1 + 10 ** ((ratings - x) / 400))).mean() - score)

    lo, hi = ratings.min() - 2000, ratings.max() + 2000
    for _ in range(200):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if excess(mid) < 0 else (lo, mid)
    return _round((lo + hi) / 2, 1)


def _with_prior(results: list[tuple[float, float]], prior_games: int) -> tuple[list[float], list[float]]:
    ratings = [r for r, _ in results]
    scores = [s for _, s in results]
    for r in sorted(set(ratings)):
        ratings += [r] * int(prior_games)
        scores += [0.5] * int(prior_games)
    return ratings, scores


def elo_against(results: list[tuple[float, float]], prior_games: int = 1) -> float:
    """The Elo rating that makes the expected score against the opponents equal the score
    reached: ``results`` are (opponent's rating, score in [0, 1]) per match; one virtual draw
    against each distinct opponent keeps it finite when every match was won or lost."""
    ratings, scores = _with_prior(results, prior_games)
    return elo_for_score(ratings, float(np.mean(scores)))


def elo_interval(results: list[tuple[float, float]], prior_games: int = 1, confidence: float = 0.95) -> list[float]:
    """The 95 % interval of :func:`elo_against`: the ratings whose expected scores are the ends
    of the Wilson interval of the score reached (with the same virtual draws)."""
    ratings, _ = _with_prior(results, prior_games)
    n, extra = len(results), len(ratings) - len(results)
    lo, hi = wilson(sum(s for _, s in results), n, confidence)
    mix = lambda p: (p * n + 0.5 * extra) / (n + extra)  # noqa: E731
    return [elo_for_score(ratings, mix(lo)), elo_for_score(ratings, mix(hi))]


__all__ = ["aggregate", "bootstrap_ci", "chain_interval", "elo_against", "elo_for_score", "elo_interval", "iqm", "performance_profile",
           "probability_of_improvement", "summary", "wilson"]
