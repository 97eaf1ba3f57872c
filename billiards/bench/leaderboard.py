"""The leaderboard: every scorecard of ``results/bench/``, one table per track, with intervals.

Sources (all data; nothing here names code). The folder a scorecard lies in gives its status: a
scorecard claims none (:func:`billiards.compat.upgrade_scorecard`).

* ``scorecards/<track>/<slug>/scorecard.json``: evaluations played here by ``evaluate.py``
  (status ``verified``);
* ``recorded/<track>/<slug>.json``: a training setting's committed final evaluations (the paper
  tables' runs, whose weights are not in the repository: their innings protocol on the training
  runs' own evaluation racks, not the track's held-out seeds; status ``recorded``);
* ``submissions/<track>/<slug>/scorecard.json``: outside entries, by pull request (status
  ``unverified`` until the same command is run here and its scorecard moves to ``scorecards/``).

A played scorecard's figures are never read from it: :func:`derive` computes every one from its
sealed ledger and its track's rules, and refuses a card that claims otherwise. Every outside
string is written inert (:mod:`billiards.bench.text`).

Scorecards sharing an agent ``group`` (a policy's training seeds) pool into one row: the mean
and the interquartile mean over every (seed, unit) score with stratified bootstrap intervals
(:func:`billiards.stats.aggregate`). Partial and limited scorecards are left out, each reported
by name; a played scorecard whose agent (or group) is named after a path is refused. The board
counts the project's rows (``agents``, ``scorecards``) apart from the outside submissions
(``outside``, present when there are any). ``python -m billiards.bench leaderboard`` writes
``leaderboard.json``, ``leaderboard.md``, ``leaderboard.png`` and ``leaderboard_profiles.png``
(CI rebuilds the first two and diffs them). :func:`placement` says where a score would rank on
the committed snapshot (``results/leaderboard.json``).
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path
from typing import Callable

import numpy as np

from billiards.compat import upgrade_scorecard
from billiards.files import SCORECARD_JSON, UNITS_FILE, RunFileError, atomic_write_text, display_path, read_run_json

from billiards import stats
from billiards.protocol import Protocol

from .text import md_text, one_line, plot_label
from .tracks import COMPUTE_CURVES, TRACKS

STATUSES = ("verified", "recorded", "unverified")
OUTSIDE = "unverified"  # the status of outside submissions: counted apart from the project's rows
SOURCES = (("verified", "scorecards/*/*/scorecard.json"), ("recorded", "recorded/*/*.json"),
           ("unverified", "submissions/*/*/scorecard.json"))
# performance profiles: the share of units (innings, chains) scoring above each threshold
PROFILE_THRESHOLDS = {Protocol.INNINGS: tuple(range(10)), Protocol.P1: tuple(round(0.1 * k, 1) for k in range(10)),
                      Protocol.P3: (0, 1, 2, 5, 10, 20, 50, 100, 200, 500)}
REBUILD = "python -m billiards.bench leaderboard"

# The project's earlier figures for the same agent and protocol, beside the leaderboard's:
# (track, row) -> (their protocol, the committed files, what differs from the track). Each is
# read from its files with its own interval (the same bootstrap), and agrees when the two
# intervals overlap.
EARLIER: dict[tuple[str, str], tuple[Protocol, tuple[str, ...], str]] = {
    **{("innings-v1", row): (Protocol.INNINGS, tuple(f"results/training/paper/table5/{folder}/seed{k}/eval.json" for k in range(3)),
                             "the training runs' final evaluations, on their own evaluation racks")
       for row, folder in (("SAC aim + features, foul penalty (Table 5)", "foul_penalty"),
                           ("SAC aim + features, both bonuses (Table 5)", "both"),
                           ("SAC aim + features, gentle (Table 5)", "gentle"),
                           ("SAC aim + features, near-miss (Table 5)", "near_miss"))},
    ("p1-exact-v1", "h2, geometric proposer"): (
        Protocol.P1, ("results/search/korean_medium/geometric_h2_p1.json",), "P1 of 100 innings x 100 shots, seed 0"),
    ("p1-exact-v1", "PUCT, geometric proposer"): (
        Protocol.P1, ("results/search/korean_medium/geometric_puct_p1.json",), "P1 of 100 innings x 100 shots, seed 0"),
    ("p3-exact-v1", "h2, geometric proposer"): (
        Protocol.P3, ("results/search/korean_medium/geometric_h2_p3.json",), "10 chains (seeds 0-9), cap 10,000"),
    ("p3-exact-v1", "PUCT, geometric proposer"): (
        Protocol.P3, ("results/search/korean_medium/geometric_puct_p3.json",), "10 chains (seeds 0-9), cap 10,000"),
    ("p1-fastfiz-v1", "position-aware robust search (the default of search.py under noise)"): (
        Protocol.P1, ("results/noisy_track/headline/target40_fastfiz_p1/results.json",), "P1 of 100 innings x 50 shots, seed 2"),
    ("p3-fastfiz-v1", "position-aware robust search (the default of search.py under noise)"): (
        Protocol.P3, ("results/noisy_track/headline/target40_fastfiz_p3/results.json",), "300 chains, seeds 2000-2299"),
    ("p1-fastfiz-v1", "robust search over the shot ranker, blind to the leave"): (
        Protocol.P1, ("results/noisy_track/headline/ranked500_fastfiz_p1/results.json",), "P1 of 100 innings x 50 shots, seed 2"),
    ("p3-fastfiz-v1", "robust search over the shot ranker, blind to the leave"): (
        Protocol.P3, ("results/noisy_track/headline/ranked500_fastfiz_p3/results.json",), "300 chains, seeds 2000-2299"),
    ("p1-x5-v1", "position-aware robust search over the shot ranker"): (
        Protocol.P1, ("results/noisy_track/headline/position_fastfiz_x5_p1/results.json",), "P1 of 100 innings x 50 shots, seed 2"),
    ("p1-x5-v1", "robust search over the shot ranker, blind to the leave"): (
        Protocol.P1, ("results/noisy_track/headline/ranked500_fastfiz_x5_p1/results.json",), "P1 of 100 innings x 50 shots, seed 2"),
}


def earlier_figure(kind: Protocol, files: tuple[str, ...]) -> dict:
    """An earlier figure and its 95 % interval, read from its committed files (innings: points
    per inning over every seed's training evaluation; P1: per-shot success resampled by inning;
    P3: the chain mean resampled by chain)."""
    from billiards.files import ROOT

    data = [json.loads((ROOT / f).read_text()) for f in files]
    if kind is Protocol.INNINGS:
        runs = [d["points"] for d in data]
        agg = stats.aggregate(runs, statistic=np.mean) if len(runs) > 1 else None
        value, ci = (agg["iqm"], agg["ci95"]) if agg else (float(np.mean(runs[0])), stats.bootstrap_ci(runs[0]))
    elif kind is Protocol.P1:
        rates = np.asarray(data[0]["values"], dtype=float) / data[0]["extra"]["shots_per_inning"]
        value, ci = float(rates.mean()), stats.bootstrap_ci(rates)
    else:
        value, ci = float(np.mean(data[0]["values"])), stats.bootstrap_ci(data[0]["values"])
    return {"value": round(value, 6), "ci95": ci, "where": ", ".join(files)}


_FILE_SUFFIX = re.compile(r"\.(py|pt|pth|zip|ckpt|pkl|onnx|json|npz|safetensors)(:\w+)?$", re.IGNORECASE)
_SEARCH_NAME = re.compile(r"^search:[\w-]+(/[\w-]+)?$")  # search:h2/geometric names a search, not a file


def looks_like_path(name: str) -> bool:
    """Whether an agent or row name names a file or folder: a path separator (but in a search's
    own ``search:<search>/<proposer>``), a home, relative or drive prefix, or a file's suffix
    (``.py``, ``.pt``, ``.zip`` ...)."""
    name = str(name).strip()
    if "\\" in name or name.startswith(("~", ".", "/")) or re.match(r"^[A-Za-z]:[\\/]", name):
        return True
    if "/" in name and not _SEARCH_NAME.match(name):
        return True
    return bool(_FILE_SUFFIX.search(name))


def _load(path: Path) -> dict:
    try:
        card = read_run_json(path)  # no link followed, a regular file of bounded size and depth
    except RunFileError as err:
        raise ValueError(f"not a readable scorecard: {err}") from None
    except OSError as err:
        raise ValueError(f"{display_path(path)}: not a readable scorecard ({err.strerror or type(err).__name__})") from None
    if not isinstance(card, dict):
        raise ValueError(f"{display_path(path)}: not a scorecard (a JSON object)")
    card = upgrade_scorecard(card)  # the board gives the status (collect)
    for key in ("track", "version", "agent"):
        if key not in card:
            raise ValueError(f"{display_path(path)}: a scorecard needs the key {key!r}")
    if card["track"] not in TRACKS:
        raise ValueError(f"{display_path(path)}: unknown track {card['track']!r}")
    if card["version"] != TRACKS[card["track"]].version:
        raise ValueError(f"{display_path(path)}: track {card['track']} is at version {TRACKS[card['track']].version}, "
                         f"the scorecard at {card['version']}: play it again on the current version")
    return card


def left_out(card: dict) -> str | None:
    """Why a scorecard does not enter the board (partial or limited), or None."""
    if card.get("partial"):
        return (f"partial, {card.get('units_done', 'not all')} units finished: the same command with out=<its directory> "
                "plays the rest")
    if card.get("limit"):
        return f"limited to {_count(card['limit'], 'unit')} per opponent or track (limit=): play the whole track, without limit="
    return None


def _check_names(path: Path, card: dict) -> None:
    """A played scorecard's agent and group name a leaderboard row: never a path."""
    agent = card["agent"] if isinstance(card["agent"], dict) else {}
    for key in ("name", "group"):
        value = agent.get(key)
        if isinstance(value, str) and looks_like_path(value):
            again = "name=<your agent's name>" if key == "name" else "group=<the row's name>"
            raise ValueError(f"{display_path(path)}: its agent's {key} {value!r} is a path, not a name; a leaderboard row "
                             f"is never named after a file: evaluate it again with {again} "
                             f"(docs/benchmark.md, Submitting an agent)")
    if not (isinstance(agent.get("name"), str) and agent["name"].strip()):
        raise ValueError(f"{display_path(path)}: its agent has no name: evaluate it again with name=<your agent's name>")


