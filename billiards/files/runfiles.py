"""The one reader of a run folder's files (:func:`open_run_file`, :func:`read_run_bytes`,
:func:`read_run_text`, :func:`read_run_json`): regular files only, no link followed, a size
bound per kind (:data:`RUN_FILE_LIMITS`), a depth bound on JSON (:func:`json_depth_problem`,
:func:`parse_json`), and sentences that name a file and never quote it (:class:`RunFileError`)."""

from __future__ import annotations

import contextlib
import errno
import os
import re
import stat
from pathlib import Path
from typing import IO, Any, Iterator

from .paths import display_path

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
