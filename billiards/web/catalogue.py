"""The agents the page may ask for a shot: a closed list, built by the benchmark's own
:func:`billiards.bench.adapters.resolve_agent` and kept once built.

The list (:func:`catalogue`): the three baselines, ``search:h2`` (depth-2 lookahead over
geometric draws), ``search:h2/base`` (the same over the shipped ``base`` ensemble),
``search:default`` (what ``search.py`` plays under the request's noise: the robust search over
the noise's shot ranker under noise), every league player of ``conf/match.yaml``
(``league:<name>``) and every shipped policy under ``results/policies``. Nothing else is
resolved: a spec naming code (``file.py:name``, ``module:name``, ``sb3:...``) is refused before
the benchmark sees it.

A built agent is kept per (spec, physics, noise) and used by one request at a time (its own
lock); it is reseeded with the request's seed before it answers, so the same request gets the
same shot. For a search, what it considered is read cheaply on the side: the proposer's first
candidates for the table (each simulated once, exactly: a few hundred shots, about a
millisecond) and the search's own statistics of its choice (its value, its predicted reward
``r1``, its simulations and the table it predicts). Under execution noise the chosen shot is
replayed ``replays`` times with the noise: the share that scores and where the cue ball ends,
and, for a search that prices leaves with a table value (the position-aware search), the value
of each replay's leave as it prices it.

For a recorded run (/api/considered) the agent is the run's own: a search run's search built
from its ``config.yaml`` (:func:`search_run_entry`: its proposer, budget, table and noise, custom
ones included), a benchmark scorecard's agent built for its track (:func:`bench_entry`, only from
a spec that names no code). :func:`reconsider` asks it again on a recorded table, reseeded with
the unit's seed (its candidates and estimates; the shot it picks now may differ from the recorded
one, whose search generator had another state in the run) and replays the recorded shot under
the run's noise.
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from billiards import domain
from billiards.bench.spec import AgentSpec, SpecKind
from billiards.files import ROOT
from billiards.physics import DEFAULT_PRESET, get_params, simulate_batch
from billiards.physics.noise import get_noise

BUDGET = 400  # simulations per decision of the searches (the benchmark's tracks')
SEARCHES = {
    "search:h2": "depth-2 lookahead (h2) over geometric draws, 400 simulations",
    "search:h2/base": "h2 over the shipped base ensemble (three trained policies), 400 simulations",
    "search:default": "what search.py plays under this noise (exact: h2; noisy: the robust search over the noise's shot ranker)",
}
BASELINE_NOTES = {
    "random": "uniform in the action box",
    "nearest": "a full-ball hit on the nearest red at half power",
    "random_aim": "uniform inside the nearest red's aim window",
}
MAX_CACHED = 12
TOP_CANDIDATES = 12


class UnknownAgent(ValueError):
    """A spec outside the closed list."""


def policy_specs(root: Path = ROOT) -> list[str]:
    """The shipped policies: ``results/policies/<name>/seed<k>.pt``, as repository paths."""
    return sorted(str(p.relative_to(root)) for p in (root / "results" / "policies").glob("*/*.pt"))


_CATALOGUE: dict = {}


def catalogue(root: Path = ROOT) -> dict[str, dict]:
    """spec -> {kind, note} for every agent the page may ask (read once a process)."""
    if root not in _CATALOGUE:
        _CATALOGUE[root] = _catalogue(root)
    return _CATALOGUE[root]


def league_names(root: Path = ROOT) -> list[str]:
    """The league players of ``conf/match.yaml`` (the play view's opponents)."""
    return [AgentSpec.parse(spec).player for spec, entry in catalogue(root).items() if entry["kind"] is SpecKind.LEAGUE]


def _catalogue(root: Path) -> dict[str, dict]:
    from billiards.bench.adapters import league_players

    out: dict[str, dict] = {name: {"kind": SpecKind.BASELINE, "note": note} for name, note in BASELINE_NOTES.items()}
    out.update({spec: {"kind": SpecKind.SEARCH, "note": note} for spec, note in SEARCHES.items()})
    for name, cfg in league_players().items():
        kind = cfg.get("kind", "search")
        note = f"league player ({kind}" + (f", {cfg.get('search', 'robust')} search" if kind in ("search", "safety") else "") + ")"
        out[f"{SpecKind.LEAGUE}:{name}"] = {"kind": SpecKind.LEAGUE, "note": note}
    out.update({spec: {"kind": SpecKind.POLICY, "note": "a shipped trained policy"} for spec in policy_specs(root)})
    return out


class _Recorder:
    """A proposer in front of the search's own: passes every call through and keeps the first
    call's candidates of a decision (the search's first look at the table)."""

    def __init__(self, inner):
        self.inner = inner
        self.first = None

    def propose(self, positions, k, rng, *args, **kwargs):
        out = self.inner.propose(positions, k, rng, *args, **kwargs)
        if self.first is None:
            self.first = np.array(out, dtype=np.float64, copy=True)
        return out

    def __getattr__(self, name):  # everything else is the inner proposer's
        return getattr(self.inner, name)


class LoadedAgent:
    """A built agent, its lock, the table and noise it plays (``params``, ``noise_model``: a
    run's own, which may be custom; ``physics``, ``noise``: their names), and the hooks that read
    what its search considered."""

    def __init__(self, spec: str, agent, physics: str, noise: str, params=None, noise_model=None):
        self.spec, self.agent, self.physics, self.noise = spec, agent, physics, noise
        self.params = params if params is not None else get_params(physics)
        self.noise_model = noise_model if noise_model is not None else get_noise(noise)
        self.lock = threading.Lock()
        self.recorder, self.last = None, None
        actor = getattr(agent, "actor", None) or getattr(getattr(agent, "player", None), "actor", None)
        self.actor = actor
        if actor is not None and hasattr(actor, "proposer"):
            self.recorder = _Recorder(actor.proposer)
            actor.proposer = self.recorder
            search = actor.search

            def recorded(*args, **kwargs):
                result = search(*args, **kwargs)
                if self.last is None:
                    self.last = result
                return result

            actor.search = recorded


_CACHE: OrderedDict = OrderedDict()
_BUILD = threading.Lock()  # building (Hydra's global state, the first compilations) one at a time


def get_entry(spec: str, physics: str, noise: str, root: Path = ROOT) -> LoadedAgent:
    """The built agent ``spec`` for this table and noise (built once; :class:`UnknownAgent` for a
    spec outside the list, :class:`billiards.bench.adapters.AgentError` when it cannot be built)."""
    from billiards.bench.adapters import resolve_agent

    spec = str(spec).strip()
    known = catalogue(root)
    if spec not in known:
        leagues = ", ".join(k for k, entry in known.items() if entry["kind"] is SpecKind.LEAGUE)
        raise UnknownAgent(f"unknown agent {spec!r}: the viewer offers random, nearest, random_aim, {', '.join(SEARCHES)}, "
                           f"{leagues} and the shipped policies results/policies/<name>/seed<k>.pt (GET /api/config lists them all)")
    track = SimpleNamespace(physics=physics, noise=noise, budget=BUDGET, name="web", tells_level=False)
    return cached_entry((spec, physics, noise), lambda: LoadedAgent(
        spec, resolve_agent(str(root / spec) if known[spec]["kind"] is SpecKind.POLICY else spec, track), physics, noise))


def cached_entry(key, build) -> LoadedAgent:
    """The entry ``key`` names, built by ``build()`` the first time (one build at a time; the
    :data:`MAX_CACHED` most recently used are kept)."""
    with _BUILD:
        if key in _CACHE:
            _CACHE.move_to_end(key)
            return _CACHE[key]
        entry = build()
        _CACHE[key] = entry
        while len(_CACHE) > MAX_CACHED:
            _CACHE.popitem(last=False)
        return entry


def bench_entry(spec: str, track) -> LoadedAgent:
    """The agent a benchmark scorecard names, built for its track (:func:`resolve_agent`; the
    caller has refused a spec that names code)."""
    from billiards.bench.adapters import resolve_agent

    key = ("bench", spec, track.name, track.units)
    return cached_entry(key, lambda: LoadedAgent(spec, resolve_agent(spec, track), track.physics, track.noise))


def search_run_entry(run_dir: Path) -> LoadedAgent:
    """The search a search run's ``config.yaml`` describes (its proposer, search, budget, table
    and noise, :func:`billiards.search.run.make_actor`), as an agent (rebuilt when the file changes)."""
    from billiards.bench.adapters import SearchActorAgent
    from billiards.physics.config import params_from_config
    from billiards.physics.noise import noise_from_config
    from billiards.search.config import saved_config
    from billiards.search.run import make_actor, make_proposer

    path = Path(run_dir) / "config.yaml"
    key = ("run", str(path), path.stat().st_mtime_ns)

    def build() -> LoadedAgent:
        cfg = saved_config(run_dir)
        params, noise = params_from_config(cfg.physics), noise_from_config(cfg.noise)
        actor = make_actor(cfg, make_proposer(cfg.proposer, params), params)
        name = f"{cfg.search.kind} search, proposer {cfg.proposer.name}, {cfg.search.budget} simulations"
        return LoadedAgent(name, SearchActorAgent(actor, name), cfg.physics.preset, noise.describe(), params, noise)

    return cached_entry(key, build)


def considered(entry: LoadedAgent, table: np.ndarray, params) -> dict | None:
    """What a search considered for its last decision (see the module docstring), or None for
    an agent that does not search."""
    if entry.recorder is None:
        return None
    out: dict = {}
    result = entry.last
    if result is not None:
        for key in ("value", "r1"):
            v = getattr(result, key, None)
            if v is not None:
                out[key] = float(np.asarray(v).reshape(-1)[0])
        out["sims"] = int(getattr(result, "n_sims", 0))
        pos = getattr(result, "positions", None)
        if pos is not None:
            out["predicted_final"] = np.asarray(pos, dtype=np.float64).reshape(-1, 4, 2)[0].tolist()
    cands = entry.recorder.first
    if cands is not None and cands.shape[-1] == 4:
        cands = cands[0] if cands.ndim == 3 else cands.reshape(-1, 4)  # (tables, K, 4): this table's
        if len(cands):
            res = simulate_batch(np.repeat(table[None], len(cands), axis=0), cands, params)
            r = res.score.astype(float) - res.foul.astype(float)
            order = np.lexsort((np.arange(len(cands)), -r))[:TOP_CANDIDATES]
            out["candidates"] = {"count": int(len(cands)), "scoring": int(res.score.sum()), "fouling": int(res.foul.sum()),
                                 "top": [{"action": cands[i].tolist(), "score": bool(res.score[i]), "foul": bool(res.foul[i]),
                                          "final": res.positions[i].tolist()} for i in order]}
    return out


def leave_value(entry: LoadedAgent):
    """The table value a position-aware (or safety) search prices its leaves with, its position
    and leave weights and its foul penalty, or None."""
    actor = entry.actor
    value = getattr(actor, "value", None) if actor is not None else None
    if value is None:
        return None
    cfg = actor.cfg
    return value, float(getattr(cfg, "position", 0.0)), float(getattr(cfg, "leave", 0.0)), float(getattr(cfg, "foul_penalty", 1.0))


def noisy_replays(table: np.ndarray, action: np.ndarray, noise, params, n: int, seed: int, level: float | None,
                  value=None) -> dict | None:
    """The shot ``action`` replayed ``n`` times under the noise (a preset name or a NoiseModel):
    the shares that score and foul and every replay's cue-ball end position (None under exact
    play or for n = 0). With ``value`` (a table value, its position and leave weights and the
    foul penalty, as :func:`leave_value` gives them) also the value of each replay's leave at the
    shot's level, as the search prices it (:func:`billiards.search.robust.leave_terms`), and the
    search's statistic of the shot over these replays (``estimate``: the mean of reward plus
    leave term)."""
    from billiards.envs.sagu import SWAP
    from billiards.physics.noise import noise_level

    noise = get_noise(noise)
    if noise.is_exact or n <= 0:
        return None
    rng = np.random.default_rng(seed + 7919)
    levels = None
    if noise.is_variable:
        levels = np.full(n, 1.0 if level is None else level)
    played = noise.perturb(np.repeat(action[None], n, axis=0), rng, params, levels=levels)
    res = simulate_batch(np.repeat(table[None], n, axis=0), played, params)
    out = {"n": n, "score_share": float(res.score.mean()), "foul_share": float(res.foul.mean()),
           "white_ends": np.round(res.positions[:, 0], 5).tolist(), "scored": res.score.astype(bool).tolist()}
    if value is not None:
        model, position, leave, foul_penalty = value
        state = (1.0 if level is None else float(level)) * noise_level(noise) * np.ones(n)
        scored = res.score.astype(bool)
        mine = model.predict(res.positions, state)  # the shooter plays on from the leave (a replay that scores)
        theirs = model.predict(res.positions[:, SWAP], state)  # the opponent's view of the leave (one that misses)
        reward = domain.shot_reward(res.score, res.foul, foul_penalty)
        out["leave"] = {"position": position, "leave": leave, "level": float(state[0]),
                        "values": np.round(np.where(scored, mine, theirs), 4).tolist(),
                        "mean_if_scored": float(mine[scored].mean()) if scored.any() else None,
                        "opponent_mean_if_missed": float(theirs[~scored].mean()) if (~scored).any() else None,
                        "estimate": float(np.mean(reward + np.where(scored, position * mine, -leave * theirs)))}
    return out


def decide(entry: LoadedAgent, table: np.ndarray, *, seed: int = 0, level: float | None = None) -> dict:
    """The agent's shot for ``table`` (its cue ball in slot 0), reseeded with ``seed``, and what
    it considered (:func:`considered`)."""
    with entry.lock:
        agent = entry.agent
        agent.reset(seed)
        if entry.recorder is not None:
            entry.recorder.first = None
        entry.last = None
        sims0 = agent.sims
        obs = domain.observation(table[None])
        levels = None if level is None or not entry.noise_model.is_variable else np.array([level])
        t0 = time.perf_counter()
        action = np.asarray(agent.act(obs, table[None], levels), dtype=np.float64).reshape(-1, 4)[0]
        seconds = time.perf_counter() - t0
        sims = int(agent.sims - sims0)
        seen = considered(entry, table, entry.params)
    return {"action": action, "seconds": seconds, "sims": sims, "considered": seen}


def ask(spec: str, positions, *, physics: str = DEFAULT_PRESET, noise: str = "none", seed: int = 0,
        level: float | None = None, replays: int = 50, root: Path = ROOT) -> dict:
    """The agent's shot for the table ``positions`` (white to play), and what it considered."""
    params = get_params(physics)
    table = np.asarray(positions, dtype=np.float64)
    entry = get_entry(spec, physics, noise, root)
    if get_noise(noise).is_variable and level is None:
        level = 1.0  # the shot's level, told to the agents that read it (fastfiz's sigmas)
    out = decide(entry, table, seed=seed, level=level)
    action = out["action"]
    return {"agent": spec, "action": action.tolist(), "seconds": out["seconds"], "sims": out["sims"], "physics": physics,
            "noise": noise, "level": level, "seed": seed, "considered": out["considered"],
            "noisy": noisy_replays(table, action, noise, params, replays, seed, level, leave_value(entry))}


def reconsider(entry: LoadedAgent, positions, commanded=None, *, shooter: int = 0, seed: int = 0, level: float | None = None,
               replays: int = 50) -> dict:
    """What the agent of ``entry`` considers for a recorded shot's table ``positions`` (in the
    table's ball order; ``shooter`` 1: the yellow's shot, looked at from its side): the agent is
    asked again, reseeded with ``seed`` (its candidates, its estimates, the shot it picks now:
    a search's generator had another state when the run played, so it may pick another shot),
    and the recorded ``commanded`` shot (else the one picked now) is replayed ``replays`` times
    under the run's noise, its leaves priced by the search's table value where it has one."""
    from billiards.envs.sagu import shooter_view

    table = shooter_view(np.asarray(positions, dtype=np.float64), shooter)
    if entry.noise_model.is_variable and level is None:
        level = 1.0
    out = decide(entry, table, seed=seed, level=level)
    action = out["action"]
    chosen = action if commanded is None else np.asarray(commanded, dtype=np.float64)
    return {"agent": entry.spec, "action": action.tolist(), "seconds": out["seconds"], "sims": out["sims"],
            "physics": entry.physics, "noise": entry.noise, "level": level, "seed": seed, "shooter": shooter,
            "recorded": None if commanded is None else chosen.tolist(),
            "same_choice": None if commanded is None else bool(np.array_equal(action, chosen)),
            "considered": out["considered"],
            "noisy": noisy_replays(table, chosen, entry.noise_model, entry.params, replays, seed, level, leave_value(entry))}


__all__ = ["BUDGET", "LoadedAgent", "UnknownAgent", "ask", "bench_entry", "cached_entry", "catalogue", "considered", "decide",
           "get_entry", "leave_value", "league_names", "noisy_replays", "policy_specs", "reconsider", "search_run_entry"]
