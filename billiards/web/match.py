"""Matches between the person at the page and a league player, kept by the server on disk.

The game is the two-player env's (:class:`billiards.envs.sagu.SaguEnv`: its rules, turns,
fouls, target and innings limit, its execution noise drawn from the match's generator): the
person is ``white`` (``human``), the league player ``yellow``. The table and the noise come from
``seed`` (one generator for the whole match, as a league's :func:`billiards.league.play.play_match`);
the league player is reseeded before each of its turns from ``(seed, turn)``
(:func:`turn_seed`), so that its next decision depends on the match's ledger alone and a match
resumed from disk plays on exactly as it would have. The person's shot is the raw (theta, p,
a, b), given to the env as its normalised action (float64, so nothing is rounded to float32 on
the way); the env applies the noise; then the league player plays its turns until the person is
to play again or the match ends. Every shot comes back with its paths so the page animates them.

A match is server state on disk from its start, ``<out>/matches/<id>/`` (``id``: its start
time and a random part, ``20260101-120000-1a2b3c4d``):

* ``shots.jsonl`` (:data:`SHOTS`, a registered ledger kind): one sealed record per shot, written
  as the shot ends (its turn number, who shot, the env's action, the commanded and played shot,
  the table before and after, the scores after), under the match's run identity;
* ``match.json``: the match's settings and where it stands (turn, scores, whose turn, over),
  written again after every shot and checked against the ledger by ``python -m billiards.files
  verify`` (:func:`summary_problems`).

Every shot is written under the folder's lock (:func:`billiards.files.run_lock`): one writer per
match, and a server that finds the ledger grown behind its back (another server over the same
folder) refuses the shot and reads the match again. A match the server does not hold (after a
restart, or forgotten past :data:`MAX_SESSIONS`) is read back from its folder on the first
request that names it: its ledger replayed shot by shot through the env (each shot must end on
its recorded table with its recorded scores), a torn last line cut off. A match that is never
finished stays on disk as it stood, verifiable and resumable. At its end a match is also saved as
a league ledger of one match in the same folder: ``matches.jsonl`` (a sealed record as
:mod:`billiards.league` writes them, with every shot in ``log``) and ``league.json`` (the pair's
counts), which the replay view lists.

Each shot request names the turn it answers (``turn``: the number of shots played, as the state
gave it); a request for another turn (a second click, a duplicate sent at once, a stale page) is
refused (:class:`StaleTurn`), and one lock per match makes concurrent requests play one at a time.
"""

from __future__ import annotations

import json
import math
import os
import re
import secrets
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from billiards import domain
from billiards.envs.sagu import AGENTS, SaguEnv, shooter_view
from billiards.files import (LEAGUE_FILE, MATCHES_FILE, LedgerError, LedgerKind, RunFileError, append_record, atomic_write_text,
                             display_path, read_ledger, read_run_json, register_ledger, run_identity, run_lock)
from billiards.physics import DEFAULT_PRESET, check_actions, get_params
from billiards.physics.noise import get_noise, noise_record

from . import sim
from .runs import WEB_APP, match_shot

HUMAN = "human"
MAX_SESSIONS = 64  # matches held in memory; the others are read back from disk when asked for
MATCHES_DIR = "matches"
SHOTS_FILE, MATCH_FILE = "shots.jsonl", "match.json"
MATCH_ID = re.compile(r"\d{8}-\d{6}-[0-9a-f]{8}")
LOCK_COMMAND = "python -m billiards.web (a match played in the page)"
SETTINGS = ("opponent", "noise", "physics", "target", "seed", "first", "max_innings", "foul_penalty")


class MatchError(ValueError):
    pass


class MatchOver(MatchError):
    pass


class StaleTurn(MatchError):
    """A shot request for a turn that is not the match's current one."""


class MatchMoved(MatchError):
    """The match's ledger grew behind this server's back (another server over the same folder)."""


def turn_seed(seed: int, turn: int) -> int:
    """The seed the league player is reseeded with before it plays the match's shot ``turn``."""
    return int(np.random.SeedSequence([2 * int(seed) + 1, int(turn)]).generate_state(1)[0])


# ----------------------------------------------------------------------------- the ledger kind


def _is_int(x, low: int = 0) -> bool:
    return isinstance(x, int) and not isinstance(x, bool) and x >= low


def _is_number(x) -> bool:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return False
    try:
        return math.isfinite(float(x))
    except OverflowError:  # an integer beyond any float
        return False


