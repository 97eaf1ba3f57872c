"""Matches and a league among players (:mod:`.players`), with seeds, resume and an Elo table.

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
import time
from pathlib import Path

from billiards.envs import sagu_v0
from billiards.envs.sagu import AGENTS, shooter_view
from billiards.files import (LEAGUE_FILE, MATCHES, MATCHES_FILE, append_record, atomic_write_text, read_ledger, run_identity,
                             run_lock, stale_summary)

from .table import elo, summarize, wilson


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
               progress: bool = True, run: str | None = None, command: str | None = None, **game) -> dict:
    """Play every missing match of the league among ``players`` (name -> player) into
    ``out_dir`` and write ``league.json`` (with ``record``: the command, commit, settings).

    ``run``: the league's identity, which every record of ``matches.jsonl`` carries (the app
    passes a hash of its settings); by default :func:`league_identity` of the arguments (the
    ``record`` less its command and commit, and ``game``). The ledger's records must all be this
    league's (:class:`billiards.files.LedgerError` otherwise). ``league.json`` is always
    written from the ledger's matches, never kept: one that disagrees with them (edited) is
    said and written again. The league holds ``out_dir``'s lock while it plays
    (:func:`billiards.files.run_lock`; ``command`` names it, by default this process's command
    line): a second league started there
    meanwhile is refused (:class:`billiards.files.RunLockedError`, naming this one)."""
    names = list(players)
    if run is None:
        run = league_identity(names, matches, seed, {"noise_name": noise_name, **game,
                                                     "record": {k: v for k, v in record.items() if k not in ("command", "commit")}})
    with run_lock(out_dir, command=command, say=lambda line: print(line, flush=True)):
        return _play_league(players, names, out_dir, matches, seed, noise_name, record, progress, run, game)


def _play_league(players: dict, names: list[str], out_dir: Path, matches: int, seed: int, noise_name: str, record: dict,
                 progress: bool, run: str, game: dict) -> dict:
    from tqdm import tqdm

    ledger = out_dir / MATCHES_FILE
    done = read_ledger(ledger, MATCHES, run, repair=True).records  # a torn last line: cut, its match played again
    have = {(r["a"], r["b"], r["i"]) for r in done}
    todo = [(p, a, b, i) for p, (a, b) in enumerate((a, b) for a in names for b in names if a != b)
            for i in range(matches) if (a, b, i) not in have]
    if not todo and (out_dir / LEAGUE_FILE).exists() and (why := stale_summary(out_dir, MATCHES, done)) is not None:
        print(f"note: {why}; {LEAGUE_FILE} is written again from {MATCHES_FILE}", flush=True)
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
