"""Matches between the person at the page and a league player, kept by the server.

The game is the two-player env's (:class:`billiards.envs.sagu.SaguEnv`: its rules, turns,
fouls, target and innings limit, its execution noise drawn from the match's generator): the
person is ``white`` (``human``), the league player ``yellow``. A match is seeded like a league's
(:func:`billiards.league.play.play_match`): the table and the noise from ``seed``, the player's
own draws from ``2 seed + 1``. The person's shot is the raw (theta, p, a, b), given to the env as
its normalised action (float64, so nothing is rounded to float32 on the way); the env applies the
noise; then the league player plays its turns until the person is to play again or the match
ends. Every shot comes back with its paths so the page animates them.

At its end a match is saved as a league ledger of one match, ``<out>/matches/<stamp>-<id>/``:
``matches.jsonl`` (a sealed record as :mod:`billiards.league` writes them, with every shot in
``log``) and ``league.json`` (the pair's counts, so ``python -m billiards.files verify`` checks it);
the replay view lists it.
"""

from __future__ import annotations

import json
import secrets
import threading
import time
from pathlib import Path

import numpy as np

from billiards import domain
from billiards.envs.sagu import AGENTS, SaguEnv, shooter_view
from billiards.files import LEAGUE_FILE, MATCHES_FILE, append_record, atomic_write_text, display_path, run_identity
from billiards.physics import check_actions, get_params
from billiards.physics.noise import get_noise, noise_record

from . import sim
from .runs import WEB_APP, match_shot

HUMAN = "human"
MAX_SESSIONS = 64


class MatchError(ValueError):
    pass


class MatchOver(MatchError):
    pass