def _numbers(x, n: int) -> bool:
    return isinstance(x, list) and len(x) == n and all(_is_number(v) for v in x)


def _table(x) -> bool:
    return isinstance(x, list) and len(x) == 4 and all(_numbers(b, 2) for b in x)


def _shot_problem(rec: dict) -> str | None:
    """What is wrong with a shot record's shape, or None."""
    if not _is_int(rec.get("turn")):
        return "turn must be an integer >= 0"
    if not isinstance(rec.get("who"), str) or not rec["who"]:
        return "who must name the player who shot"
    if rec.get("shooter") not in (0, 1) or isinstance(rec.get("shooter"), bool):
        return "shooter must be 0 (white) or 1 (yellow)"
    for key in ("action", "commanded", "played"):
        if not _numbers(rec.get(key), 4):
            return f"{key} must be four finite numbers"
    for key in ("positions", "final"):
        if not _table(rec.get(key)):
            return f"{key} must be a table: four balls of two finite numbers"
    if not _numbers(rec.get("scores"), 2):
        return "scores must be two finite numbers (white, yellow)"
    for key in ("scored", "foul", "over"):
        if not isinstance(rec.get(key), bool):
            return f"{key} must be true or false"
    return None


def summary_problems(records: list[dict], summary: dict, name: str) -> list[str]:
    """Where a match's ``match.json`` (``summary``, read from the file ``name``) disagrees with its
    ledger's shot records: the turns 0, 1, 2 ... in order, each shot starting on the table the
    one before it left, and the summary's turn, scores and end those of the last shot."""
    out = []
    for k, rec in enumerate(records):
        if rec["turn"] != k:
            out.append(f"the ledger's shot on line {k + 1} is turn {rec['turn']}, not {k}: a match's shots are its turns in order")
            break
        if k and rec["positions"] != records[k - 1]["final"]:
            out.append(f"the ledger's turn {k} does not start on the table turn {k - 1} left")
            break
    if records and any(r["over"] for r in records[:-1]):
        out.append("the ledger holds shots after the one that ended the match")
    n = len(records)
    if summary.get("turn") != n:
        out.append(f"{name} says the match is at turn {summary.get('turn')!r}; its ledger holds {n} shots")
    scores = records[-1]["scores"] if records else [0.0, 0.0]
    theirs = summary.get("scores")
    if not (isinstance(theirs, list) and len(theirs) == 2 and [float(v) for v in theirs if _is_number(v)] == scores):
        out.append(f"{name} gives scores that are not its last shot's ({scores[0]:g} - {scores[1]:g})")
    over = bool(records and records[-1]["over"])
    if summary.get("over") is not over:
        out.append(f"{name} says the match is {'over' if summary.get('over') else 'not over'}; its ledger says "
                   f"{'it is' if over else 'it is not'}")
    return out


SHOTS = register_ledger(LedgerKind(SHOTS_FILE, "viewer match shot record", lambda r: r["turn"], lambda r: f"turn {r['turn']}",
                                   _shot_problem, MATCH_FILE, summary_problems))


# ----------------------------------------------------------------------------- one match


def new_id(started: float) -> str:
    return time.strftime("%Y%m%d-%H%M%S", time.localtime(started)) + "-" + secrets.token_hex(4)


