"""Append-only ledgers and their kinds: a P3 search's ``chains.jsonl``, a league's
``matches.jsonl`` (one finished unit a line, written as it ends) share one mechanism,
:func:`append_record` and :func:`read_ledger` (:func:`scan_ledger` checks the bytes).

Every record carries its run's identity (:func:`run_identity`, a short hash of the settings
that determine the results) under :data:`RUN_KEY` and a sha256 seal over its content and that
identity; a reader refuses, by file and line, a record that is unsealed, does not match its
seal, is of the wrong shape, belongs to another run or repeats a unit, and cuts off a torn last
line (a kill mid-append: no newline) so that its unit is played again. Every kind of ledger
(:class:`LedgerKind`: :data:`CHAINS`, :data:`MATCHES`, and the kinds above this layer that
:data:`LEDGER_PROVIDERS` names) is registered (:func:`register_ledger`, :func:`ledger_kinds`).
"""

from __future__ import annotations

import errno
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Hashable

from billiards.protocol import Protocol

from .describe import _MISSING, _int, _number, _shown_ident, described, shown_name, shown_number
from .paths import CHAINS_FILE, LEAGUE_FILE, MATCHES_FILE, RESULTS_FILE, display_path
from .runfiles import _CLOEXEC, _NOFOLLOW, _NONBLOCK, RunFileError, _not_regular, json_depth_problem, read_run_bytes
from .seals import SEAL_KEY, record_digest, sealed_record

RUN_KEY = "run"  # the run identity every ledger record carries


class LedgerError(ValueError):
    """A ledger that cannot be trusted; the message names the file, the line and what is wrong."""


def run_identity(settings: dict, runtime=()) -> str:
    """The identity of a run: a short hash (16 hex digits) of the settings that determine its
    results (a plain, JSON-serialisable dict), less the top-level ``runtime`` keys (threads,
    progress, pictures, device, resume: how it runs, not what it finds). Two runs share it
    exactly when their results are the same function of their seeds."""
    import hashlib
    import json

    body = {k: v for k, v in settings.items() if k not in runtime}
    return hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()[:16]


_JSON_TYPES = {bool: "boolean", int: "number", float: "number", str: "string", list: "array", type(None): "null"}


def _chain_problem(rec: dict) -> str | None:
    for key in ("seed", "length", "decisions"):
        if not _int(rec.get(key)):
            return f"{key} must be an integer >= 0, got {described(rec.get(key, _MISSING))}"
    if not _number(rec.get("seconds"), 0.0):
        return f"seconds must be a finite number >= 0, got {described(rec.get('seconds', _MISSING))}"
    shots = rec.get("last_shots")
    if not (isinstance(shots, list) and all(isinstance(s, list) and len(s) >= 3 for s in shots)):
        return "last_shots must be a list of shots [positions, action, scored, ...]"
    return None


_SIDES = ("white", "yellow")


def _side(x) -> str:
    return "another string" if isinstance(x, str) else described(x)


def _match_problem(rec: dict) -> str | None:
    a, b = rec.get("a", _MISSING), rec.get("b", _MISSING)
    if not (isinstance(a, str) and isinstance(b, str) and a and b and a != b):
        got = "the same name twice" if isinstance(a, str) and a == b else f"{described(a)} and {described(b)}"
        return f"a and b must name two different players, got {got}"
    for key in ("i", "seed", "shots", "innings"):
        if not _int(rec.get(key)):
            return f"{key} must be an integer >= 0, got {described(rec.get(key, _MISSING))}"
    if rec.get("first") not in _SIDES:
        return f"first must be white or yellow, got {_side(rec.get('first', _MISSING))}"
    if "winner" not in rec or rec["winner"] not in (*_SIDES, None):
        return f"winner must be white, yellow or null (a draw), got {_side(rec.get('winner', _MISSING))}"
    for key, ok in (("scores", _number), ("cpu_s", lambda x: _number(x, 0.0)), ("turns", _int)):
        per = rec.get(key)
        if not (isinstance(per, dict) and all(ok(per.get(side)) for side in _SIDES)):
            got = "" if isinstance(per, dict) else f", got {described(rec.get(key, _MISSING))}"
            return f"{key} must give white and yellow each a number{got}"
    return None


