"""Matches and a league among players (:mod:`.agents`), with seeds, resume and an Elo table.

A league plays, for every ordered pair of players (a, b), ``matches`` matches with a as white
and b as yellow, the break alternating (a breaks in the even-numbered ones). Match ``i`` of pair
``p`` uses seed ``seed + 1000 p + i`` (the rack, the execution noise and both players' own
draws), so every match replays alone. Each finished match is appended to ``matches.jsonl`` as it
ends, sealed with the league's run identity (:func:`billiards.files.append_record`); a league
started again over the same directory plays only what is missing, and refuses a ledger line that
is unsealed, edited, of another league or a repeated match (a torn last line, from a kill
mid-append, is cut off and its match played again). ``league.json``:
per ordered pair ``a``, ``b``, ``noise``, ``matches``, ``a_wins``, ``b_wins``, ``draws``, ``ci95``
(the Wilson 95 % interval of a's score rate, a draw counting half), points and CPU ms per turn of
each; and the Elo ratings of a Bradley-Terry fit over all matches (mean 1500).
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path

import numpy as np

from billiards.envs import sagu_v0
from billiards.envs.sagu import AGENTS, shooter_view
from billiards.files import LEAGUE_FILE, MATCHES, MATCHES_FILE, append_record, atomic_write_text, read_ledger, run_identity


def play_match(white, yellow, *, seed: int, first: str = "white", frames: list | None = None, on_shot=None, **game) -> dict:
    """One match (``game``: :func:`billiards.envs.sagu_v0.raw_env`'s keywords); with ``frames`` a
    list, ``(rgb_array frame, (white's score, yellow's score, who plays next))`` of the table
    before the first shot and after every shot is appended to it; ``on_shot(before, level, mover,
    shot, game)`` is called after every shot (the table before it, the level it played at, the
    shooter, :meth:`billiards.envs.sagu.SaguEnv.shoot`'s answer, the game after it)."""
    env = sagu_v0.raw_env(first=first, render_mode="rgb_array" if frames is not None else None, **game)
    env.reset(seed=seed)
    if on_shot is not None:
        shoot, state = env.game.shoot, env.game

        def recorded(action, rng):  # the env's own shot, reported on the way
            before, level, mover = state.positions.copy(), state.shot_level, state.mover
            out = shoot(action, rng)
            on_shot(before, level, mover, out, state)
            return out

        state.shoot = recorded
    players = {"white": white, "yellow": yellow}
    for i, p in enumerate(AGENTS):
        players[p].reseed(seed * 2 + i)
    cpu, turns = {p: 0.0 for p in AGENTS}, {p: 0 for p in AGENTS}

    def snapshot() -> None:
        if frames is not None:
            w, y = env.game.scores
            frames.append((env.render(), (w, y, env.agent_selection)))

    snapshot()
    for agent in env.agent_iter():
        _, _, terminated, truncated, _ = env.last()
        if terminated or truncated:
            env.step(None)
            continue
        view = shooter_view(env.game.positions, AGENTS.index(agent))
        t0 = time.process_time()
        level = env.game.shot_level  # variable noise: the level this shot plays at, told to the player
        action = players[agent].act(view) if level is None else players[agent].act(view, level)
        cpu[agent] += time.process_time() - t0
        turns[agent] += 1
        env.step(action)
        snapshot()
    scores = dict(zip(AGENTS, env.game.scores))
    winner = None if scores["white"] == scores["yellow"] else max(scores, key=scores.get)
    return {"seed": seed, "first": first, "winner": winner, "scores": scores, "shots": env.game.shots,
            "innings": env.game.innings, "cpu_s": cpu, "turns": turns}


def animate_match(frames: list, captions: list[str], path: Path, scale: int = 1, ms_per_frame: int = 700) -> Path:
    """An animated GIF of a match: each table (an rgb_array frame) shrunk by ``scale``, its caption
    (the score, who plays next) drawn over it."""
    from PIL import Image, ImageDraw

    images = []
    for frame, caption in zip(frames, captions):
        image = Image.fromarray(frame).reduce(scale).convert("RGB")
        draw = ImageDraw.Draw(image)
        draw.rectangle([0, 0, image.width, 14], fill=(0, 0, 0))
        draw.text((3, 2), caption, fill=(255, 255, 255))
        images.append(image.convert("P", palette=Image.Palette.ADAPTIVE))
    path.parent.mkdir(parents=True, exist_ok=True)
    images[0].save(path, save_all=True, append_images=images[1:], duration=ms_per_frame, loop=0, optimize=True)
    return path


def wilson(successes: float, n: int, z: float = 1.96) -> list[float]:
    """The Wilson score interval of a rate ``successes / n``."""
    if n == 0:
        return [0.0, 1.0]
    p = successes / n
    centre, half = (p + z * z / (2 * n)) / (1 + z * z / n), z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return [max(0.0, round(centre - half, 4)), min(1.0, round(centre + half, 4))]


def elo(names: list[str], results: list[tuple[str, str, float]], iters: int = 2000) -> dict[str, float]:
    """Bradley-Terry strengths by minorisation-maximisation over ``(a, b, a's score)`` results
    (1 win, 0.5 draw, 0 loss), as Elo ratings (400 log10 of the strength) with mean 1500. A
    player that never lost or never won gets a finite rating through one virtual draw against
    every other player (a weak prior)."""
    idx = {n: i for i, n in enumerate(names)}
    k = len(names)
    wins, games = np.zeros((k, k)), np.zeros((k, k))
    for a, b, s in results:
        wins[idx[a], idx[b]] += s
        wins[idx[b], idx[a]] += 1 - s
        games[idx[a], idx[b]] += 1
        games[idx[b], idx[a]] += 1
    off = ~np.eye(k, dtype=bool)
    wins, games = wins + 0.5 * off, games + 1.0 * off  # the virtual draws
    gamma = np.ones(k)
    for _ in range(iters):
        denom = (games / (gamma[:, None] + gamma[None, :])).sum(axis=1)
        gamma = wins.sum(axis=1) / denom
        gamma /= np.exp(np.log(gamma).mean())
    rating = 400 * np.log10(gamma)
    return {n: round(float(1500 + rating[i] - rating.mean()), 1) for n, i in idx.items()}


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
            turns = {p: sum(r["turns"][p] for r in mine) for p in AGENTS}
            cpu = {p: sum(r["cpu_s"][p] for r in mine) for p in AGENTS}
            pairs.append({"a": a, "b": b, "noise": noise, "matches": len(mine), "a_wins": a_wins, "b_wins": b_wins,
                          "draws": draws, "a_score_rate": round((a_wins + 0.5 * draws) / len(mine), 4),
                          "ci95": wilson(a_wins + 0.5 * draws, len(mine)),
                          "a_points": round(float(np.mean([r["scores"]["white"] for r in mine])), 3),
                          "b_points": round(float(np.mean([r["scores"]["yellow"] for r in mine])), 3),
                          "a_ms_per_turn": round(1000 * cpu["white"] / max(turns["white"], 1), 2),
                          "b_ms_per_turn": round(1000 * cpu["yellow"] / max(turns["yellow"], 1), 2)})
            results += [(a, b, 1.0 if r["winner"] == "white" else 0.0 if r["winner"] == "yellow" else 0.5) for r in mine]
    return {"pairs": pairs, "elo": elo(names, results) if results else {}}


def parse_matches(text: str, name: str = MATCHES_FILE) -> list[dict]:
    """The finished matches of a league's ``matches.jsonl`` text, for a read-only view
    (:func:`billiards.compat.ledger_scan`: every form a ledger was written in): a torn last line
    (a kill mid-append) is left out; any other bad line (not JSON, not a match record, not
    matching its seal, of another league, a repeated match) is a
    :class:`billiards.files.LedgerError` naming ``name`` and the line."""
    from billiards import compat
    from billiards.files import LedgerError

    scan = compat.ledger_scan(text.encode(), name, MATCHES)
    if scan.problems:
        raise LedgerError(scan.problems[0])
    return scan.records


def league_identity(names: list[str], matches: int, seed: int, settings: dict) -> str:
    """A league's run identity: the players (in order: it sets each pair's seeds), the matches
    per ordered pair, the seed and the ``settings`` that decide the matches (plain values; a
    dataclass such as the noise model or the physics as its fields)."""
    plain = {k: dataclasses.asdict(v) if dataclasses.is_dataclass(v) else v for k, v in settings.items()}
    return run_identity({"players": list(names), "matches": matches, "seed": seed, **plain})


def run_league(players: dict, *, out_dir: Path, matches: int, seed: int, noise_name: str, record: dict,
               progress: bool = True, run: str | None = None, **game) -> dict:
    """Play every missing match of the league among ``players`` (name -> player) into
    ``out_dir`` and write ``league.json`` (with ``record``: the command, commit, settings).

    ``run``: the league's identity, which every record of ``matches.jsonl`` carries (the app
    passes a hash of its settings); by default :func:`league_identity` of the arguments (the
    ``record`` less its command and commit, and ``game``). The ledger's records must all be this
    league's (:class:`billiards.files.LedgerError` otherwise)."""
    from tqdm import tqdm

    names = list(players)
    if run is None:
        run = league_identity(names, matches, seed, {"noise_name": noise_name, **game,
                                                     "record": {k: v for k, v in record.items() if k not in ("command", "commit")}})
    out_dir.mkdir(parents=True, exist_ok=True)
    ledger = out_dir / MATCHES_FILE
    done = read_ledger(ledger, MATCHES, run, repair=True).records  # a torn last line: cut, its match played again
    have = {(r["a"], r["b"], r["i"]) for r in done}
    todo = [(p, a, b, i) for p, (a, b) in enumerate((a, b) for a in names for b in names if a != b)
            for i in range(matches) if (a, b, i) not in have]
    bar = tqdm(total=len(todo) + len(have), initial=len(have), desc="matches", disable=not progress, unit="match")
    for p, a, b, i in todo:
        result = play_match(players[a], players[b], seed=seed + 1000 * p + i, first="white" if i % 2 == 0 else "yellow",
                            **game)
        done.append(append_record(ledger, {"a": a, "b": b, "i": i, **result}, run))
        bar.update(1)
    bar.close()
    league = {**record, **summarize(done, names, noise_name), "run": run}
    atomic_write_text(out_dir / LEAGUE_FILE, json.dumps(league, indent=2) + "\n")
    return league


__all__ = ["LEAGUE_FILE", "MATCHES_FILE", "animate_match", "elo", "league_identity", "parse_matches", "play_match", "run_league",
           "summarize", "wilson"]
