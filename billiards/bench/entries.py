"""The leaderboard's own entries: every agent the project has, on every track it applies to.

Each entry is data: a row name, the spec (never code: baselines, policy files, searches and
league players only, checked), the tracks, and for trained policies one spec per training seed
pooled into one row. ``python -m billiards.bench campaign`` plays the missing ones into
``results/bench/scorecards/<track>/<slug>/`` (each scorecard records its own ``evaluate.py``
command, which replays it alone).
"""

from __future__ import annotations

from dataclasses import dataclass

from .tracks import COMPUTE_CURVES

EXACT = ("innings-v1", "p1-exact-v1", "p3-exact-v1")
# the same exact tracks at 25, 50 and 100 simulations per decision: every search agent plays them
LIMITED = tuple(name for curve in COMPUTE_CURVES.values() for name in curve[:-1])
LONG = ("p3-exact-long-v1",)  # chains to 10,000: the searches that reach p3-exact-v1's cap of 1,000 (or nearly)
NOISY_P1 = ("p1-fastfiz-v1", "p1-x5-v1", "p1-variable-v1")
NOISY = ("p1-fastfiz-v1", "p3-fastfiz-v1", "p1-x5-v1", "p1-variable-v1")
ALL_SINGLE = EXACT + NOISY
RANKING_MATCH = ("match-x5-v2",)  # the league's strongest players, 100 matches against each of the pool
MATCH = ("match-x5-v1",) + RANKING_MATCH


@dataclass(frozen=True)
class BoardEntry:
    row: str  # the leaderboard row (seeds of one setting share it)
    slug: str  # the scorecard directory name
    spec: str
    tracks: tuple[str, ...]
    note: str = ""


def _seeds(row: str, slug: str, folder: str, tracks, note: str = "") -> list[BoardEntry]:
    return [BoardEntry(row, f"{slug}_s{s}", f"results/policies/{folder}/seed{s}.pt", tracks, note) for s in range(3)]


