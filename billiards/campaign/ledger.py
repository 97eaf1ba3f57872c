"""A campaign's state on disk, under its root (``outputs/campaign/<name>/``):

* ``campaign.json``, the ledger: per entry the arguments it was first started with, every
  start (commit, time, mode, steps reached at the start, and at its end the outcome, exit
  status and the CPU seconds the process used), the list of commits it ran under, the pid of
  a process running it and how many starts failed. Written atomically (temporary file, fsync,
  ``os.replace``), so a kill or a power cut leaves the previous or the new ledger.
* each entry's directory ``<root>/<key>``: what the run itself writes, ``train.log`` (or
  ``search.log``, ``export.log``: the process's stdout and stderr) and ``campaign_starts.jsonl``
  (one line per start, the ledger's record, so the run dir alone says which commits it ran under).

Whether an entry is done is read from its files, never from the ledger: a training run when
``eval.json`` and ``summary.json`` exist, a search run when ``results.json`` does, an export
when every exported policy file does. So deleting a run dir re-runs it, and a ledger lost
with the machine's disk state rebuilds itself.
"""

from __future__ import annotations

import csv
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

from billiards.files import SEAL_KEY, record_intact, sealed_record
from .spec import PLACEHOLDER, Campaign, Entry, SpecError

LEDGER = "campaign.json"
STARTS = "campaign_starts.jsonl"
STOP = "STOP"  # `python -m billiards.campaign stop`: the runner drains (see runner.py)
STOP_NOW = "STOP_NOW"  # `... stop --now`: the runner stops every process at once
LOGS = {"train": "train.log", "export": "export.log", "search": "search.log"}


def utc_now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def _ledger_problem(data) -> str | None:
    """What is wrong with a ledger's shape (None when it is a ledger)."""
    if not isinstance(data, dict) or not isinstance(data.get("runs"), dict):
        return "expected a mapping with 'campaign' and a mapping 'runs'"
    types = {"args": (list, type(None)), "starts": list, "commits": list, "pid": (int, type(None)), "failures": int}
    for key, rec in data["runs"].items():
        if not isinstance(rec, dict):
            return f"runs[{key!r}] is a {type(rec).__name__}, not a mapping"
        for field, kind in types.items():
            if field in rec and not isinstance(rec[field], kind) or isinstance(rec.get(field), bool):
                return f"runs[{key!r}].{field} is {rec[field]!r}"
        if not all(isinstance(s, dict) for s in rec.get("starts", [])):
            return f"runs[{key!r}].starts holds something other than mappings"
    return None


class Ledger:
    """``campaign.json``: a dict ``{"campaign", "runs": {key: record}}``."""

    def __init__(self, root: Path, name: str):
        self.root = Path(root)
        self.path = self.root / LEDGER
        self.data: dict = {"campaign": name, "runs": {}}
        if self.path.is_file():
            try:
                data = json.loads(self.path.read_text())
            except ValueError as err:
                raise SpecError(f"{self.path} is corrupt ({err}); move it aside: the run dirs hold the results, "
                                f"only the start history would be lost") from None
            if isinstance(data, dict) and not record_intact(data):
                raise SpecError(f"{self.path} is damaged: its contents do not match its sha256 checksum; move it aside: "
                                f"the run dirs hold the results, only the start history would be lost")
            if problem := _ledger_problem(data):
                raise SpecError(f"{self.path} is not a campaign ledger ({problem}); move it aside: the run dirs hold "
                                f"the results, only the start history would be lost") from None
            if data.get("campaign") != name:
                raise SpecError(f"{self.path} belongs to campaign {data.get('campaign')!r}, not {name!r}; "
                                f"use another --root")
            data.pop(SEAL_KEY, None)
            self.data = data

    def record(self, key: str) -> dict:
        return self.data["runs"].setdefault(key, {"args": None, "starts": [], "commits": [], "pid": None, "failures": 0})

    def get(self, key: str) -> dict | None:
        return self.data["runs"].get(key)

    def save(self) -> None:
        self.root.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(self.path.name + ".tmp")
        with tmp.open("w") as f:
            json.dump(sealed_record(self.data), f, indent=1)
            f.write("\n")
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.path)


# ----------------------------------------------------------------------------- run dirs


