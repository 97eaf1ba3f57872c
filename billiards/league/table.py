"""A league's tables from its matches: the pairs (wins, draws, the Wilson interval of the score
rate, points and CPU per turn) and the Elo ratings of a Bradley-Terry fit with their bootstrap
intervals -- ``league.json``'s ``pairs``, ``elo`` and ``elo_ci95`` -- and the check that a ``league.json`` holds the tables its
``matches.jsonl`` gives (:func:`summary_problems`: ``python -m billiards.files verify`` and a
resume run it; a league's tables are never trusted, only recomputed from its ledger).

NumPy and the package's statistics only (no simulator, no pettingzoo), so that a ledger is checked
wherever the package loads."""

from __future__ import annotations

import math

import numpy as np

from billiards import stats

SIDES = ("white", "yellow")  # billiards.envs.sagu.AGENTS: white plays a, yellow b
_FIGURES = ("a_score_rate", "a_points", "b_points", "a_ms_per_turn", "b_ms_per_turn")


def wilson(successes: float, n: int) -> list[float]:
    """The league tables' Wilson interval of a rate ``successes / n``: :func:`billiards.stats.wilson`
    with z = 1.96, to four digits."""
    return stats.wilson(successes, n, z=1.96, digits=4)


def _strengths(wins: np.ndarray, games: np.ndarray, iters: int) -> np.ndarray:
    """Bradley-Terry log10-strengths by minorisation-maximisation, for a stack of leagues at
    once: ``wins[..., i, j]`` is i's score against j (virtual draws included), ``games`` the
    matches between them; the mean log-strength of each league is 0."""
    gamma = np.ones(wins.shape[:-1])
    for _ in range(iters):
        denom = (games / (gamma[..., :, None] + gamma[..., None, :])).sum(axis=-1)
        step = wins.sum(axis=-1) / denom
        step /= np.exp(np.log(step).mean(axis=-1, keepdims=True))
        done = np.max(np.abs(step / gamma - 1)) < 1e-13  # converged: the rest of the iterations change nothing
        gamma = step
        if done:
            break
    return np.log10(gamma)


def _tables(names: list[str], results: list[tuple[str, str, float]]) -> tuple[np.ndarray, np.ndarray]:
    idx = {n: i for i, n in enumerate(names)}
    k = len(names)
    wins, games = np.zeros((k, k)), np.zeros((k, k))
    for a, b, s in results:
        wins[idx[a], idx[b]] += s
        wins[idx[b], idx[a]] += 1 - s
        games[idx[a], idx[b]] += 1
        games[idx[b], idx[a]] += 1
    return _with_virtual_draws(wins, games)