@dataclass(frozen=True)
class LedgerKind:
    """One kind of append-only ledger: its file, what a record is, the unit a record finishes
    (each unit at most once), the record's shape, its run's summary file and how that summary
    is checked against the records.

    ``check(records, summary, name)``: the sentences where the summary (a dict read from the
    file ``name``) disagrees with the ledger's records; a function, or ``"module:function"`` for
    one that lives above this layer (imported when a summary is checked). None: the summary's
    figures are not checked (only that it names the ledger's run)."""

    file: str
    what: str  # "P3 chain record"
    unit: Callable[[dict], Hashable]
    name_unit: Callable[[dict], str]
    problem: Callable[[dict], str | None]  # what is wrong with a record's shape, or None
    summary: str  # the run's summary file, recomputed from the ledger on resume and checked by verify
    check: Callable[[list, dict, str], list] | str | None = None

    def summary_check(self) -> Callable[[list, dict, str], list] | None:
        """:attr:`check` as a function (ImportError or AttributeError if its module cannot give it)."""
        if not isinstance(self.check, str):
            return self.check
        import importlib

        module, _, name = self.check.partition(":")
        return getattr(importlib.import_module(module), name)


def _results_problems(records: list[dict], summary: dict, name: str) -> list[str]:
    """Where a P3's ``results.json`` disagrees with its chains: its values are the chain
    lengths in seed order, its mean, spread, extremes, shots and chains at the cap theirs."""
    extra = summary.get("extra") if isinstance(summary.get("extra"), dict) else {}
    seeds, values = extra.get("seeds"), summary.get("values")
    if summary.get("protocol") != Protocol.P3 or not isinstance(seeds, list) or not isinstance(values, list):
        return [f"{name} is not a P3 result (protocol p3, its values and extra.seeds)"]
    if len(seeds) != len(values):
        return [f"{name} gives {len(values)} values for {len(seeds)} seeds"]
    length = {r["seed"]: r["length"] for r in records}
    out = []
    for seed, value in zip(seeds, values):
        if not _int(seed):
            out.append(f"{name} counts a seed that is {described(seed)}, not an integer >= 0")
        elif seed not in length:
            out.append(f"{name} counts seed {seed} (value {shown_number(value)}), which the ledger does not hold")
        elif value != length[seed]:
            out.append(f"{name} gives seed {seed} the value {shown_number(value)}; the ledger's chain of seed {seed} is "
                       f"{length[seed]} long")
    if left := sorted(set(length) - set(s for s in seeds if _int(s)), key=str):
        out.append(f"the ledger holds chains {name} does not count (seeds {', '.join(map(str, left))})")
    if out or not values:
        return out
    n = len(values)
    mean = sum(values) / n
    figures = {"mean": mean, "std": math.sqrt(sum((v - mean) ** 2 for v in values) / n), "max": max(values),
               "min": min(values), "shots": sum(values) + n}
    for key, value in figures.items():
        if key in summary and not (_number(summary[key]) and abs(summary[key] - value) <= 1e-9 * max(1.0, abs(value))):
            out.append(f"{name}'s {key} {shown_number(summary[key])} is not its chains' ({value:g})")
    cap = extra.get("cap")
    if "reached_cap" in extra and _int(cap) and extra["reached_cap"] != sum(v >= cap for v in values):
        out.append(f"{name}'s extra.reached_cap {shown_number(extra['reached_cap'])} is not the number of its chains "
                   f"at the cap ({sum(v >= cap for v in values)})")
    return out


CHAINS = LedgerKind(CHAINS_FILE, "P3 chain record", lambda r: r["seed"], lambda r: f"the chain of seed {r['seed']}",
                    _chain_problem, RESULTS_FILE, _results_problems)
MATCHES = LedgerKind(MATCHES_FILE, "league match record", lambda r: (r["a"], r["b"], r["i"]),
                     lambda r: f"match {r['i']} of {shown_name(r['a'])} (white) vs {shown_name(r['b'])}", _match_problem,
                     LEAGUE_FILE, "billiards.league.table:summary_problems")  # pairs and Elo recomputed (numpy)

# ----------------------------------------------------------------------------- the registry of ledger kinds
#
# Every kind of ledger the package writes is registered here (register_ledger), so that verify
# knows them all. A kind defined above this layer (the benchmark's units.jsonl) is named in
# LEDGER_PROVIDERS as "module:attribute" and imported when the kinds are listed (ledger_kinds);
# its module may also register it itself at import time, with its own summary check.

_KINDS: dict[str, LedgerKind] = {}
LEDGER_PROVIDERS = ["billiards.bench.run:UNITS", "billiards.web.match:SHOTS"]  # kinds defined above this layer, imported when listed
_UNAVAILABLE: dict[str, str] = {}  # provider -> why it could not be imported