class Match:
    """One match (see the module docstring); ``out_dir`` None: kept in memory only."""

    def __init__(self, opponent: str, *, noise: str = "fastfiz_x5", physics: str = DEFAULT_PRESET, target: int = 5,
                 seed: int = 0, first: str = HUMAN, max_innings: int = 200, foul_penalty: float = 1.0,
                 out_dir: Path | None = None, dt: float = sim.DEFAULT_DT, match_id: str | None = None,
                 started: float | None = None):
        from billiards.bench.adapters import league_player

        self.started = time.time() if started is None else float(started)
        self.id = match_id or new_id(self.started)
        self.opponent, self.noise_name, self.physics, self.target, self.seed = opponent, noise, physics, target, seed
        self.first = first
        self.params, self.noise = get_params(physics), get_noise(noise)
        self.player, self.config = league_player(opponent, self.noise, self.params)
        self.game = SaguEnv(target=target, max_innings=max_innings, start="canonical", foul_penalty=foul_penalty,
                            noise=self.noise, physics=self.params)
        self.rng = np.random.default_rng(seed)
        self.game.reset(self.rng, 0 if first == HUMAN else 1)
        self.log: list[dict] = []
        self.over, self.truncated = False, False
        self.cpu, self.turns = {"white": 0.0, "yellow": 0.0}, {"white": 0, "yellow": 0}
        self.out_dir, self.saved, self.dt = out_dir, None, dt
        self.dir = Path(out_dir) / MATCHES_DIR / self.id if out_dir is not None else None
        self.ledger_bytes = 0  # the ledger's size after this server's last write (another writer: it differs)
        self.broken = False  # a shot played but not written: the match is read back from disk
        self.lock = threading.Lock()
        self.updated = self.started

    @property
    def turn(self) -> int:
        """The number of shots played: the turn the next shot request answers."""
        return len(self.log)

    # ------------------------------------------------------------------------- state

    def state(self) -> dict:
        g = self.game
        w, y = g.scores
        winner = None
        if self.over and w != y:
            winner = HUMAN if w > y else self.opponent
        return {"id": self.id, "opponent": self.opponent, "noise": self.noise_name, "physics": self.physics,
                "target": self.target, "seed": self.seed, "first": self.first, "max_innings": g.max_innings,
                "positions": g.positions.tolist(), "turn": self.turn,
                "scores": {HUMAN: w, self.opponent: y}, "to_play": None if self.over else (HUMAN if g.mover == 0 else self.opponent),
                "innings": g.innings, "shots": g.shots, "over": self.over, "truncated": self.truncated, "winner": winner,
                "level": g.shot_level, "folder": display_path(self.dir) if self.dir is not None else None,
                "saved": display_path(self.saved) if self.saved else None}

    def _shot(self, action, who: str, cpu: float = 0.0) -> dict:
        g = self.game
        before, level, turn = g.positions.copy(), g.shot_level, self.turn
        result = g.shoot(action, self.rng)
        rec = match_shot(before, result, level, g, who)
        paths = sim.replay_played(before, rec["played"], physics=self.physics, shooter=rec["shooter"], dt=self.dt)
        if paths["final"] != rec["final"]:  # the env's batch and the single shot agree bit for bit (docs/physics.md)
            raise RuntimeError("the replayed shot does not end where the match's shot did")
        if result["won"] or result["over_limit"]:
            self.over, self.truncated = True, bool(result["over_limit"])
        rec.update(turn=turn, action=np.asarray(action, dtype=np.float64).tolist(), innings=g.innings, over=self.over,
                   cpu_s=cpu)
        try:
            self._append(rec)
        except BaseException:
            self.broken = True  # the game moved on, its ledger did not: read back from disk on the next request
            raise
        rec.update(result=paths["result"], events=paths["events"], paths=paths["paths"])
        self.log.append(rec)
        self.updated = time.time()
        if self.dir is not None:
            self._write_summary()
        return rec

    # ------------------------------------------------------------------------- turns

    def start(self) -> list[dict]:
        """Write the match's folder; the league player's opening turns when it breaks."""
        with self.lock, self._writing(fresh=True):
            return self._agent_turns()

    def human_shot(self, action, turn: int) -> list[dict]:
        """The person's shot (raw theta, p, a, b) answering ``turn``, then the league player's turns."""
        with self.lock:
            if not self.over and self.game.mover == 1:  # the league player's turns an error cut short: played first
                with self._writing():
                    self._agent_turns()
            if self.over:
                scores = ", ".join(f"{who} {points:g}" for who, points in self.state()["scores"].items())
                raise MatchOver(f"match {self.id} is over ({scores}); start another")
            if turn != self.turn:
                played = "was played already" if turn < self.turn else "has not come"
                raise StaleTurn(f"turn {turn} of match {self.id} {played}: the match is at turn {self.turn} "
                                f"({'your shot' if self.game.mover == 0 else self.opponent + ' to play'}); nothing was played")
            if self.game.mover != 0:
                raise MatchError(f"match {self.id}: it is {self.opponent}'s turn")
            raw = np.asarray(action, dtype=np.float64)
            check_actions(raw)
            wrapped = raw.copy()
            wrapped[0] = wrapped[0] % (2 * np.pi)
            x = domain.normalize_action(wrapped)
            with self._writing():
                shots = [self._shot(x, HUMAN)]
                self.turns["white"] += 1
                shots += self._agent_turns()
            return shots

    def _agent_turns(self) -> list[dict]:
        shots = []
        while not self.over and self.game.mover == 1:
            view = shooter_view(self.game.positions, 1)
            level = self.game.shot_level
            self.player.reseed(turn_seed(self.seed, self.turn))
            t0 = time.process_time()
            action = self.player.act(view) if level is None else self.player.act(view, level)
            cpu = time.process_time() - t0
            self.cpu["yellow"] += cpu
            self.turns["yellow"] += 1
            shots.append(self._shot(action, self.opponent, cpu))
        if self.over and self.saved is None and self.out_dir is not None:
            self.save()
        return shots

    def recent(self) -> list[dict]:
        """The last exchange: the person's last shot and the league player's turns after it (with
        their paths, simulated again), or the league player's opening turns."""
        k = len(self.log)
        while k > 0 and self.log[k - 1]["who"] != HUMAN:
            k -= 1
        k = max(k - 1, 0)
        out = []
        for rec in self.log[k:]:
            if "paths" not in rec:
                paths = sim.replay_played(rec["positions"], rec["played"], physics=self.physics, shooter=rec["shooter"], dt=self.dt)
                rec.update(result=paths["result"], events=paths["events"], paths=paths["paths"])
            out.append(rec)
        return out

    # ------------------------------------------------------------------------- on disk

    def settings(self) -> dict:
        return {"app": WEB_APP, "players": [HUMAN, self.opponent], "opponent": self.config, "physics": self.physics,
                "noise": self.noise_name, "target": self.target, "seed": self.seed, "first": self.first,
                "max_innings": self.game.max_innings, "foul_penalty": self.game.foul_penalty, "id": self.id}

    def summary(self) -> dict:
        """``match.json``: the settings that rebuild the match and where it stands."""
        st = self.state()
        return {"app": WEB_APP, "kind": "a match played in the viewer (python -m billiards.web)", "id": self.id,
                "started": time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(self.started)), "started_at": self.started,
                "updated": time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(self.updated)),
                "settings": {"opponent": self.opponent, "noise": self.noise_name, "physics": self.physics, "target": self.target,
                             "seed": self.seed, "first": self.first, "max_innings": self.game.max_innings,
                             "foul_penalty": self.game.foul_penalty},
                "turn": self.turn, "scores": [float(s) for s in self.game.scores], "players": [HUMAN, self.opponent],
                "to_play": st["to_play"], "over": self.over, "truncated": self.truncated, "winner": st["winner"],
                "league": MATCHES_FILE if self.saved else None, "run": run_identity(self.settings())}

    @contextmanager
    def _writing(self, fresh: bool = False):
        """The match's folder held for writing (its run lock); refused if its ledger grew behind this server's back."""
        if self.dir is None:
            yield
            return
        with run_lock(self.dir, command=LOCK_COMMAND, say=None):
            ledger = self.dir / SHOTS_FILE
            if fresh:
                if os.path.lexists(ledger):
                    raise MatchError(f"{display_path(self.dir)} holds a match already")
                ledger.touch()
                self._write_summary()
            else:
                size = ledger.stat().st_size if ledger.is_file() else -1
                if size != self.ledger_bytes:
                    raise MatchMoved(f"match {self.id} was played on elsewhere (its ledger changed on disk, another viewer "
                                     f"over the same folder?): nothing was played; reload the match")
            yield

    def _append(self, rec: dict) -> None:
        if self.dir is None:
            return
        append_record(self.dir / SHOTS_FILE, rec, run_identity(self.settings()))
        self.ledger_bytes = (self.dir / SHOTS_FILE).stat().st_size

    def _write_summary(self) -> None:
        atomic_write_text(self.dir / MATCH_FILE, json.dumps(self.summary(), indent=2) + "\n")

    def record(self) -> dict:
        g = self.game
        scores = dict(zip(AGENTS, g.scores))
        winner = None if scores["white"] == scores["yellow"] else max(scores, key=scores.get)
        keep = ("positions", "commanded", "played", "noisy", "scored", "foul", "shooter", "level", "who", "scores", "final", "caption")
        log = [{k: s[k] for k in keep} for s in self.log]
        return {"a": HUMAN, "b": self.opponent, "i": 0, "seed": self.seed, "first": "white" if self.first == HUMAN else "yellow",
                "winner": winner, "scores": scores, "shots": g.shots, "innings": g.innings, "cpu_s": self.cpu, "turns": self.turns,
                "log": log}

    def save(self) -> Path:
        """The finished match as a league ledger of one match (``matches.jsonl``, ``league.json``) in its folder."""
        from billiards.league.play import summarize
        from billiards.provenance import git_commit

        d = self.dir
        d.mkdir(parents=True, exist_ok=True)
        run = run_identity(self.settings())
        if not (d / MATCHES_FILE).exists():
            rec = append_record(d / MATCHES_FILE, self.record(), run)
        else:  # a crash cut the summary short
            rec = read_ledger(d / MATCHES_FILE, _league_kind(), run).records[0]
        league = {"app": WEB_APP, "command": "python -m billiards.web (the play view)", "commit": git_commit(),
                  **noise_record(self.noise), "physics": self.params.describe(), "target": self.target, "start": "canonical",
                  "foul_penalty": self.game.foul_penalty, "max_innings": self.game.max_innings, "matches_per_ordered_pair": 1,
                  "seed": self.seed, "agents": {HUMAN: {"kind": "human"}, self.opponent: self.config},
                  **summarize([rec], [HUMAN, self.opponent], self.noise.describe()), "run": run}
        atomic_write_text(d / LEAGUE_FILE, json.dumps(league, indent=2) + "\n")
        self.saved = d
        self._write_summary()
        return d

    # ------------------------------------------------------------------------- read back

    @classmethod
    def load(cls, out_dir: Path, match_id: str, dt: float = sim.DEFAULT_DT) -> Match:
        """The match ``match_id`` read back from ``out_dir/matches/<id>/``: its settings from
        ``match.json``, its shots replayed from its ledger (each must end as recorded); the league
        player's pending turns played. FileNotFoundError if there is none; LedgerError (a
        sentence) if it cannot be resumed."""
        d = Path(out_dir) / MATCHES_DIR / match_id
        if not MATCH_ID.fullmatch(match_id) or d.is_symlink() or not d.is_dir():
            raise FileNotFoundError(match_id)
        with run_lock(d, command=LOCK_COMMAND, say=None):
            try:
                summary = read_run_json(d / MATCH_FILE, "summary")
            except FileNotFoundError:
                raise FileNotFoundError(match_id) from None
            except RunFileError as err:
                raise LedgerError(str(err)) from None
            settings = summary.get("settings") if isinstance(summary, dict) else None
            if not isinstance(settings, dict) or set(settings) != set(SETTINGS):
                raise LedgerError(f"{display_path(d / MATCH_FILE)} does not give the match's settings ({', '.join(SETTINGS)})")
            started = summary.get("started_at")
            try:
                m = cls(**settings, out_dir=out_dir, dt=dt, match_id=match_id,
                        started=started if _is_number(started) else None)
            except Exception as err:  # noqa: BLE001 - settings a file gave: said as a sentence
                raise LedgerError(f"{display_path(d / MATCH_FILE)}: its settings do not make a match ({err})") from None
            scan = read_ledger(d / SHOTS_FILE, SHOTS, run_identity(m.settings()), repair=True)
            m._replay(scan.records)
            m.ledger_bytes = (d / SHOTS_FILE).stat().st_size if (d / SHOTS_FILE).is_file() else 0
            if (d / MATCHES_FILE).is_file() and (d / LEAGUE_FILE).is_file():
                m.saved = d
            if not (d / SHOTS_FILE).is_file():
                (d / SHOTS_FILE).touch()
            m._write_summary()  # never trusted: written again from the ledger
            m._agent_turns()  # a server stopped between the person's shot and the player's turns
        return m

    def _replay(self, records: list[dict]) -> None:
        g, where = self.game, display_path(self.dir / SHOTS_FILE)
        for k, rec in enumerate(records):
            who = HUMAN if g.mover == 0 else self.opponent
            if self.over:
                raise LedgerError(f"{where}: turn {k} follows the end of the match")
            if rec["turn"] != k or rec["who"] != who or rec["shooter"] != g.mover:
                raise LedgerError(f"{where}: line {k + 1} is not turn {k} of {who}")
            before = g.positions.copy()
            result = g.shoot(np.asarray(rec["action"], dtype=np.float64), self.rng)
            if g.positions.tolist() != rec["final"] or [float(s) for s in g.scores] != rec["scores"] or \
                    before.tolist() != rec["positions"]:
                raise LedgerError(f"{where}: turn {k} does not replay (played again, it does not end on its recorded table "
                                  f"with its recorded scores): the match cannot be resumed")
            side = "white" if rec["shooter"] == 0 else "yellow"
            self.turns[side] += 1
            self.cpu[side] += float(rec.get("cpu_s", 0.0)) if _is_number(rec.get("cpu_s", 0.0)) else 0.0
            if result["won"] or result["over_limit"]:
                self.over, self.truncated = True, bool(result["over_limit"])
            self.log.append({key: value for key, value in rec.items() if key not in ("run", "sha256")})


