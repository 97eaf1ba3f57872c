"""Recorded runs the replay view opens, and the folders it may read them from.

Kinds (:func:`list_runs`):

* ``p3``: a search run's P3 ledger (``chains.jsonl``, one chain a line, each with its
  ``last_shots``: the table, the commanded shot, whether it scored and, under noise, the shot
  played): every chain's last shots, replayed exactly from the played shot;
* ``league``: a league's ``matches.jsonl`` (``python match.py``): its records hold the scores, not
  the shots, so a match is replayed by playing it again (the league's players, seed, break and
  noise from ``league.json``; every match of a league depends only on its seed) and the replay
  says whether it reproduces the recorded scores;
* ``web``: a match played in the viewer (``outputs/web/matches/...``): a ``matches.jsonl`` record
  that also holds every shot;
* ``scorecard``: a benchmark scorecard (``results/bench``): its numbers per unit, no shots.

Paths (:class:`RunStore`): only inside the repository's ``results/``, the viewer's own output
folder and the run directories given on the command line; a path with ``..`` is refused, as is
an absolute path elsewhere and a symlink that leads out (paths are resolved before they are
checked).
"""

from __future__ import annotations

import json
import os
import threading
from pathlib import Path

import numpy as np

from billiards.files import CHAINS, CHAINS_FILE, LEAGUE_FILE, MATCHES, MATCHES_FILE, ROOT, LedgerError, read_ledger

CONFIG_FILE = "config.yaml"
WEB_APP = "billiards.web"  # league.json's "app" of a match played in the viewer


class PathRefused(PermissionError):
    """A path outside the folders the viewer reads."""


class RunNotFound(FileNotFoundError):
    pass


