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
off a torn last line (a kill mid-append: no newline) so that its unit is played again. Every
kind of ledger is registered (:func:`register_ledger`, :func:`ledger_kinds`), and
``python -m billiards.files verify RUN_DIR`` checks a run directory's ledger of any kind record
by record and its summary (``results.json``, ``league.json``, ``scorecard.json``) against it; a
resume never trusts a summary, it recomputes it from the ledger (:func:`stale_summary`).

Every file read back from a run folder goes through one reader (:func:`open_run_file`,
:func:`read_run_bytes`, :func:`read_run_json`): regular files only, no link followed, a size
bound per kind, a depth bound on JSON, and sentences that name a file and never quote it. A run
folder has one writer at a time (:func:`run_lock`, its lock file :data:`LOCK_FILE`).
"""

from __future__ import annotations

import contextlib
import errno
import math
import os
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, Callable, Hashable, Iterator

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
    relative to it (``hydra.run.dir=/abs/repo/x`` -> ``hydra.run.dir=x``); an app run by the
    console command (:mod:`billiards.cli` names it ``sagu <app>``) as ``sagu <app> ...``."""
    import sys

    root = str(ROOT.resolve()) + "/"
    out = ["python" if c == sys.executable else c.replace(root, "") for c in cmd]
    if len(out) > 1 and out[0] == "python" and out[1].startswith("sagu "):
        out = [*out[1].split(), *out[2:]]
    return out


@contextlib.contextmanager
def atomic_open(path, mode: str = "w", **kwargs) -> Iterator[IO]:
    """Open ``path + ".tmp"`` for writing (``mode`` "w" or "wb", ``kwargs`` as for
    :func:`open`); when the block ends normally the file is flushed, fsynced and renamed over
    ``path``. If the block raises, the temporary file is removed and ``path`` is untouched."""
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open writes whole files: mode must be 'w' or 'wb', got {mode!r}")
    path = Path(path)
    tmp = path.with_name(path.name + TMP_SUFFIX)
    tmp.unlink(missing_ok=True)  # a stale temporary file, or a link planted there: never written through
    try:
        with open(tmp, mode.replace("w", "x"), **kwargs) as f:  # created afresh (O_EXCL: no link is followed)
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


# ----------------------------------------------------------------------------- reading a run folder's files
#
# One reader for every file the package reads back from a run folder (ledgers, results.json,
# league.json, scorecard.json, evaluation.json, summary.json, eval.json, config.yaml, checkpoint.pt):
# a regular file inside the folder, read without following a link, within a size bound per kind,
# JSON within a depth bound. What it refuses it refuses unread, with a sentence naming the file
# and never quoting it: a link (it could lead to any file of the machine: in CI, a secret a pull
# request names), a named pipe, a device, a socket or a directory (opened for reading, a FIFO
# would block forever), a file past its bound, JSON nested past MAX_JSON_DEPTH.

RUN_FILE_LIMITS = {  # the most bytes the package reads of a run folder's file of each kind
    "ledger": 256 << 20,  # *.jsonl: chains.jsonl, matches.jsonl, units.jsonl, eval_history.jsonl
    "summary": 32 << 20,  # *.json: results.json, league.json, scorecard.json, evaluation.json, summary.json, eval.json
    "config": 4 << 20,  # *.yaml: a run's config.yaml, Hydra's .hydra/*.yaml
    "checkpoint": 64 << 30,  # checkpoint.pt (the replay buffer included)
}
_KIND_BY_SUFFIX = {".jsonl": "ledger", ".json": "summary", ".yaml": "config", ".yml": "config", ".pt": "checkpoint"}
MAX_JSON_DEPTH = 64  # how deep a run folder's JSON may nest (the package's own files nest at most 6 levels)
_NOFOLLOW, _NONBLOCK, _CLOEXEC = (getattr(os, n, 0) for n in ("O_NOFOLLOW", "O_NONBLOCK", "O_CLOEXEC"))


class RunFileError(ValueError):
    """A run folder's file refused unread (a link, not a regular file, past its size bound) or
    unparsed (not UTF-8, not JSON, nested too deep); the message names the file, never its content."""


def run_file_kind(path) -> str:
    """The kind of a run folder's file (a key of :data:`RUN_FILE_LIMITS`), by its suffix; "summary" otherwise."""
    return _KIND_BY_SUFFIX.get(Path(path).suffix.lower(), "summary")


