"""Leagues of two-player matches (billiards.league, python match.py): the players, replayable
matches, a league that resumes, the Elo fit and the interval, and the app's config checks."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pettingzoo")

from billiards.league.players import PolicyPlayer, RandomPlayer, SafetyAgent, SafetyPlayer, SearchPlayer, make_agent, to_env_action  # noqa: E402
from billiards.league.play import MATCHES_FILE, elo, play_match, run_league, wilson  # noqa: E402
from billiards.league.table import elo_intervals, summarize  # noqa: E402
from billiards.physics import DEFAULT_PARAMS  # noqa: E402
from billiards.physics.noise import get_noise  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
X5 = get_noise("fastfiz_x5")
CHEAP = SearchPlayer(search="h2", proposer="geometric", search_budget=60, overrides={"k1": 40, "m1": 2})


def test_elo_and_the_interval():
    # a beats b 9 of 10, b beats c 9 of 10: a > b > c, symmetric in the names' order
    results = [("a", "b", 1.0)] * 9 + [("a", "b", 0.0)] + [("b", "c", 1.0)] * 9 + [("b", "c", 0.0)]
    r = elo(["a", "b", "c"], results)
    assert r["a"] > r["b"] > r["c"] and abs(np.mean(list(r.values())) - 1500) < 1e-6
    assert elo(["c", "b", "a"], results) == r
    assert elo(["a", "b"], [("a", "b", 0.5)] * 4) == {"a": 1500.0, "b": 1500.0}
    lo, hi = wilson(60, 100)
    assert lo < 0.6 < hi and 0.49 < lo < 0.51
    assert str(wilson(0, 10)[0]) == "0.0" and wilson(10, 10)[1] == 1.0  # no -0.0, nothing beyond [0, 1]


def test_the_elo_intervals_hold_the_ratings_and_narrow_with_more_matches():
    # a beats b 60 of 100, b beats c 60 of 100, a beats c 70 of 100
    def league(k):
        return ([("a", "b", 1.0)] * 60 * k + [("a", "b", 0.0)] * 40 * k + [("b", "c", 1.0)] * 60 * k + [("b", "c", 0.0)] * 40 * k
                + [("a", "c", 1.0)] * 70 * k + [("c", "a", 1.0)] * 30 * k)
    names = ["a", "b", "c"]
    r, ci = elo(names, league(1)), elo_intervals(names, league(1))
    assert ci == elo_intervals(names, league(1))  # seeded: the same matches, the same intervals
    assert ci == elo_intervals(["c", "a", "b"], league(1)[::-1])  # whatever the order of the players or the matches
    assert ci != elo_intervals(names, league(1), seed=1)
    assert all(lo < r[n] < hi for n, (lo, hi) in ci.items()) and ci["a"][0] > ci["c"][1]  # a above c, clearly
    wide, narrow = ci["b"][1] - ci["b"][0], (lambda c: c["b"][1] - c["b"][0])(elo_intervals(names, league(4)))
    assert 0.35 < narrow / wide < 0.65  # four times the matches: about half the width
    even = elo_intervals(["x", "y"], [("x", "y", 1.0), ("x", "y", 0.0)] * 50 + [("x", "y", 0.5)] * 10)
    assert even["x"][0] < 1500 < even["x"][1] and even["x"] == [3000 - even["y"][1], 3000 - even["y"][0]]
    table = summarize([{"a": "x", "b": "y", "winner": "white", "scores": {"white": 1, "yellow": 0}, "turns": {"white": 1, "yellow": 0},
                        "cpu_s": {"white": 0.0, "yellow": 0.0}}], ["x", "y"], "none")
    assert set(table["elo_ci95"]) == {"x", "y"} and table["elo_ci95"]["x"][0] <= table["elo"]["x"] <= table["elo_ci95"]["x"][1]


def test_an_action_of_a_search_is_the_envs_action():
    raw = np.array([7.0, 0.5, -0.25, 1.0])  # theta beyond 2 pi wraps
    x = to_env_action(raw)
    assert x.dtype == np.float32 and np.all(np.abs(x) <= 1.0)
    assert np.allclose(x, [(7.0 - 2 * np.pi) / np.pi - 1.0, 0.0, -0.25, 1.0], atol=1e-6)


def test_a_match_replays_from_its_seed():
    a, b = make_agent(CHEAP, X5, DEFAULT_PARAMS), make_agent(RandomPlayer(), X5, DEFAULT_PARAMS)
    first = play_match(a, b, seed=5, noise=X5, target=2)
    again = play_match(a, b, seed=5, noise=X5, target=2)
    strip = lambda r: {k: v for k, v in r.items() if k != "cpu_s"}  # noqa: E731
    assert strip(first) == strip(again) and first["winner"] == "white" and first["scores"]["white"] == 2.0
    assert sum(first["turns"].values()) == first["shots"]


def test_a_league_resumes_and_plays_only_what_is_missing(tmp_path):
    players = {"cheap": make_agent(CHEAP, X5, DEFAULT_PARAMS), "random": make_agent(RandomPlayer(), X5, DEFAULT_PARAMS)}
    game = dict(noise=X5, target=1, max_innings=30)
    league = run_league(players, out_dir=tmp_path / "a", matches=3, seed=0, noise_name="fastfiz_x5", record={"x": 1},
                        progress=False, **game)
    pairs = {(p["a"], p["b"]): p for p in league["pairs"]}
    assert set(pairs) == {("cheap", "random"), ("random", "cheap")} and league["x"] == 1
    assert all(p["matches"] == 3 and p["a_wins"] + p["b_wins"] + p["draws"] == 3 for p in pairs.values())
    assert league["elo"]["cheap"] > league["elo"]["random"]
    lines = (tmp_path / "a" / MATCHES_FILE).read_text().splitlines()
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / MATCHES_FILE).write_text("\n".join(lines[:4]) + "\n" + lines[4][:20])  # killed mid-write
    again = run_league(players, out_dir=tmp_path / "b", matches=3, seed=0, noise_name="fastfiz_x5", record={"x": 1},
                       progress=False, **game)
    untimed = lambda pairs: [{k: v for k, v in p.items() if not k.endswith("ms_per_turn")} for p in pairs]  # noqa: E731
    assert untimed(again["pairs"]) == untimed(league["pairs"])
    replayed = [json.loads(x) for x in (tmp_path / "b" / MATCHES_FILE).read_text().splitlines()[4:]]
    assert [(r["a"], r["i"]) for r in replayed] == [(json.loads(x)["a"], json.loads(x)["i"]) for x in lines[4:]]


def test_the_safety_player_values_the_searchs_shot_and_its_candidates():
    agent = make_agent(SafetyPlayer(search="h2", proposer="geometric", search_budget=60, k=8, replays=2,
                                    opp_k=4, opp_replays=1, overrides={"k1": 40, "m1": 2}), X5, DEFAULT_PARAMS)
    assert isinstance(agent, SafetyAgent)
    agent.reseed(0)
    from billiards.envs._common import initial_racks

    view = initial_racks(np.random.default_rng(1), "random", 1, DEFAULT_PARAMS)[0]
    cands, value = agent.values(view)
    assert cands.shape == (9, 4) and value.shape == (9,)
    assert np.all(value <= 1.0) and np.all(value >= -1.0 - agent.cfg.foul_penalty)
    agent.reseed(0)
    assert np.array_equal(agent.values(view)[1], value)  # the same draws from the same seed
    # above its threshold the safety player plays the search's own shot
    greedy = make_agent(CHEAP, X5, DEFAULT_PARAMS)
    sure = make_agent(SafetyPlayer(search="h2", proposer="geometric", search_budget=60, threshold=-1.0,
                                  overrides={"k1": 40, "m1": 2}), X5, DEFAULT_PARAMS)
    greedy.reseed(3)
    sure.reseed(3)
    assert np.array_equal(sure.act(view), greedy.act(view))


def test_a_trained_policy_plays_a_match():
    """Table 5's base policy (seed 0) as a player: it beats a random player to 2 points from the
    opening rack under fastfiz_x5 (either colour), and a missing policy file is named."""
    policy = make_agent(PolicyPlayer(policy="results/policies/base/seed0.pt"), X5, DEFAULT_PARAMS)
    rand = make_agent(RandomPlayer(), X5, DEFAULT_PARAMS)
    assert play_match(policy, rand, seed=1, noise=X5, target=2)["winner"] == "white"
    assert play_match(rand, policy, seed=2, noise=X5, target=2, first="yellow")["winner"] == "yellow"
    assert "agents.p.policy: no trained policy at 'nowhere.pt'" in PolicyPlayer(policy="nowhere.pt").errors("p")[0]


MATCH_BAD = [
    (["players=[greedy,nobody]"], "players must name at least two different agents"),
    (["agents.greedy.kind=smart"], "agents.greedy.kind must be one of random, search, safety"),
    (["target=0"], "target must be >= 1"),
]


@pytest.mark.slow
@pytest.mark.parametrize("args, message", MATCH_BAD)
def test_each_bad_match_setting_is_refused_with_its_message(tmp_path, args, message):
    from conftest import refusal

    assert message in refusal("match.py", *args, f"hydra.run.dir={tmp_path / 'run'}")
    assert not (tmp_path / "run").exists()


@pytest.mark.slow
@pytest.mark.parametrize("args, message", MATCH_BAD[2:])
def test_a_bad_match_config_fails_at_once_and_writes_nothing(tmp_path, args, message):
    from conftest import app_here

    proc = app_here("match.py", *args, f"hydra.run.dir={tmp_path / 'run'}", cwd=tmp_path)
    assert proc.returncode != 0 and message in proc.stderr + proc.stdout and not (tmp_path / "run").exists()


@pytest.mark.slow
def test_the_match_app_plays_a_league_resumes_it_with_its_own_settings_and_draws_a_match(tmp_path):
    run = tmp_path / "run"
    from conftest import app_here

    first = app_here("match.py", "progress=false", "players=[greedy,random]", "matches=1", "target=1", f"hydra.run.dir={run}",
                     cwd=tmp_path)
    assert first.returncode == 0, first.stderr[-2000:]
    league = json.loads((run / "league.json").read_text())
    assert league["command"].endswith(f"players=[greedy,random] matches=1 target=1 hydra.run.dir={run}")
    assert [(p["a"], p["b"], p["matches"]) for p in league["pairs"]] == [("greedy", "random", 1), ("random", "greedy", 1)]
    assert (run / "match.gif").read_bytes()[:6] == b"GIF89a"
    lines = (run / MATCHES_FILE).read_text().splitlines()
    (run / MATCHES_FILE).write_text(lines[0] + "\n")  # the second match lost
    again = app_here("match.py", "progress=false", f"resume={run}", "target=5", "picture=false", cwd=tmp_path)
    assert again.returncode == 0, again.stderr[-2000:]
    resumed = json.loads((run / "league.json").read_text())
    assert resumed["target"] == 1 and resumed["command"] == league["command"]  # the league's own settings
    untimed = [{k: v for k, v in json.loads(x).items() if k not in ("cpu_s", "sha256")}  # the seal covers the time too
               for x in (run / MATCHES_FILE).read_text().splitlines()]
    assert untimed == [{k: v for k, v in json.loads(x).items() if k not in ("cpu_s", "sha256")} for x in lines]  # the lost match replayed


@pytest.mark.parametrize("overrides, message", [
    (["noise=variable", "noise.scale=3"], "noise: at most 10 times fastfiz's aim sigma, got 15"),
    (["+agents.greedy.overrides={bogus: 1}"], "agents.greedy: overrides: "),
    (["agents.greedy.proposer=nope"], "agents.greedy: proposer must be for_noise or one of"),
    (["+agents.greedy.overrides={position: 2.0}"], "agents.greedy: search.position=2.0"),
])
@pytest.mark.slow
def test_the_match_config_checks_the_noise_cap_and_each_players_search_before_anything_runs(overrides, message):
    from hydra import compose, initialize_config_dir

    from billiards.league.config import errors

    with initialize_config_dir(str(REPO / "conf"), version_base=None):
        cfg = compose("match", overrides=overrides)
    assert any(message in e for e in errors(cfg)), errors(cfg)
    with initialize_config_dir(str(REPO / "conf"), version_base=None):
        assert errors(compose("match", overrides=["players=[greedy_v,safety_v]"])) == []


@pytest.mark.slow
def test_a_player_can_be_added_on_the_command_line_and_a_bad_one_is_named():
    from hydra import compose, initialize_config_dir

    from billiards.league.players import player_config
    from billiards.league.config import errors

    mine = "+agents.mine={kind: search, proposer: for_noise, overrides: {position: 4.0, value: results/values/run1.pt}}"
    with initialize_config_dir(str(REPO / "conf"), version_base=None):
        cfg = compose("match", overrides=[mine, "players=[greedy,mine]"])
        bad = compose("match", overrides=["+agents.b1={kind: safety, k: many}", "+agents.b2={nope: 1}",
                                          "+agents.b3={kind: search, threshold: 0.5}", "+agents.b4={kind: random, policy: a.pt}"])
    assert errors(cfg) == []
    added = player_config(cfg.agents.mine, "mine")
    assert added == SearchPlayer(proposer="for_noise", overrides={"position": 4.0, "value": "results/values/run1.pt"})  # defaults filled in
    assert player_config(cfg.agents.greedy, "greedy") == SearchPlayer(search="robust", proposer="ranked")
    assert player_config(cfg.agents.safety_t, "safety_t") == SafetyPlayer(threshold=0.5)
    errs = errors(bad)
    assert any(e.startswith("agents.b1.k: ") and "many" in e for e in errs), errs
    assert any(e.startswith("agents.b2") and "nope" in e and "a search player's keys" in e for e in errs), errs
    # one schema per kind: a knob of another kind is refused, naming the kind's own keys
    assert any(e.startswith("agents.b3") and "threshold" in e and "a search player's keys: kind, search, proposer" in e
               for e in errs), errs
    assert any(e.startswith("agents.b4") and "policy" in e and "a random player's keys: kind" in e for e in errs), errs


def test_a_league_record_of_the_one_schema_for_every_kind_loads_its_players():
    """Every committed league.json (players saved with every kind's keys) gives each player its
    own kind's schema through compat, the same knobs it played with."""
    import dataclasses

    from billiards import compat
    from billiards.league.players import player_config, player_keys as own
    records = sorted((REPO / "results" / "sagu").glob("*/league.json"))
    assert records
    for path in records:
        saved = json.loads(path.read_text())["agents"]
        for name, node in compat.upgrade_league_players(saved, own).items():
            player = player_config(node, name)
            played = dataclasses.asdict(player)
            assert {k: played[k] for k in own(player.kind) if k in saved[name]} == {k: saved[name][k] for k in own(player.kind)
                                                                                     if k in saved[name]}
            assert set(saved[name]) - own(player.kind) <= set(compat.LEGACY_PLAYER_KEYS)
