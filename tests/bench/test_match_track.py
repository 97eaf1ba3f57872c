"""The match track that ranks (match-x5-v2): its pool is the league's strongest players, its
fixed ratings are their round robin's Bradley-Terry fit (recomputed here from the committed
matches), and it plays enough matches per opponent for a Wilson half-width of at most 10 points."""

import json

from billiards import stats
from billiards.bench.tracks import POOL_LEAGUE, TRACKS
from billiards.files import ROOT
from billiards.league.table import players, summarize

TRACK = TRACKS["match-x5-v2"]
LEAGUE = ROOT / POOL_LEAGUE


def _matches() -> list[dict]:
    return [json.loads(line) for line in (LEAGUE / "matches.jsonl").read_text().splitlines()]


def test_the_pool_is_a_round_robin_of_100_matches_per_pair():
    records = _matches()
    pool = list(TRACK.opponents)
    assert sorted(players(records)) == sorted(pool) and TRACK.anchor in pool
    pairs = {}
    for r in records:
        key = frozenset((r["a"], r["b"]))
        pairs[key] = pairs.get(key, 0) + 1
    assert len(pairs) == len(pool) * (len(pool) - 1) // 2 and set(pairs.values()) == {100}
    league = json.loads((LEAGUE / "league.json").read_text())
    assert league["noise"] == TRACK.noise and league["target"] == TRACK.target


def test_the_tracks_ratings_are_the_round_robins_fit_anchored_at_greedy():
    records = _matches()
    table = summarize(records, players(records), TRACK.noise)
    shift = 1500.0 - table["elo"][TRACK.anchor]
    ratings = dict(TRACK.ratings)
    assert ratings[TRACK.anchor] == 1500.0
    for name, rating in table["elo"].items():
        assert abs(ratings[name] - (rating + shift)) <= 0.11, name  # the league table rounds to 0.1
        lo, hi = table["elo_ci95"][name]
        assert lo <= rating <= hi
    committed = json.loads((LEAGUE / "league.json").read_text())
    assert committed["elo"] == table["elo"] and committed["elo_ci95"] == table["elo_ci95"]


def test_each_opponent_gets_enough_matches_for_a_ten_point_interval():
    lo, hi = stats.wilson(TRACK.units / 2, TRACK.units)  # the widest: a score of one half
    assert (hi - lo) / 2 <= 0.10 and TRACK.units >= 100
    seeds = TRACK.seeds()
    assert len(seeds) == len(set(seeds)) == TRACK.units * len(TRACK.opponents)
    others = {s for t in TRACKS.values() if t.name != TRACK.name for s in t.seeds()}
    assert not others & set(seeds)  # seeds of its own, held out