def _not_regular(mode: int) -> str | None:
    """What a file of this mode is, if it is not a regular file."""
    for test, what in ((stat.S_ISLNK, "a symbolic link"), (stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a named pipe (FIFO)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return what
    return None if stat.S_ISREG(mode) else "not a regular file"


def _refused(name: str, what: str) -> RunFileError:
    return RunFileError(f"{name} is {what}, not a regular file: a run folder's files are read only as regular files "
                        f"inside it (nothing was read)")


def _too_large(name: str, size: int, kind: str) -> RunFileError:
    return RunFileError(f"{name} is {size:,} bytes; a {kind} file of a run folder holds at most {RUN_FILE_LIMITS[kind]:,} "
                        f"(billiards.files.RUN_FILE_LIMITS): refused unread")


def _no_links_below(path: Path, within: Path, name: str) -> None:
    """The folders between ``within`` and ``path`` are no links (``path`` itself is checked by the opener)."""
    try:
        rel = path.relative_to(within)
    except ValueError:
        raise RunFileError(f"{name} lies outside its run folder {display_path(within)}: refused unread") from None
    if ".." in rel.parts:
        raise RunFileError(f"{name} leads out of its run folder {display_path(within)} (..): refused unread")
    here = within
    for part in rel.parts[:-1]:
        here = here / part
        if os.path.islink(here):
            raise RunFileError(f"{display_path(here)} is a symbolic link: a run folder's files are read only inside it "
                               f"(nothing was read)")


@contextlib.contextmanager
def open_run_file(path, kind: str | None = None, *, within=None) -> Iterator[IO[bytes]]:
    """A run folder's file open for reading (binary), refused unread (:class:`RunFileError`) if it
    is a link, anything but a regular file, or larger than its kind's bound
    (:data:`RUN_FILE_LIMITS`; ``kind`` by default by the suffix, :func:`run_file_kind`).
    ``within``: the run folder, when the file lies in a subfolder of it (``.hydra/config.yaml``):
    the subfolders may be no links either. A missing file raises FileNotFoundError. It is
    looked at (``lstat``) before it is opened, and opened without following a link and without
    blocking (``O_NOFOLLOW | O_NONBLOCK``), then checked again on the open descriptor."""
    path = Path(path)
    kind = kind or run_file_kind(path)
    name = display_path(path)
    if within is not None:
        _no_links_below(path, Path(within), name)
    st = os.lstat(path)
    if (what := _not_regular(st.st_mode)) is not None:
        raise _refused(name, what)
    if st.st_size > RUN_FILE_LIMITS[kind]:
        raise _too_large(name, st.st_size, kind)
    try:
        fd = os.open(path, os.O_RDONLY | _NOFOLLOW | _NONBLOCK | _CLOEXEC | getattr(os, "O_BINARY", 0))
    except OSError as err:
        if err.errno == errno.ELOOP:  # became a link after the look
            raise _refused(name, "a symbolic link") from None
        raise
    try:
        now = os.fstat(fd)
        if (what := _not_regular(now.st_mode)) is not None:
            raise _refused(name, what)
        if (now.st_dev, now.st_ino) != (st.st_dev, st.st_ino):
            raise RunFileError(f"{name} was replaced while it was opened: refused unread; read it again")
        f = os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise
    with f:
        yield f


def read_run_bytes(path, kind: str | None = None, *, within=None) -> bytes:
    """The bytes of a run folder's file, read through :func:`open_run_file` (its checks and
    bound; a file that grew past the bound while read is refused too)."""
    kind = kind or run_file_kind(path)
    with open_run_file(path, kind, within=within) as f:
        data = f.read(RUN_FILE_LIMITS[kind] + 1)
    if len(data) > RUN_FILE_LIMITS[kind]:
        raise _too_large(display_path(path), len(data), kind)
    return data


def read_run_text(path, kind: str | None = None, *, within=None) -> str:
    """A run folder's file as UTF-8 text (:func:`read_run_bytes`; :class:`RunFileError` if it is not UTF-8)."""
    data = read_run_bytes(path, kind, within=within)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise RunFileError(f"{display_path(path)} is not UTF-8 text (byte {err.start:,} is not): refused unparsed") from None


_JSON_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"', re.S)
_NOT_BRACKETS = bytes(b for b in range(256) if b not in b"[]{}")
_INNERMOST = re.compile(rb"\[\]|\{\}")


def json_depth_problem(data, limit: int = MAX_JSON_DEPTH) -> str | None:
    """Why a JSON text (str or bytes) cannot be parsed within ``limit`` levels of nesting -- it
    nests deeper, or its brackets do not balance (then it is no JSON) -- or None. Looks at the
    brackets outside strings only, without recursion: one pass drops every innermost pair."""
    if isinstance(data, str):
        data = data.encode("utf-8", "surrogatepass")
    if b"[" not in data and b"{" not in data:
        return None
    skeleton = _JSON_STRING.sub(b"", data).translate(None, _NOT_BRACKETS)
    for _ in range(limit):
        if not skeleton:
            return None
        skeleton, dropped = _INNERMOST.subn(b"", skeleton)
        if not dropped:
            return "its brackets do not balance"
    if not skeleton:
        return None
    return f"it nests deeper than {limit} levels" if _INNERMOST.search(skeleton) else "its brackets do not balance"


def parse_json(data, name: str, limit: int = MAX_JSON_DEPTH) -> Any:
    """JSON text (str or bytes) parsed, nesting at most ``limit`` levels; :class:`RunFileError`
    naming ``name`` (the file) and where it breaks, never quoting it, otherwise."""
    import json

    if (why := json_depth_problem(data, limit)) is not None:
        raise RunFileError(f"{name} is not JSON the package reads: {why}")
    try:
        return json.loads(data)
    except json.JSONDecodeError as err:
        raise RunFileError(f"{name} is not JSON ({err.msg} at line {err.lineno} column {err.colno})") from None
    except UnicodeDecodeError as err:
        raise RunFileError(f"{name} is not UTF-8 text (byte {err.start:,} is not)") from None
    except (ValueError, RecursionError) as err:  # past the checks above only on a very small stack
        raise RunFileError(f"{name} is not JSON the package reads ({type(err).__name__})") from None


def read_run_json(path, kind: str | None = None, *, within=None) -> Any:
    """A run folder's JSON file parsed (:func:`read_run_bytes`, :func:`parse_json`)."""
    return parse_json(read_run_bytes(path, kind, within=within), display_path(path))


# ----------------------------------------------------------------------------- one writer per run folder
#
# A run folder has one writer: a run takes the folder's lock file (LOCK_FILE) for its lifetime
# (run_lock) and writes into it who it is; a second writer is refused at once, naming the first.
# The lock is an flock(2) on the file, which the kernel lets go when its holder dies however it
# dies: a lock file whose flock nobody holds is a dead run's, and is taken over with a note.
# Where flock is missing (no fcntl, a file system without it), the recorded pid is checked instead
# (alive on this host: held; another host: held, since it cannot be told).

LOCK_FILE = ".lock"  # in a run folder while a run writes it (readers and the directory checks ignore it)


class RunLockedError(ValueError):
    """A run folder another live run writes; the message names that run."""


@dataclass(frozen=True)
class LockHolder:
    """Who holds (or held) a run folder's lock."""

    pid: int
    host: str
    started: str
    command: str

    def describe(self) -> str:
        return f"pid {self.pid} on {self.host}, started {self.started}: {self.command}"

    def alive(self) -> bool | None:
        """Whether its process still runs: True or False on this host, None on another."""
        import socket

        if self.host != socket.gethostname():
            return None
        if self.pid <= 0:
            return False
        try:
            os.kill(self.pid, 0)
        except ProcessLookupError:
            return False
        except OSError:  # it exists, owned by another user
            return True
        return True


def _shown(text, most: int) -> str:
    """A lock file's text field as it is shown: printable characters only, at most ``most``."""
    text = "".join(c if c.isprintable() else "?" for c in str(text))
    return text if len(text) <= most else text[:most] + "..."


def _holder(data: bytes) -> LockHolder | None:
    import json

    try:
        rec = json.loads(data.decode("utf-8")) if data.strip() and json_depth_problem(data, 4) is None else None
    except (ValueError, RecursionError):
        rec = None
    pid = rec.get("pid") if isinstance(rec, dict) else None
    if not isinstance(pid, int) or isinstance(pid, bool):
        return None  # not a record run_lock wrote: it names no one
    return LockHolder(pid, _shown(rec.get("host", "?"), 64),
                      _shown(rec.get("started", "?"), 40), _shown(rec.get("command", "?"), 300))


def _flock(fd: int) -> bool | None:
    """Take the flock of ``fd`` without waiting: True taken, False another holds it, None where flock is missing."""
    try:
        import fcntl
    except ImportError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    except OSError as err:
        if err.errno in (errno.EAGAIN, errno.EACCES):
            return False
        if err.errno in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL):
            return None
        raise
    return True


def _this_command() -> str:
    import sys

    return " ".join(recorded_command([sys.executable, *sys.argv]))


@dataclass
class RunLock:
    """A held run-folder lock (:func:`run_lock`): its file, its holder (this process) and the
    dead run whose lock it took over, if any."""

    path: Path
    holder: LockHolder
    took_over: LockHolder | None = None


def _locked_by(run_dir: Path, holder: LockHolder | None) -> RunLockedError:
    who = f"another run ({holder.describe()})" if holder else "another process (which has not yet written who it is)"
    return RunLockedError(f"{display_path(run_dir)} is being written by {who}: one writer per run folder; wait for that "
                          f"run to end or stop it, then start this one again")


def _acquire(run_dir: Path, record: bytes) -> tuple[int, LockHolder | None]:
    """The lock file's descriptor, locked and holding ``record``, and the dead holder it replaced (or None)."""
    path = run_dir / LOCK_FILE
    for _ in range(50):
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | _NOFOLLOW | _CLOEXEC | getattr(os, "O_BINARY", 0), 0o644)
        except OSError as err:
            if err.errno in (errno.ELOOP, errno.EISDIR, errno.ENXIO):
                raise RunLockedError(f"{display_path(path)} is not a regular file: a run folder's lock file is the "
                                     f"package's own; remove it") from None
            raise
        keep = False
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode):
                raise RunLockedError(f"{display_path(path)} is {_not_regular(st.st_mode)}: a run folder's lock file is "
                                     f"the package's own; remove it")
            got = _flock(fd)
            previous = _holder(_read_at_start(fd))
            if got is False or (got is None and previous is not None and previous.alive() is not False
                                and (previous.pid, previous.host) != (os.getpid(), _hostname())):
                raise _locked_by(run_dir, previous)
            try:
                now = os.stat(path, follow_symlinks=False)
            except FileNotFoundError:
                continue  # its holder removed it as it let go: take the new one
            if (now.st_dev, now.st_ino) != (st.st_dev, st.st_ino):
                continue
            os.ftruncate(fd, 0)
            os.lseek(fd, 0, os.SEEK_SET)
            os.write(fd, record)
            os.fsync(fd)
            keep = True
            return fd, previous
        finally:
            if not keep:
                os.close(fd)
    raise RunLockedError(f"{display_path(path)} changes faster than it can be taken: another run is starting there")


