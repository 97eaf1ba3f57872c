"""Each protocol of the benchmark as one object (:data:`PROTOCOLS`, keyed by
:class:`billiards.protocol.Protocol`): how it plays one resumable unit for any agent (a block of
innings, a chain, a match), the ledger record that unit writes, the rules a record must follow
on its track (:func:`record_problem`), and the per-unit values and figures a scorecard derives
from the records.

Every agent's every answer passes through :class:`Clock` (its shots checked, its simulations
counted, its own time measured). The evaluation and its ledger (:mod:`billiards.bench.run`), the
viewer's replays and the offline datasets all play and read units through here.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING

import numpy as np

from billiards.protocol import Protocol

from .spec import AgentError
from .tracks import Track, is_int, number_problem

if TYPE_CHECKING:
    from .adapters import Agent


# ----------------------------------------------------------------------------- playing units


def params_noise(track: Track):
    from billiards.physics import get_params
    from billiards.physics.noise import get_noise

    return get_params(track.physics), get_noise(track.noise)


class Clock:
    """The agent's own cost: seconds of its calls (wall clock, on the one thread it runs on;
    the CPU clock costs tens of microseconds a read on some machines), decisions, simulations.
    Every answer of every agent passes here: its shots checked (:func:`checked_action`: real,
    finite numbers of the right shape) and its simulation counter read, which must be a whole
    number that never goes down."""

    def __init__(self, agent: Agent):
        from .adapters import checked_action

        self.checked_action = checked_action
        self.agent, self.cpu, self.decisions = agent, 0.0, 0
        self.sims0 = self.sims = _sims(agent, None)

    def act(self, obs, tables, levels):
        t0 = time.perf_counter()
        raw = self.agent.act(obs, tables, levels)
        self.cpu += time.perf_counter() - t0
        self.decisions += len(tables)
        shots = self.checked_action(raw, len(tables), self.agent.name)
        self.sims = _sims(self.agent, self.sims)
        return shots

    def record(self) -> dict:
        return {"decisions": self.decisions, "cpu_s": round(self.cpu, 6), "sims": int(self.sims - self.sims0)}


def _sims(agent: Agent, before: int | None) -> int:
    """The agent's simulation counter (``agent.sims``: simulations used so far), checked: a whole
    number >= 0, never below ``before`` (what it said after its previous call); an AgentError
    naming the agent otherwise."""
    sims = getattr(agent, "sims", 0)
    whole = isinstance(sims, (int, np.integer)) and not isinstance(sims, (bool, np.bool_))
    if not whole or sims < 0:
        raise AgentError(f"agent {agent.name}'s simulation counter (sims) is {str(sims)[:40]!r}, not a whole number >= 0: "
                         f"it counts the simulations the agent has used so far")
    if before is not None and sims < before:
        raise AgentError(f"agent {agent.name}'s simulation counter (sims) went down from {before} to {sims}: it counts "
                         f"the simulations the agent has used so far and never goes down")
    return int(sims)


def _levels(env) -> np.ndarray | None:
    return None if env._levels is None else env._levels.copy()


def play_innings(agent: Agent, track: Track, first: int, n: int, on_shot=None, on_step=None) -> dict:
    """Innings ``first .. first + n - 1`` of an innings or P1 track, side by side: inning i's
    rack and noise from seed ``track.seed + i`` (each inning depends only on its seed and the
    agent). ``on_shot(row, shot, before, info, level)`` after every shot of every inning (a replay
    records them): the inning's row in the block, the shot's index, its table, the env's info
    rows and the level it played at. ``on_step(shot, before, obs, raw, step)`` after every step
    of the whole block (a dataset records them): the tables and observations before the shot,
    the raw shots played and the env's ``step`` return (observation, reward, terminated,
    truncated, info)."""
    from billiards.envs.gym_vector import Billiards4BallVectorEnv

    spec = track.protocol.spec
    env = Billiards4BallVectorEnv(n, start=spec.start, on_miss=spec.on_miss, max_shots=track.shots, physics=track.physics,
                                  noise=track.noise, normalize_actions=False)
    obs, info = env.reset(seed=track.seed + first)
    agent.reset(track.seed + first)
    clock = Clock(agent)
    score = np.zeros((n, track.shots), dtype=bool)
    foul = np.zeros((n, track.shots), dtype=bool)
    tables = info["positions"]
    for t in range(track.shots):
        levels = _levels(env)
        raw = clock.act(obs, tables.copy(), levels if track.tells_level else None)
        step = env.step(raw)
        if on_step is not None:
            on_step(t, tables, obs, raw, step)
        obs, _, _, _, info = step
        score[:, t], foul[:, t] = info["score"], info["foul"]
        if on_shot is not None:
            for i in range(n):
                on_shot(i, t, tables[i], {k: v[i] for k, v in info.items()}, None if levels is None else levels[i])
        tables = info["positions"]
    return {"first": first, "n": n, "score": score.astype(int).tolist(), "foul": foul.astype(int).tolist(), **clock.record()}


def play_chain(agent: Agent, track: Track, index: int, on_shot=None) -> dict:
    """Chain ``index`` of a P3 track: the opening rack, seed ``track.seed + index``, until the first
    miss or foul or the cap (``on_shot`` as for :func:`play_innings`, the row always 0)."""
    from billiards.envs.gym_vector import Billiards4BallVectorEnv

    seed, spec = track.seed_of(index), track.protocol.spec
    env = Billiards4BallVectorEnv(1, start=spec.start, on_miss=spec.on_miss, max_shots=track.shots, physics=track.physics,
                                  noise=track.noise, normalize_actions=False)
    obs, info = env.reset(seed=seed)
    agent.reset(seed)
    clock = Clock(agent)
    length, fouled = 0, False
    while True:
        before, levels = info["positions"].copy(), _levels(env)
        raw = clock.act(obs, before.copy(), levels if track.tells_level else None)
        obs, _, terminated, truncated, info = env.step(raw)
        if on_shot is not None:
            on_shot(0, length, before[0], {k: v[0] for k, v in info.items()}, None if levels is None else levels[0])
        if not info["score"][0]:
            fouled = bool(info["foul"][0])
            break
        length += 1
        if terminated[0] or truncated[0]:
            break
    return {"index": index, "seed": seed, "length": length, "ended_by_foul": fouled, **clock.record()}


class MatchPlayer:
    """The scored agent as a player of :func:`billiards.league.play.play_match`."""

    def __init__(self, clock: Clock, tells_level: bool):
        self.clock, self.tells_level = clock, tells_level

    def reseed(self, seed: int) -> None:
        self.clock.agent.reset(seed)

    def act(self, view: np.ndarray, level: float | None = None) -> np.ndarray:
        from billiards import domain
        from billiards.envs._common import with_levels
        from billiards.league.players import to_env_action

        levels = None if level is None or not self.tells_level else np.array([float(level)])
        obs = with_levels(domain.observation(view[None]), levels)
        raw = self.clock.act(obs, view[None].astype(np.float64), levels)
        return to_env_action(raw[0])


_POOL: dict = {}  # (track name, opponent) -> league player (built once a process)


def play_match(agent: Agent, track: Track, index: int, on_shot=None, opponent=None) -> dict:
    """Match ``index`` of a match track: opponent ``index // units``, the break alternating; the
    agent plays white. ``on_shot`` as for :func:`billiards.league.play.play_match`; ``opponent``:
    the pool player to use (default: the process's own, built once)."""
    from billiards.league.play import play_match as play

    from .adapters import league_player

    params, noise = params_noise(track)
    j, i = divmod(index, track.units)
    name = track.opponents[j]
    if opponent is None:
        if (track.name, name) not in _POOL:
            _POOL[(track.name, name)] = league_player(name, noise, params)[0]
        opponent = _POOL[(track.name, name)]
    clock = Clock(agent)
    seed = track.seed_of(index)
    result = play(MatchPlayer(clock, track.tells_level), opponent, seed=seed,
                  first="white" if i % 2 == 0 else "yellow", target=track.target, max_innings=track.max_innings,
                  start=track.protocol.spec.start, noise=noise, physics=params, on_shot=on_shot)
    winner = {"white": "agent", "yellow": "opponent", None: None}[result["winner"]]
    return {"index": index, "opponent": name, "seed": seed, "first": "agent" if i % 2 == 0 else "opponent",
            "winner": winner, "points": [result["scores"]["white"], result["scores"]["yellow"]],
            "innings": result["innings"], **clock.record()}


# ----------------------------------------------------------------------------- the fingerprint


def fingerprint_data(track: Track) -> list:
    """What a track's fingerprint covers: its first racks and the nearest-red reference agent's
    first decisions on them (the shots, and the tables and outcomes they give, noise included),
    rounded to 1e-9."""
    from billiards.envs.gym_vector import Billiards4BallVectorEnv

    from .adapters import NearestRedAgent

    params, noise = params_noise(track)
    ref = NearestRedAgent(params)
    r9 = lambda a: np.round(np.asarray(a, dtype=np.float64), 9).tolist()
    out: list = []
    if track.protocol.spec.two_player:
        from billiards.envs import sagu_v0
        from billiards.envs.sagu import AGENTS, shooter_view
        from billiards.league.players import to_env_action

        env = sagu_v0.raw_env(first="white", target=track.target, max_innings=track.max_innings, start=track.protocol.spec.start,
                              noise=noise, physics=params)
        env.reset(seed=track.seed)
        for _ in range(6):
            view = shooter_view(env.game.positions, AGENTS.index(env.agent_selection))
            action = to_env_action(ref.act(None, view[None], None)[0])
            env.step(action)
            out.append([r9(env.game.positions), list(env.game.scores), env.agent_selection])
        return out
    spec = track.protocol.spec
    env = Billiards4BallVectorEnv(4, start=spec.start, on_miss=spec.on_miss, max_shots=max(track.shots, 2), physics=track.physics,
                                  noise=track.noise, normalize_actions=False)
    obs, info = env.reset(seed=track.seed)
    out.append([r9(info["positions"]), r9(obs), None if env._levels is None else r9(env._levels)])
    for _ in range(2):
        raw = ref.act(obs, info["positions"], None)
        obs, reward, term, trunc, info = env.step(raw)
        out.append([r9(raw), r9(info["positions"]), info["score"].astype(int).tolist(), info["foul"].astype(int).tolist()])
    return out


# ----------------------------------------------------------------------------- records and values


def _per_inning(records: list[dict], key: str) -> np.ndarray:
    return np.asarray([row for r in records for row in r[key]], dtype=float)


def _match_score(rec: dict) -> float:
    return 1.0 if rec["winner"] == "agent" else 0.0 if rec["winner"] == "opponent" else 0.5


def _innings_problem(track: Track, rec: dict) -> str | None:
    first = rec["unit"] * track.block
    n = min(track.block, track.units - first)
    if not (is_int(rec["first"]) and is_int(rec["n"]) and rec["first"] == first and rec["n"] == n):
        return f"a block of {track.name} starting at inning {first} holds innings {first} to {first + n - 1}"
    for key in ("score", "foul"):
        rows = rec[key]
        if not (isinstance(rows, list) and len(rows) == n and all(isinstance(r, list) and len(r) == track.shots for r in rows)):
            return f"its {key} must be {n} innings of {track.shots} shots each"
        if any(not is_int(x) or x not in (0, 1) for r in rows for x in r):
            return f"its {key} holds a shot that is not 0 or 1 (a shot scores one point or none)"
    if any(s and f for rs, rf in zip(rec["score"], rec["foul"]) for s, f in zip(rs, rf)):
        return "a shot both scores and fouls"
    if rec["decisions"] != n * track.shots:
        return f"{rec['decisions']} decisions, but {n} innings of {track.shots} shots take {n * track.shots}"
    return None

def _chain_problem(track: Track, rec: dict) -> str | None:
    unit, cap = rec["unit"], track.shots
    if not (is_int(rec["index"]) and is_int(rec["seed"]) and rec["index"] == unit and rec["seed"] == track.seed + unit):
        return f"chain {unit} of {track.name} has index {unit} and seed {track.seed + unit}"
    length = rec["length"]
    if not (is_int(length) and 0 <= length <= cap):
        return f"its length {str(length)[:40]} is not a whole number in [0, {cap}] (the chain's cap)"
    if not isinstance(rec["ended_by_foul"], bool) or (length == cap and rec["ended_by_foul"]):
        return "its ended_by_foul must be true or false, and false for a chain that reached the cap"
    decisions = length + (1 if length < cap else 0)  # every scoring shot, and the miss or foul that ended it
    if rec["decisions"] != decisions:
        return f"{rec['decisions']} decisions, but a chain of {length} (cap {cap}) takes {decisions}"
    return None

def _match_problem(track: Track, rec: dict) -> str | None:
    unit = rec["unit"]
    j, i = divmod(unit, track.units)
    want = {"index": unit, "opponent": track.opponents[j], "seed": track.seed_of(unit),
            "first": "agent" if i % 2 == 0 else "opponent"}
    if any(rec[k] != v or isinstance(rec[k], bool) for k, v in want.items()):
        return f"match {unit} of {track.name} is {', '.join(f'{k} {v!r}' for k, v in want.items())}"
    points = rec["points"]
    if not (isinstance(points, list) and len(points) == 2):
        return "its points must be [the agent's, the opponent's]"
    for who, p in zip(("agent's", "opponent's"), points):
        if why := number_problem(p, 0, track.target, True):
            return f"the {who} points {str(p)[:40]}: {why} (a match to {track.target})"
    mine, theirs = points
    if mine >= track.target and theirs >= track.target:
        return f"both players reached {track.target} points: the match ends when the first does"
    winner = "agent" if mine > theirs else "opponent" if theirs > mine else None
    if rec["winner"] != winner:
        return f"its winner {rec['winner']!r} is not the one its points {mine:g} - {theirs:g} give ({winner!r})"
    innings = rec["innings"]
    if not (is_int(innings) and 1 <= innings <= track.max_innings + 1):
        return f"its innings {str(innings)[:40]} is not a whole number in [1, {track.max_innings + 1}]"
    if (max(mine, theirs) >= track.target) == (innings > track.max_innings):
        return (f"{innings} innings with points {mine:g} - {theirs:g}: a match ends at {track.target} points or, "
                f"short of them, after {track.max_innings} innings")
    if mine > rec["decisions"]:
        return f"the agent scored {mine:g} points with {rec['decisions']} shots (a point takes a shot)"
    return None


# ----------------------------------------------------------------------------- the protocols


class UnitProtocol:
    """One protocol of the benchmark: its unit played for any agent, the unit's record checked
    against the track's rules, the values and figures of finished records."""

    def __init__(self, kind: Protocol):
        self.kind = kind

    @property
    def spec(self):
        return self.kind.spec

    def play(self, agent: Agent, track: Track, unit: int, on_shot=None) -> dict:
        """Unit ``unit`` of ``track`` played by ``agent``: its ledger record (``on_shot`` as the
        protocol's own function takes it)."""
        raise NotImplementedError

    def record_problem(self, track: Track, rec: dict) -> str | None:
        """What in a unit's record breaks the track's rules for this protocol, or None."""
        raise NotImplementedError

    def values(self, track: Track, records: list[dict]) -> list:
        """The per-unit scores the intervals resample (a scorecard's ``values``)."""
        raise NotImplementedError

    def figures(self, track: Track, records: list[dict]) -> dict:
        """The protocol's own figures of a scorecard from the finished records (at least one)."""
        raise NotImplementedError


class InningsBlocks(UnitProtocol):
    """``innings`` and ``p1``: blocks of ``track.block`` random-start innings played side by side;
    points per inning (innings) or each inning's success per shot (P1)."""

    def play(self, agent, track, unit, on_shot=None):
        first = unit * track.block
        return play_innings(agent, track, first, min(track.block, track.units - first), on_shot)

    def record_problem(self, track, rec):
        return _innings_problem(track, rec)

    def values(self, track, records):
        if self.kind is Protocol.INNINGS:
            return _per_inning(records, "score").sum(axis=1).astype(int).tolist()
        return [round(float(v), 6) for v in _per_inning(records, "score").mean(axis=1)]

    def figures(self, track, records):
        from billiards import stats

        score, foul = _per_inning(records, "score"), _per_inning(records, "foul")
        rate = score.mean(axis=1)  # each inning's success rate: the unit of resampling
        return {"success_per_shot": {"mean": round(float(score.mean()), 6), "ci95": stats.bootstrap_ci(rate),
                                     "n_shots": int(score.size), "n_innings": int(len(rate))},
                "foul_per_shot": {"mean": round(float(foul.mean()), 6), "ci95": stats.bootstrap_ci(foul.mean(axis=1))},
                "points_per_inning": stats.summary(score.sum(axis=1))}


class Chains(UnitProtocol):
    """``p3``: one chain from the opening rack per seed, to its first miss or foul or the cap."""

    def play(self, agent, track, unit, on_shot=None):
        return play_chain(agent, track, unit, on_shot)

    def record_problem(self, track, rec):
        return _chain_problem(track, rec)

    def values(self, track, records):
        return [int(r["length"]) for r in records]

    def figures(self, track, records):
        from billiards import stats

        lengths = np.asarray([r["length"] for r in records], dtype=float)
        shots = lengths.sum() + sum(1 for r in records if r["length"] < track.shots)
        return {"chain": {**stats.summary(lengths), "max": int(lengths.max()), "reached_cap": int((lengths >= track.shots).sum()),
                          "cap": track.shots},
                "success_per_shot": {"mean": round(float(lengths.sum() / max(shots, 1)), 6), "n_shots": int(shots)}}


class Matches(UnitProtocol):
    """``match``: matches against each reference opponent, the break alternating; win rate and
    an Elo against the pool's fixed ratings."""

    def play(self, agent, track, unit, on_shot=None):
        return play_match(agent, track, unit, on_shot)

    def record_problem(self, track, rec):
        return _match_problem(track, rec)

    def values(self, track, records):
        return [_match_score(r) for r in records]

    def figures(self, track, records):
        from billiards import stats

        ratings = dict(track.ratings)
        scores = [_match_score(r) for r in records]
        total = float(sum(scores))
        out = {"match": {"matches": len(records), "wins": sum(r["winner"] == "agent" for r in records),
                         "draws": sum(r["winner"] is None for r in records), "win_rate": round(total / len(records), 6),
                         "ci95": stats.wilson(total, len(records)),
                         "points_for": round(float(np.mean([r["points"][0] for r in records])), 4),
                         "points_against": round(float(np.mean([r["points"][1] for r in records])), 4),
                         "by_opponent": {o: round(float(np.mean([s for s, r in zip(scores, records) if r["opponent"] == o])), 4)
                                         for o in track.opponents if any(r["opponent"] == o for r in records)}}}
        results = [(ratings[r["opponent"]], s) for r, s in zip(records, scores)]
        out["elo"] = stats.elo_against(results)
        out["elo_ci95"] = stats.elo_interval(results)
        return out


PROTOCOLS: dict[Protocol, UnitProtocol] = {Protocol.INNINGS: InningsBlocks(Protocol.INNINGS), Protocol.P1: InningsBlocks(Protocol.P1),
                                           Protocol.P3: Chains(Protocol.P3), Protocol.MATCH: Matches(Protocol.MATCH)}


def protocol_of(track: Track) -> UnitProtocol:
    """The protocol object a track plays."""
    return PROTOCOLS[track.protocol]


def record_problem(track: Track, rec: dict) -> str | None:
    """What in the ledger record of one finished unit of ``track`` (a block of innings, a chain,
    a match; its shape already checked: ``unit``, ``decisions`` and ``sims`` integers >= 0,
    ``cpu_s`` a number >= 0) breaks the track's rules, or None: its index among the track's
    units, its innings, seeds, opponent and break as the track plays them, every outcome within
    what the protocol allows (a shot scores 0 or 1 and is not both a score and a foul; a chain
    lies within the cap and ends as chains end; a match's points, winner and innings follow the
    match rules), the decisions the protocol asks for, and the simulations within the track's
    budget."""
    unit, n_units = rec["unit"], track.n_blocks()
    if unit >= n_units:
        return f"unit {unit} is not one of {track.name}'s {n_units} units (0 to {n_units - 1})"
    if not (isinstance(rec["cpu_s"], (int, float)) and math.isfinite(rec["cpu_s"])):
        return f"its cpu_s {rec['cpu_s']!r} is not a finite number"
    if rec["sims"] > track.budget * rec["decisions"]:
        return (f"{rec['sims']} simulations for {rec['decisions']} decisions, past the track's budget of {track.budget} "
                "per decision")
    try:
        return protocol_of(track).record_problem(track, rec)
    except (KeyError, TypeError, ValueError) as err:  # a key missing or of another kind: a sentence
        return f"it is not a {track.protocol} unit record ({type(err).__name__}: {str(err)[:80]})"


__all__ = ["Chains", "Clock", "InningsBlocks", "MatchPlayer", "Matches", "PROTOCOLS", "UnitProtocol", "fingerprint_data",
           "params_noise", "play_chain", "play_innings", "play_match", "protocol_of", "record_problem"]
