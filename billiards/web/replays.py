"""Recorded runs whose records hold scores, not shots, played again shot by shot.

Three kinds (:mod:`.runs` lists them and caches what is played here):

* a **benchmark scorecard's unit** (``results/bench/scorecards/<track>/<agent>/``: its
  ``evaluation.json`` names the track and the agent spec, ``units.jsonl`` holds each unit's
  scores): the agent built again by :func:`billiards.bench.adapters.resolve_agent` -- only from a
  spec that names no code (the baselines, ``search:...``, ``league:...``, a ``.pt`` policy under
  ``results/``; :func:`scorecard_refusal` says why any other is refused) -- plays the unit on its
  seed as :func:`billiards.bench.run.play_unit` plays it (the same envs, seeds, clock and
  players), each shot recorded; the replayed unit's record is compared with the ledger's
  (``matches_ledger``). A unit of an innings or P1 track is a block of innings played side by
  side with one agent generator, so the whole block is played and each inning is one replay;
* a **search run's P1 innings** (``results.json`` of protocol p1 beside ``config.yaml``): every
  inning of a P1 steps together with one actor generator, so one inning alone cannot be played
  again; the whole run is played once (the search and the env built from the run's own config,
  seeded as :func:`billiards.search.protocols.run_p1` seeds them; at most :data:`MAX_P1_SHOTS`
  shots) and its points per inning compared with ``results.json``'s ``values``;
* a **training run's evaluation innings** (``eval.json`` beside ``config.yaml``), where the
  run's weights were shipped (``results/policies/<name>/seed<k>.pt`` whose ``source`` names the
  run): :func:`billiards.evaluation.evaluate_policy`'s innings played again with that policy, their
  points compared with ``eval.json``'s ``points``.

Every shot is recorded as the replay view reads it (:func:`shot_entry`): the table before,
the commanded and the played shot, the outcome and, under variable noise, the shot's level.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from billiards.files import IDENTITY_FILE, UNITS_FILE
from billiards.protocol import Protocol

MAX_P1_SHOTS = 20_000  # a P1 run is played again whole: larger ones are refused


class ReplayRefused(ValueError):
    """A run that cannot be played again, with the sentence that says why."""


def _run_json(path: Path):
    """A run folder's JSON file through the one reader (no link, no FIFO, bounded); ReplayRefused naming it otherwise."""
    from billiards.files import RunFileError, read_run_json

    try:
        return read_run_json(path)
    except RunFileError as err:
        raise ReplayRefused(str(err)) from None


# ----------------------------------------------------------------------------- one shot


def shot_entry(before, commanded, played, scored: bool, foul: bool, level=None, caption: str = "", shooter: int = 0,
               **extra) -> dict:
    """A shot as the replay view reads it (the table in its own ball order, shooter 0 white)."""
    commanded = np.asarray(commanded, dtype=np.float64)
    played = np.asarray(played, dtype=np.float64)
    out = {"positions": np.asarray(before, dtype=np.float64).tolist(), "commanded": commanded.tolist(), "played": played.tolist(),
           "noisy": not np.array_equal(played, commanded), "scored": bool(scored), "foul": bool(foul), "shooter": int(shooter),
           "level": None if level is None else float(level), "caption": caption}
    out.update(extra)
    return out


def match_shot(before: np.ndarray, shot: dict, level, game, who: str) -> dict:
    """A shot of a two-player game (:class:`billiards.envs.sagu.SaguEnv`'s ``shoot`` answer) as
    the replay view reads it."""
    played, commanded = shot["raw_action"], shot["commanded_action"]
    return {"positions": before.tolist(), "commanded": commanded.tolist(), "played": played.tolist(),
            "noisy": not np.array_equal(played, commanded), "scored": bool(shot["score"]), "foul": bool(shot["foul"]),
            "shooter": int(shot["player"]), "level": level, "who": who, "scores": [float(s) for s in game.scores],
            "final": game.positions.tolist(), "caption": f"{who} ({'white' if shot['player'] == 0 else 'yellow'}) shoots"}


# ----------------------------------------------------------------------------- benchmark scorecards