def _read_at_start(fd: int, most: int = 4096) -> bytes:
    os.lseek(fd, 0, os.SEEK_SET)
    return os.read(fd, most)


def _hostname() -> str:
    import socket

    return socket.gethostname()


@contextlib.contextmanager
def run_lock(run_dir, command: str | None = None, say: Callable[[str], None] | None = print) -> Iterator[RunLock]:
    """Hold ``run_dir``'s lock (:data:`LOCK_FILE`, the folder created if missing) for the block:
    the one writer of the folder. The lock file names its holder (pid, host, start time and
    ``command``, by default this process's command line). Another live holder: refused at once
    (:class:`RunLockedError` naming it). A dead holder's lock (no process holds its flock; where
    flock is missing, a pid no longer alive on this host) is taken over, and ``say`` (None:
    silent) tells whose. The lock file is removed when the block ends."""
    import json
    import time

    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    me = LockHolder(os.getpid(), _hostname(), time.strftime("%Y-%m-%dT%H:%M:%S%z"), _shown(command or _this_command(), 300))
    record = (json.dumps({"pid": me.pid, "host": me.host, "started": me.started, "command": me.command}) + "\n").encode()
    fd, previous = _acquire(run_dir, record)
    path = run_dir / LOCK_FILE
    if previous is not None and say is not None:
        say(f"note: {display_path(run_dir)}: took over the lock of a run that is no longer running ({previous.describe()})")
    try:
        yield RunLock(path, me, previous)
    finally:
        try:
            st, now = os.fstat(fd), os.stat(path, follow_symlinks=False)
            if (now.st_dev, now.st_ino) == (st.st_dev, st.st_ino):
                os.unlink(path)  # while still held: a process that opened it before retries on the next one
        except OSError:
            pass
        os.close(fd)