def collect(root: Path, report: Callable[[str], None] | None = None) -> list[dict]:
    """Every scorecard under ``root`` with its status and source path. Partial and limited ones
    are left out, each reported to ``report`` (a line naming the file and why); a played one
    whose agent is named after a path, or whose claims its ledger does not give, is refused
    (ValueError). A played scorecard's figures are those its ledger gives (:func:`derive`), a
    recorded one's unit scores checked against the track's rules: the board reads no figure a
    card only claims."""
    cards = []
    for status, pattern in SOURCES:
        for path in sorted(Path(root).glob(pattern)):
            card = _load(path)
            why = left_out(card)
            if why is not None:
                if report is not None:
                    report(f"left out {display_path(path)}: {why}")
                continue
            if status != "recorded":
                _check_names(path, card)
                card.update(derive(path, card))
            else:
                check_recorded(path, card)
            card["status"] = status
            card["source"] = display_path(path)
            cards.append(card)
    return cards


COMPUTE = ("observation", "simulator")


def derive(path: Path, card: dict) -> dict:
    """Every figure of the played scorecard at ``path`` as its sealed ledger (``units.jsonl``
    beside it) and its track's rules give it -- the one derivation the board ranks by:

    * the ledger: every record sealed, of the scorecard's run, each unit once, every one of the
      track's units and no other (:func:`billiards.bench.run.read_ledger`), each within the
      track's rules (:func:`~billiards.bench.protocols.record_problem`: points per inning in
      [0, shots], a shot scoring 0 or 1, chains within the cap, match results as the match rules
      give them, decisions as the protocol asks, simulations within the budget);
    * the run: the identity its records carry is the one of the track, the agent and the limit
      the scorecard names (its name, group and class are those it was played under);
    * the figures (:func:`billiards.bench.run.ledger_figures`: the mean, the success and foul
      rates, the chain and match summaries, the win rate, the Elo, every interval, the per-unit
      scores, the time and simulations per decision), computed from the records;
    * the class: ``observation`` or ``simulator``, and an agent that simulated is ``simulator``.

    Returns the figures; a scorecard that claims anything else (:data:`billiards.bench.run.DERIVED`,
    :func:`~billiards.bench.run.claim_problems`) is refused: ValueError naming the file and what
    differs."""
    from .run import EvaluationError, claim_problems, ledger_figures, read_ledger, run_identity

    track = TRACKS[card["track"]]
    ledger = path.parent / UNITS_FILE
    if not os.path.lexists(ledger):
        raise ValueError(f"{display_path(path)}: no {UNITS_FILE} beside it (a scorecard is checked against its ledger)")
    run = card.get("run")
    if not isinstance(run, str):
        raise ValueError(f"{display_path(path)}: it names no run (the identity its ledger's records carry)")
    try:
        records = read_ledger(ledger, run, repair=False, track=track)
    except EvaluationError as err:
        raise ValueError(str(err)) from None
    if len(records) != track.n_blocks():
        raise ValueError(f"{display_path(ledger)}: {len(records)} units, the track has {track.n_blocks()}")
    if not isinstance(card["agent"], dict) or run_identity(track, card["agent"], card.get("limit")) != run:
        raise ValueError(f"{display_path(path)}: its agent or limit is not the one its ledger was played with (the run "
                         f"identity of {track.name}, its agent and its limit is not {run})")
    derived = ledger_figures(track, list(records.values()))
    if problems := claim_problems(card, derived, display_path(path)):
        raise ValueError(f"{problems[0]}; the board takes every figure from {display_path(ledger)}")
    compute = card["agent"].get("compute", "observation")
    if compute not in COMPUTE:
        raise ValueError(f"{display_path(path)}: its agent's class {one_line(repr(compute))[:60]} is none of "
                         f"{', '.join(COMPUTE)}")
    if compute == "observation" and derived["sims_per_decision"] > 0:
        raise ValueError(f"{display_path(path)}: its agent claims to use the observation only, but its ledger counts "
                         f"{derived['sims_per_decision']} simulations per decision (class simulator)")
    return derived