def scorecard_refusal(spec, root: Path) -> str | None:
    """Why the viewer will not build the agent a scorecard names, or None: it builds the
    baselines, ``search:``, ``league:`` and ``.pt`` policies under ``results/``; a spec naming
    code (``file.py:name``, ``module:name``, ``sb3:...``) or another file is refused."""
    from billiards.bench.spec import AgentError, AgentSpec, SpecKind

    if not isinstance(spec, str) or not spec.strip():
        return "its evaluation.json names no agent spec, so the agent cannot be built again"
    try:
        parsed = AgentSpec.parse(spec)
    except AgentError:
        return f"its agent {spec.strip()!r} names nothing this version builds, so the agent cannot be built again"
    spec = parsed.text
    if parsed.kind in (SpecKind.BASELINE, SpecKind.SEARCH, SpecKind.LEAGUE):
        return None
    if spec.endswith(".pt"):
        path = Path(spec) if Path(spec).is_absolute() else Path(root) / spec
        results = (Path(root) / "results").resolve()
        try:
            real = path.resolve(strict=True)
        except OSError:
            return f"its policy {spec} does not exist here, so the agent cannot be built again"
        if not real.is_relative_to(results):
            return f"its policy {spec} lies outside results/: the viewer builds only the policies shipped there"
        return None
    if parsed.kind is SpecKind.POLICY:
        return f"its policy {spec} is a training run directory: the viewer builds only the .pt policies shipped under results/"
    what = "a Stable-Baselines3 model (loading it imports code)" if parsed.kind is SpecKind.SB3 else "code to import"
    return (f"its agent {spec!r} names {what}: the viewer never imports code a file it reads names, so this scorecard "
            f"cannot be played again (python evaluate.py plays it)")


def read_scorecard(d: Path) -> tuple[dict, object, str | None]:
    """(evaluation.json, the track as scored -- cut to the limit --, why the track cannot be
    played again or None)."""
    from billiards.bench.tracks import get_track

    ev = _run_json(d / IDENTITY_FILE)
    rec = ev.get("track") or {}
    try:
        track = get_track(rec.get("name"))
    except ValueError:
        return ev, None, f"its track {rec.get('name')!r} is not one of this version's tracks"
    if track.record() != rec:
        return ev, None, (f"its track {track.name} was scored with other settings than today's {track.name} "
                          f"(its fingerprint or settings differ)")
    limit = ev.get("limit")
    return ev, (track.scaled(limit) if limit else track), None


def scorecard_records(d: Path, ev: dict) -> list[dict]:
    """The ledger's unit records (sealed, of this evaluation), by unit."""
    from billiards.bench.run import UNITS
    from billiards.files import read_ledger

    return sorted(read_ledger(d / UNITS_FILE, UNITS, ev.get("run"), repair=False).records, key=lambda r: r["unit"])


def scorecard_units(track, records: list[dict]) -> list[dict]:
    """The replay view's units of a scorecard, without shots: innings (innings and P1 tracks),
    chains (P3), matches (match tracks)."""
    units = []
    if track.protocol is None:
        return units
    if track.protocol.spec.by_innings:
        for r in records:
            for k, row in enumerate(r["score"]):
                i = r["first"] + k
                units.append({"id": i, "title": f"inning {i} (seed {track.seed + i}): {sum(row)} points of {len(row)} shots",
                              "shots": None, "block": r["unit"], "seed": track.seed + i, "record": {"points": int(sum(row))}})
    elif track.protocol is Protocol.P3:
        for r in records:
            units.append({"id": r["unit"], "title": f"chain {r['index']} (seed {r['seed']}): {r['length']} points"
                          + (", ended by a foul" if r["ended_by_foul"] else ""), "shots": None, "block": r["unit"],
                          "seed": r["seed"], "record": {"length": r["length"], "ended_by_foul": r["ended_by_foul"]}})
    else:
        for r in records:
            who = {"agent": "the agent wins", "opponent": f"{r['opponent']} wins", None: "a draw"}[r["winner"]]
            units.append({"id": r["unit"], "title": f"match {r['index']} against {r['opponent']} (seed {r['seed']}, "
                          f"{'the agent' if r['first'] == 'agent' else r['opponent']} breaks): {r['points'][0]:g} - "
                          f"{r['points'][1]:g}, {who}", "shots": None, "block": r["unit"], "seed": r["seed"],
                          "record": {"points": r["points"], "winner": r["winner"]}})
    return units