def lock_holder(run_dir) -> LockHolder | None:
    """Who the lock file of ``run_dir`` names, if that process may still run (alive on this
    host, or on another host), else None. Only looks (for notes: :func:`verify`)."""
    path = Path(run_dir) / LOCK_FILE
    try:
        holder = _holder(read_run_bytes(path, "config"))
    except (OSError, ValueError):
        return None
    return holder if holder is not None and holder.alive() is not False else None


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
_MISSING = object()


def described(x=_MISSING) -> str:
    """What a value read from a file is, without quoting it (a message about a file never
    repeats what the file holds): "nothing" (missing), "null", "a boolean", "a negative
    integer", "a fraction", "a string", "an array" ..."""
    if x is _MISSING:
        return "nothing"
    if x is None:
        return "null"
    if isinstance(x, bool):
        return "a boolean"
    if isinstance(x, int):
        if not _number(x):
            return "an integer beyond any float"
        return "a negative integer" if x < 0 else "an integer"
    if isinstance(x, float):
        if not math.isfinite(x):
            return "a non-finite number"
        return "a negative number" if x < 0 else "a number" if x.is_integer() else "a fraction"
    return {str: "a string", list: "an array", dict: "an object"}.get(type(x), f"a {type(x).__name__}")


def shown_number(x) -> str:
    """A value read from a file as a message shows it: a finite number as it is (a number is no
    secret), anything else :func:`described`."""
    return repr(x) if _number(x) else described(x)