def register_ledger(kind: LedgerKind) -> LedgerKind:
    """Make ``kind`` one of the ledger kinds :func:`verify` knows (by its file name; the same
    kind registered again replaces the earlier registration, e.g. with a summary check). A file
    name is one kind's: ValueError if another kind has it."""
    if not isinstance(kind, LedgerKind):
        raise TypeError(f"register_ledger takes a LedgerKind, got a {type(kind).__name__}")
    known = _KINDS.get(kind.file)
    if known is not None and known.what != kind.what:
        raise ValueError(f"{kind.file} is the ledger of {known.what}s already; one file name is one kind's")
    _KINDS[kind.file] = kind
    return kind


register_ledger(CHAINS)
register_ledger(MATCHES)


def ledger_kinds() -> tuple[LedgerKind, ...]:
    """Every registered ledger kind, the providers' (:data:`LEDGER_PROVIDERS`) imported first;
    one that cannot be imported is left out (and said by :func:`verify`)."""
    import importlib

    for provider in LEDGER_PROVIDERS:
        module, _, attr = provider.partition(":")
        try:
            kind = getattr(importlib.import_module(module), attr)
        except Exception as err:  # an optional dependency missing, a module renamed: verify says so
            _UNAVAILABLE[provider] = f"{type(err).__name__}: {err}"
            continue
        _UNAVAILABLE.pop(provider, None)
        if isinstance(kind, LedgerKind) and kind.file not in _KINDS:
            register_ledger(kind)
    return tuple(_KINDS.values())


@dataclass
class LedgerScan:
    """What a ledger holds: its intact ``records`` in file order, one sentence per bad line
    (``problems``), the line numbers of the records read ``unchecked`` (sealed without a run
    identity, or ``unsealed``), the line number of a ``torn`` last line and whether it was ``cut``."""

    records: list = field(default_factory=list)
    problems: list = field(default_factory=list)
    unchecked: list = field(default_factory=list)
    unsealed: list = field(default_factory=list)
    torn: int | None = None
    cut: bool = False


def scan_ledger(data: bytes, name: str, kind: LedgerKind, run: str | None = None, unchecked: bool = False) -> LedgerScan:
    """Check a ledger's bytes line by line (``name``: the file, for the messages, which never
    quote a line). A record must be a JSON object (nesting at most :data:`MAX_JSON_DEPTH`
    levels) of the kind's shape whose seal matches it, carry the identity ``run`` (with None:
    the same identity as the other records) and finish a unit no earlier line finished.
    With ``unchecked`` (read-only views: :func:`billiards.compat.ledger_records`, and
    :func:`verify`), a record without a seal or without a run identity, whose content or
    writer cannot be checked, is read on its shape and listed in ``unchecked``. A last line
    without its newline is a torn append: not read, its line number in ``torn``."""
    import json

    end = len(data) if not data or data.endswith(b"\n") else data.rfind(b"\n") + 1
    lines = data[:end].split(b"\n")[:-1]
    scan = LedgerScan(torn=len(lines) + 1 if end < len(data) else None)
    seen: dict = {}  # unit -> line
    owner: tuple[str, int] | None = (run, 0) if run is not None else None  # the run's identity, and where it was seen

    def bad(n: int, why: str) -> None:
        why = why if len(why) <= 240 else why[:240] + "..."
        scan.problems.append(f"{name}: line {n} is not an intact {kind.what}: {why}")

    for n, raw in enumerate(lines, 1):
        if not raw.strip():
            continue
        if (deep := json_depth_problem(raw)) is not None:
            bad(n, f"it is not JSON a ledger reads ({deep})")
            continue
        try:
            rec = json.loads(raw)
        except json.JSONDecodeError as err:
            bad(n, f"it is not JSON ({err.msg} at column {err.colno})")
            continue
        except (ValueError, RecursionError):  # not UTF-8
            bad(n, "it is not JSON (not UTF-8 text)")
            continue
        if not isinstance(rec, dict):
            bad(n, f"it is a JSON {_JSON_TYPES.get(type(rec), 'value')}, not a record (an object)")
            continue
        sealed = SEAL_KEY in rec
        if sealed and rec[SEAL_KEY] != record_digest(rec):
            bad(n, "its content does not match its seal (the line was edited or damaged)")
            continue
        if not sealed and not unchecked:
            bad(n, "it carries no seal, and an unsealed record cannot be told from an edited one: no run continues "
                   "from it (python -m billiards.files verify reads it)")
            continue
        if (why := kind.problem(rec)) is not None:
            bad(n, why)
            continue
        ident = rec.get(RUN_KEY) if sealed else None
        if ident is None:
            if not unchecked:
                bad(n, "it carries no run identity: which run wrote it cannot be told")
                continue
            scan.unchecked.append(n)
            if not sealed:
                scan.unsealed.append(n)
        elif owner is None:
            owner = (ident, n)
        elif ident != owner[0]:
            whose = f"line {owner[1]}'s run {_shown_ident(owner[0])}" if owner[1] else f"this run is {owner[0]}"
            scan.problems.append(f"{name}: line {n} belongs to another run (run {_shown_ident(ident)}; {whose}): "
                                 f"a ledger holds the records of one run")
            continue
        unit = kind.unit(rec)
        if unit in seen:
            scan.problems.append(f"{name}: line {n} repeats {kind.name_unit(rec)}, already finished on line {seen[unit]}: "
                                 f"a unit is recorded once")
            continue
        seen[unit] = n
        scan.records.append(rec)
    return scan