def _innings_recorded(agent, track, first: int, n: int) -> tuple[dict, list[list[dict]]]:
    """:func:`billiards.bench.protocols.play_innings`, every shot recorded: (its record, shots per inning)."""
    from billiards.bench.protocols import play_innings

    shots: list[list[dict]] = [[] for _ in range(n)]

    def on_shot(i, t, before, info, level):
        shots[i].append(shot_entry(before, info["commanded_action"], info["raw_action"], info["score"], info["foul"], level,
                                   f"inning {first + i}, shot {t + 1} of {track.shots}"))

    return play_innings(agent, track, first, n, on_shot), shots


def _chain_recorded(agent, track, index: int) -> tuple[dict, list[dict]]:
    """:func:`billiards.bench.protocols.play_chain`, every shot recorded."""
    from billiards.bench.protocols import play_chain

    shots: list[dict] = []

    def on_shot(i, t, before, info, level):
        shots.append(shot_entry(before, info["commanded_action"], info["raw_action"], info["score"], info["foul"], level,
                                f"chain {index}, shot {t + 1}"))

    return play_chain(agent, track, index, on_shot), shots


def _match_recorded(agent, track, index: int) -> tuple[dict, list[dict]]:
    """:func:`billiards.bench.protocols.play_match`, every shot recorded: the agent is white, the pool
    player yellow (a player of its own, reseeded per match as the pool's is)."""
    from billiards.bench.adapters import league_player
    from billiards.bench.protocols import params_noise, play_match

    params, noise = params_noise(track)
    name = track.opponents[index // track.units]
    shots: list[dict] = []

    def on_shot(before, level, mover, out, game):
        shots.append({**match_shot(before, out, level, game, agent.name if mover == 0 else name), "agent_shot": mover == 0})

    rec = play_match(agent, track, index, on_shot, opponent=league_player(name, noise, params)[0])
    return rec, shots


def play_scorecard_unit(agent, track, unit: int) -> tuple[dict, list[list[dict]]]:
    """Unit ``unit`` of ``track`` played again as :func:`billiards.bench.run.play_unit` plays it:
    (its record, as the ledger holds it, and its shots: one list per inning of a block, one
    list for a chain or a match)."""
    if track.protocol.spec.by_innings:
        first = unit * track.block
        return _innings_recorded(agent, track, first, min(track.block, track.units - first))
    if track.protocol is Protocol.P3:
        rec, shots = _chain_recorded(agent, track, unit)
    else:
        rec, shots = _match_recorded(agent, track, unit)
    return rec, [shots]


def ledger_differences(replayed: dict, recorded: dict) -> list[str]:
    """The keys of a replayed unit record that differ from the ledger's (its own timing aside)."""
    return sorted(k for k in replayed if k != "cpu_s" and replayed[k] != recorded.get(k))


def replay_scorecard_block(d: Path, root: Path, block: int, build=None) -> dict:
    """Scorecard ``d``'s unit ``block`` played again: ``{"shots": per inning/chain/match,
    "units": their ids, "replayed", "recorded", "matches_ledger", "differences"}``. ``build``
    (spec, track) -> agent: how the agent is built (default :func:`resolve_agent`; the viewer
    passes its cache)."""
    from billiards.bench.adapters import AgentError, resolve_agent

    ev, track, why = read_scorecard(d)
    spec = (ev.get("agent") or {}).get("spec")
    refusal = why or scorecard_refusal(spec, root)
    if refusal:
        raise ReplayRefused(f"this scorecard cannot be played again: {refusal}")
    records = {r["unit"]: r for r in scorecard_records(d, ev)}
    if block not in records:
        raise ReplayRefused(f"the scorecard's ledger holds no unit {block}")
    spec = spec.strip()
    full = str(Path(root) / spec) if spec.endswith(".pt") and not Path(spec).is_absolute() else spec
    try:
        agent, lock = build(full, track) if build is not None else (resolve_agent(full, track), None)
    except AgentError as err:
        raise ReplayRefused(f"the scorecard's agent {spec!r} cannot be built: {err}") from None
    if lock is not None:
        with lock:
            rec, shots = play_scorecard_unit(agent, track, block)
    else:
        rec, shots = play_scorecard_unit(agent, track, block)
    recorded = {k: v for k, v in records[block].items() if k not in ("unit", "run", "sha256")}
    diff = ledger_differences(rec, recorded)
    ids = list(range(rec["first"], rec["first"] + rec["n"])) if track.protocol.spec.by_innings else [block]
    return {"shots": shots, "units": ids, "replayed": rec, "recorded": recorded, "matches_ledger": not diff, "differences": diff,
            "protocol": track.protocol}


def scorecard_agent_searches(spec) -> bool:
    """Whether the agent a scorecard names searches with the simulator (what it considered can be shown)."""
    from billiards.bench.spec import AgentError, AgentSpec, SpecKind

    if not isinstance(spec, str):
        return False
    try:
        parsed = AgentSpec.parse(spec)
    except AgentError:
        return False
    if parsed.kind is SpecKind.LEAGUE:
        from billiards.bench.adapters import league_players

        cfg = league_players().get(parsed.player) or {}
        return cfg.get("kind", "search") not in ("random", "policy")
    return parsed.kind is SpecKind.SEARCH


# ----------------------------------------------------------------------------- search runs' P1


def p1_size(d: Path) -> tuple[int, int]:
    """(innings, shots per inning) of the P1 search run in ``d`` (its config)."""
    from billiards.search.config import saved_config

    cfg = saved_config(d)
    return int(cfg.protocol.n_innings), int(cfg.protocol.shots)


def replay_p1(d: Path, max_shots: int = MAX_P1_SHOTS) -> dict:
    """The P1 search run in ``d`` played again whole, as :func:`billiards.search.protocols.run_p1`
    plays it (the proposer, the actor and the env built from its config.yaml and seeded with its
    seed, every inning stepped together): ``{"innings": shots per inning, "points", "recorded",
    "matches_record"}``."""
    from billiards.envs import BilliardsEnv
    from billiards.envs.torchrl_env import exact_positions
    from billiards.physics.config import params_from_config
    from billiards.physics.noise import noise_from_config
    from billiards.search.actors import make_search_collector
    from billiards.search.config import saved_config
    from billiards.search.run import make_actor, make_proposer

    try:
        cfg = saved_config(d)
    except Exception as err:  # a config today's code cannot read
        raise ReplayRefused(f"its config.yaml cannot be read as a search config ({str(err).splitlines()[0]})") from None
    n, shots, seed = int(cfg.protocol.n_innings), int(cfg.protocol.shots), int(cfg.seed)
    if n * shots > max_shots:
        raise ReplayRefused(f"its {n} innings of {shots} shots ({n * shots:,} shots, all stepped together with one search "
                            f"generator) would have to be played again whole; the viewer plays at most {max_shots:,}")
    results = _run_json(d / "results.json")
    params = params_from_config(cfg.physics)
    noise = noise_from_config(cfg.noise)
    actor = make_actor(cfg, make_proposer(cfg.proposer, params), params)
    env = BilliardsEnv(batch_size=[n], start="random", on_miss="continue", max_shots=shots, seed=seed, params=params, noise=noise)
    actor.reseed(seed)
    collector = make_search_collector(env, actor, frames_per_batch=n, total_frames=n * shots)
    innings: list[list[dict]] = [[] for _ in range(n)]
    points = np.zeros(n, dtype=int)
    try:
        for t, batch in enumerate(collector):
            before = exact_positions(batch).reshape(n, 4, 2)
            commanded = batch["action"].reshape(n, 4).numpy().astype(np.float64)
            played = batch["next", "played_action"].reshape(n, 4).numpy() if not noise.is_exact else commanded
            levels = batch["noise_level"].reshape(n).numpy().astype(np.float64) if noise.is_variable else None
            score = batch["next", "score"].reshape(n).numpy()
            foul = batch["next", "foul"].reshape(n).numpy()
            points += score.astype(int)
            for i in range(n):
                innings[i].append(shot_entry(before[i], commanded[i], played[i], score[i], foul[i],
                                             None if levels is None else levels[i], f"inning {i}, shot {t + 1} of {shots}"))
    finally:
        collector.shutdown()
    recorded = [float(v) for v in results.get("values", [])]
    return {"innings": innings, "points": points.tolist(), "recorded": recorded,
            "matches_record": [float(p) for p in points] == recorded, "seed": seed}


# ----------------------------------------------------------------------------- training runs' evaluation


def policy_sources(root: Path) -> dict[str, str]:
    """The shipped policies by the training run they came from: run dir (as the repository
    names it) -> policy file (relative to ``root``)."""
    from billiards.files import load_tagged
    from billiards.rl.checkpoint import CheckpointError
    from billiards.rl.policy import POLICY_FORMAT

    out: dict[str, str] = {}
    for p in sorted((Path(root) / "results" / "policies").glob("*/*.pt")):
        try:
            source = load_tagged(p, POLICY_FORMAT, CheckpointError, "exported policy").get("source")
        except (CheckpointError, OSError):
            continue
        if isinstance(source, str):
            out.setdefault(source, str(p.relative_to(root)))
    return out


def replay_training(d: Path, policy: Path) -> dict:
    """The evaluation of training run ``d`` (``eval.json``) played again with its shipped policy
    ``policy``, as :func:`billiards.evaluation.evaluate_policy` plays it (the same env, seed and noise,
    the deterministic policy): ``{"innings", "points", "recorded", "matches_record"}``."""
    import torch
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from billiards import domain
    from billiards.envs import make_env
    from billiards.envs.torchrl_env import exact_positions
    from billiards.physics.config import params_from_config
    from billiards.physics.noise import noise_from_config
    from billiards.rl.checkpoint import CheckpointError
    from billiards.rl.policy import load_policy

    from billiards import compat

    ev = compat.upgrade_eval_record(_run_json(d / "eval.json"))
    try:
        module, cfg = load_policy(policy)
    except (CheckpointError, OSError, ValueError) as err:
        raise ReplayRefused(f"its policy {policy} cannot be loaded: {err}") from None
    params = params_from_config(cfg.physics)
    noise = noise_from_config(cfg.noise)
    n, shots, seed, start = int(ev["n_innings"]), int(ev["max_shots"]), int(ev["seed"]), ev.get("start", "random")
    constrain = bool(cfg.env.constrain_aim)
    env = make_env(n, start=start, on_miss="continue", max_shots=shots, constrain_aim=constrain,
                   extra_features=bool(cfg.env.extra_features), seed=seed, noise=noise, params=params)
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        rollout = env.rollout(shots, module, break_when_any_done=False)
    before = exact_positions(rollout).reshape(n, shots, 4, 2)
    action = rollout["action"].reshape(n, shots, 4).numpy().astype(np.float64)
    commanded = domain.raw_action(action, before, params.ball_radius, constrain)
    played = rollout["next", "played_action"].reshape(n, shots, 4).numpy() if not noise.is_exact else commanded
    levels = rollout["noise_level"].reshape(n, shots).numpy().astype(np.float64) if noise.is_variable else None
    score = rollout["next", "score"].reshape(n, shots).numpy().astype(bool)
    foul = rollout["next", "foul"].reshape(n, shots).numpy().astype(bool)
    innings = [[shot_entry(before[i, t], commanded[i, t], played[i, t], score[i, t], foul[i, t],
                           None if levels is None else levels[i, t], f"inning {i}, shot {t + 1} of {shots}")
                for t in range(shots)] for i in range(n)]
    points = score.sum(axis=1).astype(int).tolist()
    recorded = [int(p) for p in ev.get("points", [])]
    return {"innings": innings, "points": points, "recorded": recorded, "matches_record": points == recorded,
            "noise": noise.describe(), "recorded_noise": ev.get("noise"), "seed": seed}


__all__ = ["MAX_P1_SHOTS", "ReplayRefused", "ledger_differences", "match_shot", "p1_size", "play_scorecard_unit", "policy_sources",
           "read_scorecard", "replay_p1", "replay_scorecard_block", "replay_training", "scorecard_agent_searches",
           "scorecard_records", "scorecard_refusal", "scorecard_units", "shot_entry"]