_NAME = re.compile(r"[\w.:/+@-]{1,64}")
_IDENT = re.compile(r"[0-9a-f]{16}")


def shown_name(x) -> str:
    """A name read from a file (a player's) as a message shows it: itself when it is a short
    name (letters, digits, ``_ . : / + @ -``, at most 64), else :func:`described`."""
    return x if isinstance(x, str) and _NAME.fullmatch(x) else f"{described(x)} (no player's name)"


def _shown_ident(x) -> str:
    return repr(x) if isinstance(x, str) and _IDENT.fullmatch(x) else "an identity that is no 16-digit hash"


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
    if summary.get("protocol") != "p3" or not isinstance(seeds, list) or not isinstance(values, list):
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


# ----------------------------------------------------------------------------- summaries from their ledgers


def read_summary(run_dir, kind: LedgerKind) -> tuple[dict | None, str | None]:
    """The run's summary file (``kind.summary`` in ``run_dir``) read through
    :func:`read_run_json`: (the summary, None), or (None, a sentence: missing, refused, damaged,
    not an object)."""
    spath = Path(run_dir) / kind.summary
    try:
        summary = read_run_json(spath, "summary")
    except FileNotFoundError:
        return None, f"{display_path(spath)} does not exist: the run did not finish (its resume finishes it)"
    except RunFileError as err:
        return None, str(err)
    except OSError as err:
        return None, f"{display_path(spath)} cannot be read ({err.strerror or type(err).__name__})"
    if not isinstance(summary, dict):
        return None, f"{display_path(spath)} is not a JSON object"
    return summary, None


def summary_problems(kind: LedgerKind, records: list[dict], summary: dict, name: str) -> list[str]:
    """Where a run's summary (read from the file ``name``) disagrees with its ledger's records,
    one sentence each (the kind's :attr:`LedgerKind.check`); [] when it agrees or the kind has no check."""
    try:
        check = kind.summary_check()
    except (ImportError, AttributeError) as err:
        return [f"{name} cannot be checked against its ledger: {kind.check} cannot be loaded ({type(err).__name__})"]
    return [] if check is None else list(check(records, summary, name))