def check_against_ledger(path: Path, card: dict) -> dict:
    """A played scorecard must agree with the sealed ledger beside it (:func:`derive`); returns
    the figures the ledger gives."""
    return derive(path, card)


def check_recorded(path: Path, card: dict) -> None:
    """A recorded scorecard (a training setting's own evaluations, no ledger): one list of unit
    scores per training seed, each a whole evaluation of its track within the track's rules
    (:meth:`~billiards.bench.tracks.Track.values_problem`: 100 innings of 0 to 10 points on
    ``innings-v1``), and no figure of its own."""
    track = TRACKS[card["track"]]
    runs = card.get("runs")
    if not (isinstance(runs, list) and runs and all(isinstance(r, dict) for r in runs)):
        raise ValueError(f"{display_path(path)}: a recorded scorecard holds runs, one list of unit scores per training seed")
    for k, r in enumerate(runs):
        if why := track.values_problem(r.get("values"), track.n_values()):
            raise ValueError(f"{display_path(path)}: run {k}: {why}")
    from .run import DERIVED

    for key in DERIVED:
        if card.get(key) is not None:
            raise ValueError(f"{display_path(path)}: a recorded scorecard claims no {key} (its figures come from its runs)")


def _runs(cards: list[dict]) -> list[list[float]]:
    out = []
    for c in cards:
        if "runs" in c:  # a recorded setting: one list of scores per training seed
            out += [r["values"] for r in c["runs"]]
        else:
            out.append(c["values"])
    return out