class Match:
    """One match in progress (see the module docstring)."""

    def __init__(self, opponent: str, *, noise: str = "fastfiz_x5", physics: str = "korean_medium", target: int = 5,
                 seed: int = 0, first: str = HUMAN, max_innings: int = 200, foul_penalty: float = 1.0,
                 out_dir: Path | None = None, dt: float = sim.DEFAULT_DT):
        from billiards.bench.agents import league_player

        self.id = secrets.token_hex(6)
        self.opponent, self.noise_name, self.physics, self.target, self.seed = opponent, noise, physics, target, seed
        self.first = first
        self.params, self.noise = get_params(physics), get_noise(noise)
        self.player, self.config = league_player(opponent, self.noise, self.params)
        self.game = SaguEnv(target=target, max_innings=max_innings, start="canonical", foul_penalty=foul_penalty,
                            noise=self.noise, physics=self.params)
        self.rng = np.random.default_rng(seed)
        self.game.reset(self.rng, 0 if first == HUMAN else 1)
        self.player.reseed(seed * 2 + 1)
        self.log: list[dict] = []
        self.over, self.truncated = False, False
        self.cpu, self.turns = {"white": 0.0, "yellow": 0.0}, {"white": 0, "yellow": 0}
        self.out_dir, self.saved, self.dt = out_dir, None, dt
        self.lock = threading.Lock()
        self.started = time.time()

    # ------------------------------------------------------------------------- state

    def state(self) -> dict:
        g = self.game
        w, y = g.scores
        winner = None
        if self.over and w != y:
            winner = HUMAN if w > y else self.opponent
        return {"id": self.id, "opponent": self.opponent, "noise": self.noise_name, "physics": self.physics,
                "target": self.target, "seed": self.seed, "positions": g.positions.tolist(),
                "scores": {HUMAN: w, self.opponent: y}, "to_play": None if self.over else (HUMAN if g.mover == 0 else self.opponent),
                "innings": g.innings, "shots": g.shots, "over": self.over, "truncated": self.truncated, "winner": winner,
                "level": g.shot_level, "saved": display_path(self.saved) if self.saved else None}

    def _shot(self, action, who: str) -> dict:
        g = self.game
        before, level = g.positions.copy(), g.shot_level
        result = g.shoot(action, self.rng)
        rec = match_shot(before, result, level, g, who)
        paths = sim.replay_played(before, rec["played"], physics=self.physics, shooter=rec["shooter"], dt=self.dt)
        if paths["final"] != rec["final"]:  # the env's batch and the single shot agree bit for bit (docs/physics.md)
            raise RuntimeError("the replayed shot does not end where the match's shot did")
        rec.update(result=paths["result"], events=paths["events"], paths=paths["paths"])
        self.log.append(rec)
        if result["won"] or result["over_limit"]:
            self.over, self.truncated = True, bool(result["over_limit"])
        return rec

    # ------------------------------------------------------------------------- turns

    def start(self) -> list[dict]:
        """The league player's opening turns when it breaks."""
        with self.lock:
            return self._agent_turns()

    def human_shot(self, action) -> list[dict]:
        """The person's shot (raw theta, p, a, b), then the league player's turns."""
        with self.lock:
            if self.over:
                scores = ", ".join(f"{who} {points}" for who, points in self.state()["scores"].items())
                raise MatchOver(f"match {self.id} is over ({scores}); start another")
            if self.game.mover != 0:
                raise MatchError(f"match {self.id}: it is {self.opponent}'s turn")
            raw = np.asarray(action, dtype=np.float64)
            check_actions(raw)
            wrapped = raw.copy()
            wrapped[0] = wrapped[0] % (2 * np.pi)
            x = domain.normalize_action(wrapped)
            shots = [self._shot(x, HUMAN)]
            self.turns["white"] += 1
            shots += self._agent_turns()
            return shots

    def _agent_turns(self) -> list[dict]:
        shots = []
        while not self.over and self.game.mover == 1:
            view = shooter_view(self.game.positions, 1)
            level = self.game.shot_level
            t0 = time.process_time()
            action = self.player.act(view) if level is None else self.player.act(view, level)
            self.cpu["yellow"] += time.process_time() - t0
            self.turns["yellow"] += 1
            shots.append(self._shot(action, self.opponent))
        if self.over and self.saved is None and self.out_dir is not None:
            self.save()
        return shots

    # ------------------------------------------------------------------------- the record

    def record(self) -> dict:
        g = self.game
        scores = dict(zip(AGENTS, g.scores))
        winner = None if scores["white"] == scores["yellow"] else max(scores, key=scores.get)
        log = [{k: v for k, v in s.items() if k not in ("paths", "events")} for s in self.log]
        return {"a": HUMAN, "b": self.opponent, "i": 0, "seed": self.seed, "first": "white" if self.first == HUMAN else "yellow",
                "winner": winner, "scores": scores, "shots": g.shots, "innings": g.innings, "cpu_s": self.cpu, "turns": self.turns,
                "log": log}

    def settings(self) -> dict:
        return {"app": WEB_APP, "players": [HUMAN, self.opponent], "opponent": self.config, "physics": self.physics,
                "noise": self.noise_name, "target": self.target, "seed": self.seed, "first": self.first,
                "max_innings": self.game.max_innings, "foul_penalty": self.game.foul_penalty, "id": self.id}

    def save(self) -> Path:
        from billiards.league.play import summarize
        from billiards.provenance import git_commit

        stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(self.started))
        d = Path(self.out_dir) / "matches" / f"{stamp}-{self.id}"
        d.mkdir(parents=True, exist_ok=True)
        run = run_identity(self.settings())
        rec = append_record(d / MATCHES_FILE, self.record(), run)
        league = {"app": WEB_APP, "command": "python -m billiards.web (the play view)", "commit": git_commit(),
                  **noise_record(self.noise), "physics": self.params.describe(), "target": self.target, "start": "canonical",
                  "foul_penalty": self.game.foul_penalty, "max_innings": self.game.max_innings, "matches_per_ordered_pair": 1,
                  "seed": self.seed, "agents": {HUMAN: {"kind": "human"}, self.opponent: self.config},
                  **summarize([rec], [HUMAN, self.opponent], self.noise.describe()), "run": run}
        atomic_write_text(d / LEAGUE_FILE, json.dumps(league, indent=2) + "\n")
        self.saved = d
        return d


class Matches:
    """The matches in progress, by id (the oldest finished ones are forgotten past MAX_SESSIONS)."""

    def __init__(self, out_dir: Path | None):
        self.out_dir = out_dir
        self.sessions: dict[str, Match] = {}
        self.lock = threading.Lock()

    def new(self, **kwargs) -> Match:
        m = Match(out_dir=self.out_dir, **kwargs)
        with self.lock:
            self.sessions[m.id] = m
            while len(self.sessions) > MAX_SESSIONS:
                old = next((k for k, v in self.sessions.items() if v.over), next(iter(self.sessions)))
                del self.sessions[old]
        return m

    def get(self, match_id: str) -> Match:
        with self.lock:
            if match_id not in self.sessions:
                raise KeyError(match_id)
            return self.sessions[match_id]


__all__ = ["HUMAN", "Match", "MatchError", "MatchOver", "Matches"]