def stale_summary(run_dir, kind: LedgerKind, records: list[dict]) -> str | None:
    """Why the summary a finished run left in ``run_dir`` cannot stand for its ledger's
    ``records`` -- missing, refused, damaged, or not what the records give (edited) -- or None
    if it can. A resume asks this before it calls a run finished: a summary is never trusted,
    only recomputed from the ledger (the apps write it again when this says why)."""
    summary, problem = read_summary(run_dir, kind)
    if problem is not None:
        return problem
    name = display_path(Path(run_dir) / kind.summary)
    if (ident := summary.get(RUN_KEY)) is not None and records and ident != records[0].get(RUN_KEY):
        return f"{name} names another run than its ledger's records"
    problems = summary_problems(kind, records, summary, name)
    return problems[0] + (f" (and {len(problems) - 1} more)" if len(problems) > 1 else "") if problems else None


def verify(run_dir, strict: bool = False) -> tuple[list[str], list[str]]:
    """Check a run directory's ledger -- every kind the package writes (:func:`ledger_kinds`:
    ``chains.jsonl``, ``matches.jsonl``, the benchmark's ``units.jsonl``) -- record by record
    and its summary against it (the kind's check: ``results.json``'s values are the ledger's
    chain lengths in seed order; ``league.json``'s pair tables and Elo ratings are the ones its
    matches give). Every file is read through :func:`read_run_bytes`: a link, a FIFO, a file
    past its bound or JSON nested too deep is a problem, named, never read. Returns (problems,
    notes), one sentence each. Records whose seal or run identity is missing are checked on
    their shape and are a note (a problem with ``strict``, or when the summary names the run's
    identity: such a run seals every record with it)."""
    run_dir = Path(run_dir)
    known = ledger_kinds()
    kinds = [k for k in known if os.path.lexists(run_dir / k.file)]
    if not kinds:
        missing = [f"{display_path(run_dir)}: no ledger ({' or '.join(k.file for k in known)}) there"]
        return missing + [f"the ledger kind {p} could not be loaded ({why})" for p, why in _UNAVAILABLE.items()], []
    problems: list[str] = []
    notes: list[str] = []
    if (holder := lock_holder(run_dir)) is not None:
        notes.append(f"{display_path(run_dir)} is being written now ({holder.describe()}): its ledger may grow and its "
                     f"summary be written again")
    for kind in kinds:
        path, spath = run_dir / kind.file, run_dir / kind.summary
        summary, problem = read_summary(run_dir, kind)
        if problem is not None:
            problems.append(problem)
        run = summary.get(RUN_KEY) if summary is not None else None
        run = run if isinstance(run, str) else None
        try:
            data = read_run_bytes(path, "ledger")
        except RunFileError as err:
            problems.append(str(err))
            continue
        except OSError as err:
            problems.append(f"{display_path(path)} cannot be read ({err.strerror or type(err).__name__})")
            continue
        scan = scan_ledger(data, display_path(path), kind, run, unchecked=run is None)
        problems += scan.problems
        if scan.torn is not None:
            problems.append(f"{display_path(path)}: line {scan.torn} is torn (no newline: a kill mid-append); "
                            f"resume cuts it off and plays its unit again")
        if summary is not None:
            if kind.check is None:
                notes.append(f"{display_path(spath)}: its figures are not checked against the ledger (the {kind.what} "
                             f"kind registers no check)")
            problems += summary_problems(kind, scan.records, summary, display_path(spath))
        if scan.unchecked:
            n, unsealed = len(scan.unchecked), len(scan.unsealed)
            what = ("carry no seal: their shape is checked, their content cannot be" if unsealed == n else
                    f"carry a seal but no run identity{f' ({unsealed} no seal either)' if unsealed else ''}: "
                    f"their shape and seals are checked, which run wrote them cannot be")
            say = f"{display_path(path)}: {n} of {len(scan.records)} records {what}; such a run is not resumed"
            (problems if strict else notes).append(say)
        else:
            notes.append(f"{display_path(path)}: {len(scan.records)} sealed records"
                         + (f" of run {_shown_ident(scan.records[0][RUN_KEY])}" if scan.records else ""))
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
    vp = sub.add_parser("verify", help="check each run directory's ledger (every kind the package writes: chains.jsonl, "
                                       "matches.jsonl, units.jsonl) record by record and its summary (results.json, "
                                       "league.json, scorecard.json) against it; one line per problem, exit status 1 if any")
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
    # `python -m billiards.files` runs this file as __main__: run the package's own module, whose
    # ledger registry (LedgerKind) is the one every provider registers into
    from billiards.files import main as _main

    raise SystemExit(_main())
