"""The compute-limited exact tracks: the 400-budget exact tracks' racks at 25, 50 and 100
simulations per decision, h2's split scaled to the budget, and the leaderboard's compute curves."""

import json

import pytest

from billiards.bench.entries import ENTRIES, LIMITED
from billiards.bench.tracks import BUDGETS, COMPUTE_CURVES, TRACKS
from billiards.files import ROOT
from billiards.search.settings import H2Config

BOARD = json.loads((ROOT / "results" / "leaderboard.json").read_text())


@pytest.mark.parametrize("budget", [1, 2, 7, 25, 50, 100, 133, 400, 1000])
def test_h2s_split_scales_to_any_budget_and_spends_it_exactly(budget):
    k1, m1 = H2Config().split_for(budget)
    cfg = H2Config(budget=budget, k1=k1, m1=m1).settings()  # a valid split (checked)
    assert cfg.sims_per_decision == budget and 1 <= k1 <= budget and 0 <= m1 <= k1
    if budget >= 40:  # a split that expands where the default does
        assert m1 >= 1
    assert H2Config().split_for(400) == (200, 10)  # the default split is its own scaling


def test_each_limited_track_is_its_exact_track_with_a_smaller_budget():
    for base, names in COMPUTE_CURVES.items():
        full = TRACKS[names[-1]]
        assert [TRACKS[n].budget for n in names] == [*BUDGETS, 400]
        for name in names[:-1]:
            t = TRACKS[name]
            assert (t.protocol, t.units, t.shots, t.seed, t.physics, t.noise) == \
                (full.protocol, full.units, full.shots, full.seed, full.physics, full.noise)
            assert t.seeds() == full.seeds() and t.fingerprint != full.fingerprint
    searches = [e for e in ENTRIES if e.spec.startswith("search:") and "p1-exact-v1" in e.tracks]
    assert len(searches) >= 3 and all(set(LIMITED) <= set(e.tracks) for e in searches)


def test_each_search_plays_over_every_shipped_exact_play_proposer_at_every_budget():
    from billiards.bench.entries import EXACT
    from billiards.search.config import SHIPPED_PROPOSERS

    proposers = {"geometric", *SHIPPED_PROPOSERS, "exit", "ranked_exact", "ranked_exact_small"}
    for search in ("h2", "puct"):
        played = {e.spec.split("/", 1)[1] for e in ENTRIES
                  if e.spec.startswith(f"search:{search}/") and set(EXACT + LIMITED) <= set(e.tracks)}
        assert played >= proposers, (search, sorted(proposers - played))


@pytest.mark.slow
def test_a_search_agent_is_sized_to_the_tracks_budget():
    from billiards.bench.adapters import resolve_agent

    for name, budget in (("p1-exact-b25-v1", 25), ("p1-exact-b100-v1", 100), ("p1-exact-v1", 400)):
        h2 = resolve_agent("search:h2/geometric", TRACKS[name]).actor.cfg
        assert (h2.budget, h2.sims_per_decision, (h2.k1, h2.m1)) == (budget, budget, H2Config().split_for(budget))
        assert resolve_agent("search:puct/geometric", TRACKS[name]).actor.cfg.budget == budget


def test_the_boards_compute_curves_are_its_rows_at_each_budget():
    curves = BOARD["compute_curves"]
    assert set(curves) == set(COMPUTE_CURVES)
    for base, c in curves.items():
        assert c["tracks"] == list(COMPUTE_CURVES[base])
        for row, points in c["rows"].items():
            assert len(points) >= 2 and [p["budget"] for p in points] == sorted(p["budget"] for p in points)
            for p in points:
                on_track = {r["row"]: r for r in BOARD["tracks"][p["track"]]["rows"]}[row]
                assert (p["score"], p["ci95"], p["budget"]) == (on_track["score"], on_track["ci95"], TRACKS[p["track"]].budget)


def test_the_campaign_as_multiruns_puts_each_job_in_its_scorecard_folder(monkeypatch, tmp_path):
    """``python -m billiards.bench campaign --multirun``: one ``evaluate.py -m`` per entry over the
    tracks it has yet to play; every job composes, and its out= resolves to that track's folder."""
    import shlex

    from hydra import compose, initialize_config_dir

    import billiards.bench.__main__ as bench_main
    import billiards.bench.config  # noqa: F401  (registers evaluate.py's schema)
    from billiards.app_config import override_errors

    monkeypatch.setattr(bench_main, "ROOT", tmp_path)  # no scorecard here: every one is missing
    commands = bench_main.multirun_commands("puct_geometric", list(LIMITED[:2]), launcher="local_parallel")
    assert len(commands) == 1 and commands[0].endswith(" hydra/launcher=local_parallel")
    words = shlex.split(commands[0])
    assert words[:3] == ["python", "evaluate.py", "-m"] and not override_errors(words[3:])
    overrides = [w for w in words[3:] if not w.startswith("hydra/")]
    swept = next(o for o in overrides if o.startswith("track=")).split("=", 1)[1].split(",")
    assert swept == list(LIMITED[:2])
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        for track in swept:
            cfg = compose("evaluate", overrides=[f"track={track}" if o.startswith("track=") else o for o in overrides])
            assert (cfg.out, cfg.agent, cfg.name, cfg.group) == (f"results/bench/scorecards/{track}/puct_geometric",
                                                                 "search:puct/geometric", "puct_geometric", "PUCT, geometric proposer")


def test_the_campaign_warms_each_agent_up_once_before_timing_it(monkeypatch):
    """Each agent plays a cut-down unit (nothing written) before its first timed scorecard of the
    campaign, so what it compiles on first use is not in its milliseconds per decision."""
    import billiards.bench.__main__ as bench_main
    import billiards.bench.run as run
    import billiards.device as device
    from billiards.bench.entries import BoardEntry

    monkeypatch.setattr(device, "set_threads", lambda n: None)  # the test process keeps its threads
    calls = []
    monkeypatch.setattr(run, "evaluate", lambda spec, track, **kw: calls.append((spec, getattr(track, "name", track), kw.get("out"))))
    a, b = BoardEntry("a", "a", "nearest", ()), BoardEntry("b", "b", "random", ())
    monkeypatch.setattr(bench_main, "_missing", lambda only, tracks: [(a, "p3-exact-v1"), (a, "p1-exact-v1"), (b, "match-x5-v1")])
    bench_main.campaign(None, None, progress=False)
    assert [(spec, track, out is None) for spec, track, out in calls] == [
        ("nearest", "p3-exact-v1", True), ("nearest", "p3-exact-v1", False), ("nearest", "p1-exact-v1", False),
        ("random", "match-x5-v1", True), ("random", "match-x5-v1", False)]