class RunStore:
    """The folders runs are read from, and the checks every path goes through."""

    def __init__(self, root: Path = ROOT, run_dirs=(), out_dir: Path | None = None):
        self.root = Path(root).resolve()
        self.results = self.root / "results"
        self.out_dir = Path(out_dir).resolve() if out_dir is not None else None
        self.run_dirs = [Path(d).resolve() for d in run_dirs]
        self.allowed = [self.results, *([self.out_dir] if self.out_dir else []), *self.run_dirs]
        self._replays: dict = {}
        self._settings: dict = {}  # (config.yaml, its mtime) -> (physics, noise)
        self._lock = threading.Lock()

    # ------------------------------------------------------------------------- paths

    def display(self, path: Path) -> str:
        """A run's path as the API names it: relative to the repository when inside it."""
        try:
            return str(path.relative_to(self.root))
        except ValueError:
            return str(path)

    def resolve(self, path: str) -> Path:
        """The real path of ``path`` (relative to the repository, or absolute) if it lies inside
        an allowed folder; :class:`PathRefused` or :class:`RunNotFound` otherwise."""
        if not isinstance(path, str) or not path.strip():
            raise PathRefused("path is empty: give a run's path as /api/runs lists it")
        if "\x00" in path or len(path) > 1000:
            raise PathRefused("path is not a usable path")
        p = Path(path)
        if ".." in p.parts:
            raise PathRefused(f"path {path!r} contains '..': give a run's path as /api/runs lists it")
        full = p if p.is_absolute() else self.root / p
        try:
            real = full.resolve(strict=True)
        except (FileNotFoundError, NotADirectoryError):
            if not any(full.absolute() == a or full.absolute().is_relative_to(a) for a in self.allowed):
                raise PathRefused(self._outside(path)) from None
            raise RunNotFound(f"no run at {path!r}") from None
        except OSError as err:
            raise PathRefused(f"path {path!r} cannot be read ({err.strerror})") from None
        if not any(real == a or real.is_relative_to(a) for a in self.allowed):
            raise PathRefused(self._outside(path) + (" (it is a symlink that leads out)" if real != full.absolute() else ""))
        return real

    def _outside(self, path: str) -> str:
        where = ", ".join(self.display(a) for a in self.allowed)
        return f"path {path!r} is outside the folders the viewer reads ({where})"

    # ------------------------------------------------------------------------- listing

    def list_runs(self) -> list[dict]:
        """Every run under the allowed folders (symlinks are not followed), sorted by path."""
        runs: dict[str, dict] = {}
        for base in self.allowed:
            if not base.is_dir():
                continue
            for dirpath, dirnames, filenames in os.walk(base, followlinks=False):
                dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
                d = Path(dirpath)
                if CHAINS_FILE in filenames and not (d / CHAINS_FILE).is_symlink():
                    runs.setdefault(self.display(d), self._p3_entry(d))
                if MATCHES_FILE in filenames and not (d / MATCHES_FILE).is_symlink():
                    runs.setdefault(self.display(d), self._league_entry(d))
                if "scorecard.json" in filenames or d.is_relative_to(self.results / "bench" / "recorded"):
                    for name in sorted(filenames):
                        if name == "scorecard.json" or (name.endswith(".json") and d.is_relative_to(self.results / "bench" / "recorded")):
                            entry = self._scorecard_entry(d / name)
                            if entry is not None:
                                runs.setdefault(self.display(d / name), entry)
        return [runs[k] for k in sorted(runs)]

    def _p3_entry(self, d: Path) -> dict:
        physics, noise = self._p3_settings(d)
        with open(d / CHAINS_FILE, "rb") as f:
            chains = sum(1 for line in f if line.strip())
        return {"path": self.display(d), "kind": "p3", "label": f"P3 chains ({chains}): {self.display(d)}",
                "units": chains, "physics": physics, "noise": noise, "replayable": True}

    def _league_entry(self, d: Path) -> dict:
        league = _read_json(d / LEAGUE_FILE) or {}
        web = league.get("app") == WEB_APP
        with open(d / MATCHES_FILE, "rb") as f:
            matches = sum(1 for line in f if line.strip())
        kind = "web" if web else "league"
        label = ("viewer match" if web else f"league ({matches} matches)") + f": {self.display(d)}"
        return {"path": self.display(d), "kind": kind, "label": label, "units": matches,
                "physics": league.get("physics", "korean_medium"), "noise": league.get("noise", "none"), "replayable": True}

    def _scorecard_entry(self, path: Path) -> dict | None:
        card = _read_json(path)
        if not (isinstance(card, dict) and isinstance(card.get("track"), str) and "agent" in card):
            return None
        agent = card["agent"].get("name") if isinstance(card["agent"], dict) else card["agent"]
        return {"path": self.display(path), "kind": "scorecard", "label": f"scorecard {card['track']}: {agent}",
                "units": None, "physics": None, "noise": None, "replayable": False}

    def _p3_settings(self, d: Path) -> tuple[str, str]:
        """The physics preset and noise preset of a search run (its config.yaml)."""
        import yaml

        path = d / CONFIG_FILE
        try:
            key = (str(path), path.stat().st_mtime_ns)
        except OSError:
            return "korean_medium", "none"
        if key in self._settings:
            return self._settings[key]
        try:
            cfg = yaml.load(path.read_text(), Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader)) or {}
        except (OSError, yaml.YAMLError):
            cfg = {}
        self._settings[key] = out = self._settings_of(cfg if isinstance(cfg, dict) else {})
        return out

    @staticmethod
    def _settings_of(cfg: dict) -> tuple[str, str]:
        phys, noise = cfg.get("physics") or {}, cfg.get("noise") or {}
        physics = phys.get("preset", "korean_medium") if isinstance(phys, dict) else "korean_medium"
        if isinstance(phys, dict) and any(v is not None for k, v in phys.items() if k != "preset"):
            physics += "+custom"
        if isinstance(noise, dict):
            name = noise.get("preset", "none")
            overridden = any(noise.get(k) is not None for k in ("aim_deg", "speed", "tip_mm", "level_range"))
            if overridden or noise.get("scale", 1) not in (1, 1.0, None):
                name += "+custom"
        else:
            name = "none"
        return physics, name

    # ------------------------------------------------------------------------- one run

    def load(self, path: str, unit: int | None = None) -> dict:
        """A run's replayable shots (see the module docstring); ``unit``: a league match's index,
        which is played again."""
        real = self.resolve(path)
        if real.is_dir() and (real / CHAINS_FILE).is_file():
            return self._load_p3(real)
        if real.is_dir() and (real / MATCHES_FILE).is_file():
            return self._load_matches(real, unit)
        if real.is_file() and real.suffix == ".json":
            card = _read_json(real)
            if isinstance(card, dict) and isinstance(card.get("track"), str) and "agent" in card:
                return self._load_scorecard(real, card)
        raise RunNotFound(f"{path!r} is not a run the viewer replays (a directory with {CHAINS_FILE} or {MATCHES_FILE}, "
                          f"or a benchmark scorecard)")

    def _load_p3(self, d: Path) -> dict:
        physics, noise = self._p3_settings(d)
        records = read_ledger(d / CHAINS_FILE, CHAINS, legacy=True).records
        units = []
        for rec in sorted(records, key=lambda r: r["seed"]):
            shots, n = [], len(rec["last_shots"])
            total = rec["length"] + 1  # the scoring shots and the one that ended the chain
            for k, s in enumerate(rec["last_shots"]):
                played = s[3] if len(s) > 3 else None
                level = float(s[4]) if len(s) > 4 else None
                shots.append({"positions": s[0], "commanded": s[1], "played": played if played is not None else s[1],
                              "noisy": played is not None, "scored": bool(s[2]), "shooter": 0, "level": level,
                              "caption": f"shot {total - n + k + 1} of {total}"})
            units.append({"id": rec["seed"], "title": f"seed {rec['seed']}: {rec['length']} points (last {n} shots)",
                          "shots": shots})
        replayable = "+custom" not in physics
        return {"path": self.display(d), "kind": "p3", "physics": physics.split("+")[0], "noise": noise,
                "replayable": replayable, "note": None if replayable else "custom physics: the viewer replays presets only",
                "units": units}

    def _load_matches(self, d: Path, unit: int | None) -> dict:
        league = _read_json(d / LEAGUE_FILE) or {}
        web = league.get("app") == WEB_APP
        records = read_ledger(d / MATCHES_FILE, MATCHES, legacy=True).records
        units = []
        for i, r in enumerate(records):
            s = r["scores"]
            who = {"white": r["a"], "yellow": r["b"], None: "nobody (a draw)"}[r["winner"]]
            title = (f"match {i}: {r['a']} (white) {s['white']:g} - {s['yellow']:g} {r['b']} (yellow), seed {r['seed']}, "
                     f"{r['first']} breaks; {who} wins")
            shots = r.get("log") if web else None
            units.append({"id": i, "title": title, "shots": shots, "record": {k: r[k] for k in
                          ("a", "b", "i", "seed", "first", "winner", "scores", "shots", "innings")}})
        out = {"path": self.display(d), "kind": "web" if web else "league", "physics": league.get("physics", "korean_medium"),
               "noise": league.get("noise", "none"), "target": league.get("target"), "replayable": True,
               "note": None if web else "a league records scores, not shots: choose a match and it is played again",
               "units": units}
        if unit is not None:
            if not 0 <= unit < len(records):
                raise RunNotFound(f"{self.display(d)} has matches 0..{len(records) - 1}, not {unit}")
            if not web:
                key = (str(d), unit)
                with self._lock:
                    if key not in self._replays:
                        self._replays[key] = replay_league_match(league, records[unit])
                units[unit] = {**units[unit], **self._replays[key]}
            out["units"] = [units[unit]]
        return out

    def _load_scorecard(self, path: Path, card: dict) -> dict:
        summary = {k: v for k, v in card.items() if k not in ("values", "runs", "track_record", "agent")}
        return {"path": self.display(path), "kind": "scorecard", "physics": None, "noise": None, "replayable": False,
                "note": "a scorecard records its numbers per inning, chain or match, not the shots: nothing to replay",
                "summary": summary, "agent": card.get("agent"), "units": []}


