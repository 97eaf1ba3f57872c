"""Recorded runs the replay view opens, and the folders it may read them from.

Kinds (:func:`list_runs`):

* ``p3``: a search run's P3 ledger (``chains.jsonl``, one chain a line, each with its
  ``last_shots``: the table, the commanded shot, whether it scored and, under noise, the shot
  played): every chain's last shots, replayed exactly from the played shot;
* ``p1``: a search run's P1 (``results.json`` of protocol p1 beside ``config.yaml``): its
  record holds each inning's points, not the shots, and its innings step together with one
  search generator, so the first inning asked for plays the whole run again once
  (:func:`billiards.web.replays.replay_p1`, at most 20,000 shots), kept for the others, and the
  replay says whether its points per inning equal the record's;
* ``league``: a league's ``matches.jsonl`` (``python match.py``): its records hold the scores, not
  the shots, so a match is replayed by playing it again (the league's players, seed, break and
  noise from ``league.json``; every match of a league depends only on its seed) and the replay
  says whether it reproduces the recorded scores;
* ``web``: a match played in the viewer (``outputs/web/matches/...``): a ``matches.jsonl`` record
  that also holds every shot;
* ``scorecard``: a benchmark scorecard's run (``results/bench/scorecards/<track>/<agent>/``:
  ``evaluation.json`` and the ledger ``units.jsonl``): an inning, chain or match asked for is
  played again by its agent on its seed (its whole unit: a block of innings plays together) and
  the replay says whether the unit's record equals the ledger's; a spec that names code is
  refused with the reason. A scorecard file without its ledger (``results/bench/recorded``) is
  listed with its figures, nothing to replay;
* ``training``: a training run's evaluation (``eval.json`` beside ``config.yaml``): where the
  run's weights were shipped (``results/policies/<name>/seed<k>.pt`` whose ``source`` is the
  run) its innings are played again with them and compared with ``eval.json``'s points; the
  others are listed with the sentence that says they cannot be.

Paths (:class:`RunStore`): only inside the repository's ``results/``, the viewer's own output
folder and the run directories given on the command line; a path with ``..`` is refused, as is
an absolute path elsewhere and a symlink that leads out (paths are resolved before they are
checked).
"""

from __future__ import annotations

import os
import threading
from collections import OrderedDict
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from billiards import compat
from billiards.physics import DEFAULT_PRESET
from billiards.protocol import Protocol, find_protocol
from billiards.files import (CHAINS, CHAINS_FILE, EVAL_FILE, IDENTITY_FILE, LEAGUE_FILE, MATCHES, MATCHES_FILE, RESULTS_FILE, ROOT,
                             SCORECARD_JSON, UNITS_FILE, LedgerError, read_run_bytes, read_run_json, read_run_text)

from . import replays
from .replays import ReplayRefused, match_shot

