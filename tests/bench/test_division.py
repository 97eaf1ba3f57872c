"""The no-simulator division: on every track the agents that act from the observation alone are
ranked among themselves (their own order, their own P(above the next)), in leaderboard.json and
leaderboard.md, beside the overall table."""

from __future__ import annotations

import json

from billiards.bench.entries import LIMITED, LONG
from billiards.bench.leaderboard import markdown
from billiards.bench.tracks import TRACKS
from billiards.files import ROOT

BOARD = json.loads((ROOT / "results" / "leaderboard.json").read_text())


def test_every_track_ranks_its_observation_agents_among_themselves():
    assert set(BOARD["tracks"]) == set(TRACKS)
    for name, t in BOARD["tracks"].items():
        division = t["no_simulator"]["rows"]
        assert division == [r["row"] for r in t["rows"] if r["compute"] == "observation"], name
        if name in LIMITED + LONG:  # a compute-limited track (an observation agent plays it as its 400-budget track, same
            continue  # racks) or the long chains (no observation agent reaches p3-exact-v1's cap)
        assert division, f"{name}: no agent of the division"  # every track has learned policies or baselines
        # one probability per row of the division but its last, each against the next row of the division
        assert list(t["no_simulator"]["p_above_next"]) == division[:-1], name
        for p in t["no_simulator"]["p_above_next"].values():
            assert 0.0 <= p["ci95"][0] <= p["p"] <= p["ci95"][1] <= 1.0


def test_where_two_observation_agents_are_neighbours_overall_the_division_agrees():
    """The division's P(above the next) compares neighbours of the division; where the two are
    neighbours in the overall table too, it is the overall figure for the same pair."""
    for name, t in BOARD["tracks"].items():
        rows = t["rows"]
        for upper, lower in zip(rows, rows[1:]):
            if upper["compute"] == lower["compute"] == "observation":
                assert t["no_simulator"]["p_above_next"][upper["row"]] == upper["p_above_next"], (name, upper["row"])


def test_the_markdown_shows_the_division_after_each_track():
    md = markdown(BOARD)
    assert md == (ROOT / "results" / "leaderboard.md").read_text()
    for name, t in BOARD["tracks"].items():
        if not t["no_simulator"]["rows"]:
            assert f"### {name}: the no-simulator division" not in md, name
            continue
        section = md.split(f"### {name}: the no-simulator division", 1)[1].split("\n## ", 1)[0]
        listed = [line.split(" | ")[1] for line in section.splitlines() if line.startswith("| ") and line[2].isdigit()]
        assert len(listed) == len(t["no_simulator"]["rows"]), name
        assert not any(r["compute"] == "simulator" and r["row"] in listed for r in t["rows"]), name


def test_an_observation_agent_is_placed_overall_and_in_the_division():
    from billiards.bench.leaderboard import placement, placement_line

    t = BOARD["tracks"]["p1-exact-v1"]
    division = [r for r in t["rows"] if r["compute"] == "observation"]
    first = division[0]["score"] + 0.001  # just above the division's best, below every search
    overall = placement("p1-exact-v1", first, BOARD)
    assert overall.startswith(f"would rank {len(t['rows']) - len(division) + 1} of {len(t['rows']) + 1} on p1-exact-v1")
    inside = placement("p1-exact-v1", first, BOARD, division=True)
    assert inside.startswith(f"would rank 1 of {len(division) + 1} in the no-simulator division of p1-exact-v1, above ")
    card = {"track": "p1-exact-v1", "version": t["version"], "agent": {"name": "mine", "compute": "observation"},
            "success_per_shot": {"mean": first}}
    search = {**card, "agent": {"name": "mine", "compute": "simulator"}}
    assert "division" in placement_line(card, BOARD) and "division" not in placement_line(search, BOARD)