def _open_ledger(path: Path, flags: int) -> int:
    """A descriptor of the ledger at ``path`` opened with ``flags``, never through a link and
    only if it is a regular file (:class:`LedgerError` otherwise)."""
    try:
        fd = os.open(path, flags | _NOFOLLOW | _NONBLOCK | _CLOEXEC | getattr(os, "O_BINARY", 0), 0o644)
    except OSError as err:
        if err.errno in (errno.ELOOP, errno.EISDIR, errno.ENXIO):
            what = "a symbolic link" if err.errno == errno.ELOOP else "not a regular file"
            raise LedgerError(f"{display_path(path)} is {what}: a ledger is written only as a regular file inside its run "
                              f"folder (nothing was written)") from None
        raise
    what = _not_regular(os.fstat(fd).st_mode)
    if what is not None:
        os.close(fd)
        raise LedgerError(f"{display_path(path)} is {what}: a ledger is written only as a regular file inside its run "
                          f"folder (nothing was written)")
    return fd


def read_ledger(path, kind: LedgerKind, run: str | None = None, *, unchecked: bool = False,
                repair: bool = False) -> LedgerScan:
    """The records of the ledger at ``path`` (none if there is no file), read through
    :func:`read_run_bytes` (a link, a FIFO or a file past its bound is refused unread) and
    checked by :func:`scan_ledger`; :class:`LedgerError` naming the file and the first bad
    line if any line is bad. A torn last line is left out; with ``repair`` (the resume path)
    it is cut off the file (``cut``), so that the next append starts a line of its own and its
    unit is played again."""
    path = Path(path)
    if not os.path.lexists(path):
        return LedgerScan()
    try:
        data = read_run_bytes(path, "ledger")
    except RunFileError as err:
        raise LedgerError(str(err)) from None
    scan = scan_ledger(data, display_path(path), kind, run, unchecked)
    if scan.problems:
        more = f" (and {len(scan.problems) - 1} more bad lines)" if len(scan.problems) > 1 else ""
        raise LedgerError(scan.problems[0] + more)
    if scan.torn is not None and repair:
        fd = _open_ledger(path, os.O_WRONLY)
        try:  # the torn tail of a killed append
            os.ftruncate(fd, data.rfind(b"\n") + 1)
            os.fsync(fd)
        finally:
            os.close(fd)
        scan.cut = True
    return scan


def append_record(path, record: dict, run: str) -> dict:
    """Append ``record`` with the identity ``run`` and its seal to the ledger at ``path`` (a
    regular file, created if missing; never written through a link): one whole line with its
    newline, flushed and fsynced; returns the sealed record. A ledger that ends in a torn line
    is refused (:func:`read_ledger` with ``repair`` cuts it first)."""
    import json

    rec = json.loads(json.dumps({**record, RUN_KEY: run}))  # what a reader will see (floats, tuples, keys)
    line = (json.dumps(sealed_record(rec)) + "\n").encode()
    with os.fdopen(_open_ledger(Path(path), os.O_RDWR | os.O_APPEND | os.O_CREAT), "a+b") as f:
        if f.seek(0, os.SEEK_END) > 0:
            f.seek(-1, os.SEEK_END)
            if f.read(1) != b"\n":
                raise LedgerError(f"{display_path(path)} ends in a torn line: it is cut (read_ledger(..., repair=True)) "
                                  f"before anything is appended")
        f.write(line)
        f.flush()
        os.fsync(f.fileno())
    return sealed_record(rec)