def _league_kind():
    from billiards.files import MATCHES

    return MATCHES


class Matches:
    """The matches, by id: the ones in memory (the least recently used forgotten past
    MAX_SESSIONS) and, with an out folder, every one saved there (read back when asked for)."""

    def __init__(self, out_dir: Path | None, dt: float = sim.DEFAULT_DT):
        self.out_dir = Path(out_dir) if out_dir is not None else None
        self.dt = dt
        self.sessions: dict[str, Match] = {}
        self.keys: dict[str, str] = {}  # a start request's key -> the match it started
        self.lock = threading.Lock()
        self.start_lock = threading.Lock()  # one match started at a time: a repeated key finds the first
        self._loading: dict[str, threading.Lock] = {}

    def new(self, key: str | None = None, **kwargs) -> tuple[Match, list[dict], bool]:
        """A new match started (its folder written, the league player's opening turns played):
        (the match, those turns, False); a ``key`` already used: (its match, [], True)."""
        with self.start_lock:
            if key is not None and key in self.keys:
                try:
                    return self.get(self.keys[key]), [], True
                except KeyError:
                    pass
            m = Match(out_dir=self.out_dir, dt=self.dt, **kwargs)
            self._hold(m)
            if key is not None:
                self.keys[key] = m.id
                while len(self.keys) > 4 * MAX_SESSIONS:
                    del self.keys[next(iter(self.keys))]
        shots = m.start()
        return m, shots, False

    def _hold(self, m: Match) -> None:
        with self.lock:
            self.sessions.pop(m.id, None)
            self.sessions[m.id] = m
            while len(self.sessions) > MAX_SESSIONS:
                old = next((k for k, v in self.sessions.items() if v.over or v.dir is not None), next(iter(self.sessions)))
                del self.sessions[old]

    def get(self, match_id: str) -> Match:
        """The match ``match_id``: held, or read back from its folder (KeyError: none;
        LedgerError: its folder cannot be resumed)."""
        with self.lock:
            if match_id in self.sessions and not self.sessions[match_id].broken:
                m = self.sessions.pop(match_id)
                self.sessions[match_id] = m  # the most recently used last
                return m
            self.sessions.pop(match_id, None)
            if self.out_dir is None or not MATCH_ID.fullmatch(match_id):
                raise KeyError(match_id)
            loading = self._loading.setdefault(match_id, threading.Lock())
        with loading:
            with self.lock:
                if match_id in self.sessions:
                    return self.sessions[match_id]
            try:
                m = Match.load(self.out_dir, match_id, dt=self.dt)
            except FileNotFoundError:
                raise KeyError(match_id) from None
            finally:
                with self.lock:
                    self._loading.pop(match_id, None)
            self._hold(m)
            return m

    def forget(self, match_id: str) -> None:
        with self.lock:
            self.sessions.pop(match_id, None)

    def listed(self, most: int = 20) -> list[dict]:
        """The matches saved in the out folder, the most recent first: id, opponent, scores, turn, over."""
        if self.out_dir is None or not (self.out_dir / MATCHES_DIR).is_dir():
            return []
        ids = sorted((p.name for p in (self.out_dir / MATCHES_DIR).iterdir() if MATCH_ID.fullmatch(p.name)), reverse=True)
        out = []
        for match_id in ids[:most]:
            with self.lock:
                held = self.sessions.get(match_id)
            if held is not None:
                s = held.summary()
            else:
                try:
                    s = read_run_json(self.out_dir / MATCHES_DIR / match_id / MATCH_FILE, "summary")
                except (OSError, ValueError):
                    continue
            settings = s.get("settings") if isinstance(s, dict) else None
            if not isinstance(settings, dict):
                continue
            out.append({"id": match_id, "opponent": settings.get("opponent"), "target": settings.get("target"),
                        "noise": settings.get("noise"), "scores": s.get("scores"), "turn": s.get("turn"), "over": s.get("over"),
                        "winner": s.get("winner"), "updated": s.get("updated")})
        return out


__all__ = ["HUMAN", "MATCH_FILE", "MATCH_ID", "SHOTS", "SHOTS_FILE", "Match", "MatchError", "MatchMoved", "MatchOver", "Matches",
           "StaleTurn", "summary_problems", "turn_seed"]