CONFIG_FILE = "config.yaml"
WEB_APP = "billiards.web"  # league.json's "app" of a match played in the viewer
MAX_REPLAYS = 24  # runs and units played again, kept (the most recently used)


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
        self._replays: OrderedDict = OrderedDict()  # what was played again, by (kind, path, unit)
        self._locks: dict = {}  # one lock per replay key: one plays it, the others wait for it
        self._settings: dict = {}  # (config.yaml, its mtime) -> (physics, noise)
        self._protocols: dict = {}  # (results.json, its mtime) -> its protocol and size
        self._sources: tuple | None = None  # (the shipped policies' mtimes, run dir -> policy)
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
                files = {f for f in filenames if not (d / f).is_symlink()}
                kind = self.kind_here(d, files.__contains__)
                if kind is not None and (entry := self._handlers(kind)[0](d)) is not None:
                    runs[self.display(d)] = entry
                if kind != "scorecard" and (SCORECARD_JSON in files or d.is_relative_to(self.results / "bench" / "recorded")):
                    for name in sorted(files):
                        if name == SCORECARD_JSON or (name.endswith(".json") and d.is_relative_to(self.results / "bench" / "recorded")):
                            entry = self._scorecard_file_entry(d / name)
                            if entry is not None:
                                runs.setdefault(self.display(d / name), entry)
        return [runs[k] for k in sorted(runs)]

    def _p3_entry(self, d: Path) -> dict:
        physics, noise = self._p3_settings(d)
        chains = _count_lines(d / CHAINS_FILE)
        return {"path": self.display(d), "kind": Protocol.P3, "label": f"P3 chains ({chains}): {self.display(d)}",
                "units": chains, "physics": physics, "noise": noise, "replayable": True}

    def _p1_size(self, d: Path) -> dict | None:
        """A search run's protocol and size from its results.json (None: not a P1 run)."""
        path = d / RESULTS_FILE
        try:
            key = (str(path), path.stat().st_mtime_ns)
        except OSError:
            return None
        if key not in self._protocols:
            res = _read_json(path)
            out = None
            if isinstance(res, dict) and find_protocol(res.get("protocol")) is Protocol.P1 and isinstance(res.get("values"), list):
                extra = res.get("extra") if isinstance(res.get("extra"), dict) else {}
                out = {"innings": len(res["values"]), "shots": extra.get("shots_per_inning"), "values": res["values"],
                       "partial": bool(extra.get("partial"))}
            self._protocols[key] = out
        return self._protocols[key]

    def _p1_refusal(self, d: Path, size: dict, physics: str) -> str | None:
        if size["partial"]:
            return "an interrupted P1 (results.json says partial): its innings stopped part-way and are not played again"
        if "+custom" in physics:
            return "custom physics: the viewer replays presets only"
        shots = size["innings"] * (size["shots"] or 0)
        if shots > replays.MAX_P1_SHOTS:
            return (f"its {size['innings']} innings of {size['shots']} shots ({shots:,} shots, stepped together with one search "
                    f"generator) would have to be played again whole; the viewer plays at most {replays.MAX_P1_SHOTS:,}")
        return None

    def _p1_entry(self, d: Path) -> dict | None:
        size = self._p1_size(d)
        if size is None:
            return None
        physics, noise = self._p3_settings(d)
        refusal = self._p1_refusal(d, size, physics)
        return {"path": self.display(d), "kind": Protocol.P1, "label": f"P1 innings ({size['innings']} x {size['shots']} shots): "
                f"{self.display(d)}", "units": size["innings"], "physics": physics, "noise": noise, "replayable": refusal is None,
                "why_not": refusal}

    def _league_entry(self, d: Path) -> dict:
        league = _read_json(d / LEAGUE_FILE) or {}
        web = league.get("app") == WEB_APP
        matches = _count_lines(d / MATCHES_FILE)
        kind = "web" if web else "league"
        label = ("viewer match" if web else f"league ({matches} matches)") + f": {self.display(d)}"
        return {"path": self.display(d), "kind": kind, "label": label, "units": matches,
                "physics": league.get("physics", DEFAULT_PRESET), "noise": league.get("noise", "none"), "replayable": True}

    def _scorecard_file_entry(self, path: Path) -> dict | None:
        card = _read_json(path)
        if not (isinstance(card, dict) and isinstance(card.get("track"), str) and "agent" in card):
            return None
        agent = card["agent"].get("name") if isinstance(card["agent"], dict) else card["agent"]
        return {"path": self.display(path), "kind": "scorecard", "label": f"scorecard {card['track']}: {agent}",
                "units": None, "physics": None, "noise": None, "replayable": False,
                "why_not": "a scorecard without its ledger (units.jsonl) and evaluation.json: nothing to play again"}

    def _scorecard_entry(self, d: Path) -> dict | None:
        ev = _read_json(d / IDENTITY_FILE)
        if not (isinstance(ev, dict) and isinstance(ev.get("track"), dict) and isinstance(ev.get("agent"), dict)):
            return None
        track, agent = ev["track"], ev["agent"]
        spec = agent.get("spec")
        refusal = replays.scorecard_refusal(spec, self.root)
        units = _count_lines(d / UNITS_FILE)
        return {"path": self.display(d), "kind": "scorecard", "label": f"scorecard {track.get('name')}: {agent.get('name')} ({spec})",
                "units": units, "physics": track.get("physics"), "noise": track.get("noise"), "replayable": refusal is None,
                "why_not": refusal, "track": track.get("name"), "agent": spec}

    def policy_sources(self) -> dict[str, str]:
        """The shipped policies by the training run they came from (read again when a file changes)."""
        files = sorted((self.root / "results" / "policies").glob("*/*.pt"))
        stamp = tuple((str(p), p.stat().st_mtime_ns) for p in files)
        with self._lock:
            if self._sources is None or self._sources[0] != stamp:
                self._sources = (stamp, replays.policy_sources(self.root) if files else {})
            return self._sources[1]

    def _training_entry(self, d: Path) -> dict:
        ev = _read_json(d / EVAL_FILE) or {}
        physics, noise = self._p3_settings(d)
        policy = self.policy_sources().get(self.display(d))
        n = ev.get("n_innings")
        return {"path": self.display(d), "kind": "training", "label": f"training eval ({n} innings): {self.display(d)}",
                "units": n, "physics": physics, "noise": noise, "replayable": policy is not None, "policy": policy,
                "why_not": None if policy else _NO_WEIGHTS}

    def _p3_settings(self, d: Path) -> tuple[str, str]:
        """The physics preset and noise preset of a search run (its config.yaml)."""
        import yaml

        path = d / CONFIG_FILE
        try:
            key = (str(path), path.stat().st_mtime_ns)
        except OSError:
            return DEFAULT_PRESET, "none"
        if key in self._settings:
            return self._settings[key]
        try:
            cfg = yaml.load(read_run_text(path, "config"), Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader)) or {}
        except (OSError, ValueError, yaml.YAMLError):  # refused by the one reader (a link, a FIFO, too large), unreadable
            cfg = {}
        self._settings[key] = out = self._settings_of(compat.upgrade_config_nodes(cfg) if isinstance(cfg, dict) and cfg else {})
        return out

    @staticmethod
    def _settings_of(cfg: dict) -> tuple[str, str]:
        phys, noise = cfg.get("physics") or {}, cfg.get("noise") or {}
        physics = phys.get("preset", DEFAULT_PRESET) if isinstance(phys, dict) else DEFAULT_PRESET
        if isinstance(phys, dict) and any(v is not None for k, v in phys.items() if k != "preset"):
            physics += "+custom"
        if isinstance(noise, dict):
            name = noise.get("preset", "none")
            overridden = any(noise.get(k) is not None for k in ("aim_deg", "speed", "tip_mm", "level_range"))
            if overridden or noise.get("scale") not in (1, 1.0, None):
                name += "+custom"
        else:
            name = "none"
        return physics, name

    # ------------------------------------------------------------------------- one run

    def kind_here(self, d: Path, has) -> Protocol | str | None:
        """The kind of run the directory ``d`` holds (``has(name)``: whether it holds that file),
        or None: one answer, in one order, for listing, loading and asking again -- a P3 (its
        chains' ledger), a league or a viewer match (its matches' ledger), a benchmark
        evaluation (its identity and ledger), a P1 search run, a training run's evaluation.
        Each kind has its listing's line and its loader (:meth:`_handlers`)."""
        if has(CHAINS_FILE):
            return Protocol.P3
        if has(MATCHES_FILE):
            return "league"
        if has(IDENTITY_FILE) and has(UNITS_FILE):
            return "scorecard"
        if has(CONFIG_FILE) and has(RESULTS_FILE) and self._p1_size(d) is not None:
            return Protocol.P1
        if has(CONFIG_FILE) and has(EVAL_FILE):
            return "training"
        return None

    def _handlers(self, kind) -> tuple:
        """(its listing's line, its loader) of a kind :meth:`kind_here` names."""
        return {Protocol.P3: (self._p3_entry, self._load_p3), "league": (self._league_entry, self._load_league),
                "scorecard": (self._scorecard_entry, self._load_scorecard), Protocol.P1: (self._p1_entry, self._load_p1),
                "training": (self._training_entry, self._load_training)}[kind]

    def load(self, path: str, unit: int | None = None) -> dict:
        """A run's replayable shots (see the module docstring); ``unit``: the match, inning or
        chain to play again (leagues, scorecards, P1 runs, training evaluations)."""
        real = self.resolve(path)
        if real.is_file() and real.name == SCORECARD_JSON and (real.parent / IDENTITY_FILE).is_file():
            real = real.parent  # a scorecard's run is its directory
        if real.is_dir() and (kind := self.kind_here(real, lambda name: (real / name).is_file())) is not None:
            return self._handlers(kind)[1](real, unit)
        if real.is_file() and real.suffix == ".json":
            card = _read_json(real)
            if isinstance(card, dict) and isinstance(card.get("track"), str) and "agent" in card:
                return self._load_scorecard_file(real, card)
        raise RunNotFound(f"{path!r} is not a run the viewer replays (a directory with {CHAINS_FILE}, {MATCHES_FILE}, a P1's "
                          f"{RESULTS_FILE}, a training run's {EVAL_FILE} or a benchmark scorecard's {UNITS_FILE}, or a scorecard)")

    def kind_of(self, path: str) -> tuple[str, Path]:
        """(the kind of run at ``path``, its real directory) for the runs whose agent can be asked
        again (/api/considered): ``p3`` and ``p1`` search runs, ``scorecard`` runs."""
        real = self.resolve(path)
        if real.is_file() and real.name == SCORECARD_JSON:
            real = real.parent
        kind = self.kind_here(real, lambda name: (real / name).is_file()) if real.is_dir() else None
        if kind == "scorecard":
            return "scorecard", real
        if kind in (Protocol.P3, Protocol.P1) and (real / CONFIG_FILE).is_file():  # a search run: its config rebuilds the search
            return "search", real
        raise RunNotFound(f"{path!r} is not a run whose agent the viewer asks again (a search run's P3 or P1, "
                          f"or a benchmark scorecard's run)")

    def _played(self, key: tuple, play):
        """What ``play()`` gives, played once per ``key`` (the others asking meanwhile wait for it) and kept."""
        with self._lock:
            if key in self._replays:
                self._replays.move_to_end(key)
                return self._replays[key]
            lock = self._locks.setdefault(key, threading.Lock())
        with lock:
            with self._lock:
                if key in self._replays:
                    return self._replays[key]
            out = play()
            with self._lock:
                self._replays[key] = out
                self._locks.pop(key, None)
                while len(self._replays) > MAX_REPLAYS:
                    self._replays.popitem(last=False)
            return out

    def _load_p3(self, d: Path, unit: int | None = None) -> dict:
        physics, noise = self._p3_settings(d)
        records = compat.ledger_records(d / CHAINS_FILE, CHAINS)
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
                          "shots": shots, "seed": rec["seed"]})
        replayable = "+custom" not in physics
        return {"path": self.display(d), "kind": Protocol.P3, "physics": physics.split("+")[0], "noise": noise,
                "replayable": replayable, "note": None if replayable else "custom physics: the viewer replays presets only",
                "considers": replayable and (d / CONFIG_FILE).is_file(), "units": units}

    def _load_league(self, d: Path, unit: int | None) -> dict:
        league = _read_json(d / LEAGUE_FILE) or {}
        web = league.get("app") == WEB_APP
        records = compat.ledger_records(d / MATCHES_FILE, MATCHES)
        units = []
        for i, r in enumerate(records):
            s = r["scores"]
            who = {"white": r["a"], "yellow": r["b"], None: "nobody (a draw)"}[r["winner"]]
            title = (f"match {i}: {r['a']} (white) {s['white']:g} - {s['yellow']:g} {r['b']} (yellow), seed {r['seed']}, "
                     f"{r['first']} breaks; {who} wins")
            shots = r.get("log") if web else None
            units.append({"id": i, "title": title, "shots": shots, "record": {k: r[k] for k in
                          ("a", "b", "i", "seed", "first", "winner", "scores", "shots", "innings")}})
        out = {"path": self.display(d), "kind": "web" if web else "league", "physics": league.get("physics", DEFAULT_PRESET),
               "noise": league.get("noise", "none"), "target": league.get("target"), "replayable": True,
               "note": None if web else "a league records scores, not shots: choose a match and it is played again",
               "units": units}
        if unit is not None:
            if not 0 <= unit < len(records):
                raise RunNotFound(f"{self.display(d)} has matches 0..{len(records) - 1}, not {unit}")
            if not web:
                played = self._played(("league", str(d), unit), lambda: replay_league_match(league, records[unit]))
                units[unit] = {**units[unit], **played}
            out["units"] = [units[unit]]
        return out

    def _load_scorecard_file(self, path: Path, card: dict) -> dict:
        summary = {k: v for k, v in card.items() if k not in ("values", "runs", "track_record", "agent")}
        return {"path": self.display(path), "kind": "scorecard", "physics": None, "noise": None, "replayable": False,
                "note": "a scorecard without its ledger (units.jsonl) and evaluation.json records figures, not shots: "
                        "nothing to play again",
                "summary": summary, "agent": card.get("agent"), "units": []}

    def _load_scorecard(self, d: Path, unit: int | None) -> dict:
        ev, track, why = replays.read_scorecard(d)
        spec = (ev.get("agent") or {}).get("spec")
        refusal = why or replays.scorecard_refusal(spec, self.root)
        records = replays.scorecard_records(d, ev)
        like = track or SimpleNamespace(protocol=find_protocol(ev["track"].get("protocol")), seed=ev["track"].get("seed", 0))
        units = replays.scorecard_units(like, records)
        card = _read_json(d / SCORECARD_JSON)
        summary = None
        if isinstance(card, dict):
            summary = {k: v for k, v in card.items() if k not in ("values", "runs", "track_record", "agent")}
        word = like.protocol.spec.item[0] if like.protocol is not None else "unit"
        note = (f"this scorecard cannot be played again: {refusal}" if refusal else
                f"a scorecard records scores, not shots: choose {'an' if word == 'inning' else 'a'} {word} and its agent plays "
                f"it again on its seed" + (" (with the 49 innings of its block: they play together)" if word == "inning" else "")
                + "; the replay says whether the unit's record equals the ledger's")
        out = {"path": self.display(d), "kind": "scorecard", "physics": ev["track"].get("physics"), "noise": ev["track"].get("noise"),
               "replayable": refusal is None, "note": note, "summary": summary, "agent": ev.get("agent"),
               "track": ev["track"].get("name"), "protocol": like.protocol,
               "considers": refusal is None and replays.scorecard_agent_searches(spec), "units": units}
        if unit is None:
            return out
        chosen = next((u for u in units if u["id"] == unit), None)
        if chosen is None:
            raise RunNotFound(f"{self.display(d)} holds no {word} {unit} in its ledger")
        if refusal:
            raise ReplayRefused(out["note"])
        from . import catalogue

        def build(spec_full, track_):
            entry = catalogue.bench_entry(spec_full, track_)
            return entry.agent, entry.lock

        block = self._played(("scorecard", str(d), chosen["block"]),
                             lambda: replays.replay_scorecard_block(d, self.root, chosen["block"], build=build))
        shots = block["shots"][block["units"].index(unit)]
        if like.protocol.spec.by_innings:
            replayed = {"points": int(sum(s["scored"] for s in shots))}
        elif like.protocol is Protocol.P3:
            replayed = {"length": block["replayed"]["length"], "ended_by_foul": block["replayed"]["ended_by_foul"]}
        else:
            replayed = {"points": block["replayed"]["points"], "winner": block["replayed"]["winner"]}
        what = f"unit {chosen['block']} of the ledger" + (f" (innings {block['units'][0]}-{block['units'][-1]})"
                                                            if like.protocol.spec.by_innings else "")
        check = (f"played again: {what} gives the ledger's record (scores, fouls, decisions, simulations)" if block["matches_ledger"]
                 else f"played again: {what} differs from the ledger in {', '.join(block['differences'])}")
        out["units"] = [{**chosen, "shots": shots, "replayed": replayed, "matches_ledger": block["matches_ledger"],
                         "reproduced": block["matches_ledger"], "differences": block["differences"], "check": check}]
        return out

    def _load_p1(self, d: Path, unit: int | None) -> dict:
        size = self._p1_size(d)
        physics, noise = self._p3_settings(d)
        refusal = self._p1_refusal(d, size, physics)
        values = size["values"]
        units = [{"id": i, "title": f"inning {i}: {v:g} points of {size['shots']} shots", "shots": None,
                  "record": {"points": v}} for i, v in enumerate(values)]
        note = (f"this P1 cannot be played again: {refusal}" if refusal else
                f"a P1 records points, not shots, and its {len(values)} innings step together with one search generator: "
                f"choosing an inning plays the whole run again once ({len(values) * (size['shots'] or 0):,} shots) and "
                f"says whether its points per inning equal results.json's")
        out = {"path": self.display(d), "kind": Protocol.P1, "physics": physics.split("+")[0], "noise": noise,
               "replayable": refusal is None, "note": note, "considers": refusal is None, "units": units}
        if unit is None:
            return out
        if not 0 <= unit < len(values):
            raise RunNotFound(f"{self.display(d)} has innings 0..{len(values) - 1}, not {unit}")
        if refusal:
            raise ReplayRefused(note)
        run = self._played((Protocol.P1, str(d)), lambda: replays.replay_p1(d))
        shots = run["innings"][unit]
        check = ("played again whole: every inning's points equal results.json's values" if run["matches_record"] else
                 f"played again whole: the points differ from results.json's in "
                 f"{sum(a != b for a, b in zip(run['points'], run['recorded']))} of {len(run['recorded'])} innings")
        out["units"] = [{**units[unit], "shots": shots, "seed": run["seed"], "replayed": {"points": run["points"][unit]},
                         "matches_record": run["matches_record"], "reproduced": run["matches_record"], "check": check}]
        return out

    def _load_training(self, d: Path, unit: int | None) -> dict:
        ev = _read_json(d / EVAL_FILE) or {}
        physics, noise = self._p3_settings(d)
        policy = self.policy_sources().get(self.display(d))
        points = ev.get("points") or []
        units = [{"id": i, "title": f"inning {i}: {p} points of {ev.get('max_shots')} shots", "shots": None, "record": {"points": p}}
                 for i, p in enumerate(points)]
        refusal = None if policy else _NO_WEIGHTS
        if refusal is None and "+custom" in physics:
            refusal = "custom physics: the viewer replays presets only"
        note = (f"this run's evaluation cannot be played again: {refusal}" if refusal else
                f"eval.json records points, not shots: choosing an inning plays the evaluation again with the run's shipped "
                f"policy {policy} ({len(points)} innings side by side, as billiards.evaluation.evaluate_policy plays them) and says "
                f"whether its points equal eval.json's")
        out = {"path": self.display(d), "kind": "training", "physics": physics.split("+")[0], "noise": noise,
               "replayable": refusal is None, "note": note, "policy": policy, "considers": False, "units": units}
        if unit is None:
            return out
        if not 0 <= unit < len(points):
            raise RunNotFound(f"{self.display(d)} has innings 0..{len(points) - 1}, not {unit}")
        if refusal:
            raise ReplayRefused(note)
        run = self._played(("training", str(d), policy), lambda: replays.replay_training(d, self.root / policy))
        shots = run["innings"][unit]
        if run["matches_record"]:
            check = "played again: every inning's points equal eval.json's"
        else:
            differ = sum(a != b for a, b in zip(run["points"], run["recorded"]))
            check = (f"played again: the points differ from eval.json's in {differ} of {len(run['recorded'])} innings (mean "
                     f"{np.mean(run['points']):.2f} against {np.mean(run['recorded']):.2f}): today's code, whose own "
                     f"billiards.evaluation.evaluate_policy gives these points, does not play this evaluation bit for bit as the code "
                     f"that wrote eval.json did (docs/reproducibility.md); these are today's innings of the same policy on the "
                     f"same racks and noise seed")
        out["units"] = [{**units[unit], "shots": shots, "seed": run["seed"], "replayed": {"points": run["points"][unit]},
                         "matches_record": run["matches_record"], "reproduced": run["matches_record"], "check": check}]
        return out


_NO_WEIGHTS = ("no weights of this run were shipped (no policy under results/policies names it as its source), so its "
               "evaluation innings cannot be played again")


def _read_json(path: Path):
    try:  # the one reader of run-folder files: no link, no FIFO, bounded size and depth
        return read_run_json(path)
    except (OSError, ValueError):
        return None


def _count_lines(path: Path) -> int:
    """The records of a ledger (its non-empty lines), read through the one reader; 0 for a file it refuses."""
    try:
        return sum(1 for line in read_run_bytes(path, "ledger").splitlines() if line.strip())
    except (OSError, ValueError):
        return 0


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
    from billiards.league.players import make_agent, player_keys
    from billiards.physics import get_params

    try:
        params = get_params(league.get("physics", DEFAULT_PRESET))
        noise = _league_noise(league)
        agents = compat.upgrade_league_players(league["agents"], player_keys)
        players = {side: make_agent(agents[name], noise, params)
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


__all__ = ["PathRefused", "ReplayRefused", "RunNotFound", "RunStore", "WEB_APP", "match_shot", "replay_league_match"]