def _with_virtual_draws(wins: np.ndarray, games: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The score and match tables (of one league or a stack) with one virtual draw between every
    two players: the weak prior that keeps a rating finite for a player that never lost or never won."""
    off = ~np.eye(wins.shape[-1], dtype=bool)
    return wins + 0.5 * off, games + 1.0 * off


def elo(names: list[str], results: list[tuple[str, str, float]], iters: int = 2000) -> dict[str, float]:
    """Bradley-Terry strengths by minorisation-maximisation over ``(a, b, a's score)`` results
    (1 win, 0.5 draw, 0 loss), as Elo ratings (400 log10 of the strength) with mean 1500. A
    player that never lost or never won gets a finite rating through one virtual draw against
    every other player (a weak prior)."""
    rating = 400 * _strengths(*_tables(names, results), iters)
    return {n: round(float(1500 + rating[i] - rating.mean()), 1) for i, n in enumerate(names)}


ELO_DRAWS = 1000  # bootstrap resamples of a league's Elo intervals (seeded: the same matches, the same intervals)


def elo_intervals(names: list[str], results: list[tuple[str, str, float]], draws: int = ELO_DRAWS, seed: int = 0,
                  confidence: float = 0.95, iters: int = 2000) -> dict[str, list[float]]:
    """The ``confidence`` intervals of :func:`elo`'s ratings (on its scale: mean 1500): the
    percentiles of the ratings refit to ``draws`` resamples of the league, each ordered pair's
    matches drawn again with replacement (their wins, draws and losses from a multinomial); the
    generator is seeded and draws the pairs in the order of their names, so the same matches give
    the same intervals whatever the order of ``names`` or of the matches."""
    idx = {n: i for i, n in enumerate(names)}
    k = len(names)
    counts: dict[tuple[str, str], list[int]] = {}
    for a, b, s in results:  # per ordered pair: a's wins, draws, losses
        c = counts.setdefault((a, b), [0, 0, 0])
        c[0 if s == 1 else 1 if s == 0.5 else 2] += 1
    rng = np.random.default_rng(seed)
    wins, games = np.zeros((draws, k, k)), np.zeros((draws, k, k))
    for (a, b), c in sorted(counts.items()):
        i, j, n = idx[a], idx[b], sum(c)
        w, d, _ = rng.multinomial(n, np.asarray(c) / n, size=draws).T
        score = w + 0.5 * d
        wins[:, i, j] += score
        wins[:, j, i] += n - score
        games[:, i, j] += n
        games[:, j, i] += n
    rating = 400 * _strengths(*_with_virtual_draws(wins, games), iters)
    rating = 1500 + rating - rating.mean(axis=-1, keepdims=True)
    tail = 100 * (1 - confidence) / 2
    lo, hi = np.percentile(rating, [tail, 100 - tail], axis=0)
    return {n: [round(float(lo[i]), 1), round(float(hi[i]), 1)] for n, i in idx.items()}


def summarize(records: list[dict], names: list[str], noise: str) -> dict:
    """``league.json``'s pairs and Elo table from the finished matches."""
    pairs, results = [], []
    for a in names:
        for b in names:
            if a == b:
                continue
            mine = [r for r in records if (r["a"], r["b"]) == (a, b)]
            if not mine:
                continue
            a_wins = sum(r["winner"] == "white" for r in mine)
            b_wins = sum(r["winner"] == "yellow" for r in mine)
            draws = len(mine) - a_wins - b_wins
            turns = {p: sum(r["turns"][p] for r in mine) for p in SIDES}
            cpu = {p: sum(r["cpu_s"][p] for r in mine) for p in SIDES}
            pairs.append({"a": a, "b": b, "noise": noise, "matches": len(mine), "a_wins": a_wins, "b_wins": b_wins,
                          "draws": draws, "a_score_rate": round((a_wins + 0.5 * draws) / len(mine), 4),
                          "ci95": wilson(a_wins + 0.5 * draws, len(mine)),
                          "a_points": round(float(np.mean([r["scores"]["white"] for r in mine])), 3),
                          "b_points": round(float(np.mean([r["scores"]["yellow"] for r in mine])), 3),
                          "a_ms_per_turn": round(1000 * cpu["white"] / max(turns["white"], 1), 2),
                          "b_ms_per_turn": round(1000 * cpu["yellow"] / max(turns["yellow"], 1), 2)})
            results += [(a, b, 1.0 if r["winner"] == "white" else 0.0 if r["winner"] == "yellow" else 0.5) for r in mine]
    if not results:
        return {"pairs": pairs, "elo": {}, "elo_ci95": {}}
    return {"pairs": pairs, "elo": elo(names, results), "elo_ci95": elo_intervals(names, results)}


def players(records: list[dict]) -> list[str]:
    """The league's players in its order (the order its matches were played in: the first
    pair's white, its yellow, then each new name as it appears)."""
    seen: dict[str, None] = {}
    for r in records:
        seen.setdefault(r["a"])
        seen.setdefault(r["b"])
    return list(seen)


def _close(x, y, tol: float) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and abs(x - y) <= tol


def summary_problems(records: list[dict], league: dict, name: str) -> list[str]:
    """Where a ``league.json`` (``league``, read from the file ``name``) disagrees with the
    tables its matches (``records``, a ledger's) give: each pair's counts, score rate, interval,
    points and CPU per turn, and each player's Elo rating (recomputed by :func:`summarize`;
    a rating within one rounding step), one sentence each; [] when it agrees."""
    from billiards.files import described, shown_name, shown_number

    pairs = league.get("pairs")
    if not isinstance(pairs, list) or not all(isinstance(p, dict) for p in pairs):
        return [f"{name} holds no pairs"]
    table = summarize(records, players(records), "")
    theirs = {(p["a"], p["b"]): p for p in table["pairs"]}
    out = []
    show = lambda c: f"{c['a_wins']}-{c['b_wins']} with {c['draws']} draws of {c['matches']}"  # noqa: E731
    for p in pairs:
        a, b = p.get("a"), p.get("b")
        what = f"{shown_name(a)} vs {shown_name(b)}"
        mine = {k: p.get(k) for k in ("matches", "a_wins", "b_wins", "draws")}
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in mine.values()):
            out.append(f"{name} counts {what} with entries that are no counts")
            continue
        got = theirs.pop((a, b), None) if isinstance(a, str) and isinstance(b, str) else None
        if got is None:
            out.append(f"{name} counts {what} ({mine['matches']} matches), of which the ledger holds none")
            continue
        if mine != {k: got[k] for k in mine}:
            out.append(f"{name} counts {what} {show(mine)}; the ledger holds {show(got)}")
            continue
        for key in _FIGURES:
            if not _close(p.get(key), got[key], 1e-9 * max(1.0, abs(got[key]))):
                out.append(f"{name} gives {what} {key} {shown_number(p.get(key))}; its matches give {got[key]}")
        ci = p.get("ci95")
        if not (isinstance(ci, list) and len(ci) == 2 and all(_close(x, y, 1e-9) for x, y in zip(ci, got["ci95"]))):
            shown = f"[{', '.join(map(shown_number, ci))}]" if isinstance(ci, list) and len(ci) <= 4 else described(ci)
            out.append(f"{name} gives {what} the interval {shown}; its matches give {got['ci95']}")
    for (a, b), c in theirs.items():
        out.append(f"the ledger holds {c['matches']} matches of {shown_name(a)} vs {shown_name(b)} that {name} does not count")
    ratings, expected = league.get("elo"), table["elo"]
    if not isinstance(ratings, dict):
        return out + [f"{name} holds no Elo table"]
    if sorted(map(str, ratings)) != sorted(expected):
        who = ", ".join(map(shown_name, expected))
        return out + [f"{name} rates {len(ratings)} players; its matches are played by {len(expected)} ({who})"]
    for player, rating in expected.items():
        if not _close(ratings[player], rating, 0.11):  # one rounding step of the table's 0.1
            out.append(f"{name} rates {shown_name(player)} at {shown_number(ratings[player])} Elo; its matches give {rating}")
    intervals, expected = league.get("elo_ci95"), table["elo_ci95"]
    if not isinstance(intervals, dict):
        return out + [f"{name} holds no Elo intervals"]
    if sorted(map(str, intervals)) != sorted(expected):
        return out + [f"{name}'s Elo intervals are not one per player of its matches"]
    for player, (lo, hi) in expected.items():
        ci = intervals[player]
        if not (isinstance(ci, list) and len(ci) == 2 and _close(ci[0], lo, 0.11) and _close(ci[1], hi, 0.11)):
            out.append(f"{name} gives {shown_name(player)} the Elo interval {described(ci)}; its matches give [{lo}, {hi}]")
    return out


__all__ = ["SIDES", "elo", "players", "summarize", "summary_problems", "wilson"]
