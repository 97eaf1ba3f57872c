"""One writer per run folder: :func:`run_lock` holds the folder's lock file (:data:`LOCK_FILE`)
for a run's lifetime, refusing a second live writer (:class:`RunLockedError`) and taking over a
dead one's; :func:`lock_holder` only looks."""

from __future__ import annotations

import contextlib
import errno
import os
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

from .paths import display_path, recorded_command
from .runfiles import _CLOEXEC, _NOFOLLOW, _not_regular, json_depth_problem, read_run_bytes

#
# A run folder has one writer: a run takes the folder's lock file (LOCK_FILE) for its lifetime
# (run_lock) and writes into it who it is; a second writer is refused at once, naming the first.
# The lock is an flock(2) on the file, which the kernel lets go when its holder dies however it
# dies: a lock file whose flock nobody holds is a dead run's, and is taken over with a note.
# Where flock is missing (no fcntl, a file system without it), the recorded pid is checked instead
# (alive on this host: held; another host: held, since it cannot be told).

LOCK_FILE = ".lock"  # in a run folder while a run writes it (readers and the directory checks ignore it)


def run_folder_names(d: Path | str) -> list[str]:
    """The names in the folder ``d``, sorted, but its lock file: a lock (left by a run killed
    while it wrote) belongs to whatever run the rest is and says nothing alone, so a folder
    holding only a lock is an empty one. Raises OSError if ``d`` cannot be listed."""
    return sorted(n for n in os.listdir(d) if n != LOCK_FILE)


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