def _read_json(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _league_noise(league: dict):
    from billiards.physics.noise import NOISE_PRESETS, NoiseModel

    name = league.get("noise", "none")
    if name in NOISE_PRESETS:
        return NOISE_PRESETS[name]
    sig = league.get("noise_sigmas") or {}
    levels = league.get("noise_levels")
    return NoiseModel(sigma_aim_deg=sig.get("aim_deg", 0.0), sigma_speed=sig.get("speed", 0.0), sigma_tip_mm=sig.get("tip_mm", 0.0),
                      level_range=tuple(levels) if levels else None)


def replay_league_match(league: dict, rec: dict) -> dict:
    """A league's match played again, shot by shot, with its own players, seed, break and rules
    (as :func:`billiards.league.play.play_match` plays it): ``shots`` and whether the replay
    gave the recorded scores (``reproduced``)."""
    from billiards.envs.sagu import AGENTS, SaguEnv, shooter_view
    from billiards.league.agents import AgentConfig, make_agent
    from billiards.physics import get_params

    try:
        params = get_params(league.get("physics", "korean_medium"))
        noise = _league_noise(league)
        players = {side: make_agent(AgentConfig(**league["agents"][name]), noise, params)
                   for side, name in zip(AGENTS, (rec["a"], rec["b"]))}
    except (KeyError, TypeError, ValueError) as err:
        raise LedgerError(f"cannot rebuild this league's players from its league.json: {type(err).__name__}: {err}") from None
    game = SaguEnv(target=league.get("target", 10), max_innings=league.get("max_innings", 200), start=league.get("start", "canonical"),
                   foul_penalty=league.get("foul_penalty", 1.0), noise=noise, physics=params)
    rng = np.random.default_rng(rec["seed"])
    game.reset(rng, AGENTS.index(rec["first"]))
    for i, side in enumerate(AGENTS):
        players[side].reseed(rec["seed"] * 2 + i)
    shots = []
    while True:
        mover = game.mover
        before, level = game.positions.copy(), game.shot_level
        view = shooter_view(game.positions, mover)
        action = players[AGENTS[mover]].act(view) if level is None else players[AGENTS[mover]].act(view, level)
        shot = game.shoot(action, rng)
        shots.append(match_shot(before, shot, level, game, [rec["a"], rec["b"]][mover]))
        if shot["won"] or shot["over_limit"]:
            break
    scores = dict(zip(AGENTS, game.scores))
    return {"shots": shots, "replayed_scores": scores, "reproduced": scores == rec["scores"]}


def match_shot(before: np.ndarray, shot: dict, level, game, who: str) -> dict:
    """A shot of a two-player game as the replay view reads it (the table in its own ball order)."""
    played, commanded = shot["raw_action"], shot["commanded_action"]
    return {"positions": before.tolist(), "commanded": commanded.tolist(), "played": played.tolist(),
            "noisy": not np.array_equal(played, commanded), "scored": bool(shot["score"]), "foul": bool(shot["foul"]),
            "shooter": int(shot["player"]), "level": level, "who": who, "scores": [float(s) for s in game.scores],
            "final": game.positions.tolist(), "caption": f"{who} ({'white' if shot['player'] == 0 else 'yellow'}) shoots"}


__all__ = ["PathRefused", "RunNotFound", "RunStore", "WEB_APP", "match_shot", "replay_league_match"]