def entry_dir(root: Path, campaign: Campaign, entry: Entry) -> Path:
    return Path(root) / campaign.source(entry).key


def fill(arg: str, root: Path) -> str:
    """``{dir:<key>}`` -> the absolute directory of that entry."""
    return PLACEHOLDER.sub(lambda m: str(Path(root).resolve() / m.group(1)), arg)


def export_sources(entry: Entry, root: Path) -> list[Path]:
    return [Path(fill(a, root)) for a in entry.args]


def _seed_of(run_dir: Path) -> int | None:
    import yaml

    cfg = run_dir / "config.yaml"
    if not cfg.is_file():
        return None
    return (yaml.safe_load(cfg.read_text()) or {}).get("seed")


def is_stale(ledger: Ledger, entry: Entry) -> bool:
    """The entry's arguments in the campaign differ from those it was first started with."""
    rec = ledger.get(entry.key)
    return bool(rec and rec.get("args") is not None and rec["args"] != list(entry.args))


def entry_done(campaign: Campaign, root: Path, ledger: Ledger, entry: Entry) -> bool:
    """Done and not stale (a shared entry: its source)."""
    src = campaign.source(entry)
    return is_done(src, entry_dir(root, campaign, src), root) and not is_stale(ledger, src)


def is_done(entry: Entry, run_dir: Path, root: Path) -> bool:
    """True when the entry's results exist (see the module docstring)."""
    if entry.kind == "train":
        return (run_dir / "eval.json").is_file() and (run_dir / "summary.json").is_file()
    if entry.kind == "search":  # a stopped search writes a results.json marked partial
        result = search_result(run_dir)
        return result is not None and not (result.get("extra") or {}).get("partial")
    seeds = [_seed_of(src) for src in export_sources(entry, root)]
    return all(s is not None and (run_dir / f"seed{s}.pt").is_file() for s in seeds)


@dataclass
class Progress:
    """How far an unfinished training run got, from its own files: ``frames`` and
    ``cpu_seconds`` of the last metrics.csv row (at most ``budget.log_every`` steps past what
    the run accounts; a resume restarts from its last checkpoint, up to
    ``budget.checkpoint_every`` steps earlier); ``checkpoint``: whether it can resume."""

    frames: int = 0
    cpu_seconds: float = 0.0
    checkpoint: bool = False


def progress(run_dir: Path) -> Progress:
    p = Progress(checkpoint=(run_dir / "checkpoint.pt").is_file())
    summary = run_dir / "summary.json"
    if summary.is_file():
        s = json.loads(summary.read_text())
        return Progress(int(s.get("frames", 0)), float(s.get("cpu_seconds", 0.0)), p.checkpoint)
    metrics = run_dir / "metrics.csv"
    if metrics.is_file():
        with metrics.open(newline="") as f:
            rows = [r for r in csv.DictReader(f) if r.get("step") and r.get("cpu_time")]
        if rows:
            p.frames, p.cpu_seconds = int(float(rows[-1]["step"])), float(rows[-1]["cpu_time"])
    return p


def search_result(run_dir: Path) -> dict | None:
    """A search run's results.json (None if absent or unreadable: a run to do again)."""
    path = run_dir / "results.json"
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def search_seconds(run_dir: Path) -> tuple[int, float] | None:
    """(decisions, seconds) of a search run's results.json, finished or partial."""
    r = search_result(run_dir)
    return None if r is None else (int(r.get("shots", 0)), float(r.get("seconds", 0.0)))


def search_resumable(run_dir: Path) -> bool:
    """A stopped P3 search continues from its next chain (``search.py resume=``); a P1 starts over."""
    import yaml

    path = run_dir / "config.yaml"
    if not path.is_file():
        return False
    try:
        cfg = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError:
        return False
    return (cfg.get("protocol") or {}).get("name") == "p3"


def pid_alive(pid: int | None, run_dir: Path) -> bool:
    """True if ``pid`` is a live process whose command line names ``run_dir`` (so a pid
    reused after a restart of the machine is not taken for the run)."""
    if not pid:
        return False
    try:
        args = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0")
    except OSError:
        return False
    # (a zombie, exited but not reaped, has an empty command line)
    target = str(run_dir)
    return any(a == target or a.endswith("=" + target) for a in args)
