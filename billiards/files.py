"""Files the package writes and reads back: the repository root and paths relative to it, the
names of the files a run directory holds, one atomic writer for every result file, and one
loader for the small ``torch.save`` files with a format tag (exported policies, reward models)
that turns every way such a file can be bad into one clear error.

The lowest layer of the package: standard library only (torch lazily, in :func:`load_tagged`),
so anything may import it.

Atomic means a reader (or a kill at any moment) sees either the old file or the new one,
never half of one: the content goes to a temporary file in the same directory, is flushed and
fsynced, and then replaces the old file by :func:`os.replace` (an atomic rename on POSIX and
Windows); the directory is fsynced too, so the rename survives a power loss.

Append-only ledgers (a P3 search's ``chains.jsonl``, a league's ``matches.jsonl``: one finished
unit a line, written as it ends) share one mechanism, :func:`append_record` and
:func:`read_ledger`: every record carries its run's identity (:func:`run_identity`, a short hash
of the settings that determine the results) under :data:`RUN_KEY` and a sha256 seal over its
content and that identity; a reader refuses, by file and line, a record that is unsealed, does
not match its seal, is of the wrong shape, belongs to another run or repeats a unit, and cuts
off a torn last line (a kill mid-append: no newline) so that its unit is played again.
``python -m billiards.files verify RUN_DIR`` checks a run directory's ledger record by record
and its summary (``results.json``, ``league.json``) against it.
"""

from __future__ import annotations

import contextlib
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Callable, Hashable, Iterator

TMP_SUFFIX = ".tmp"

PACKAGE = Path(__file__).resolve().parent
# Where the project's own files are read from (conf/, the shipped models under results/, the
# leaderboard's snapshot): the repository when this package is a source checkout's (billiards/
# beside conf/ and pyproject.toml), else the copy an installed wheel carries in billiards/_data,
# laid out as in the repository (setup.py: SHIPPED). Nothing is written under it outside a checkout.
IN_CHECKOUT = (PACKAGE.parent / "conf").is_dir() and (PACKAGE.parent / "pyproject.toml").is_file()
ROOT = PACKAGE.parent if IN_CHECKOUT else PACKAGE / "_data"
CONF_DIR = ROOT / "conf"  # the Hydra configs every app composes
OUTPUTS = PACKAGE.parent / "outputs" if IN_CHECKOUT else Path("outputs")  # where tools write by default (an install: the working directory)

# What a training run directory holds (billiards.rl) ...
CONFIG_FILE = "config.yaml"  # the resolved config, written at start (training and search runs)
CHECKPOINT_FILE = "checkpoint.pt"
EVAL_FILE = "eval.json"
EVAL_HISTORY_FILE = "eval_history.jsonl"
METRICS_FILE = "metrics.csv"
SUMMARY_FILE = "summary.json"
# ... a search run directory (billiards.search) ...
RESULTS_FILE = "results.json"
CHAINS_FILE = "chains.jsonl"  # a P3's ledger: one finished chain a line
# ... and a league's run directory (billiards.league)
MATCHES_FILE = "matches.jsonl"  # one finished match a line
LEAGUE_FILE = "league.json"


def repo_path(path) -> Path:
    """A path a config or a command line gives: itself if it is absolute or exists (relative to
    the working directory), else the same path under the repository root, so the shipped
    ``results/...`` files are found from any working directory."""
    p = Path(path)
    if p.is_absolute() or p.exists():
        return p
    return ROOT / p


def display_path(path) -> str:
    """How a path is written into logs and records: relative to the repository when it lies
    inside it, so no committed file names a folder of the machine that wrote it."""
    p = Path(path)
    try:
        return str(p.resolve().relative_to(ROOT.resolve()))
    except ValueError:
        return str(path)


def recorded_command(cmd) -> list[str]:
    """A command line as recorded: the interpreter as ``python`` and paths inside the repository
    relative to it (``hydra.run.dir=/abs/repo/x`` -> ``hydra.run.dir=x``)."""
    import sys

    root = str(ROOT.resolve()) + "/"
    return ["python" if c == sys.executable else c.replace(root, "") for c in cmd]