ENTRIES: tuple[BoardEntry, ...] = (
    BoardEntry("random", "random", "random", ALL_SINGLE + MATCH, "uniform in the normalised box"),
    # the floor of the matches: random alone on match-x5-v2 (the three lose every match of match-x5-v1)
    BoardEntry("nearest-red heuristic", "nearest", "nearest", ALL_SINGLE + MATCH[:1], "full-ball hit on the nearest red, half power"),
    BoardEntry("random inside the aim window", "random_aim", "random_aim", ALL_SINGLE + MATCH[:1], "uniform u, power, tip"),
    *_seeds("SAC aim + features, foul penalty (Table 5)", "sac_base", "base", ALL_SINGLE),
    *_seeds("SAC aim + features, gentle (Table 5)", "sac_gentle", "gentle", EXACT),
    *_seeds("SAC aim + features, near-miss (Table 5)", "sac_near_miss", "near_miss", EXACT),
    *_seeds("SAC aim + features, both bonuses (Table 5)", "sac_both", "both", EXACT),
    *_seeds("SAC aim + features trained under fastfiz", "sac_fastfiz", "fastfiz_aim_features", ALL_SINGLE),
    BoardEntry("SAC aim + features, foul penalty (Table 5), seed 0", "sac_base_s0_match", "results/policies/base/seed0.pt", MATCH),
    BoardEntry("expert iteration policy (exact), seed 0", "exit_s0", "results/policies/exit/seed0.pt", EXACT + NOISY_P1),
    BoardEntry("expert iteration policy started from SAC (exact), seed 0", "exit_sac_s0", "results/policies/exit_sac/seed0.pt",
          EXACT + NOISY_P1),
    BoardEntry("h2, geometric proposer", "h2_geometric", "search:h2/geometric", EXACT + LIMITED + ("p1-fastfiz-v1",)),
    BoardEntry("h2, expert-iteration policy proposer", "h2_exit", "search:h2/exit", EXACT + LIMITED + LONG),
    BoardEntry("h2, SAC ensemble proposer (base)", "h2_base", "search:h2/base", EXACT + LIMITED + LONG),
    BoardEntry("h2, SAC ensemble proposer (near_miss)", "h2_near_miss", "search:h2/near_miss", EXACT + LIMITED + LONG),
    BoardEntry("h2, SAC ensemble proposer (gentle)", "h2_gentle", "search:h2/gentle", EXACT + LIMITED),
    BoardEntry("h2, SAC ensemble proposer (both)", "h2_both", "search:h2/both", EXACT + LIMITED + LONG),
    BoardEntry("h2, exact-play shot ranker proposer", "h2_ranked_exact", "search:h2/ranked_exact", EXACT + LIMITED),
    BoardEntry("h2, small exact-play shot ranker proposer", "h2_ranked_exact_small", "search:h2/ranked_exact_small",
               EXACT + LIMITED + LONG),
    BoardEntry("PUCT, geometric proposer", "puct_geometric", "search:puct/geometric", EXACT + LIMITED),
    BoardEntry("PUCT, SAC ensemble proposer (near_miss)", "puct_near_miss", "search:puct/near_miss", EXACT + LIMITED),
    BoardEntry("PUCT, SAC ensemble proposer (base)", "puct_base", "search:puct/base", EXACT + LIMITED),
    BoardEntry("PUCT, SAC ensemble proposer (gentle)", "puct_gentle", "search:puct/gentle", EXACT + LIMITED),
    BoardEntry("PUCT, SAC ensemble proposer (both)", "puct_both", "search:puct/both", EXACT + LIMITED),
    BoardEntry("PUCT, expert-iteration policy proposer", "puct_exit", "search:puct/exit", EXACT + LIMITED),
    BoardEntry("PUCT, exact-play shot ranker proposer", "puct_ranked_exact", "search:puct/ranked_exact", EXACT + LIMITED),
    BoardEntry("PUCT, small exact-play shot ranker proposer", "puct_ranked_exact_small", "search:puct/ranked_exact_small",
               EXACT + LIMITED),
    BoardEntry("robust search over the shot ranker, blind to the leave", "robust_ranked", "search:robust/for_noise", NOISY),
    BoardEntry("position-aware robust search (the default of search.py under noise)", "position_default", "search:default", NOISY),
    BoardEntry("position-aware robust search over the shot ranker", "position_ranked", "search:default/for_noise",
          ("p1-x5-v1", "p1-variable-v1")),
    BoardEntry("position-aware robust search over the expert-iteration policy", "position_exit", "search:default/exit", NOISY_P1),
    BoardEntry("expert iteration policy (fastfiz_x5), seed 0", "exit_x5_s0", "results/policies/exit_x5/seed0.pt",
               NOISY_P1 + RANKING_MATCH),
    BoardEntry("position-aware robust search over the fastfiz_x5 expert-iteration policy", "position_exit_x5", "search:default/exit_x5",
          NOISY_P1),
    BoardEntry("position-aware robust search over the fastfiz_x5 expert-iteration policy and shot ranker (half each)",
               "position_exit_x5_mixed", "search:default/exit_x5_mixed", NOISY_P1),
    BoardEntry("expert iteration policy started from SAC under fastfiz, seed 0", "exit_fastfiz_s0",
          "results/policies/exit_fastfiz/seed0.pt", NOISY_P1),
    BoardEntry("league: greedy", "league_greedy", "league:greedy", MATCH),
    BoardEntry("league: greedy_r (run value)", "league_greedy_r", "league:greedy_r", MATCH),
    BoardEntry("league: safety_r (run value, safety shots)", "league_safety_r", "league:safety_r", MATCH),
    BoardEntry("league: greedy_v (table value)", "league_greedy_v", "league:greedy_v", RANKING_MATCH),
    BoardEntry("league: safety_v (table value, safety shots)", "league_safety_v", "league:safety_v", RANKING_MATCH),
    BoardEntry("league: safety_rx (run value, safety shots, fastfiz_x5 expert-iteration proposer)", "league_safety_rx",
               "league:safety_rx", RANKING_MATCH),
)


def check_entries() -> None:
    """Entries name no code: every spec is a baseline, a policy file, a search or a league player."""
    from .spec import AgentError, AgentSpec, SpecKind

    for e in ENTRIES:
        try:
            spec = AgentSpec.parse(e.spec)
        except AgentError:
            spec = None
        shipped = spec is not None and spec.kind is SpecKind.POLICY and spec.text.startswith("results/") and spec.text.endswith(".pt")
        if spec is None or not (spec.kind in (SpecKind.BASELINE, SpecKind.SEARCH, SpecKind.LEAGUE) or shipped):
            raise ValueError(f"leaderboard entry {e.slug}: spec {e.spec!r} is not a baseline, policy file, search or league player")
        if any(q in e.row for q in "'\"\\"):
            raise ValueError(f"leaderboard entry {e.slug}: a row name has no quotes (it is quoted in the recorded command)")


__all__ = ["ENTRIES", "BoardEntry", "check_entries"]