def _row(track, cards: list[dict]) -> dict:
    """One leaderboard row from the scorecards of one group on one track."""
    first = cards[0]
    row = {"row": first["agent"].get("group") or first["agent"]["name"], "status": first["status"],
           "agents": [c["agent"]["name"] for c in cards], "sources": [c["source"] for c in cards],
           "compute": first["agent"].get("compute", "observation"), "version": first["version"]}
    runs = _runs(cards)
    row["seeds"] = len(runs)
    if track.protocol.spec.two_player:
        card = first
        ratings = dict(track.ratings)
        opponents = [track.opponents[u // track.units] for u in range(len(card["values"]))]
        results = [(ratings[o], v) for o, v in zip(opponents, card["values"])]
        against = {o: [v for p, v in zip(opponents, card["values"]) if p == o] for o in track.opponents}
        row.update(score=stats.elo_against(results), elo_ci95=stats.elo_interval(results), win_rate=card["match"]["win_rate"],
                   ci95=card["match"]["ci95"], matches=card["match"]["matches"], by_opponent=card["match"]["by_opponent"],
                   by_opponent_ci95={o: stats.wilson(sum(v), len(v)) for o, v in against.items() if v})
    else:
        if len(runs) == 1:
            summary = stats.summary(runs[0])
            row.update(score=summary["mean"], ci95=summary["ci95"], iqm=summary["iqm"])
        else:
            mean = stats.aggregate(runs, statistic=np.mean)
            iqm = stats.aggregate(runs)
            row.update(score=mean["iqm"], ci95=mean["ci95"], iqm=iqm["iqm"], iqm_ci95=iqm["ci95"], per_seed=mean["per_seed"])
        if track.protocol is Protocol.P3:
            pooled = np.concatenate([np.asarray(r, dtype=float) for r in runs])
            row.update(median=float(np.median(pooled)), max=int(pooled.max()), reached_cap=int((pooled >= track.shots).sum()),
                       chains=int(pooled.size))
    ms = [c["ms_per_decision"] for c in cards if c.get("ms_per_decision") is not None]
    sims = [c["sims_per_decision"] for c in cards if c.get("sims_per_decision") is not None]
    row["ms_per_decision"] = round(float(np.mean(ms)), 3) if ms else None
    row["sims_per_decision"] = round(float(np.mean(sims)), 1) if sims else None
    earlier = EARLIER.get((track.name, row["row"]))
    if earlier is not None:
        kind, files, differs = earlier
        fig = earlier_figure(kind, files)
        lo, hi = row["ci95"]
        row["earlier"] = {**fig, "intervals_overlap": bool(fig["ci95"][0] <= hi and lo <= fig["ci95"][1]),
                          "within_ci95": bool(lo <= fig["value"] <= hi), "protocol": differs}
    if first.get("note"):
        row["note"] = first["note"]
    return row


def leaderboard(root: Path, report: Callable[[str], None] | None = None) -> dict:
    """The leaderboard of the scorecards under ``root`` (see the module docstring; ``report``
    as for :func:`collect`). ValueError where it finds none, naming where it looked."""
    cards = collect(root, report)
    if not cards:
        where = ", ".join(pattern for _, pattern in SOURCES)
        found = "no such folder" if not Path(root).is_dir() else f"looked for {where}"
        raise ValueError(f"no scorecards to rank under {display_path(root)} ({found}); nothing written "
                         f"(`{REBUILD} --scorecards DIR` reads another folder)")
    tracks = {}
    for name, track in TRACKS.items():
        groups: dict[tuple, list[dict]] = {}
        for c in cards:
            if c["track"] == name:
                groups.setdefault((c["status"], c["agent"].get("group") or c["agent"]["name"]), []).append(c)
        ranked = sorted(((_row(track, g), _runs(g)) for g in groups.values()), key=lambda rr: (-rr[0]["score"], rr[0]["row"]))
        entry = {"rules": track.rules(), "description": track.description, "version": track.version,
                 "metric": track.metric, "rows": [r for r, _ in ranked]}
        # the no-simulator division: the agents that act from the observation alone, ranked among themselves
        division = [(row, runs) for row, runs in ranked if row["compute"] == "observation"]
        entry["no_simulator"] = {"rows": [row["row"] for row, _ in division]}
        for (row, runs), (_, below) in zip(ranked, ranked[1:]):  # is each row really above the next?
            row["p_above_next"] = stats.probability_of_improvement(runs, below)  # (a unit: an inning, a chain, a match)
        entry["no_simulator"]["p_above_next"] = {row["row"]: stats.probability_of_improvement(runs, below)
                                                 for (row, runs), (_, below) in zip(division, division[1:])}
        if not track.protocol.spec.two_player and ranked:
            thresholds = PROFILE_THRESHOLDS[track.protocol]
            entry["profiles"] = {"thresholds": list(thresholds),
                                 "rows": {row["row"]: stats.performance_profile(runs, thresholds) for row, runs in ranked}}
        tracks[name] = entry
    board = {"rebuild": REBUILD, **_counts(tracks, cards, own=True)}
    outside = _counts(tracks, cards, own=False)
    if outside["agents"]:  # present only where there are outside rows
        board["outside"] = outside
    board["tracks"] = tracks
    board["compute_curves"] = compute_curves(tracks)
    return board


def compute_curves(tracks: dict) -> dict:
    """Each exact track's compute curve (:data:`~billiards.bench.tracks.COMPUTE_CURVES`): for every
    row scored on at least two of its budgets, its figure with the interval and its milliseconds
    per decision at each budget (simulations per decision, cheapest first)."""
    out = {}
    for base, names in COMPUTE_CURVES.items():
        points: dict[str, list] = {}
        for name in names:
            for r in tracks[name]["rows"]:
                points.setdefault(r["row"], []).append({"budget": TRACKS[name].budget, "track": name, "score": r["score"],
                                                         "ci95": r["ci95"], "ms_per_decision": r["ms_per_decision"]})
        out[base] = {"tracks": list(names), "metric": TRACKS[names[-1]].metric,
                     "rows": {row: p for row, p in sorted(points.items()) if len(p) >= 2}}
    return out


def _counts(tracks: dict, cards: list[dict], own: bool) -> dict:
    """The distinct rows and the scorecards of the project (``own``) or of outside submissions."""
    rows = {r["row"] for t in tracks.values() for r in t["rows"] if (r["status"] != OUTSIDE) == own}
    return {"agents": len(rows), "scorecards": sum((c["status"] != OUTSIDE) == own for c in cards)}


def _count(n: int, what: str) -> str:
    return f"{n} {what}{'' if n == 1 else 's'}"


_FORMATS = {Protocol.P1: lambda v: f"{100 * v:.2f} %", Protocol.INNINGS: lambda v: f"{v:.3f}", Protocol.P3: lambda v: f"{v:.2f}",
            Protocol.MATCH: lambda v: f"{v:.0f}"}


def format_score(protocol: Protocol | str, value: float) -> str:
    """A row's figure as the board writes it: success per shot in %, points per inning to three
    decimals, chain lengths to two, Elo to the unit."""
    return _FORMATS[Protocol(protocol)](value)


def _division_markdown(name: str, track, t: dict) -> list[str]:
    """A track's no-simulator division: its observation-only rows ranked among themselves, with
    the probability that each is above the next one of the division."""
    division = t.get("no_simulator", {})
    by_name = {r["row"]: r for r in t["rows"]}
    rows = [by_name[name] for name in division.get("rows", [])]
    if not rows:
        return []
    fmt = lambda v: format_score(track.protocol, v)  # noqa: E731
    lines = [f"### {name}: the no-simulator division", "",
             "The agents that act from the observation alone (no simulator at decision time: learned policies and "
             "baselines), ranked among themselves.", "",
             f"| # | agent | {track.protocol.spec.metric_name} [95 %] | "
             + ("win rate [95 %] | " if track.protocol.spec.two_player else "")
             + "P(above the next) [95 %] | ms / decision | overall # | status |",
             "|---|---|---|---|---|---|---|" + ("---|" if track.protocol.spec.two_player else "")]
    overall = {r["row"]: i for i, r in enumerate(t["rows"], 1)}
    above = division.get("p_above_next", {})
    for i, r in enumerate(rows, 1):
        p = above.get(r["row"])
        second = "" if p is None else f"{p['p']:.2f} [{p['ci95'][0]:.2f}, {p['ci95'][1]:.2f}]"
        if track.protocol.spec.two_player:
            main = f"{fmt(r['score'])} [{fmt(r['elo_ci95'][0])}, {fmt(r['elo_ci95'][1])}]"
            second = f"{100 * r['win_rate']:.1f} % [{100 * r['ci95'][0]:.1f}, {100 * r['ci95'][1]:.1f}] | " + second
        else:
            main = f"{fmt(r['score'])} [{fmt(r['ci95'][0])}, {fmt(r['ci95'][1])}]"
        cost = "—" if r["ms_per_decision"] is None else f"{r['ms_per_decision']:.2f}"
        lines.append(f"| {i} | {md_text(r['row'])} | {main} | {second} | {cost} | {overall[r['row']]} | {r['status']} |")
    return lines + [""]


def _opponents_markdown(name: str, track, t: dict) -> list[str]:
    """A match track's rows against each opponent of its pool: the score (a draw counting half)
    and its Wilson 95 % interval."""
    if not track.protocol.spec.two_player or not t["rows"]:
        return []
    ratings = dict(track.ratings)
    lines = [f"### {name}: against each opponent", "",
             f"Each row's score against each player of the pool ({track.units} matches each, the break alternating; "
             "a draw counts half), with its Wilson 95 % interval; the pool's ratings in the header.", "",
             "| agent | " + " | ".join(f"{md_text(o)} ({ratings[o]:.0f})" for o in track.opponents) + " |",
             "|---|" + "---|" * len(track.opponents)]
    for r in t["rows"]:
        cells = []
        for o in track.opponents:
            ci = r.get("by_opponent_ci95", {}).get(o)
            cells.append("" if ci is None else f"{100 * r['by_opponent'][o]:.0f} % [{100 * ci[0]:.0f}, {100 * ci[1]:.0f}]")
        lines.append(f"| {md_text(r['row'])} | " + " | ".join(cells) + " |")
    return lines + [""]


def _curves_markdown(board: dict) -> list[str]:
    """The compute curves: each search row's figure on an exact track at each budget."""
    curves = {base: c for base, c in board.get("compute_curves", {}).items() if c["rows"]}
    if not curves:
        return []
    lines = ["## How cheaply search solves the exact tracks", "",
             "Each row's figure on an exact track and on its compute-limited versions (the same racks and seeds, the "
             "search budget cut to 25, 50 and 100 simulations per decision): figure [95 %] · ms per decision "
             "(`leaderboard_compute.png`). An agent that acts without the simulator scores the same at every budget.", ""]
    for base, c in curves.items():
        protocol = TRACKS[c["tracks"][-1]].protocol
        budgets = [TRACKS[n].budget for n in c["tracks"]]
        lines += [f"### {base}: {protocol.spec.metric_name}", "",
                  "| agent | " + " | ".join(f"{b} sims" for b in budgets) + " |", "|---|" + "---|" * len(budgets)]
        for row, pts in c["rows"].items():
            at = {p["budget"]: p for p in pts}
            cells = []
            for b in budgets:
                p = at.get(b)
                if p is None:
                    cells.append("—")
                    continue
                fmt = lambda v: format_score(protocol, v)  # noqa: E731
                cost = "" if p["ms_per_decision"] is None else f" · {p['ms_per_decision']:.2f}"
                cells.append(f"{fmt(p['score'])} [{fmt(p['ci95'][0])}, {fmt(p['ci95'][1])}]{cost}")
            lines.append(f"| {md_text(row)} | " + " | ".join(cells) + " |")
        lines.append("")
    return lines


def markdown(board: dict) -> str:
    """``leaderboard.md``."""
    outside = board.get("outside")
    others = "" if not outside else \
        (f", and {_count(outside['agents'], 'outside agent')} submitted to it ({_count(outside['scorecards'], 'scorecard')}; "
         "status unverified)")
    lines = ["# Leaderboard", "",
             f"Every agent of the project on every track it applies to ({board['agents']} agents, {board['scorecards']} "
             f"scorecards){others}. Rebuilt by `" + board["rebuild"] + "` from the scorecards under `results/bench/` "
             "(docs/benchmark.md: the tracks, how to score and submit an agent). Intervals are 95 % bootstrap "
             "intervals resampled by inning, chain or match (rows pooling training seeds: a stratified bootstrap over "
             "seeds and their units; IQM: the interquartile mean); match win rates carry Wilson intervals. Compute: "
             "the agent's own CPU milliseconds per decision on one core of the machine that played it, and simulations "
             "per decision (the tracks allow 400; a -b<N> track N). Status: **verified** played here by the recorded command; "
             "**recorded** a training setting's own final evaluations (same protocol, the training runs' evaluation "
             "racks, no weights in the repository); **unverified** an outside submission not yet re-run.", ""]
    for name, t in board["tracks"].items():
        track = TRACKS[name]
        metric = track.protocol.spec.metric_name
        lines += [f"## {name}", "", f"{t['description']}: {t['rules']}.", ""]
        if not t["rows"]:
            lines += ["(no scorecards yet)", ""]
            continue
        extra = {Protocol.INNINGS: "IQM", Protocol.P1: "IQM", Protocol.P3: "median · IQM · max · at cap",
                 Protocol.MATCH: "win rate [95 %]"}[track.protocol]
        lines += [f"| # | agent | {metric} [95 %] | {extra} | P(above the next) [95 %] | seeds | ms · sims / decision | class "
                  "| status | earlier figure |", "|---|---|---|---|---|---|---|---|---|---|"]
        for i, r in enumerate(t["rows"], 1):
            fmt = lambda v: format_score(track.protocol, v)  # noqa: E731
            if track.protocol.spec.two_player:
                main = f"{fmt(r['score'])} [{fmt(r['elo_ci95'][0])}, {fmt(r['elo_ci95'][1])}]"
                more = f"{100 * r['win_rate']:.1f} % [{100 * r['ci95'][0]:.1f}, {100 * r['ci95'][1]:.1f}]"
            else:
                main = f"{fmt(r['score'])} [{fmt(r['ci95'][0])}, {fmt(r['ci95'][1])}]"
                more = fmt(r["iqm"]) if track.protocol is not Protocol.P3 else \
                    f"{r['median']:.1f} · {r['iqm']:.2f} · {r['max']} · {r['reached_cap']}/{r['chains']}"
            cost = "—" if r["ms_per_decision"] is None else f"{r['ms_per_decision']:.2f} · {r['sims_per_decision']:.0f}"
            earlier = ""
            if "earlier" in r:
                e = r["earlier"]
                verdict = "agrees" if e["within_ci95"] else "intervals overlap" if e["intervals_overlap"] else "differs"
                earlier = f"{fmt(e['value'])} [{fmt(e['ci95'][0])}, {fmt(e['ci95'][1])}], {verdict} ({e['protocol']})"
            above = "" if "p_above_next" not in r else \
                f"{r['p_above_next']['p']:.2f} [{r['p_above_next']['ci95'][0]:.2f}, {r['p_above_next']['ci95'][1]:.2f}]"
            lines.append(f"| {i} | {md_text(r['row'])} | {main} | {more} | {above} | {r['seeds']} | {cost} | {md_text(r['compute'])} "
                         f"| {r['status']} | {earlier} |")
        lines.append("")
        lines += _opponents_markdown(name, track, t)
        lines += _division_markdown(name, track, t)
    lines += _curves_markdown(board)
    lines += ["P(above the next): the probability that a unit (inning, chain, match) of the row scores above one of the row "
              "below it, ties counting half (rliable's probability of improvement, stratified bootstrap interval); 0.5 "
              "means the two rows cannot be told apart. `leaderboard.json` also holds each track's performance profiles "
              "(the share of units above each threshold; `leaderboard_profiles.png`) and each row's scorecards "
              "(`sources`), each with the command that played it and its commit.", ""]
    return "\n".join(lines)


def _pyplot():
    """matplotlib's pyplot on the file backend (the figures are written, never shown)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _saved(plt, fig, path: Path) -> Path:
    """Write ``fig`` to ``path`` as every figure of the board is written (the same bytes for the
    same board: no software stamp) and close it."""
    fig.tight_layout()
    fig.savefig(path, dpi=110, metadata={"Software": None})
    plt.close(fig)
    return path


def draw_figure(board: dict, path: Path) -> Path:
    """``leaderboard.png``: one panel per track, each row's figure with its interval."""
    plt = _pyplot()

    names = [n for n, t in board["tracks"].items() if t["rows"]]
    fig, axes = plt.subplots(len(names), 1, figsize=(8, 1.2 + 0.28 * sum(len(board["tracks"][n]["rows"]) for n in names)),
                             squeeze=False, gridspec_kw={"height_ratios": [max(len(board["tracks"][n]["rows"]), 1) for n in names]})
    for ax, name in zip(axes[:, 0], names):
        rows = board["tracks"][name]["rows"][::-1]
        y = np.arange(len(rows))
        protocol = TRACKS[name].protocol
        scale = 100.0 if protocol is Protocol.P1 else 1.0
        score = np.array([r["score"] for r in rows]) * (scale if not protocol.spec.two_player else 1)
        if protocol.spec.two_player:
            lo = score - np.array([r["elo_ci95"][0] for r in rows])
            hi = np.array([r["elo_ci95"][1] for r in rows]) - score
        else:
            lo = score - np.array([r["ci95"][0] for r in rows]) * scale
            hi = np.array([r["ci95"][1] for r in rows]) * scale - score
        colors = ["tab:blue" if r["compute"] == "observation" else "tab:orange" for r in rows]
        if protocol.spec.two_player:  # ratings: dots with their intervals, not bars from 0
            ax.errorbar(score, y, xerr=[lo, hi], fmt="none", ecolor="black", capsize=2)
            ax.scatter(score, y, c=colors, zorder=3)
        else:
            ax.barh(y, score, xerr=[lo, hi], color=colors, capsize=2)
        ax.set_yticks(y, [plot_label(r["row"], 48, 46) for r in rows], fontsize=6)
        ax.set_title(f"{name}: {board['tracks'][name]['metric'].replace('_', ' ')}" + (" (%)" if scale == 100 else ""), fontsize=8)
        ax.tick_params(axis="x", labelsize=6)
    from matplotlib.patches import Patch

    axes[0, 0].legend(handles=[Patch(color="tab:blue", label="observation only"),
                               Patch(color="tab:orange", label="searches with the simulator (400 / decision)")],
                      fontsize=6, loc="lower right")
    return _saved(plt, fig, path)


def build(root: Path, out: Path, figure: bool = True, report: Callable[[str], None] | None = None) -> list[Path]:
    """Write ``leaderboard.json``, ``.md`` (and ``.png``) into ``out`` from the scorecards under
    ``root`` (``report``: as for :func:`collect`)."""
    return write(leaderboard(root, report), out, figure)


def write(board: dict, out: Path, figure: bool = True) -> list[Path]:
    """Write a board's ``leaderboard.json``, ``.md`` (and ``.png``) into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = [atomic_write_text(out / "leaderboard.json", json.dumps(board, indent=2) + "\n"),
             atomic_write_text(out / "leaderboard.md", markdown(board))]
    if figure:
        paths.append(draw_figure(board, out / "leaderboard.png"))
        paths.append(draw_profiles(board, out / "leaderboard_profiles.png"))
        if any(c["rows"] for c in board.get("compute_curves", {}).values()):
            paths.append(draw_compute_curves(board, out / "leaderboard_compute.png"))
    return paths


def draw_compute_curves(board: dict, path: Path) -> Path:
    """``leaderboard_compute.png``: each search row's figure against its simulations per decision,
    one panel per exact track, with the intervals."""
    plt = _pyplot()

    curves = {base: c for base, c in board["compute_curves"].items() if c["rows"]}
    rows = sorted({row for c in curves.values() for row in c["rows"]})
    colour = {row: plt.get_cmap("tab10" if len(rows) <= 10 else "tab20")(i) for i, row in enumerate(rows)}  # one per row, every panel
    fig, axes = plt.subplots(1, len(curves), figsize=(4.8 * len(curves), 4.2), squeeze=False)
    for ax, (base, c) in zip(axes[0], curves.items()):
        protocol = TRACKS[c["tracks"][-1]].protocol
        scale = 100.0 if protocol is Protocol.P1 else 1.0
        for row, pts in c["rows"].items():
            x = np.array([p["budget"] for p in pts], dtype=float)
            y = np.array([p["score"] for p in pts]) * scale
            lo = y - np.array([p["ci95"][0] for p in pts]) * scale
            hi = np.array([p["ci95"][1] for p in pts]) * scale - y
            ax.errorbar(x, y, yerr=[lo, hi], marker=".", linewidth=1, capsize=2, color=colour[row], label=plot_label(row, 40, 40, ""))
        ax.set_xscale("log")
        if protocol is Protocol.P3:  # chains from under one to the cap: a log scale past 1
            ax.set_yscale("symlog", linthresh=1.0)
        budgets = [TRACKS[n].budget for n in c["tracks"]]
        ax.set_xticks(budgets, [str(b) for b in budgets], fontsize=7)
        ax.minorticks_off()
        ax.set_xlabel("simulations per decision", fontsize=7)
        ax.set_title(f"{base}: {protocol.spec.metric_name}" + (" (%)" if scale != 1.0 else ""), fontsize=8)
        ax.tick_params(axis="y", labelsize=6)
        ax.legend(fontsize=4, loc="lower right")
    return _saved(plt, fig, path)


def draw_profiles(board: dict, path: Path) -> Path:
    """``leaderboard_profiles.png``: the performance profiles of the exact tracks' rows."""
    plt = _pyplot()

    names = [n for n in ("innings-v1", "p1-exact-v1", "p3-exact-v1", "p3-fastfiz-v1") if board["tracks"][n].get("profiles")]
    fig, axes = plt.subplots(1, len(names), figsize=(4.6 * len(names), 4.2), squeeze=False)
    for ax, name in zip(axes[0], names):
        prof = board["tracks"][name]["profiles"]
        x = np.arange(len(prof["thresholds"]))
        for row, fractions in prof["rows"].items():
            ax.plot(x, fractions, marker=".", linewidth=1, label=plot_label(row, 40, 40, ""))
        ax.set_xticks(x, [str(t) for t in prof["thresholds"]], fontsize=6)
        ax.set_title(f"{name}: share of units above tau", fontsize=8)
        ax.set_ylim(-0.02, 1.02)
        ax.tick_params(axis="y", labelsize=6)
        ax.legend(fontsize=4, loc="upper right")
    return _saved(plt, fig, path)


def record_training(setting: Path, row: str, slug: str, root: Path | None = None) -> Path:
    """A ``recorded`` innings-v1 scorecard from a training setting's committed final evaluations
    (``<setting>/seed<k>/eval.json``: the innings protocol, 100 innings x 10 shots)."""
    from billiards.files import ROOT

    root = root or ROOT / "results" / "bench"
    runs = []
    for seed_dir in sorted(Path(setting).glob("seed*")):
        ev = json.loads((seed_dir / "eval.json").read_text())
        if (ev.get("n_innings"), ev.get("max_shots"), ev.get("start"), ev.get("noise", "none")) != (100, 10, "random", "none"):
            raise ValueError(f"{seed_dir}/eval.json is not the innings protocol (100 random-start innings of 10 shots, exact)")
        runs.append({"seed_dir": display_path(seed_dir), "eval_seed": ev["seed"], "values": ev["points"]})
    if not runs:
        raise ValueError(f"{setting}: no seed*/eval.json")
    track = TRACKS["innings-v1"]
    card = {"track": track.name, "version": track.version,
            "agent": {"name": slug, "group": row, "kind": "recorded", "compute": "observation"},
            "runs": runs, "ms_per_decision": None, "sims_per_decision": None,
            "note": "the training runs' final evaluations (their own evaluation racks, not the track's seeds)",
            "command": f"python -m billiards.bench record-training {display_path(setting)} --row '{row}' --slug {slug}"}
    path = root / "recorded" / track.name / f"{slug}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(card, indent=2) + "\n")
    return path


def snapshot_path() -> Path:
    """The committed leaderboard snapshot (in a checkout, or the copy an installed package carries)."""
    from billiards.files import ROOT

    return ROOT / "results" / "leaderboard.json"


def headline_value(card: dict) -> float:
    """The figure of a scorecard that the board ranks rows by (a row's ``score``): points per
    inning (innings), success per shot (P1), the mean chain length (P3), the Elo (matches)."""
    metric = TRACKS[card["track"]].protocol.spec.metric
    return float(card[metric]) if metric == "elo" else float(card[metric]["mean"])


def placement(track: str, value: float, board: dict | str | Path | None = None, version: int | None = None,
              division: bool = False) -> str:
    """Where ``value`` (a scorecard's :func:`headline_value`) would rank among the rows of
    ``track`` on ``board`` (a board dict or a ``leaderboard.json``; default the committed
    snapshot), ranked as the board ranks them: "would rank k of n on <track>, between A (a) and
    B (b)" (n counts the new entry; first place: "above A", last: "below A", equal to rows:
    "tied with A (a)"). ``division``: among the track's no-simulator division alone ("would rank k
    of n in the no-simulator division of <track>, ..."). ValueError when the board cannot be read or
    has no such track (or holds another ``version`` of it)."""
    if not isinstance(board, dict):
        path = Path(board) if board is not None else snapshot_path()
        try:
            board = json.loads(path.read_text())
        except (OSError, ValueError) as err:
            raise ValueError(f"no leaderboard to place it on: {display_path(path)} ({type(err).__name__}: {err})") from None
    entry = board.get("tracks", {}).get(track)
    if entry is None:
        raise ValueError(f"the leaderboard has no track {track!r}")
    if version is not None and entry.get("version", version) != version:
        raise ValueError(f"the leaderboard ranks {track} version {entry['version']}, the score is of version {version}")
    protocol = TRACKS[track].protocol if track in TRACKS else None
    show = lambda r: f"{one_line(r['row'])} ({format_score(protocol, r['score'])})"  # noqa: E731
    rows = entry["rows"]
    if division:
        members = set(entry.get("no_simulator", {}).get("rows", []))
        rows = [r for r in rows if r["row"] in members]
    rows = sorted(rows, key=lambda r: (-r["score"], r["row"]))
    v = round(float(value), 6)
    above = [r for r in rows if round(r["score"], 6) > v]
    tied = [r for r in rows if round(r["score"], 6) == v]
    below = [r for r in rows if round(r["score"], 6) < v]
    rank, n = len(above) + 1, len(rows) + 1
    head = f"would rank {rank} of {n} " + (f"in the no-simulator division of {track}" if division else f"on {track}")
    if tied:
        return f"{head}, tied with " + _and([show(r) for r in tied])
    if not rows:
        return f"{head} (the first row on it)"
    if not above:
        return f"{head}, above {show(below[0])}"
    if not below:
        return f"{head}, below {show(above[-1])}"
    return f"{head}, between {show(above[-1])} and {show(below[0])}"


def _and(items: list[str]) -> str:
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def placement_line(card: dict, board: dict | str | Path | None = None) -> str:
    """``evaluate.py``'s last line: where the scorecard would rank on the committed board, with
    the caveat of a limited run; what is missing where it cannot be placed."""
    name = one_line(card["agent"]["name"])
    try:
        where = placement(card["track"], headline_value(card), board, card.get("version"))
        if card["agent"].get("compute", "observation") == "observation":  # it competes in the division too
            where += "; it " + placement(card["track"], headline_value(card), board, card.get("version"), division=True)
    except (KeyError, ValueError) as err:
        return f"placement: {name} cannot be placed ({err})"
    caveat = "" if not card.get("limit") else \
        (f"; but a limited run ({_count(card['limit'], 'unit')} per opponent or track) is a quick look, not comparable to the full-track "
         "rows nor a leaderboard entry")
    return f"placement: {name} {where}{caveat}"


def compare(first: Path, second: Path) -> dict:
    """Two agents' scorecards of one track compared unit by unit: every unit of a track is the
    same rack (inning, chain or match) for every agent, so the difference of their per-unit
    scores (a scorecard's ``values``: per shot for innings and P1, chain lengths for P3, match
    scores) is paired, and its bootstrap interval is narrower than the two scorecards'
    intervals side by side. ``first``, ``second``: scorecard files or their folders, complete
    (not partial nor limited) and of the same track and version. A scorecard with its ledger
    beside it is compared by the scores its ledger gives (:func:`derive`; one that claims others
    is refused); one without, by its own, each within the track's rules. ValueError says what
    differs or why the two cannot be compared (never a NaN)."""
    cards = []
    for path in (Path(first), Path(second)):
        path = path / SCORECARD_JSON if path.is_dir() else path
        card = _load(path)
        if card.get("partial") or card.get("limit"):
            raise ValueError(f"{display_path(path)}: a partial or limited scorecard (play the whole track first)")
        if os.path.lexists(path.parent / UNITS_FILE):
            card.update(derive(path, card))
        elif why := TRACKS[card["track"]].values_problem(card.get("values")):
            raise ValueError(f"{display_path(path)}: {why}; it cannot be compared")
        if not isinstance(card["agent"], dict):
            card["agent"] = {}
        cards.append((path, card))
    (pa, a), (pb, b) = cards
    if a["track"] != b["track"]:
        raise ValueError(f"{display_path(pa)} is on {a['track']}, {display_path(pb)} on {b['track']}: compare one track")
    va, vb = (np.asarray(c["values"], dtype=np.float64) for c in (a, b))
    if va.shape != vb.shape:
        raise ValueError(f"{display_path(pa)} has {va.size} units, {display_path(pb)} {vb.size}")
    track = TRACKS[a["track"]]
    if va.size != track.n_values():
        raise ValueError(f"{display_path(pa)} and {display_path(pb)} hold {va.size} unit scores each, but a whole evaluation "
                         f"of {track.name} has {track.n_values()}: they cannot be compared")
    unit, scale = {Protocol.INNINGS: ("success per shot", 1.0 / track.shots), Protocol.P1: ("success per shot", 1.0),
                   Protocol.P3: ("chain length", 1.0), Protocol.MATCH: ("match score", 1.0)}[track.protocol]
    diff = (va - vb) * scale
    name = lambda c: one_line(c["agent"].get("name", "?"))  # noqa: E731
    return {"track": a["track"], "unit": unit, "first": name(a), "second": name(b),
            "first_mean": round(float(va.mean() * scale), 6), "second_mean": round(float(vb.mean() * scale), 6),
            "difference": round(float(diff.mean()), 6), "ci95": stats.bootstrap_ci(diff), "units": int(diff.size),
            "first_better": int((diff > 0).sum()), "second_better": int((diff < 0).sum()),
            "sources": [display_path(pa), display_path(pb)]}


__all__ = ["COMPUTE", "EARLIER", "OUTSIDE", "PROFILE_THRESHOLDS", "REBUILD", "SOURCES", "STATUSES", "build",
           "check_against_ledger", "check_recorded", "collect", "compare", "compute_curves", "derive", "draw_compute_curves",
           "draw_figure", "draw_profiles",
           "earlier_figure", "format_score", "headline_value", "leaderboard", "left_out", "looks_like_path", "markdown",
           "placement", "placement_line", "record_training", "snapshot_path", "write"]