@contextlib.contextmanager
def atomic_open(path, mode: str = "w", **kwargs) -> Iterator[IO]:
    """Open ``path + ".tmp"`` for writing (``mode`` "w" or "wb", ``kwargs`` as for
    :func:`open`); when the block ends normally the file is flushed, fsynced and renamed over
    ``path``. If the block raises, the temporary file is removed and ``path`` is untouched."""
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open writes whole files: mode must be 'w' or 'wb', got {mode!r}")
    path = Path(path)
    tmp = path.with_name(path.name + TMP_SUFFIX)
    try:
        with open(tmp, mode, **kwargs) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_dir(path.parent)


def _fsync_dir(directory: Path) -> None:
    """Make a rename in ``directory`` durable (POSIX; a no-op where directories cannot be opened)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write_bytes(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (see the module docstring); returns the path."""
    with atomic_open(path, "wb") as f:
        f.write(data)
    return Path(path)


def atomic_write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (see the module docstring); returns the path."""
    with atomic_open(path, "w", encoding="utf-8", newline="") as f:
        f.write(text)
    return Path(path)


SEAL_KEY = "sha256"  # the checksum entry of a sealed (tagged) file


def payload_digest(payload) -> str:
    """SHA-256 over a payload's content in a canonical order: every key (sorted), tensor (dtype,
    shape, bytes), array and plain value, except the top-level :data:`SEAL_KEY` itself. The same
    content gives the same digest however ``torch.save`` lays it out."""
    import hashlib
    import json

    import numpy as np
    import torch

    h = hashlib.sha256()

    def feed(x) -> None:
        if isinstance(x, dict):
            h.update(b"d%d" % len(x))
            for k in sorted(x, key=str):
                feed(str(k))
                feed(x[k])
        elif isinstance(x, (list, tuple)):
            h.update(b"l%d" % len(x))
            for v in x:
                feed(v)
        elif torch.is_tensor(x):
            t = x.detach().cpu().contiguous()
            h.update(f"t{t.dtype}{tuple(t.shape)}".encode())
            h.update(t.reshape(-1).view(torch.uint8).numpy().tobytes() if t.numel() else b"")
        elif isinstance(x, np.ndarray):
            a = np.ascontiguousarray(x)
            h.update(f"a{a.dtype}{a.shape}".encode() + a.tobytes())
        else:
            h.update(("v" + json.dumps(x, sort_keys=True, default=repr)).encode())

    feed({k: v for k, v in payload.items() if k != SEAL_KEY})
    return h.hexdigest()


def non_finite_entry(payload, prefix: str = "") -> str | None:
    """The first entry of ``payload`` holding a NaN or an infinity (floating tensors and arrays)."""
    import numpy as np
    import torch

    items = payload.items() if isinstance(payload, dict) else enumerate(payload) if isinstance(payload, (list, tuple)) else ()
    for k, v in items:
        name = f"{prefix}{k}"
        if torch.is_tensor(v) and v.is_floating_point() and v.numel() and not bool(torch.isfinite(v).all()):
            return name
        if isinstance(v, np.ndarray) and v.dtype.kind == "f" and not np.isfinite(v).all():
            return name
        if isinstance(v, (dict, list, tuple)) and (bad := non_finite_entry(v, f"{name}.")):
            return bad
    return None


def record_digest(record: dict) -> str:
    """SHA-256 of a JSON record (its keys sorted), without its own :data:`SEAL_KEY` entry: the
    checksum each line of an append-only ledger and each whole JSON ledger carries."""
    import hashlib
    import json

    body = {k: v for k, v in record.items() if k != SEAL_KEY}
    return hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def sealed_record(record: dict) -> dict:
    """The record with its checksum (:func:`record_digest`) under :data:`SEAL_KEY`."""
    return {**{k: v for k, v in record.items() if k != SEAL_KEY}, SEAL_KEY: record_digest(record)}


# ----------------------------------------------------------------------------- sealed ledgers

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


def _int(x, low: int = 0) -> bool:
    return isinstance(x, int) and not isinstance(x, bool) and x >= low


def _number(x, low: float | None = None) -> bool:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return False
    try:
        f = float(x)
    except OverflowError:  # an integer beyond any float
        return False
    return math.isfinite(f) and (low is None or f >= low)


_JSON_TYPES = {bool: "boolean", int: "number", float: "number", str: "string", list: "array", type(None): "null"}


def _chain_problem(rec: dict) -> str | None:
    for key in ("seed", "length", "decisions"):
        if not _int(rec.get(key)):
            return f"{key} must be an integer >= 0, got {rec.get(key, 'nothing')!r}"
    if not _number(rec.get("seconds"), 0.0):
        return f"seconds must be a finite number >= 0, got {rec.get('seconds', 'nothing')!r}"
    shots = rec.get("last_shots")
    if not (isinstance(shots, list) and all(isinstance(s, list) and len(s) >= 3 for s in shots)):
        return "last_shots must be a list of shots [positions, action, scored, ...]"
    return None


_SIDES = ("white", "yellow")


def _match_problem(rec: dict) -> str | None:
    a, b = rec.get("a"), rec.get("b")
    if not (isinstance(a, str) and isinstance(b, str) and a and b and a != b):
        return f"a and b must name two different players, got {a!r} and {b!r}"
    for key in ("i", "seed", "shots", "innings"):
        if not _int(rec.get(key)):
            return f"{key} must be an integer >= 0, got {rec.get(key, 'nothing')!r}"
    if rec.get("first") not in _SIDES:
        return f"first must be white or yellow, got {rec.get('first', 'nothing')!r}"
    if "winner" not in rec or rec["winner"] not in (*_SIDES, None):
        return f"winner must be white, yellow or null (a draw), got {rec.get('winner', 'nothing')!r}"
    for key, ok in (("scores", _number), ("cpu_s", lambda x: _number(x, 0.0)), ("turns", _int)):
        per = rec.get(key)
        if not (isinstance(per, dict) and all(ok(per.get(side)) for side in _SIDES)):
            return f"{key} must give white and yellow each a number, got {per!r}"
    return None


@dataclass(frozen=True)
class LedgerKind:
    """One kind of append-only ledger: its file, what a record is, the unit a record finishes
    (each unit at most once), the record's shape, and its run's summary file."""

    file: str
    what: str  # "P3 chain record"
    unit: Callable[[dict], Hashable]
    name_unit: Callable[[dict], str]
    problem: Callable[[dict], str | None]  # what is wrong with a record's shape, or None
    summary: str  # the run's summary file, checked against the ledger by verify


CHAINS = LedgerKind(CHAINS_FILE, "P3 chain record", lambda r: r["seed"], lambda r: f"the chain of seed {r['seed']}",
                    _chain_problem, RESULTS_FILE)
MATCHES = LedgerKind(MATCHES_FILE, "league match record", lambda r: (r["a"], r["b"], r["i"]),
                     lambda r: f"match {r['i']} of {r['a']} (white) vs {r['b']}", _match_problem, LEAGUE_FILE)
LEDGERS = (CHAINS, MATCHES)


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
    """Check a ledger's bytes line by line (``name``: the file, for the messages). A record must
    be a JSON object of the kind's shape whose seal matches it, carry the identity ``run`` (with
    None: the same identity as the other records) and finish a unit no earlier line finished.
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
        why = why if len(why) <= 240 else why[:240] + "..."  # a hostile value is not echoed whole
        scan.problems.append(f"{name}: line {n} is not an intact {kind.what}: {why}")

    for n, raw in enumerate(lines, 1):
        if not raw.strip():
            continue
        try:
            rec = json.loads(raw)
        except (ValueError, RecursionError):
            bad(n, f"it is not JSON ({raw[:60].decode(errors='replace')!r})")
            continue
        if not isinstance(rec, dict):
            bad(n, f"it is a JSON {_JSON_TYPES.get(type(rec), 'value')} ({raw[:60].decode(errors='replace')}), "
                   f"not a record (an object)")
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
            whose = f"line {owner[1]}'s run {owner[0]}" if owner[1] else f"this run is {owner[0]}"
            scan.problems.append(f"{name}: line {n} belongs to another run (run {ident!r}; {whose}): "
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


def read_ledger(path, kind: LedgerKind, run: str | None = None, *, unchecked: bool = False,
                repair: bool = False) -> LedgerScan:
    """The records of the ledger at ``path`` (none if there is no file), checked by
    :func:`scan_ledger`; :class:`LedgerError` naming the file and the first bad line if any line
    is bad. A torn last line is left out; with ``repair`` (the resume path) it is cut off the
    file (``cut``), so that the next append starts a line of its own and its unit is played
    again."""
    path = Path(path)
    if not path.is_file():
        return LedgerScan()
    scan = scan_ledger(path.read_bytes(), display_path(path), kind, run, unchecked)
    if scan.problems:
        more = f" (and {len(scan.problems) - 1} more bad lines)" if len(scan.problems) > 1 else ""
        raise LedgerError(scan.problems[0] + more)
    if scan.torn is not None and repair:
        data = path.read_bytes()
        with open(path, "r+b") as f:  # the torn tail of a killed append
            f.truncate(data.rfind(b"\n") + 1)
            f.flush()
            os.fsync(f.fileno())
        scan.cut = True
    return scan


def append_record(path, record: dict, run: str) -> dict:
    """Append ``record`` with the identity ``run`` and its seal to the ledger at ``path``: one
    whole line with its newline, flushed and fsynced; returns the sealed record. A ledger that
    ends in a torn line is refused (:func:`read_ledger` with ``repair`` cuts it first)."""
    import json

    rec = json.loads(json.dumps({**record, RUN_KEY: run}))  # what a reader will see (floats, tuples, keys)
    line = (json.dumps(sealed_record(rec)) + "\n").encode()
    with open(path, "a+b") as f:
        if f.seek(0, os.SEEK_END) > 0:
            f.seek(-1, os.SEEK_END)
            if f.read(1) != b"\n":
                raise LedgerError(f"{display_path(path)} ends in a torn line: it is cut (read_ledger(..., repair=True)) "
                                  f"before anything is appended")
        f.write(line)
        f.flush()
        os.fsync(f.fileno())
    return sealed_record(rec)


def _summary_problems(kind: LedgerKind, records: list[dict], summary: dict, name: str) -> list[str]:
    """Where a run's summary disagrees with its ledger's records."""
    if kind is CHAINS:
        extra = summary.get("extra") if isinstance(summary.get("extra"), dict) else {}
        seeds, values = extra.get("seeds"), summary.get("values")
        if summary.get("protocol") != "p3" or not isinstance(seeds, list) or not isinstance(values, list):
            return [f"{name} is not a P3 result (protocol p3, its values and extra.seeds)"]
        if len(seeds) != len(values):
            return [f"{name} gives {len(values)} values for {len(seeds)} seeds"]
        length = {r["seed"]: r["length"] for r in records}
        out = []
        for seed, value in zip(seeds, values):
            if seed not in length:
                out.append(f"{name} counts seed {seed} (value {value}), which the ledger does not hold")
            elif value != length[seed]:
                out.append(f"{name} gives seed {seed} the value {value}; the ledger's chain of seed {seed} is "
                           f"{length[seed]} long")
        if left := sorted(set(length) - set(seeds), key=str):
            out.append(f"the ledger holds chains {name} does not count (seeds {', '.join(map(str, left))})")
        if values and all(_number(v) for v in values) and _number(summary.get("mean")) \
                and abs(summary["mean"] - sum(values) / len(values)) > 1e-9 * max(1.0, abs(summary["mean"])):
            out.append(f"{name}'s mean {summary['mean']} is not the mean of its values")
        return out
    pairs = summary.get("pairs")
    if not isinstance(pairs, list) or not all(isinstance(p, dict) for p in pairs):
        return [f"{name} holds no pairs"]
    counts: dict = {}
    for r in records:
        c = counts.setdefault((r["a"], r["b"]), {"matches": 0, "a_wins": 0, "b_wins": 0, "draws": 0})
        c["matches"] += 1
        c[{"white": "a_wins", "yellow": "b_wins", None: "draws"}[r["winner"]]] += 1
    out = []
    for p in pairs:
        key = (p.get("a"), p.get("b"))
        mine = {k: p.get(k) for k in ("matches", "a_wins", "b_wins", "draws")}
        theirs = counts.pop(key, None)
        if theirs is None:
            out.append(f"{name} counts {key[0]} vs {key[1]} ({mine['matches']} matches), of which the ledger holds none")
        elif mine != theirs:
            show = lambda c: f"{c['a_wins']}-{c['b_wins']} with {c['draws']} draws of {c['matches']}"  # noqa: E731
            out.append(f"{name} counts {key[0]} vs {key[1]} {show(mine)}; the ledger holds {show(theirs)}")
    for (a, b), c in counts.items():
        out.append(f"the ledger holds {c['matches']} matches of {a} vs {b} that {name} does not count")
    return out


def verify(run_dir, strict: bool = False) -> tuple[list[str], list[str]]:
    """Check a run directory's ledger (``chains.jsonl`` or ``matches.jsonl``) record by record
    and its summary (``results.json``: its values are the ledger's chain lengths in seed order;
    ``league.json``: its pair counts are the ledger's). Returns (problems, notes), one sentence
    each. Records whose seal or run identity is missing are checked on their shape and are a
    note (a problem with ``strict``, or when the summary names the run's identity: such a run
    seals every record with it)."""
    import json

    run_dir = Path(run_dir)
    kinds = [k for k in LEDGERS if (run_dir / k.file).is_file()]
    if not kinds:
        return [f"{display_path(run_dir)}: no ledger ({' or '.join(k.file for k in LEDGERS)}) there"], []
    problems: list[str] = []
    notes: list[str] = []
    for kind in kinds:
        path, spath = run_dir / kind.file, run_dir / kind.summary
        summary = None
        try:
            summary = json.loads(spath.read_text())
            if not isinstance(summary, dict):
                problems.append(f"{display_path(spath)} is not a JSON object")
                summary = None
        except FileNotFoundError:
            problems.append(f"{display_path(spath)} does not exist: the run did not finish (its resume finishes it)")
        except (OSError, ValueError) as err:
            problems.append(f"{display_path(spath)} is damaged: {err}")
        run = summary.get(RUN_KEY) if summary is not None else None
        run = run if isinstance(run, str) else None
        scan = scan_ledger(path.read_bytes(), display_path(path), kind, run, unchecked=run is None)
        problems += scan.problems
        if scan.torn is not None:
            problems.append(f"{display_path(path)}: line {scan.torn} is torn (no newline: a kill mid-append); "
                            f"resume cuts it off and plays its unit again")
        if summary is not None:
            problems += _summary_problems(kind, scan.records, summary, display_path(spath))
        if scan.unchecked:
            n, unsealed = len(scan.unchecked), len(scan.unsealed)
            what = ("carry no seal: their shape is checked, their content cannot be" if unsealed == n else
                    f"carry a seal but no run identity{f' ({unsealed} no seal either)' if unsealed else ''}: "
                    f"their shape and seals are checked, which run wrote them cannot be")
            say = f"{display_path(path)}: {n} of {len(scan.records)} records {what}; such a run is not resumed"
            (problems if strict else notes).append(say)
        else:
            notes.append(f"{display_path(path)}: {len(scan.records)} sealed records"
                         + (f" of run {scan.records[0][RUN_KEY]}" if scan.records else ""))
    return problems, notes


# ----------------------------------------------------------------------------- a file's meaning
#
# A seal proves a file is what was written, not that it makes sense: each model file kind checks
# its content in one place after the seal (``check_policy``, ``check_checkpoint``,
# ``TaggedMLP.check`` for rankers and table values, ``check_reward_model``), with these helpers.
# Each returns what is wrong, one phrase naming the entry, or None; the caller raises its own
# error naming the file.

MAX_NESTING = 64  # how deep stored plain data may nest (a deeper one is damage, and would exhaust the stack)


def tensor_problem(tree, where: str, floats_only: bool = True) -> str | None:
    """The first tensor (or NumPy array) in ``tree`` (dicts, lists and tuples at any depth) that
    is complex, or holds NaN or an infinity, or (``floats_only``) is not of a real
    floating-point dtype, as ``"<where>.<key>: ..."``."""
    import numpy as np
    import torch

    def visit(x, name: str, depth: int) -> str | None:
        if depth > MAX_NESTING:
            return f"{name}: nested deeper than {MAX_NESTING} levels"
        if torch.is_tensor(x):
            complex_, floating = x.is_complex(), x.is_floating_point()
            finite = lambda: bool(torch.isfinite(x).all())  # noqa: E731
        elif isinstance(x, np.ndarray):
            complex_, floating = x.dtype.kind == "c", x.dtype.kind == "f"
            finite = lambda: bool(np.isfinite(x).all())  # noqa: E731
        else:
            complex_ = floating = None
        if complex_ is not None:
            if complex_ or (floats_only and not floating):
                return f"{name}: a tensor of dtype {x.dtype}, not of real floating-point numbers"
            if floating and not finite():
                return f"{name}: holds NaN or an infinity"
            return None
        items = x.items() if isinstance(x, dict) else enumerate(x) if isinstance(x, (list, tuple)) else ()
        for k, v in items:
            if (bad := visit(v, f"{name}.{k}", depth + 1)) is not None:
                return bad
        return None

    return visit(tree, where, 0)


def key_problem(payload, spec: dict, where: str = "") -> str | None:
    """What is wrong with ``payload``'s keys: ``spec`` maps each required key to its type (or a
    tuple of types); a key missing or of another type (a boolean is no number) is named."""
    say = f"{where}: " if where else ""
    if not isinstance(payload, dict):
        return f"{say}a {type(payload).__name__}, not a mapping"
    for key, kind in spec.items():
        if key not in payload:
            return f"{say}'{key}' is missing"
        value = payload[key]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
            names = " or ".join(k.__name__ if k is not type(None) else "None" for k in kinds)
            return f"{say}'{key}' is a {type(value).__name__}, not a {names}"
    return None


def plain_data_problem(value, where: str) -> str | None:
    """What keeps ``value`` from being plain data (a stored config, metadata): anything but
    dicts with string keys, lists, strings, numbers, booleans and None, nesting past
    :data:`MAX_NESTING`, or a string holding an interpolation (``${``: a stored config is what
    was resolved when it was written; ``${oc.env:HOME}`` would read this machine's environment)."""

    def visit(x, name: str, depth: int) -> str | None:
        if depth > MAX_NESTING:
            return f"{name}: nested deeper than {MAX_NESTING} levels"
        if isinstance(x, str):
            return f"{name}={x[:80]!r}: an interpolation ('${{'); a stored config holds values only" if "${" in x else None
        if x is None or isinstance(x, (bool, int, float)):
            return None
        if isinstance(x, dict):
            for k, v in x.items():
                if not isinstance(k, str):
                    return f"{name}: a key of type {type(k).__name__} (keys are strings)"
                if "${" in k:
                    return f"{name}: the key {k[:80]!r} holds an interpolation"
                if (bad := visit(v, f"{name}.{k}", depth + 1)) is not None:
                    return bad
            return None
        if isinstance(x, (list, tuple)):
            for i, v in enumerate(x):
                if (bad := visit(v, f"{name}[{i}]", depth + 1)) is not None:
                    return bad
            return None
        return f"{name}: a {type(x).__name__}, not plain data"

    return visit(value, where, 0)


def shape_problem(expected: dict, got, where: str) -> str | None:
    """What is wrong with the tensors ``got`` (a state dict) against ``expected`` (name ->
    shape, from the network the file's own config builds): a name missing or extra, a value
    that is no tensor, a shape that differs."""
    import torch

    if not isinstance(got, dict):
        return f"{where}: a {type(got).__name__}, not a mapping of tensors"
    missing = [k for k in expected if k not in got]
    extra = [str(k) for k in got if k not in expected]
    if missing or extra:
        say = [f"lacks {', '.join(missing[:4])}{' ...' if len(missing) > 4 else ''}" if missing else "",
               f"holds {', '.join(extra[:4])}{' ...' if len(extra) > 4 else ''} that it does not have" if extra else ""]
        return f"{where}: not the network its config describes: it " + " and ".join(s for s in say if s)
    for k, shape in expected.items():
        v = got[k]
        if not torch.is_tensor(v):
            return f"{where}.{k}: a {type(v).__name__}, not a tensor"
        if tuple(v.shape) != tuple(shape):
            return f"{where}.{k}: shape {tuple(v.shape)}, but the network its config describes has {tuple(shape)}"
    return None


def save_tagged(path, payload: dict) -> Path:
    """Write a tagged payload (``"format"`` set by the caller) with its checksum
    (:func:`payload_digest`), atomically; :func:`load_tagged` checks both."""
    import io

    import torch

    buf = io.BytesIO()
    torch.save({**payload, SEAL_KEY: payload_digest(payload)}, buf)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    return atomic_write_bytes(path, buf.getvalue())


def load_tagged(path, tag: str, error: type[Exception], what: str) -> dict:
    """``torch.load`` (tensors and plain containers only: nothing in the file is executed) of a
    dict whose ``"format"`` is ``tag``, sealed by :func:`save_tagged`; raises ``error`` naming
    the path and ``what`` was expected if the file is missing, empty, unreadable, of another
    format, without its checksum or not matching it (a flipped bit), or holds a NaN or an
    infinity. The loaders check the shapes their layout declares."""
    payload = _load_tagged_unchecked(path, tag, error, what)
    if SEAL_KEY not in payload:
        raise error(f"{what} file {path} carries no checksum: python -m billiards.compat seal {path} checks its "
                    f"contents and seals it")
    if payload[SEAL_KEY] != payload_digest(payload):
        raise error(f"{what} file {path} is damaged: its contents do not match its sha256 checksum")
    if (bad := non_finite_entry(payload)) is not None:
        raise error(f"{what} file {path} holds non-finite values (NaN or inf) in {bad}")
    return payload


def _load_tagged_unchecked(path, tag: str, error: type[Exception], what: str) -> dict:
    import torch

    path = Path(path)
    if not path.is_file():
        raise error(f"{what} file {path} does not exist")
    if path.stat().st_size == 0:
        raise error(f"{what} file {path} is empty")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # torch raises many types for a corrupt file
        raise error(f"{what} file {path} is corrupt or not a torch file ({type(err).__name__}: {err})") from None
    if not isinstance(payload, dict) or payload.get("format") != tag:
        raise error(f"{path} is not a {what} file (expected format tag {tag!r})")
    return payload


def main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="python -m billiards.files", description="Verify run directories' ledgers.")
    sub = ap.add_subparsers(dest="command", required=True)
    vp = sub.add_parser("verify", help="check each run directory's ledger (chains.jsonl, matches.jsonl) record by record "
                                       "and its summary (results.json, league.json) against it; one line per problem, "
                                       "exit status 1 if any")
    vp.add_argument("dirs", nargs="+", type=Path, metavar="RUN_DIR")
    vp.add_argument("--strict", action="store_true", help="records without a seal or a run identity are problems too")
    args = ap.parse_args(argv)
    bad = 0
    for d in args.dirs:
        problems, notes = verify(d, strict=args.strict)
        for line in problems:
            print(f"problem: {line}")
        for line in notes:
            print(f"note: {line}")
        print(f"{display_path(d)}: " + (f"{len(problems)} problems" if problems else "ledger and summary agree"))
        bad += len(problems)
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
